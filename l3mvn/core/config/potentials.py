"""Settings of the PONI policy (``--policy poni``): the map window its network reads, what its two
potentials mean, and how the policy turns them into a frontier choice.

The network (``l3mvn.agent.potentials``) reads the agent's map around the agent, ``input_window_m`` wide,
pooled to ``cell_m`` cells. Its object potential for a goal at a frontier is ``1 - d / range_m``
(clipped to [0, 1]), d the geodesic metres from the frontier to the goal's nearest instance; its area
potential is the unexplored floor reachable through the frontier, over ``area_scale_m2`` (clipped).
Training (``l3mvn poni train``) writes these numbers into the checkpoint, and whether the totals it
learned through carry the size bonus; a checkpoint trained with other ones is refused, since its
outputs would be read on the wrong scale or against the wrong criterion.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from l3mvn.core.errors import L3MVNError


@dataclass(frozen=True)
class PotentialConfig:
    checkpoint: str | None = None  # a .pt file from ``l3mvn poni train``; None: the shipped one
    cell_m: float = 0.2  # the network's cell: four 5 cm map cells a side
    input_window_m: float = 25.6  # the window it reads, centred on the agent (128 cells of 0.2 m)
    range_m: float = 12.0  # the object potential reaches zero this many geodesic metres from the goal
    area_scale_m2: float = 40.0  # this much unexplored floor through a frontier is an area potential of 1
    # Selection: least (metres to the frontier - area_bonus_m x area potential - size bonus + expected
    # metres on to the goal), the expected metres being range_m x (1 - object potential). A frontier
    # beyond the window is read as potential 0 (range_m on to the goal, no area).
    area_bonus_m: float = 3.0
    # The size bonus is cost-utility's U / frontiers.cu_lambda: a wide frontier opens a room seen from
    # its mouth, which the area potential (floor behind it) does not measure. The walks' stage learns
    # the potentials through the same totals, so the net corrects the bonus where the goal does not
    # follow a frontier's width; a checkpoint fixes whether it was trained with it.
    size_bonus: bool = True

    def __post_init__(self) -> None:
        for name in ("cell_m", "input_window_m", "range_m", "area_scale_m2"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise L3MVNError(f"poni.{name} must be a positive number, got {value}")
        if not (math.isfinite(self.area_bonus_m) and self.area_bonus_m >= 0):
            raise L3MVNError(f"poni.area_bonus_m must be a non-negative number, got {self.area_bonus_m}")
        cells = self.input_window_m / self.cell_m
        if abs(cells - round(cells)) > 1e-6 or round(cells) % 8:
            raise L3MVNError(
                f"poni.input_window_m / poni.cell_m must be a whole multiple of 8 cells (the network halves it "
                f"three times), got {self.input_window_m} / {self.cell_m}"
            )
        if self.checkpoint is not None and not self.checkpoint.strip():
            raise L3MVNError("poni.checkpoint must name a .pt file from `l3mvn poni train`, or be left unset")

    @property
    def window_cells(self) -> int:
        return round(self.input_window_m / self.cell_m)

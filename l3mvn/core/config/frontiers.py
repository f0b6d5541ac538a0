"""Frontier extraction and cost-utility scoring (paper defaults); distances are measured on the
agent's map, at its resolution (``MapConfig.resolution_m``)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from l3mvn.core.errors import L3MVNError

UTILITY_MODES = ("paper", "official_code")
EDGE_MODES = ("largest", "all")


@dataclass(frozen=True)
class FrontierConfig:
    """Every constant of frontier extraction and cost-utility scoring (paper defaults).

    Units: ``*_cells`` in map cells, ``*_m`` in metres. ``cu_lambda`` is in cells of frontier per
    metre of travel (the paper gives no value): the default 40 makes one metre of walking cost as
    much as two metres of frontier are worth. With a cheaper walk (a smaller lambda) a large far
    cluster wins over the small room next door, and toilet episodes suffer most (the spec's
    lessons). ``utility="official_code"`` scores ``size + near_bonus`` when the
    frontier is closer than ``near_bonus_m`` and ignores the cost term; use ``official_code()`` for
    the code's full setting (top 4). ``edge="largest"`` keeps the contour of the largest explored blob
    only (the paper); ``"all"`` keeps the outer contour of every explored blob.
    """

    min_cluster_cells: int = 5
    min_distance_m: float = 0.5
    max_distance_m: float = 5.0
    obstacle_dilation_cells: int = 1
    cu_lambda: float = 40.0
    utility: str = "paper"
    near_bonus: float = 8.0
    near_bonus_m: float = 3.0
    top_k: int | None = None
    edge: str = "largest"
    window_m: float = 3.0
    # Cost of turning to face a frontier, metres per radian (0: the paper's pure geodesic cost).
    # Turning is charged like walking: one 30-degree turn = one 0.25 m step.
    turn_cost_m_per_rad: float = 0.25 / (math.pi / 6)

    def __post_init__(self) -> None:
        if self.utility not in UTILITY_MODES:
            raise L3MVNError(f"unknown frontier utility {self.utility!r}; choose one of {', '.join(UTILITY_MODES)}")
        if self.edge not in EDGE_MODES:
            raise L3MVNError(f"unknown frontier edge {self.edge!r}; choose one of {', '.join(EDGE_MODES)}")
        if self.min_cluster_cells < 1:
            raise L3MVNError(f"min_cluster_cells must be >= 1, got {self.min_cluster_cells}")
        if self.obstacle_dilation_cells < 0:
            raise L3MVNError(f"obstacle_dilation_cells must be >= 0, got {self.obstacle_dilation_cells}")
        if not 0 <= self.min_distance_m < self.max_distance_m:
            raise L3MVNError(
                f"frontier distances must satisfy 0 <= min_distance_m < max_distance_m, "
                f"got {self.min_distance_m} and {self.max_distance_m}"
            )
        if self.top_k is not None and self.top_k < 1:
            raise L3MVNError(f"top_k must be >= 1 or None (keep all), got {self.top_k}")
        for name in ("cu_lambda", "near_bonus", "near_bonus_m", "window_m", "turn_cost_m_per_rad"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise L3MVNError(f"{name} must be a finite number >= 0, got {value}")

    @classmethod
    def official_code(cls, **overrides: Any) -> FrontierConfig:
        """The authors' code: utility = size (+8 within 3 m), no cost term, best 4 kept."""
        settings: dict[str, Any] = {"utility": "official_code", "top_k": 4}
        settings.update(overrides)
        return cls(**settings)

    def window_cells(self, resolution_m: float) -> int:
        """Half size of the objects window, in cells of a map at ``resolution_m``."""
        return int(round(self.window_m / resolution_m))

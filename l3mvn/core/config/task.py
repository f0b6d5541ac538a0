"""The ObjectNav task: what counts as success, and the thresholds behind each failure cause."""

from __future__ import annotations

import math
from dataclasses import dataclass

from l3mvn.core.errors import L3MVNError

SUCCESS_RULES = ("semexp", "geodesic", "hm3d", "mp3d")
# Habitat's ObjectNav rule for HM3D and MP3D episode files: success is standing within
# ``view_point_distance_m`` (geodesic) of any view point of a goal instance, the positions the file
# lists from which that instance is in view. It needs view points, so only scans read from such a
# file have it.
VIEW_POINT_RULES = ("hm3d", "mp3d")


@dataclass(frozen=True)
class TaskConfig:
    """Success rule and distance (SemExp's Gibson rule by default, as in the paper's table), and the
    measures that name a failure."""

    success_rule: str = "semexp"
    success_distance_m: float = 1.0
    view_point_distance_m: float = 0.1
    # The target counts as seen once this share of a frame shows it with valid depth.
    seen_fraction: float = 0.001
    # Forward moves over which the collision rate is measured; at this rate or above a run that ran
    # out of steps is "stuck".
    collision_window: int = 50
    stuck_collision_rate: float = 0.5
    # The share of the reachable floor seen above which a target never seen counts as hidden rather
    # than not yet explored.
    explored_coverage: float = 0.9
    # The goal counts as confirmed in view once this many connected cells of it were seen with valid
    # depth (the measure's counterpart of the agent's AgentConfig.target_min_cells, judged on the truth).
    confirm_min_cells: int = 4
    # Frames are judged strided to at most this many rows (what the task reads of a frame, not the agent).
    view_rows: int = 120

    def __post_init__(self) -> None:
        if self.success_rule not in SUCCESS_RULES:
            raise L3MVNError(f"unknown success rule {self.success_rule!r}; choose one of {', '.join(SUCCESS_RULES)}")
        if not (math.isfinite(self.success_distance_m) and self.success_distance_m > 0):
            raise L3MVNError(f"success_distance_m must be a positive finite number, got {self.success_distance_m}")
        if not (math.isfinite(self.view_point_distance_m) and self.view_point_distance_m > 0):
            raise L3MVNError(
                f"view_point_distance_m must be a positive finite number, got {self.view_point_distance_m}"
            )
        for name in ("collision_window", "confirm_min_cells", "view_rows"):
            if getattr(self, name) < 1:
                raise L3MVNError(f"{name} must be >= 1, got {getattr(self, name)}")
        for name in ("seen_fraction", "stuck_collision_rate", "explored_coverage"):
            if not 0 < getattr(self, name) <= 1:
                raise L3MVNError(f"{name} must lie in (0, 1], got {getattr(self, name)}")

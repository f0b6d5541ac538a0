"""Map building: resolution, size, height bands, thresholds (the agent's map, not the scene's).

The sensor's depth range and the agent's body radius are the simulator's (``SimConfig``): the mapper
reads them from there, so they are set once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from l3mvn.core.errors import L3MVNError

_UINT16_MAX = 65535  # category hit counts are uint16


@dataclass(frozen=True)
class MapConfig:
    """Every constant of map building (spec defaults; 36 m is the Gibson map, use 48 m for large houses).

    Height bands, in metres above the floor: obstacle = [obstacle_min_height_m, camera height +
    obstacle_above_camera_m]; explored = [floor_min_height_m, obstacle top] (floor points included);
    categories = [floor_min_height_m, category_max_height_m], deliberately not tied to the obstacle band
    so an object seen over low furniture or on the floor still registers.
    """

    resolution_m: float = 0.05
    # 48 m: a 36 m map reaches only 18 m from the start, and large Gibson houses are over 30 m wide.
    map_size_m: float = 48.0
    local_map_divisor: int = 2
    obstacle_min_height_m: float = 0.25
    obstacle_above_camera_m: float = 0.5
    # Points below this are depth noise or a hole in the floor, not evidence about this floor.
    floor_min_height_m: float = -0.4
    # SemExp's voxel grid top: ceiling-mounted or tall objects (a wall TV) still count.
    category_max_height_m: float = 3.6
    category_point_threshold: int = 5
    # Free-space carving: cells between the camera and what it saw are explored too (bearings are
    # binned this finely across the view; 0 turns it off). Without it, floor nearer than the lowest
    # image row (1.4 m at tilt 0) stays unexplored and leaves phantom frontiers along every wall.
    free_space_bins: int = 160
    # A cell is "looked at" once seen from within this distance: close enough that an object there
    # would have mapped to enough cells to confirm. Explored from farther (a room seen through a
    # door across the house) tells where the floor is, not what stands on it.
    look_distance_m: float = 2.5

    def __post_init__(self) -> None:
        if not (math.isfinite(self.resolution_m) and self.resolution_m > 0):
            raise L3MVNError(f"resolution_m must be positive, got {self.resolution_m}")
        cells = self.map_size_m / self.resolution_m
        whole = math.isfinite(cells) and abs(cells - round(cells)) < 1e-6
        if not (whole and cells >= 2 and round(cells) % 2 == 0):
            raise L3MVNError(
                "map_size_m / resolution_m must be an even whole number of cells (e.g. 36 or 48 m at "
                f"0.05 m), got {self.map_size_m} / {self.resolution_m}"
            )
        if self.local_map_divisor < 1 or self.map_cells % self.local_map_divisor:
            raise L3MVNError(
                f"local_map_divisor must be >= 1 and divide the {self.map_cells} map cells, "
                f"got {self.local_map_divisor}"
            )
        if not self.floor_min_height_m < self.obstacle_min_height_m:
            raise L3MVNError("height bands must satisfy floor_min_height_m < obstacle_min_height_m")
        if not self.floor_min_height_m < self.category_max_height_m:
            raise L3MVNError("height bands must satisfy floor_min_height_m < category_max_height_m")
        if not 1 <= self.category_point_threshold <= _UINT16_MAX:
            raise L3MVNError(f"category_point_threshold must lie in 1..65535, got {self.category_point_threshold}")
        if self.free_space_bins < 0:
            raise L3MVNError(
                f"free_space_bins must be >= 0 (0 turns free-space carving off), got {self.free_space_bins}"
            )
        if not (math.isfinite(self.look_distance_m) and self.look_distance_m > 0):
            raise L3MVNError(f"look_distance_m must be positive, got {self.look_distance_m}")

    @property
    def map_cells(self) -> int:
        return int(round(self.map_size_m / self.resolution_m))

    @property
    def local_cells(self) -> int:
        return self.map_cells // self.local_map_divisor

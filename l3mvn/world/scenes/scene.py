"""A floor of a house as a top-down semantic grid: the one format every scene source produces.

SemExp-format Gibson maps load into it directly; procedural houses are generated into it; the 3D
world, collisions and ground-truth geodesics are all derived from it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import cast, overload

import numpy as np
from scipy import ndimage as ndi

from l3mvn.core.categories import GOAL_CATEGORIES
from l3mvn.core.errors import L3MVNError
from l3mvn.core.grid import disk
from l3mvn.core.types import Pose, wrap_angle


@dataclass(frozen=True, eq=False)
class SceneMap:
    """One floor. ``navigable`` is the navmesh (channel 0, already eroded by the agent radius);
    ``objects[k]`` is the filled footprint of ``categories[k]``; cells that are neither are walls or
    unlabelled furniture. Cells are ``resolution_m`` wide; ``origin_cm`` is SemExp's (ox, oy)."""

    name: str
    floor: int
    categories: tuple[str, ...]
    navigable: np.ndarray
    objects: np.ndarray
    origin_cm: tuple[float, float] = (0.0, 0.0)
    floor_height_m: float = 0.0
    resolution_m: float = 0.05
    free_recovery_cells: int = 2
    traversible_dilation_cells: int = 2

    def __post_init__(self) -> None:
        nav, obj = self.navigable, self.objects
        if not (isinstance(nav, np.ndarray) and isinstance(obj, np.ndarray)):
            raise L3MVNError(f"scene {self.name}: navigable and objects must be numpy arrays")
        if nav.dtype.kind not in "biuf" or obj.dtype.kind not in "biuf":
            raise L3MVNError(
                f"scene {self.name}: navigable and objects must be numeric arrays, got {nav.dtype} and {obj.dtype}"
            )
        self._check_geometry()
        if nav.ndim != 2 or obj.ndim != 3 or obj.shape[1:] != nav.shape:
            raise L3MVNError(f"scene {self.name}: navigable {nav.shape} and objects {obj.shape} shapes disagree")
        if obj.shape[0] != len(self.categories):
            raise L3MVNError(f"scene {self.name}: {obj.shape[0]} object channels for {len(self.categories)} categories")
        if not nav.any():
            raise L3MVNError(f"scene {self.name} floor {self.floor}: no navigable cell")
        object.__setattr__(self, "navigable", nav.astype(bool, copy=False))
        object.__setattr__(self, "objects", obj.astype(bool, copy=False))

    def _check_geometry(self) -> None:
        """Non-finite or non-positive geometry would turn every pose conversion into NaN or an overflow."""
        if not (math.isfinite(self.resolution_m) and self.resolution_m > 0):
            raise L3MVNError(
                f"scene {self.name}: resolution_m must be a positive finite number, got {self.resolution_m}"
            )
        if len(self.origin_cm) != 2 or not all(math.isfinite(v) for v in self.origin_cm):
            raise L3MVNError(f"scene {self.name}: origin_cm must be two finite numbers, got {self.origin_cm}")
        if not math.isfinite(self.floor_height_m):
            raise L3MVNError(f"scene {self.name}: floor_height_m must be finite, got {self.floor_height_m}")

    @property
    def key(self) -> str:
        return f"{self.name}/{self.floor}"

    @property
    def shape(self) -> tuple[int, int]:
        return self.navigable.shape

    @cached_property
    def object_any(self) -> np.ndarray:
        # numpy's stubs allow a scalar for any reduction along an axis; of a 3-D grid it is a 2-D array.
        return cast(np.ndarray, self.objects.any(axis=0))

    @cached_property
    def free(self) -> np.ndarray:
        """Free floor: the navmesh grown back by the erosion margin, never into an object."""
        grown = ndi.binary_dilation(self.navigable, disk(self.free_recovery_cells))
        return grown & ~self.object_any

    @cached_property
    def traversible(self) -> np.ndarray:
        """SemExp's ground-truth traversible grid (channel 0 dilated by a 2-cell disk)."""
        return ndi.binary_dilation(self.navigable, disk(self.traversible_dilation_cells))

    @cached_property
    def walkable(self) -> np.ndarray:
        """Where the agent's centre may stand: the navmesh plus one cell of rasterisation slack."""
        return ndi.binary_dilation(self.navigable, disk(1)) & ~self.object_any

    def category_mask(self, category: str) -> np.ndarray:
        if category not in self.categories:
            raise L3MVNError(f"unknown category {category!r} in scene {self.name}; valid: {', '.join(self.categories)}")
        return self.objects[self.categories.index(category)]

    def present_goals(self, goals: tuple[str, ...] = GOAL_CATEGORIES) -> list[str]:
        return [g for g in goals if g in self.categories and self.category_mask(g).any()]

    # --- coordinates -------------------------------------------------------------------------
    def cell_of(self, x: float, y: float) -> tuple[int, int]:
        return int(math.floor(y / self.resolution_m)), int(math.floor(x / self.resolution_m))

    @overload
    def cell_center(self, row: float, col: float) -> tuple[float, float]: ...

    @overload
    def cell_center(self, row: np.ndarray, col: np.ndarray) -> tuple[np.ndarray, np.ndarray]: ...

    def cell_center(
        self, row: float | np.ndarray, col: float | np.ndarray
    ) -> tuple[float | np.ndarray, float | np.ndarray]:
        """World (x, y) of a cell's centre (element-wise for arrays of rows and columns)."""
        return (col + 0.5) * self.resolution_m, (row + 0.5) * self.resolution_m

    def in_bounds(self, row: int, col: int) -> bool:
        h, w = self.shape
        return 0 <= row < h and 0 <= col < w

    @property
    def extent_m(self) -> tuple[float, float]:
        """World size (x, y) of the grid in metres: it covers ``0 <= x < width`` and ``0 <= y < height``."""
        h, w = self.shape
        return w * self.resolution_m, h * self.resolution_m

    def contains(self, x: float, y: float) -> bool:
        """Whether a world point lies on the grid. Check it before ``cell_of``: a point such as 1e308
        overflows there, and any point off the grid indexes outside the arrays."""
        width, height = self.extent_m
        return 0.0 <= x < width and 0.0 <= y < height and self.in_bounds(*self.cell_of(x, y))

    def extent_text(self) -> str:
        """The grid's extent for error messages, in our frame and in the Habitat frame of episode files."""
        width, height = self.extent_m
        ox, oy = self.origin_cm[0] / 100.0, self.origin_cm[1] / 100.0
        return (
            f"x 0..{width:.2f} m, y 0..{height:.2f} m (Habitat p2 {ox:.2f}..{ox + width:.2f}, "
            f"p0 {oy:.2f}..{oy + height:.2f})"
        )

    def pose_from_habitat(self, position: list[float], rotation_wxyz: list[float]) -> Pose:
        """Habitat position ``[p0, p1 (up), p2]`` and a (w, x, y, z) yaw quaternion -> our pose.

        SemExp maps put ``p0`` on rows and ``p2`` on columns; habitat's forward is ``-z``, which
        after that axis swap makes our heading equal habitat's yaw plus pi.
        """
        p0, _, p2 = (float(v) for v in position)
        w, _, qy, _ = (float(v) for v in rotation_wxyz)
        yaw = 2.0 * math.atan2(qy, w)
        ox, oy = self.origin_cm
        return Pose(x=p2 - ox / 100.0, y=p0 - oy / 100.0, heading=wrap_angle(yaw + math.pi))

    def pose_to_habitat(self, pose: Pose) -> tuple[list[float], list[float]]:
        ox, oy = self.origin_cm
        yaw = wrap_angle(pose.heading - math.pi)
        position = [pose.y + oy / 100.0, self.floor_height_m, pose.x + ox / 100.0]
        rotation = [math.cos(yaw / 2.0), 0.0, math.sin(yaw / 2.0), 0.0]
        return position, rotation

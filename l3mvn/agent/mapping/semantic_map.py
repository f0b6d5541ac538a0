"""Top-down semantic map built from depth, semantic ids and an odometry pose: no simulator needed.

Map frame: the start pose's position sits at the corner between the four centre cells, axes are the
odometry axes (heading preserved), so a cell is ``(row, col) = (floor(dy / res) + M/2, floor(dx / res)
+ M/2)`` with ``dx, dy`` the offset from the start (see ``l3mvn.core.types`` for the world frame).
Heights are measured from the floor the agent stands on (z = 0).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import overload

import numba as nb
import numpy as np
import numpy.typing as npt

from l3mvn.core.camera import CameraIntrinsics, depth_to_points, too_near_points
from l3mvn.core.compiled import hypot32
from l3mvn.core.config import MapConfig, SimConfig
from l3mvn.core.errors import L3MVNError
from l3mvn.core.grid import disk
from l3mvn.core.types import Pose, wrap_angle


@dataclass(frozen=True, eq=False)
class LocalWindow:
    """The agent-centred window (clamped to the map): rows ``r0:r1``, cols ``c0:c1``; arrays are views."""

    bounds: tuple[int, int, int, int]
    obstacle: np.ndarray
    explored: np.ndarray
    visited: np.ndarray
    categories: np.ndarray
    agent_cell: tuple[int, int]


@dataclass(frozen=True, eq=False)
class SemanticMap:
    """The map as the rest of the agent sees it. (M, M) / (K, M, M) bool grids, row = y, col = x.

    The arrays are live views of the mapper's state (no per-step copy of a 960x960xK map): they change
    on the next ``update``; call ``copy()`` to keep a snapshot. ``looked`` is the part of ``explored``
    seen from within ``MapConfig.look_distance_m`` (see there). ``inferred`` is the part of
    ``obstacle`` only guessed from depth readings nearer than the sensor's minimum range (None: no
    guesses). ``start_xy`` is the world position of the map centre; ``agent_heading`` is in radians,
    counter-clockwise from +x.
    """

    obstacle: np.ndarray
    explored: np.ndarray
    visited: np.ndarray
    categories: np.ndarray
    category_names: tuple[str, ...]
    looked: np.ndarray
    resolution_m: float
    start_xy: tuple[float, float]
    agent_cell: tuple[int, int]
    agent_heading: float
    local_cells: int
    footprint_radius_cells: int
    inferred: np.ndarray | None = None

    @property
    def size(self) -> int:
        size: int = self.obstacle.shape[0]  # numpy types a shape's entries as Any
        return size

    @property
    def current(self) -> np.ndarray:
        """Current-location channel: the agent's footprint disk (built on demand)."""
        grid = np.zeros_like(self.obstacle)
        rr, cc = _footprint_cells(self.agent_cell, self.footprint_radius_cells, self.size)
        grid[rr, cc] = True
        return grid

    @property
    def seen_obstacle(self) -> np.ndarray:
        """``obstacle`` less its guesses (``inferred``): the obstacles depth actually hit (allocates)."""
        return self.obstacle if self.inferred is None else self.obstacle & ~self.inferred

    def in_bounds(self, row: int, col: int) -> bool:
        return 0 <= row < self.size and 0 <= col < self.size

    def world_to_cell(self, x: float, y: float) -> tuple[int, int]:
        row, col = _cell(x - self.start_xy[0], y - self.start_xy[1], self.resolution_m, self.size)
        if not self.in_bounds(row, col):
            raise L3MVNError(
                f"world point ({x:.2f}, {y:.2f}) lies off the {self.size}x{self.size} map (cell {row}, {col})"
            )
        return row, col

    @overload
    def cell_to_world(self, row: int, col: int) -> tuple[float, float]: ...

    @overload
    def cell_to_world(self, row: np.ndarray, col: np.ndarray) -> tuple[np.ndarray, np.ndarray]: ...

    def cell_to_world(
        self, row: int | np.ndarray, col: int | np.ndarray
    ) -> tuple[float | np.ndarray, float | np.ndarray]:
        """World (x, y) of the cell's centre; rows and columns may be arrays."""
        half = self.size // 2
        return (
            self.start_xy[0] + (col - half + 0.5) * self.resolution_m,
            self.start_xy[1] + (row - half + 0.5) * self.resolution_m,
        )

    def explored_at(self, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
        """Whether each world point (x, y) lies on an explored cell; points off the map are not."""
        rows, cols = _cells(
            np.asarray(xs) - self.start_xy[0], np.asarray(ys) - self.start_xy[1], self.resolution_m, self.size
        )
        ok = (rows >= 0) & (rows < self.size) & (cols >= 0) & (cols < self.size)
        out = np.zeros(rows.shape, dtype=bool)
        out[ok] = self.explored[rows[ok], cols[ok]]
        return out

    def category(self, name: str) -> npt.NDArray[np.bool_]:
        if name not in self.category_names:
            raise L3MVNError(f"unknown map category {name!r}; valid: {', '.join(self.category_names)}")
        plane: npt.NDArray[np.bool_] = self.categories[self.category_names.index(name)]  # numpy: indexing is Any
        return plane

    def local_window(self) -> LocalWindow:
        """SemExp's local map: ``local_cells`` square centred on the agent, shifted to stay on the map."""
        size, n = self.size, self.local_cells
        r0 = min(max(self.agent_cell[0] - n // 2, 0), size - n)
        c0 = min(max(self.agent_cell[1] - n // 2, 0), size - n)
        rows, cols = slice(r0, r0 + n), slice(c0, c0 + n)
        return LocalWindow(
            bounds=(r0, r0 + n, c0, c0 + n),
            obstacle=self.obstacle[rows, cols],
            explored=self.explored[rows, cols],
            visited=self.visited[rows, cols],
            categories=self.categories[:, rows, cols],
            agent_cell=(self.agent_cell[0] - r0, self.agent_cell[1] - c0),
        )

    def channels(self) -> np.ndarray:
        """A (4 + K, M, M) bool copy in SemExp's channel order: obstacle, explored, current, visited,
        categories (for recorders and dashboards, not for the per-step hot path)."""
        fixed = np.stack([self.obstacle, self.explored, self.current, self.visited])
        return np.concatenate([fixed, self.categories], axis=0)

    def copy(self) -> SemanticMap:
        return SemanticMap(
            obstacle=self.obstacle.copy(),
            explored=self.explored.copy(),
            visited=self.visited.copy(),
            categories=self.categories.copy(),
            category_names=self.category_names,
            looked=self.looked.copy(),
            resolution_m=self.resolution_m,
            start_xy=self.start_xy,
            agent_cell=self.agent_cell,
            agent_heading=self.agent_heading,
            local_cells=self.local_cells,
            footprint_radius_cells=self.footprint_radius_cells,
            inferred=None if self.inferred is None else self.inferred.copy(),
        )


class SemanticMapper:
    """Accumulates frames into a ``SemanticMap``. Feed it plain arrays from any source.

    ``update`` takes depth (H, W) float metres (0 = invalid), semantic (H, W) int ids (0 = background,
    k = category_names[k - 1]) or None, the odometry pose and the camera tilt in radians.
    """

    def __init__(
        self,
        cfg: MapConfig,
        intrinsics: CameraIntrinsics,
        category_names: tuple[str, ...],
        *,
        max_depth_m: float,
        body_radius_m: float,
        min_depth_m: float = 0.0,
    ) -> None:
        """``max_depth_m``: the sensor's range (readings at or beyond it are saturation, not a
        surface); ``body_radius_m``: the agent's, whose footprint counts as explored;
        ``min_depth_m``: the range below which the sensor reads 0 (0: it reads every range), so an
        invalid ray that would have met the floor within range marks an obstacle nearer than that."""
        names = tuple(category_names)
        if len(set(names)) != len(names):
            raise L3MVNError(f"duplicate map categories in {names}")
        if not (max_depth_m > 0 and body_radius_m >= 0 and 0 <= min_depth_m < max_depth_m):
            raise L3MVNError(
                f"need max_depth_m > 0, body_radius_m >= 0 and 0 <= min_depth_m < max_depth_m, "
                f"got {max_depth_m}, {body_radius_m}, {min_depth_m}"
            )
        self.cfg = cfg
        self.intrinsics = intrinsics
        self.max_depth_m = max_depth_m
        self.min_depth_m = min_depth_m
        self.footprint_radius_cells = int(math.floor(body_radius_m / cfg.resolution_m + 1e-9))
        self.category_names = names
        self.obstacle_max_height_m = intrinsics.camera_height_m + cfg.obstacle_above_camera_m
        if not cfg.obstacle_min_height_m < self.obstacle_max_height_m:
            raise L3MVNError(
                f"obstacle band is empty: obstacle_min_height_m {cfg.obstacle_min_height_m} >= camera height "
                f"+ obstacle_above_camera_m = {self.obstacle_max_height_m}"
            )
        m, k = cfg.map_cells, len(names)
        self._obstacle = np.zeros((m, m), dtype=bool)
        self._inferred = np.zeros((m, m), dtype=bool)  # obstacles only guessed from too-near readings
        self._explored = np.zeros((m, m), dtype=bool)
        self._visited = np.zeros((m, m), dtype=bool)
        self._looked = np.zeros((m, m), dtype=bool)
        self._categories = np.zeros((k, m, m), dtype=bool)
        # Saturates at the threshold: only "reached it or not" matters, and it can never overflow.
        self._counts = np.zeros((k, m, m), dtype=np.uint16)
        self._start: Pose | None = None
        self._cell = (m // 2, m // 2)
        self._heading = 0.0

    @classmethod
    def for_sim(
        cls, cfg: MapConfig, sim: SimConfig, height: int, width: int, category_names: tuple[str, ...]
    ) -> SemanticMapper:
        """A mapper for the simulated robot's camera fed ``height`` x ``width`` frames."""
        return cls(
            cfg,
            CameraIntrinsics.from_sim(sim, height, width),
            category_names,
            max_depth_m=sim.max_depth_m,
            body_radius_m=sim.agent_radius_m,
            min_depth_m=sim.min_depth_m,
        )

    @property
    def map(self) -> SemanticMap:
        if self._start is None:
            raise L3MVNError("the mapper has no map yet: call reset(start_pose) first")
        return SemanticMap(
            obstacle=self._obstacle,
            explored=self._explored,
            visited=self._visited,
            categories=self._categories,
            category_names=self.category_names,
            looked=self._looked,
            inferred=self._inferred,
            resolution_m=self.cfg.resolution_m,
            start_xy=(self._start.x, self._start.y),
            agent_cell=self._cell,
            agent_heading=self._heading,
            local_cells=self.cfg.local_cells,
            footprint_radius_cells=self.footprint_radius_cells,
        )

    def reset(self, start_pose: Pose) -> SemanticMap:
        """Clear everything; ``start_pose`` becomes the map centre (heading kept as is)."""
        for grid in (
            self._obstacle,
            self._inferred,
            self._explored,
            self._visited,
            self._looked,
            self._categories,
            self._counts,
        ):
            grid.fill(0)
        self._start = start_pose
        self._cell = (self.cfg.map_cells // 2, self.cfg.map_cells // 2)
        self._heading = start_pose.heading
        self._visited[self._cell] = True
        self._mark_footprint(self._cell)
        return self.map

    def update(self, depth: np.ndarray, semantic: np.ndarray | None, pose: Pose, tilt: float) -> SemanticMap:
        if self._start is None:
            raise L3MVNError("update() before reset(): call reset(start_pose) first")
        if not math.isfinite(tilt):
            raise L3MVNError(f"non-finite camera tilt {tilt}")
        cfg, size = self.cfg, self.cfg.map_cells
        dx, dy = pose.x - self._start.x, pose.y - self._start.y
        cell = _cell(dx, dy, cfg.resolution_m, size)
        if not (0 <= cell[0] < size and 0 <= cell[1] < size):
            raise L3MVNError(
                f"pose ({pose.x:.2f}, {pose.y:.2f}) is ({dx:+.2f}, {dy:+.2f}) m from the start, off the "
                f"{cfg.map_size_m:g} m map (half width {cfg.map_size_m / 2:g} m); raise MapConfig.map_size_m"
            )
        if semantic is not None and semantic.size:
            lo, hi = int(semantic.min()), int(semantic.max())
            if lo < 0 or hi > len(self.category_names):
                raise L3MVNError(
                    f"semantic ids must lie in 0..{len(self.category_names)} (0 = background, "
                    f"k = category k - 1 of {self.category_names}); got {lo}..{hi}"
                )

        relative = Pose(dx, dy, pose.heading)
        cloud = depth_to_points(depth, self.intrinsics, relative, tilt, semantic, self.max_depth_m)
        seen_obstacle, seen_floor = self._splat(cloud.points, cloud.labels, dx, dy)
        carved = self._carve(cloud.points, dx, dy, pose.heading)
        if self.min_depth_m > 0:
            self._infer_too_near(depth, relative, tilt, seen_obstacle, np.concatenate([seen_floor, carved]))
        self._draw_visited(self._cell, cell)
        self._mark_footprint(cell)
        self._cell = cell
        self._heading = pose.heading
        return self.map

    def _splat(self, points: np.ndarray, labels: np.ndarray, x: float, y: float) -> tuple[np.ndarray, np.ndarray]:
        """Mark the points' cells; returns the flat indices of the cells that got an obstacle point and
        of those that got a floor point."""
        cfg, f32 = self.cfg, np.float32
        seen_obstacle = np.empty(len(points), np.int64)
        seen_floor = np.empty(len(points), np.int64)
        n_obstacle, n_floor = _splat_points(
            np.ascontiguousarray(points, dtype=np.float32),
            np.ascontiguousarray(labels, dtype=np.int32),
            f32(x),
            f32(y),
            f32(cfg.resolution_m),
            cfg.map_cells,
            np.array(
                [
                    cfg.floor_min_height_m,
                    self.obstacle_max_height_m,
                    cfg.obstacle_min_height_m,
                    cfg.category_max_height_m,
                    cfg.look_distance_m,
                ],
                dtype=np.float32,
            ),
            cfg.category_point_threshold,
            self._explored,
            self._looked,
            self._obstacle,
            self._counts,
            self._categories,
            seen_obstacle,
            seen_floor,
        )
        return seen_obstacle[:n_obstacle], seen_floor[:n_floor]

    def _carve(self, points: np.ndarray, x: float, y: float, heading: float) -> np.ndarray:
        """Mark explored along each viewing bearing up to the first obstacle point, or up to the
        farthest floor point seen on that bearing; returns the flat indices of the cells marked."""
        cfg, bins = self.cfg, self.cfg.free_space_bins
        none = np.empty(0, dtype=np.int64)
        if bins <= 0 or len(points) == 0:
            return none
        z = points[:, 2]
        keep = (z >= cfg.floor_min_height_m) & (z <= self.obstacle_max_height_m)
        px, py, z = points[keep, 0] - x, points[keep, 1] - y, z[keep]
        if len(px) == 0:
            return none
        dist = np.hypot(px, py).astype(np.float64)  # exact; ufunc.at is ~20x slower when it must cast
        bearing = wrap_angle(np.arctan2(py, px) - heading)
        half = math.radians(self.intrinsics.hfov_deg) / 2
        idx = np.clip(((bearing + half) / (2 * half) * bins).astype(np.int64), 0, bins - 1)
        obstacle = z >= cfg.obstacle_min_height_m
        reach = np.zeros(bins)
        np.maximum.at(reach, idx[~obstacle], dist[~obstacle])
        nearest = np.full(bins, np.inf)
        np.minimum.at(nearest, idx[obstacle], dist[obstacle])
        reach = np.where(np.isfinite(nearest), nearest - cfg.resolution_m, reach)
        steps = np.arange(int(math.ceil(reach.max() / cfg.resolution_m)) + 1) * cfg.resolution_m
        if len(steps) < 2:
            return none
        angles = heading - half + (np.arange(bins) + 0.5) * (2 * half / bins)
        ok = steps[None, :] < reach[:, None]
        xs = (x + steps[None, :] * np.cos(angles)[:, None])[ok]
        ys = (y + steps[None, :] * np.sin(angles)[:, None])[ok]
        size, half_cells = cfg.map_cells, cfg.map_cells // 2
        cols = np.floor(xs / cfg.resolution_m).astype(np.int64) + half_cells
        rows = np.floor(ys / cfg.resolution_m).astype(np.int64) + half_cells
        inside = (rows >= 0) & (rows < size) & (cols >= 0) & (cols < size)
        flat: npt.NDArray[np.int64] = rows[inside] * size + cols[inside]
        self._explored.reshape(-1)[flat] = True
        near = np.broadcast_to(steps[None, :] <= cfg.look_distance_m, ok.shape)[ok][inside]
        self._looked.reshape(-1)[flat[near]] = True
        return flat

    def _infer_too_near(
        self, depth: np.ndarray, pose: Pose, tilt: float, seen_obstacle: np.ndarray, seen_free: np.ndarray
    ) -> None:
        """Obstacles nearer than the sensor's minimum range (``too_near_points``) are a guess, put at
        the farthest such an obstacle can be: in front of a wall that lies inside it, but round a
        corner (a door frame) it is floor. So a guess never lands on floor the map has seen, floor
        seen later takes it back, and an obstacle seen there makes it a real one. A guess leaves its
        cell unexplored: guesses beyond a door frame marked explored would close the frontier into
        the room, and a goal just beyond that frontier would never be found."""
        cfg, size = self.cfg, self.cfg.map_cells
        obstacle, inferred = self._obstacle.reshape(-1), self._inferred.reshape(-1)
        inferred[seen_obstacle] = False
        back = seen_free[inferred[seen_free]]
        obstacle[back] = False
        inferred[back] = False
        points = too_near_points(depth, self.intrinsics, pose, tilt, self.min_depth_m, self.max_depth_m)
        points = points[points[:, 2] >= cfg.obstacle_min_height_m]  # below the band it could be floor
        rows, cols = _cells(points[:, 0], points[:, 1], cfg.resolution_m, size)
        inside = (rows >= 0) & (rows < size) & (cols >= 0) & (cols < size)
        flat = np.unique(rows[inside] * size + cols[inside])
        new = flat[~self._explored.reshape(-1)[flat]]  # never a cell already seen, free or obstacle
        obstacle[new] = True
        inferred[new] = True

    def _draw_visited(self, start: tuple[int, int], end: tuple[int, int]) -> None:
        """Rasterise the step as an 8-connected line so the trajectory has no gaps."""
        dr, dc = end[0] - start[0], end[1] - start[1]
        steps = max(abs(dr), abs(dc))
        t = np.arange(steps + 1) / max(steps, 1)
        rows = np.rint(start[0] + t * dr).astype(np.int64)
        cols = np.rint(start[1] + t * dc).astype(np.int64)
        self._visited[rows, cols] = True

    def _mark_footprint(self, cell: tuple[int, int]) -> None:
        rr, cc = _footprint_cells(cell, self.footprint_radius_cells, self.cfg.map_cells)
        self._explored[rr, cc] = True
        self._looked[rr, cc] = True


def _cells(
    dx: float | np.ndarray, dy: float | np.ndarray, resolution_m: float, size: int
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """(rows, cols) of offsets (dx, dy) from the map centre, in metres; scalars or arrays."""
    half = size // 2
    rows = np.floor(np.asarray(dy) / resolution_m).astype(np.int64) + half
    cols = np.floor(np.asarray(dx) / resolution_m).astype(np.int64) + half
    return rows, cols


def _cell(dx: float, dy: float, resolution_m: float, size: int) -> tuple[int, int]:
    row, col = _cells(dx, dy, resolution_m, size)
    return int(row), int(col)


def _footprint_cells(cell: tuple[int, int], radius: int, size: int) -> tuple[np.ndarray, np.ndarray]:
    """Cells of a disk around ``cell``, clipped to the map."""
    dr, dc = np.nonzero(disk(radius))
    rr, cc = dr - radius + cell[0], dc - radius + cell[1]
    inside = (rr >= 0) & (rr < size) & (cc >= 0) & (cc < size)
    return rr[inside], cc[inside]


@nb.njit(cache=True)
def _splat_points(
    points: np.ndarray,
    labels: np.ndarray,
    x: float,
    y: float,
    res: float,
    size: int,
    heights: np.ndarray,
    threshold: int,
    explored: np.ndarray,
    looked: np.ndarray,
    obstacle: np.ndarray,
    counts: np.ndarray,
    categories: np.ndarray,
    seen_obstacle: np.ndarray,
    seen_floor: np.ndarray,
) -> tuple[int, int]:
    """``SemanticMapper._splat`` in one compiled pass, every comparison in the points' float32;
    ``heights``: floor minimum, obstacle maximum, obstacle minimum, category maximum, look distance.
    Fills ``seen_obstacle`` and ``seen_floor`` with flat cell indices; returns how many of each."""
    floor_min, top, obstacle_min, category_max, look = heights[0], heights[1], heights[2], heights[3], heights[4]
    half = size // 2
    n_obstacle, n_floor = 0, 0
    for i in range(points.shape[0]):
        px, py, z = points[i, 0], points[i, 1], points[i, 2]
        col = math.floor(px / res) + half
        row = math.floor(py / res) + half
        if not (0 <= row < size and 0 <= col < size and z >= floor_min):
            continue
        high = z >= obstacle_min
        if not high:
            seen_floor[n_floor] = row * size + col
            n_floor += 1
        if z <= top:
            explored[row, col] = True
            dx, dy = px - x, py - y
            if hypot32(dx, dy) <= look:
                looked[row, col] = True
            if high:
                obstacle[row, col] = True
                seen_obstacle[n_obstacle] = row * size + col
                n_obstacle += 1
        if labels[i] > 0 and z <= category_max:
            k = labels[i] - 1
            if counts[k, row, col] < threshold:
                counts[k, row, col] += 1
            if counts[k, row, col] >= threshold:
                categories[k, row, col] = True
    return n_obstacle, n_floor

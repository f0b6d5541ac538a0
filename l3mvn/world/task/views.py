"""What the camera showed, as the task records it: the judge's own account of the floor and the goal
seen, from the rendered frames and the true poses, the same for every policy.

The failure causes ask whether the agent ever had the goal in view well enough to confirm it, and how
much of the floor it had seen when it failed. Answering from the agent's own map would make two
policies' causes two self-reports; so the task back-projects each frame (strided to at most
``TaskConfig.view_rows`` rows: the floor is filled between neighbouring rows, so the stride loses no
coverage) at the pose the simulator placed the agent, onto the scene's own grid.

* Floor seen: along each pixel column's bearing, the floor from the agent up to the first surface the
  column meets that is not floor (or its farthest floor point), as SemExp's "explored" counts it: the
  rays crossed that space, so nothing stands there; beyond it, cells where a pixel met the floor and
  the floor between two vertically neighbouring pixels that both met it (seen over a low obstacle);
  and the cells under the agent's body.
* Goal seen: cells where a pixel of the goal category met a surface within the sensor's range;
  ``confirmed`` once the largest 8-connected group of them has ``TaskConfig.confirm_min_cells`` cells.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage as ndi

from l3mvn.core.camera import CameraIntrinsics, depth_to_points
from l3mvn.core.config import Config
from l3mvn.core.grid import disk
from l3mvn.core.types import Observation, Pose
from l3mvn.world.scenes.scene import SceneMap

_EIGHT = np.ones((3, 3), dtype=bool)


class ViewRecord:
    """The floor and goal cells one episode's frames have shown (see the module docstring)."""

    def __init__(self, scene: SceneMap, config: Config) -> None:
        self.scene, self.config = scene, config
        self.seen_floor = np.zeros(scene.shape, dtype=bool)
        self.goal_seen = np.zeros(scene.shape, dtype=bool)
        radius = int(math.floor(config.sim.agent_radius_m / scene.resolution_m + 1e-9))
        self._body = np.argwhere(disk(radius)) - radius  # cell offsets under the agent's body
        self._intrinsics: CameraIntrinsics | None = None

    def retarget(self) -> None:
        """A new goal: its cells seen start over (the floor seen stays)."""
        self.goal_seen[:] = False

    def add(self, obs: Observation, pose: Pose) -> None:
        """Record the frame ``obs`` taken from the true ``pose``."""
        depth, semantic = obs.frame.strided(max(1, math.ceil(obs.frame.shape[0] / self.config.task.view_rows)))
        intrinsics = self._intrinsics
        if intrinsics is None or (intrinsics.height, intrinsics.width) != depth.shape:
            intrinsics = self._intrinsics = CameraIntrinsics.from_sim(self.config.sim, *depth.shape)
        valid = np.isfinite(depth) & (depth > 0) & (depth < self.config.sim.max_depth_m)
        cloud = depth_to_points(np.where(valid, depth, 0.0).astype(np.float32), intrinsics, pose, obs.tilt)
        points = np.full((*depth.shape, 3), np.nan, dtype=np.float32)
        points[valid] = cloud.points
        floor = valid.copy()
        floor[valid] = cloud.points[:, 2] < self.config.sim.max_climb_m
        self._mark(self.seen_floor, points[floor])
        self._mark(self.seen_floor, _up_to_first_surface(points, valid, floor, pose, self.scene.resolution_m / 2))
        pairs = floor[:-1] & floor[1:]  # vertically neighbouring pixels that both met the floor
        flat = points[..., :2]  # the marks are cells of the floor plane
        self._mark(self.seen_floor, _between(flat[:-1][pairs], flat[1:][pairs], self.scene.resolution_m / 2))
        self._mark_body(pose)
        if obs.goal in obs.categories:
            self._mark(self.goal_seen, points[valid & (semantic == obs.goal_id)])

    def coverage(self, rows: np.ndarray, cols: np.ndarray) -> float:
        """The share of the cells (``rows``, ``cols``) whose floor was seen."""
        return float(self.seen_floor[rows, cols].mean()) if len(rows) else 0.0

    @property
    def confirmed(self) -> bool:
        """Whether the goal's cells seen hold an 8-connected group of ``confirm_min_cells``."""
        if not self.goal_seen.any():
            return False
        labels, n = ndi.label(self.goal_seen, structure=_EIGHT)
        return int(np.bincount(labels.ravel())[1:].max()) >= self.config.task.confirm_min_cells

    def _mark(self, grid: np.ndarray, points: np.ndarray) -> None:
        if not len(points):
            return
        res, (h, w) = self.scene.resolution_m, grid.shape
        rows = np.floor(points[:, 1] / res).astype(np.int64)
        cols = np.floor(points[:, 0] / res).astype(np.int64)
        ok = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
        grid[rows[ok], cols[ok]] = True

    def _mark_body(self, pose: Pose) -> None:
        cells = self._body + self.scene.cell_of(pose.x, pose.y)
        h, w = self.scene.shape
        ok = (cells[:, 0] >= 0) & (cells[:, 0] < h) & (cells[:, 1] >= 0) & (cells[:, 1] < w)
        self.seen_floor[cells[ok, 0], cells[ok, 1]] = True


def _up_to_first_surface(
    points: np.ndarray, valid: np.ndarray, floor: np.ndarray, pose: Pose, spacing_m: float
) -> np.ndarray:
    """Floor points (x, y) every ``spacing_m`` from the agent along each pixel column, up to the
    nearest point of the column that is not floor, or (none) to its farthest floor point."""
    reach = np.hypot(points[..., 0] - pose.x, points[..., 1] - pose.y)
    wall = np.where(valid & ~floor, reach, np.inf)
    far = np.where(floor, reach, -1.0)
    has_wall = np.isfinite(wall).any(axis=0)
    row = np.where(has_wall, wall.argmin(axis=0), far.argmax(axis=0))  # the point that ends the column
    columns = np.flatnonzero(has_wall | floor.any(axis=0))
    if not len(columns):
        return np.empty((0, 2), np.float32)
    end = points[row[columns], columns, :2]
    start = np.empty_like(end)
    start[:, 0], start[:, 1] = pose.x, pose.y
    return np.concatenate([start, _between(start, end, spacing_m)])


def _between(a: np.ndarray, b: np.ndarray, spacing_m: float) -> np.ndarray:
    """Points (x, y) every ``spacing_m`` along each segment a[i] -> b[i] of the floor plane (a and b:
    (N, 2) x, y), endpoints excluded: only the segments longer than the spacing need any."""
    length = np.hypot(b[:, 0] - a[:, 0], b[:, 1] - a[:, 1])
    long = length > spacing_m
    if not long.any():
        return np.empty((0, 2), np.float32)
    a, b, length = a[long], b[long], length[long]
    count = np.ceil(length / spacing_m).astype(np.int64)
    seg = np.repeat(np.arange(len(a)), count - 1)
    k = np.arange(len(seg)) - np.repeat(np.cumsum(count - 1) - (count - 1), count - 1) + 1
    t = (k / count[seg])[:, None].astype(np.float32)
    return a[seg] + t * (b[seg] - a[seg])

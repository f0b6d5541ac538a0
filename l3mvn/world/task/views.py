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

The record is taken at every step of every episode, so one compiled pass over the frame marks the
cells directly (no array of points per frame); its arithmetic is the camera's float32 back-projection
(``l3mvn.core.camera``) step for step, so it marks the cells that projection gives.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np
from scipy import ndimage as ndi

from l3mvn.core.camera import CameraIntrinsics, ray_factors
from l3mvn.core.compiled import hypot32
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
        right, forward, rise = ray_factors(intrinsics, obs.tilt)
        f32 = np.float32
        res = self.scene.resolution_m
        _record_frame(
            np.ascontiguousarray(depth, dtype=np.float32),
            np.ascontiguousarray(semantic, dtype=np.int32),
            obs.goal_id if obs.goal in obs.categories else -1,
            right,
            forward,
            rise,
            np.array([pose.x, pose.y, math.cos(pose.heading), math.sin(pose.heading)], dtype=np.float32),
            f32(intrinsics.camera_height_m),
            f32(self.config.sim.max_depth_m),
            f32(self.config.sim.max_climb_m),
            f32(res),
            f32(res / 2),
            self.seen_floor,
            self.goal_seen,
        )
        self._mark_body(pose)

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

    def _mark_body(self, pose: Pose) -> None:
        cells = self._body + self.scene.cell_of(pose.x, pose.y)
        h, w = self.scene.shape
        ok = (cells[:, 0] >= 0) & (cells[:, 0] < h) & (cells[:, 1] >= 0) & (cells[:, 1] < w)
        self.seen_floor[cells[ok, 0], cells[ok, 1]] = True


@nb.njit(cache=True)
def _record_frame(
    depth,
    semantic,
    goal_id,
    right,
    forward,
    rise,
    pose,
    camera_height,
    max_depth,
    max_climb,
    res,
    spacing,
    floor_grid,
    goal_grid,
):
    """Mark the floor (``floor_grid``) and, with ``goal_id`` >= 0, the goal (``goal_grid``) that one
    frame shows; ``pose`` is (x, y, cos heading, sin heading), every number float32 as the camera's."""
    h, w = depth.shape
    x0, y0, ch, sh = pose[0], pose[1], pose[2], pose[3]
    px = np.empty((h, w), np.float32)
    py = np.empty((h, w), np.float32)
    valid = np.zeros((h, w), np.bool_)
    floor = np.zeros((h, w), np.bool_)
    for r in range(h):
        for c in range(w):
            d = depth[r, c]
            if not (np.isfinite(d) and d > 0 and d < max_depth):
                continue
            ahead = d * forward[r]
            rightward = d * right[c]
            x = x0 + ahead * ch + rightward * sh
            y = y0 + ahead * sh - rightward * ch
            px[r, c], py[r, c] = x, y
            valid[r, c] = True
            if camera_height + d * rise[r] < max_climb:
                floor[r, c] = True
                _mark(floor_grid, x, y, res)
            if goal_id >= 0 and semantic[r, c] == goal_id:
                _mark(goal_grid, x, y, res)
    # Along each column, the floor up to the first surface that is not floor (or its farthest floor).
    for c in range(w):
        end, end_reach, is_wall = -1, np.float32(0.0), False
        for r in range(h):
            if not valid[r, c]:
                continue
            reach = hypot32(px[r, c] - x0, py[r, c] - y0)
            if not floor[r, c]:
                if not is_wall or reach < end_reach:
                    end, end_reach, is_wall = r, reach, True
            elif not is_wall and (end < 0 or reach > end_reach):
                end, end_reach = r, reach
        if end >= 0:
            _mark(floor_grid, x0, y0, res)
            _mark_between(floor_grid, x0, y0, px[end, c], py[end, c], res, spacing)
    # The floor between vertically neighbouring pixels that both met it (seen over a low obstacle).
    for r in range(h - 1):
        for c in range(w):
            if floor[r, c] and floor[r + 1, c]:
                _mark_between(floor_grid, px[r, c], py[r, c], px[r + 1, c], py[r + 1, c], res, spacing)


@nb.njit(cache=True)
def _mark(grid, x, y, res):
    row, col = math.floor(y / res), math.floor(x / res)
    if 0 <= row < grid.shape[0] and 0 <= col < grid.shape[1]:
        grid[row, col] = True


@nb.njit(cache=True)
def _mark_between(grid, ax, ay, bx, by, res, spacing):
    """Mark the points every ``spacing`` along a -> b, endpoints excluded (none when shorter)."""
    dx, dy = bx - ax, by - ay
    length = hypot32(dx, dy)
    if not length > spacing:
        return
    count = math.ceil(length / spacing)
    for k in range(1, count):
        t = np.float32(k / count)
        _mark(grid, ax + t * dx, ay + t * dy, res)

"""Failed forward steps: the cells they block (the collision map) and whether the agent is stuck.

A forward step that moved less than ``collision_threshold_m`` blocks a rectangle ahead of the agent,
wider with every consecutive collision (narrower marks while approaching a target, where one wide mark
can close the last passage); the planner treats those cells as obstacles. Stuck means too
many collisions, or too little displacement, within the last ``stuck_window_steps``.
"""

from __future__ import annotations

import collections
import math

import numpy as np

from l3mvn.config import PlannerConfig
from l3mvn.errors import L3MVNError


class CollisionTracker:
    """The collision marks and motion history of one episode on one map."""

    def __init__(self, cfg: PlannerConfig, resolution_m: float) -> None:
        self.cfg, self.resolution_m = cfg, resolution_m
        self.map: np.ndarray | None = None
        self._cells = np.zeros((0, 2), dtype=np.int32)  # the marked cells, in marking order
        self._consecutive_collisions = 0
        window = cfg.stuck_window_steps
        self._recent_collisions: collections.deque[bool] = collections.deque(maxlen=window)
        self._recent_cells: collections.deque[tuple[int, int]] = collections.deque(maxlen=window)

    def start(self, shape: tuple[int, int]) -> None:
        """Allocate the collision map for maps of ``shape`` (the first plan), or check it still fits."""
        if self.map is None:
            self.map = np.zeros(shape, dtype=bool)
        elif self.map.shape != shape:
            raise L3MVNError(f"map shape changed from {self.map.shape} to {shape}; call reset() first")

    def clear(self) -> None:
        """Forget the marks and the history (an agent escaping a trap it marked itself)."""
        self.clear_marks()
        self._consecutive_collisions = 0
        self._recent_collisions.clear()
        self._recent_cells.clear()

    def clear_marks(self) -> None:
        """Forget the marks only: the collisions still count towards the stuck signal."""
        if self.map is not None:
            self.map.fill(False)
        self._cells = np.zeros((0, 2), dtype=np.int32)

    def record(self, agent: tuple[int, int], heading: float, last_move_m: float | None, *,
               target: bool = False) -> bool:
        """Mark the cells ahead as blocked when a forward step moved less than the threshold; with
        ``target`` (approaching the goal object) the narrower target widths apply."""
        cfg = self.cfg
        collided = False
        if last_move_m is not None:
            if not math.isfinite(last_move_m) or last_move_m < 0:
                raise L3MVNError(f"last_move_m must be a finite distance >= 0 or None, got {last_move_m}")
            collided = last_move_m < cfg.collision_threshold_m
            self._consecutive_collisions = self._consecutive_collisions + 1 if collided else 0
        if collided:
            first, widest = ((cfg.collision_mark_target_width_cells, cfg.collision_mark_target_max_width_cells)
                             if target else (cfg.collision_mark_width_cells, cfg.collision_mark_max_width_cells))
            width = min(first + 2 * (self._consecutive_collisions - 1), widest)
            ahead = np.arange(
                cfg.collision_mark_offset_cells,
                cfg.collision_mark_offset_cells + cfg.collision_mark_length_cells - 0.5 + 1e-9,
                0.5,
            )
            half = (width - 1) / 2
            side = np.arange(-half, half + 1e-9, 0.5)
            a, s = np.meshgrid(ahead, side, indexing="ij")
            sin_h, cos_h = math.sin(heading), math.cos(heading)
            rows = np.rint(agent[0] + a * sin_h + s * cos_h).astype(np.int64).ravel()
            cols = np.rint(agent[1] + a * cos_h - s * sin_h).astype(np.int64).ravel()
            shape = self.map.shape
            ok = (rows >= 0) & (rows < shape[0]) & (cols >= 0) & (cols < shape[1])
            ok &= (rows != agent[0]) | (cols != agent[1])
            rows, cols = rows[ok], cols[ok]
            fresh = np.unique((rows * shape[1] + cols)[~self.map[rows, cols]])
            self.map[rows, cols] = True
            if len(fresh):
                added = np.stack(np.divmod(fresh, shape[1]), axis=1).astype(np.int32)
                self._cells = np.concatenate([self._cells, added])
        self._recent_collisions.append(collided)
        return collided

    @property
    def cells(self) -> np.ndarray:
        """(N, 2) int32 (row, col) of every marked cell; a new array whenever a mark is added, so a
        reference kept by a step event never changes under it."""
        return self._cells

    def stuck(self, agent: tuple[int, int]) -> bool:
        """Too many collisions, or too little displacement, within the last window of steps."""
        cfg = self.cfg
        self._recent_cells.append(agent)
        if sum(self._recent_collisions) >= cfg.stuck_collisions:
            return True
        if len(self._recent_cells) < cfg.stuck_window_steps:
            return False
        cells = np.asarray(self._recent_cells)
        spread = np.hypot(cells[:, 0] - agent[0], cells[:, 1] - agent[1]).max() * self.resolution_m
        return bool(spread < cfg.stuck_min_displacement_m)

"""Failed forward steps: the cells they block (the collision map) and whether the agent is stuck.

A forward step that moved less than ``collision_threshold_m`` blocks a rectangle ahead of the agent,
wider with every consecutive collision (narrower marks while approaching a target, where one wide mark
can close the last passage); the planner treats those cells as obstacles. Where the map shows an
obstacle the first failed step of a run swept nearer to, the cells beside that obstacle are kept as
an alternative mark, which the planner lays instead when the rectangle lengthens its way and the
plan then turns off the failed heading: grazing a mapped corner, the rectangle would shut a
passage barely wider than the body beside it, and the room behind it would never be reached. Laid
whenever the map shows an obstacle, the marks beside cost a second collision where that obstacle
was not what the body hit (floor the navmesh lost looks free on the map). Stuck means too many
collisions, or too little displacement, within the last ``stuck_window_steps``.
"""

from __future__ import annotations

import collections
import math

import numpy as np
import numpy.typing as npt

from l3mvn.core.config import PlannerConfig
from l3mvn.core.errors import L3MVNError


class CollisionTracker:
    """The collision marks and motion history of one episode on one map."""

    def __init__(self, cfg: PlannerConfig, resolution_m: float, *, body_radius_m: float, forward_step_m: float) -> None:
        """``body_radius_m``, ``forward_step_m``: the agent's, for the region a forward step sweeps."""
        if not (body_radius_m >= 0 and forward_step_m > 0):
            raise L3MVNError(f"need body_radius_m >= 0 and forward_step_m > 0, got {body_radius_m}, {forward_step_m}")
        self.cfg, self.resolution_m = cfg, resolution_m
        self._body_cells, self._step_cells = body_radius_m / resolution_m, forward_step_m / resolution_m
        self.map: npt.NDArray[np.bool_] | None = None
        self._cells = np.zeros((0, 2), dtype=np.int32)  # the marked cells, in marking order
        self._fresh = 0  # how many of them the last record() added
        self._beside: tuple[np.ndarray, np.ndarray] | None = None  # the last step's alternative mark
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

    def record(
        self,
        agent: tuple[int, int],
        heading: float,
        last_move_m: float | None,
        *,
        target: bool = False,
        obstacle: np.ndarray | None = None,
    ) -> bool:
        """Mark the cells ahead as blocked when a forward step moved less than the threshold; with
        ``target`` (approaching the goal object) the narrower target widths apply. With the agent's
        ``obstacle`` map, the first failed step of a run also keeps the cells beside the obstacle
        it swept nearer to (``beside``)."""
        cfg = self.cfg
        collided = False
        self._fresh, self._beside = 0, None
        if last_move_m is not None:
            if not math.isfinite(last_move_m) or last_move_m < 0:
                raise L3MVNError(f"last_move_m must be a finite distance >= 0 or None, got {last_move_m}")
            collided = last_move_m < cfg.collision_threshold_m
            self._consecutive_collisions = self._consecutive_collisions + 1 if collided else 0
        if collided:
            first, widest = (
                (cfg.collision_mark_target_width_cells, cfg.collision_mark_target_max_width_cells)
                if target
                else (cfg.collision_mark_width_cells, cfg.collision_mark_max_width_cells)
            )
            width = min(first + 2 * (self._consecutive_collisions - 1), widest)
            self._mark(*self._ahead(agent, heading, width))
            if obstacle is not None and self._consecutive_collisions == 1:
                self._beside = self._beside_what_was_hit(obstacle, agent, heading)
        self._recent_collisions.append(collided)
        return collided

    @property
    def beside(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The free cells beside the mapped obstacle the last failed step swept nearer to (the first
        of a run), an alternative to its rectangle; None when the map does not explain it."""
        return self._beside

    def swap_last_mark(self, rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Replace the cells the last step marked with ``(rows, cols)``; returns the cells replaced."""
        assert self.map is not None  # a mark was laid, so ``start`` allocated the map
        kept = len(self._cells) - self._fresh
        gone = self._cells[kept:]
        self.map[gone[:, 0], gone[:, 1]] = False
        self._cells = self._cells[:kept]
        self._mark(rows, cols)
        return gone[:, 0].astype(np.int64), gone[:, 1].astype(np.int64)

    def _mark(self, rows: np.ndarray, cols: np.ndarray) -> None:
        assert self.map is not None  # ``start`` comes before any mark
        fresh = np.unique((rows * self.map.shape[1] + cols)[~self.map[rows, cols]])
        self.map[rows, cols] = True
        self._fresh = len(fresh)
        if len(fresh):
            added = np.stack(np.divmod(fresh, self.map.shape[1]), axis=1).astype(np.int32)
            self._cells = np.concatenate([self._cells, added])

    def _ahead(self, agent: tuple[int, int], heading: float, width: int) -> tuple[np.ndarray, np.ndarray]:
        """The cells of a ``width``-cell rectangle ahead of the agent (SemExp's mark)."""
        cfg = self.cfg
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
        assert self.map is not None  # ``start`` comes before any mark
        shape = self.map.shape
        ok = (rows >= 0) & (rows < shape[0]) & (cols >= 0) & (cols < shape[1])
        ok &= (rows != agent[0]) | (cols != agent[1])
        return rows[ok], cols[ok]

    def _beside_what_was_hit(
        self, obstacle: np.ndarray, agent: tuple[int, int], heading: float
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """The free cells the step swept (the body's disk moved one step ahead, the half in front of
        its centre) next to the obstacle cells it swept and would have come nearer to than it stands
        to any obstacle now; None when there are none. A wall alongside is no nearer a step on, so a
        step that failed beside one hit something the map does not show."""
        reach = int(math.ceil(self._body_cells + self._step_cells))
        dr, dc = np.mgrid[-reach : reach + 1, -reach : reach + 1]
        rows, cols = dr.ravel() + agent[0], dc.ravel() + agent[1]
        shape = obstacle.shape
        inside = (rows >= 0) & (rows < shape[0]) & (cols >= 0) & (cols < shape[1])
        dr, dc, rows, cols = dr.ravel()[inside], dc.ravel()[inside], rows[inside], cols[inside]
        blocked = obstacle[rows, cols]
        if not blocked.any():
            return None
        along = dr * math.sin(heading) + dc * math.cos(heading)
        across = -dr * math.cos(heading) + dc * math.sin(heading)
        gap = np.hypot(np.maximum(along - self._step_cells, 0.0), across)
        clearance = np.hypot(dr[blocked], dc[blocked]).min()
        swept = (along >= 0) & (gap <= self._body_cells)
        hit = blocked & swept & (gap < clearance - 0.5)
        if not hit.any():
            return None
        free = ~blocked & swept & ((rows != agent[0]) | (cols != agent[1]))
        near = (np.abs(rows[free][:, None] - rows[hit][None, :]) <= 1) & (
            np.abs(cols[free][:, None] - cols[hit][None, :]) <= 1
        )
        keep = near.any(axis=1)
        return (rows[free][keep], cols[free][keep]) if keep.any() else None

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

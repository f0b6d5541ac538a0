"""Action choice of the local policy: the short-term goal along free straight rays, and the turn or
step towards it.

Kept apart from the distance fields (``goal_field.py``) because it is the part a different robot
changes (another action set, another turn angle), while the fields stay the same.
"""

from __future__ import annotations

import math

import numpy as np

from l3mvn.agent.planning.fmm import GeodesicField
from l3mvn.core.config import PlannerConfig
from l3mvn.core.types import Action, wrap_angle

# Directions of the rays that look for the short-term goal (5 degrees apart), sampled every half
# cell so a ray cannot slip between two diagonal blocked cells.
_RAY_DIRECTIONS = 72
_RAY_STEP_CELLS = 0.5
# Ties between equal distances (every cell inside the dilated goal reads 0; reachable cells
# equally near an unreachable goal) go to the cell nearest the goal, resp. the agent; the weight is
# far below one cell so it never overrides a real difference in distance.
TIE_WEIGHT = 1e-3
_TURN_BACK = {Action.TURN_LEFT: Action.TURN_RIGHT, Action.TURN_RIGHT: Action.TURN_LEFT}


class Steering:
    """Short-term goal and discrete action on a distance field (one per planner)."""

    def __init__(self, cfg: PlannerConfig, resolution_m: float, forward_step_m: float) -> None:
        self.cfg, self.resolution_m = cfg, resolution_m
        self.lookahead_cells = max(1, int(round(cfg.stg_lookahead_m / resolution_m)))
        self._ray_rows, self._ray_cols = _rays(self.lookahead_cells)
        # Samples of one forward step (origin excluded), half a cell apart as the rays are.
        self._step = np.arange(_RAY_STEP_CELLS, forward_step_m / resolution_m + 1e-9, _RAY_STEP_CELLS)
        self._last: tuple[tuple[int, int], Action] | None = None  # the cell and action of the last choice

    def reset(self) -> None:
        self._last = None

    def short_term_goal(
        self, field: GeodesicField, trav: np.ndarray, agent: tuple[int, int], nearest_goal: tuple[int, int]
    ) -> tuple[int, int]:
        """The cell nearest the goal among those seen from the agent along free straight rays.

        Only cells that score strictly better than the agent's own count; with none (boxed in, or
        as near the goal as the free space allows) the short-term goal is the agent's cell.
        """
        window = field.window
        local = (agent[0] - window.r0, agent[1] - window.c0)
        rows = self._ray_rows + local[0]
        cols = self._ray_cols + local[1]
        inside = (rows >= 0) & (rows < window.shape[0]) & (cols >= 0) & (cols < window.shape[1])
        rows, cols = np.where(inside, rows, 0), np.where(inside, cols, 0)
        visible = np.logical_and.accumulate(inside & trav[rows, cols], axis=1)
        tie = TIE_WEIGHT * self.resolution_m
        score = field.values[rows, cols] + tie * np.hypot(
            rows + window.r0 - nearest_goal[0], cols + window.c0 - nearest_goal[1]
        )
        own = field.values[local] + tie * math.hypot(agent[0] - nearest_goal[0], agent[1] - nearest_goal[1])
        score = np.where(visible & (score < own), score, np.inf)
        best = int(np.argmin(score))
        if not math.isfinite(score.flat[best]):
            return agent
        return int(rows.flat[best]) + window.r0, int(cols.flat[best]) + window.c0

    def steps_towards(self, agent: tuple[int, int], heading: float, target: tuple[int, int]) -> bool:
        """Whether ``target`` lies within the turn threshold of ``heading`` (the step goes straight on)."""
        threshold = math.radians(self.cfg.turn_threshold_deg)
        return target != agent and abs(_bearing_error(agent, heading, target)) <= threshold

    def action(
        self, agent: tuple[int, int], heading: float, target: tuple[int, int], field: GeodesicField, trav: np.ndarray
    ) -> Action:
        """Turn toward ``target`` or step; ``field`` and its traversible window ``trav`` tell whether a
        step that moved may be followed by another off the turn threshold (``_keeps_heading``)."""
        if target == agent:  # standing on the goal cell itself: any turn is harmless
            action = Action.TURN_LEFT
        else:
            error = _bearing_error(agent, heading, target)
            threshold = math.radians(self.cfg.turn_threshold_deg)
            action = (
                Action.TURN_LEFT
                if error > threshold
                else Action.TURN_RIGHT
                if error < -threshold
                else Action.MOVE_FORWARD
            )
            if action != Action.MOVE_FORWARD and self._keeps_heading(agent, heading, error, field, trav):
                action = Action.MOVE_FORWARD
            # A turn straight back on the same cell undoes the last one. It happens when the goal moves
            # with the view (a sighting's bearing shifts as the frame does): the two headings then take
            # turns for ever. Within two thresholds of the goal, step instead.
            back = _TURN_BACK.get(action)
            if back is not None and self._last == (agent, back) and abs(error) <= 2 * threshold:
                action = Action.MOVE_FORWARD
        self._last = (agent, action)
        return action

    def _keeps_heading(
        self, agent: tuple[int, int], heading: float, error: float, field: GeodesicField, trav: np.ndarray
    ) -> bool:
        """Whether the agent, having just stepped forward off its last cell, steps on rather than turn:
        the short-term goal lies within ``keep_heading_deg``, the step's cells are traversible and
        it ends nearer the goal on ``field``. A path between two headings otherwise flips the bearing
        error across ``turn_threshold_deg`` at every step, and the agent turns left, steps, turns
        right, steps, spending a large share of its step budget on turns along its paths."""
        if self._last is None:
            return False
        cell, last = self._last
        if last != Action.MOVE_FORWARD or cell == agent or abs(error) > math.radians(self.cfg.keep_heading_deg):
            return False
        window = field.window
        rows = np.rint(agent[0] + math.sin(heading) * self._step).astype(np.int64)
        cols = np.rint(agent[1] + math.cos(heading) * self._step).astype(np.int64)
        if not window.inside(rows, cols).all():
            return False
        if not trav[rows - window.r0, cols - window.c0].all():
            return False
        return bool(field.at(rows[-1], cols[-1]) < field.at(*agent))


def _bearing_error(agent: tuple[int, int], heading: float, target: tuple[int, int]) -> float:
    """Radians from ``heading`` to the bearing of ``target``, in [-pi, pi)."""
    desired = math.atan2(target[0] - agent[0], target[1] - agent[1])
    return wrap_angle(desired - heading)


def _rays(length_cells: int) -> tuple[np.ndarray, np.ndarray]:
    """(directions, samples) cell offsets along straight rays from the agent, origin excluded."""
    angles = np.linspace(0.0, 2 * np.pi, _RAY_DIRECTIONS, endpoint=False)
    steps = np.arange(_RAY_STEP_CELLS, length_cells + 1e-9, _RAY_STEP_CELLS)
    rows = np.rint(np.sin(angles)[:, None] * steps[None, :]).astype(np.int64)
    cols = np.rint(np.cos(angles)[:, None] * steps[None, :]).astype(np.int64)
    at_origin = (rows == 0) & (cols == 0)
    # A sample that rounds back onto the agent's cell is not a goal; push it one step out.
    rows = np.where(at_origin, np.rint(np.sin(angles)[:, None] * 1.0).astype(np.int64), rows)
    cols = np.where(at_origin, np.rint(np.cos(angles)[:, None] * 1.0).astype(np.int64), cols)
    return rows, cols

"""Local policy: Fast Marching toward a goal on the agent's own map, one discrete action per step.

Map frame: (row, col) cells; world ``x = col * res``, ``y = row * res``; heading counter-clockwise
from ``+x``, so heading ``h`` points along ``(drow, dcol) = (sin h, cos h)`` and ``TURN_LEFT`` adds to
it. Three parts, one module each: the distance fields and their cache (``goal_field.py``), the
collision marks and stuck signal (``collisions.py``) and the action choice (``steering.py``); this
class checks the inputs and runs them in order once per step. The planner never stops by itself:
whether the goal is the target object is the agent's call.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from l3mvn.agent.planning.collisions import CollisionTracker
from l3mvn.agent.planning.fmm import GeodesicField
from l3mvn.agent.planning.goal_field import GoalFields, mask_cells
from l3mvn.agent.planning.steering import Steering
from l3mvn.core.config import PlannerConfig, SimConfig
from l3mvn.core.errors import L3MVNError
from l3mvn.core.types import Action


@dataclass(frozen=True)
class Plan:
    """One step of the local policy.

    distance_to_goal_m: geodesic estimate to the goal: FMM distance to the goal dilated by
    ``goal_dilation_m`` plus that dilation, or the straight-line distance once inside it; ``inf``
    when unreachable (then ``short_term_goal`` leads to the reachable cell nearest the goal).
    field: the distance field the step followed (to the goal, or to that fallback cell).
    replanned: whether this step ran FMM (False when the previous field was still valid).
    marks_cleared: approaching the target, the collision marks lengthened the way to it by more
    than ``target_mark_detour_m`` and were cleared this step (``LocalPlanner.plan``).
    marked_beside: this step's failed step swept nearer a mapped obstacle, its rectangle across the
    way lengthened it by more than ``target_mark_detour_m``, and with the cells beside the obstacle
    marked instead the plan no longer steps straight on: those were marked.
    """

    action: Action
    short_term_goal: tuple[int, int]
    distance_to_goal_m: float
    reachable: bool
    reached: bool
    collided: bool
    stuck: bool
    replanned: bool
    field: GeodesicField
    marks_cleared: bool = False  # collision marks that made a detour to the target were just cleared
    marked_beside: bool = False  # this step's collision marked beside what it ran into (``CollisionTracker``)


class LocalPlanner:
    """Fast Marching local policy with a collision map and stuck detection; one per episode.

    Call ``plan`` once per step (collisions and stuck detection count calls as steps) and
    ``reset`` between episodes. ``fmm_runs`` counts the marches so far (for speed reports).
    """

    def __init__(self, cfg: PlannerConfig, resolution_m: float, *, body_radius_m: float, forward_step_m: float) -> None:
        """``resolution_m``: the cell size of the maps it will plan on (the agent's map);
        ``body_radius_m``, ``forward_step_m``: the agent's, to tell what a failed step ran into."""
        if not (math.isfinite(resolution_m) and resolution_m > 0):
            raise L3MVNError(f"resolution_m must be positive, got {resolution_m}")
        self.cfg, self.resolution_m = cfg, resolution_m
        self._body = {"body_radius_m": body_radius_m, "forward_step_m": forward_step_m}
        self._steering = Steering(cfg, resolution_m, forward_step_m)
        self._collisions = CollisionTracker(cfg, resolution_m, **self._body)
        self._fields = GoalFields(cfg, resolution_m, self._steering, self._collisions)
        self.goal_dilation_cells = self._fields.goal_dilation_cells
        self.lookahead_cells = self._steering.lookahead_cells
        self._target_clears = 0  # clears of detour-making marks this episode (``target_mark_clears``)

    @classmethod
    def for_sim(cls, cfg: PlannerConfig, resolution_m: float, sim: SimConfig) -> LocalPlanner:
        """A planner for the simulated robot's body and step, on maps of ``resolution_m`` cells."""
        return cls(cfg, resolution_m, body_radius_m=sim.agent_radius_m, forward_step_m=sim.forward_step_m)

    def reset(self) -> None:
        """Forget the collision map, the cached field, the stuck history and the last turn (new episode)."""
        self._collisions = CollisionTracker(self.cfg, self.resolution_m, **self._body)
        self._fields.reset(self._collisions)
        self._steering.reset()
        self._target_clears = 0

    @property
    def fmm_runs(self) -> int:
        return self._fields.fmm_runs

    def clear_collisions(self) -> None:
        """Forget the collision marks and the stuck history (an agent escaping a trap it marked)."""
        self._collisions.clear()
        self._fields.forget()

    @property
    def collision_map(self) -> np.ndarray | None:
        """(M, M) bool cells blocked by failed forward steps (None before the first plan)."""
        return self._collisions.map

    @property
    def collision_cells(self) -> np.ndarray:
        """(N, 2) int32 cells of ``collision_map``, for views (cheaper than scanning the map)."""
        return self._collisions.cells

    def plan(
        self,
        obstacle: np.ndarray,
        agent_cell: tuple[int, int],
        heading: float,
        goal: np.ndarray | tuple[int, int],
        *,
        last_move_m: float | None = None,
        goal_reached_radius_m: float = 0.5,
        goal_dilation_m: float | None = None,
        target: bool = False,
    ) -> Plan:
        """Choose the next action toward ``goal``.

        obstacle: (M, M) bool obstacle map (undilated). agent_cell: (row, col). heading: radians.
        goal: a (row, col) cell, an (N, 2) int array of cells, or an (M, M) bool mask.
        last_move_m: distance actually moved by the previous action if it was MOVE_FORWARD, else
        None; below ``collision_threshold_m`` it counts as a collision. reached: the goal
        distance estimate is within ``goal_reached_radius_m`` and the goal is reachable.
        goal_dilation_m: overrides the config's for this call. The 0.5 m disk suits an object
        (approached from any free side), but it reaches through walls: an exploration goal needs
        a small one, or a frontier behind a wall reads as reached from the wrong room.
        target: the goal is the object itself; a failed step then lays the narrower target marks.
        """
        obstacle = self._check_map(obstacle)
        agent = _check_cell(agent_cell, obstacle.shape)
        if not math.isfinite(heading):
            raise L3MVNError(f"heading must be finite radians, got {heading}")
        if goal_reached_radius_m < 0:
            raise L3MVNError(f"goal_reached_radius_m must be >= 0, got {goal_reached_radius_m}")
        goal_rows, goal_cols = _goal_cells(goal, obstacle.shape)
        dilation = self._dilation_cells(goal_dilation_m)
        collided = self._collisions.record(agent, heading, last_move_m, target=target, obstacle=obstacle)

        nearest_goal = _nearest(agent, goal_rows, goal_cols)
        field, trav, stg, replanned = self._fields.field_to(
            obstacle, agent, goal_rows, goal_cols, nearest_goal, dilation
        )
        d_agent = float(field.at(*agent))
        # Only a replanned field can hold new marks across the way (a reused one provably does not).
        replan = (obstacle, agent, goal_rows, goal_cols, nearest_goal, dilation)
        beside = self._collisions.beside
        marked_beside = beside is not None and replanned and self._marks_make_detour(*replan, d_agent)
        if marked_beside:
            assert beside is not None  # ``marked_beside`` requires it
            across, kept = self._collisions.swap_last_mark(*beside), self._fields.saved()
            plan_across = field, trav, stg, replanned, d_agent
            field, trav, stg, replanned, d_agent = self._field_anew(*replan)
            if stg is None:
                stg = self._steering.short_term_goal(field, trav, agent, nearest_goal)
            if self._steering.steps_towards(agent, heading, stg if stg != agent else nearest_goal):
                # The marks beside leave the failed step the way on: no explanation the plan can use.
                marked_beside = False
                self._collisions.swap_last_mark(*across)
                self._fields.restore(kept)
                field, trav, stg, replanned, d_agent = plan_across
        marks_cleared = (
            target
            and replanned
            and self._target_clears < self.cfg.target_mark_clears
            and self._marks_make_detour(*replan, d_agent)
        )
        if marks_cleared:
            self._collisions.clear_marks()
            self._target_clears += 1
            field, trav, stg, replanned, d_agent = self._field_anew(*replan)
        reachable = math.isfinite(d_agent)
        if not reachable:
            distance = math.inf
            field, trav = self._fields.fallback_field(obstacle, agent, goal_rows, goal_cols)
        elif d_agent > 0:
            distance = d_agent + dilation * self.resolution_m
        else:
            distance = math.dist(nearest_goal, agent) * self.resolution_m
        if stg is None:
            stg = self._steering.short_term_goal(field, trav, agent, nearest_goal)
        action = self._steering.action(agent, heading, stg if stg != agent else nearest_goal, field, trav)
        return Plan(
            action=action,
            short_term_goal=stg,
            distance_to_goal_m=distance,
            reachable=reachable,
            reached=reachable and distance <= goal_reached_radius_m,
            collided=collided,
            stuck=self._collisions.stuck(agent),
            replanned=replanned,
            field=field,
            marks_cleared=marks_cleared,
            marked_beside=marked_beside,
        )

    def _field_anew(
        self,
        obstacle: np.ndarray,
        agent: tuple[int, int],
        goal_rows: np.ndarray,
        goal_cols: np.ndarray,
        nearest_goal: tuple[int, int],
        dilation: int,
    ) -> tuple[GeodesicField, np.ndarray, tuple[int, int] | None, bool, float]:
        """``field_to`` after the collision marks changed under the cached field, and the agent's distance."""
        self._fields.forget()
        field, trav, stg, replanned = self._fields.field_to(
            obstacle, agent, goal_rows, goal_cols, nearest_goal, dilation
        )
        return field, trav, stg, replanned, float(field.at(*agent))

    def _marks_make_detour(
        self,
        obstacle: np.ndarray,
        agent: tuple[int, int],
        goal_rows: np.ndarray,
        goal_cols: np.ndarray,
        nearest_goal: tuple[int, int],
        dilation: int,
        d_agent: float,
    ) -> bool:
        """Whether the collision marks lengthen the way to the goal by more than
        ``target_mark_detour_m`` (or close it)."""
        if not len(self._collisions.cells):
            return False
        free, _, _, _ = self._fields.field_to(
            obstacle, agent, goal_rows, goal_cols, nearest_goal, dilation, marks=False
        )
        return float(free.at(*agent)) + self.cfg.target_mark_detour_m < d_agent

    def distance_from_agent(
        self,
        obstacle: np.ndarray,
        agent_cell: tuple[int, int],
        *,
        targets: np.ndarray | None = None,
        max_distance_m: float | None = None,
    ) -> GeodesicField:
        """Geodesic distance from the agent over the planner's traversible map (frontier costs);
        ``GoalFields.distance_from_agent`` says what the window covers."""
        obstacle = self._check_map(obstacle)
        agent = _check_cell(agent_cell, obstacle.shape)
        return self._fields.distance_from_agent(obstacle, agent, targets=targets, max_distance_m=max_distance_m)

    def _dilation_cells(self, goal_dilation_m: float | None) -> int:
        if goal_dilation_m is None:
            return self.goal_dilation_cells
        if not (math.isfinite(goal_dilation_m) and 0 <= goal_dilation_m <= self.cfg.goal_dilation_m):
            raise L3MVNError(
                f"goal_dilation_m must lie in [0, {self.cfg.goal_dilation_m}] (the config's), got {goal_dilation_m}"
            )
        return int(round(goal_dilation_m / self.resolution_m))

    # -- map preparation ------------------------------------------------------------------------

    def _check_map(self, obstacle: np.ndarray) -> np.ndarray:
        obstacle = np.asarray(obstacle)
        if obstacle.ndim != 2 or obstacle.dtype != bool:
            raise L3MVNError(f"obstacle map must be a 2D bool array, got {obstacle.dtype} {obstacle.shape}")
        self._collisions.start(obstacle.shape)
        return obstacle


def _check_cell(cell: tuple[int, int], shape: tuple[int, int]) -> tuple[int, int]:
    try:
        r, c = (int(v) for v in cell)
    except (TypeError, ValueError):
        raise L3MVNError(f"a cell must be a (row, col) pair of ints, got {cell!r}") from None
    if not (0 <= r < shape[0] and 0 <= c < shape[1]):
        raise L3MVNError(f"cell ({r}, {c}) lies outside the {shape[0]}x{shape[1]} map")
    return r, c


def _goal_cells(goal: np.ndarray | tuple[int, int], shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    arr = np.asarray(goal)
    if arr.dtype == bool:
        if arr.shape != shape:
            raise L3MVNError(f"goal mask has shape {arr.shape}, expected the map shape {shape}")
        rows, cols = mask_cells(arr)
        if rows.size == 0:
            raise L3MVNError("goal mask is empty")
        return rows, cols
    if arr.shape == (2,):
        r, c = _check_cell(tuple(arr.tolist()), shape)
        return np.array([r]), np.array([c])
    if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] == 0 or not np.issubdtype(arr.dtype, np.integer):
        raise L3MVNError(
            f"goal must be a (row, col) cell, an (N, 2) int array of cells or a bool map mask; got {arr.shape}"
        )
    rows, cols = arr[:, 0].astype(np.int64), arr[:, 1].astype(np.int64)
    if ((rows < 0) | (rows >= shape[0]) | (cols < 0) | (cols >= shape[1])).any():
        raise L3MVNError(f"goal cells must lie inside the {shape[0]}x{shape[1]} map")
    return rows, cols


def _nearest(agent: tuple[int, int], rows: np.ndarray, cols: np.ndarray) -> tuple[int, int]:
    i = int(np.argmin((rows - agent[0]) ** 2 + (cols - agent[1]) ** 2))
    return int(rows[i]), int(cols[i])


__all__ = ["PlannerConfig", "Plan", "LocalPlanner"]

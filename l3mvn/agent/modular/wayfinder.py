"""The way to a goal of any kind, and what several goal modes ask about it.

The local planner plans to a cell or a mask; how near counts as reached and how wide the goal is drawn
depend on what the goal is (the target under the success rule, a candidate, an exploration goal, a
frontier walked up to). The wayfinder owns that mapping, the patience with a goal that gets no nearer,
the count of steps the goal has been unreachable, and the escape from a spot the agent is stuck in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from l3mvn.agent.decision import GoalKind
from l3mvn.agent.looking import distance_to, turn_towards
from l3mvn.agent.mapping import SemanticMap
from l3mvn.agent.modular.exploration import ExplorationGoals
from l3mvn.agent.modular.target import TargetSearch
from l3mvn.agent.planning import LocalPlanner, Plan
from l3mvn.core.config import Config
from l3mvn.core.types import Action

Cell = tuple[int, int]
Goal = Cell | np.ndarray  # a map cell, or a mask of the target's cells


@dataclass
class GoalProgress:
    """Whether the goal pursued has come ``goal_progress_m`` nearer, or the walk has mapped
    ``progress_cells`` new cells, within ``goal_patience_steps``: a path through unknown space that
    keeps meeting new walls stays "reachable" while the agent circles, and circling maps nothing new."""

    patience_steps: int
    progress_m: float
    progress_cells: float
    _goal: Cell | None = None
    _best_m: float = math.inf
    _mapped: int = 0
    _since: int = 0

    def reset(self) -> None:
        self._goal, self._best_m, self._mapped, self._since = None, math.inf, 0, 0

    def stalled(self, goal: Cell, distance_m: float, mapped_cells: int) -> bool:
        """Record this step's distance to ``goal`` and the map's explored cell count; True once it has
        gone the patience without either (a new goal, or real progress, starts the count again)."""
        if goal != self._goal or distance_m < self._best_m - self.progress_m:
            self._goal, self._best_m, self._mapped, self._since = goal, distance_m, mapped_cells, 0
            return False
        if mapped_cells >= self._mapped + self.progress_cells:
            self._best_m, self._mapped, self._since = min(self._best_m, distance_m), mapped_cells, 0
            return False
        self._since += 1
        return self._since >= self.patience_steps


@dataclass
class Escape:
    """A way out of a spot the agent cannot plan from: a random number of turns one way, then two
    steps forward."""

    _moves: list[Action] = field(default_factory=list)

    @property
    def active(self) -> bool:
        return bool(self._moves)

    def reset(self) -> None:
        self._moves = []

    def start(self, rng: np.random.Generator) -> Action:
        """Draw a new escape and return its first action."""
        turn = Action.TURN_LEFT if rng.random() < 0.5 else Action.TURN_RIGHT
        moves = [turn] * int(rng.integers(1, 7)) + [Action.MOVE_FORWARD] * 2
        self._moves = moves[::-1]  # popped from the end
        return self._moves.pop()

    def next(self) -> Action:
        return self._moves.pop()


class Wayfinder:
    """Plans this step's way to the goal under the rules of its kind (``plan``), and keeps the state
    that outlives one goal mode's step: progress, the unreachable count, the escape."""

    def __init__(self, config: Config, planner: LocalPlanner, search: TargetSearch, explore: ExplorationGoals) -> None:
        self.config, self.cfg = config, config.agent
        self.planner = planner
        self.search, self.explore = search, explore
        self.progress = GoalProgress(
            self.cfg.goal_patience_steps,
            self.cfg.goal_progress_m,
            self.cfg.goal_progress_area_m2 / config.map.resolution_m**2,
        )
        self._mapped = 0  # explored cells of the map the last plan was made on
        self.escape = Escape()
        self.unreachable = 0  # consecutive steps whose goal was unreachable

    def reset(self) -> None:
        self.progress.reset()
        self.escape.reset()
        self.unreachable = 0

    def plan(self, sem_map: SemanticMap, goal: Goal, kind: GoalKind, last_move: float | None) -> Plan:
        """The next action towards ``goal``: how near is reached and how wide the goal is drawn
        depend on its ``kind``."""
        self._mapped = int(np.count_nonzero(sem_map.explored))
        if kind == GoalKind.TARGET and self.config.task.success_rule == "semexp":
            # That rule measures straight-line distance, through walls: head for the nearest cell
            # within stop distance of the target, which may be the far side of its room's wall
            # (else a target seen through a doorway sends the agent the long way round).
            assert isinstance(goal, np.ndarray)  # the target is a mask of cells
            goal, radius, dilation = _within(goal, self.cfg.stop_distance_m / sem_map.resolution_m), 0.0, 0.0
        elif kind == GoalKind.TARGET:
            radius, dilation = self.cfg.stop_distance_m, None
        elif kind == GoalKind.CANDIDATE:
            radius, dilation = self.cfg.candidate_reached_m, None
        else:
            radius, dilation = self.cfg.frontier_reached_m, self.cfg.explore_goal_dilation_m
            if kind == GoalKind.FRONTIER and goal == self.explore.pressing:
                radius = self.cfg.frontier_press_m
        return self.planner.plan(
            sem_map.obstacle,
            sem_map.agent_cell,
            sem_map.agent_heading,
            goal,
            last_move_m=last_move,
            goal_reached_radius_m=radius,
            goal_dilation_m=dilation,
            target=kind in (GoalKind.TARGET, GoalKind.CANDIDATE),
        )

    def stalled(self, goal: Cell, plan: Plan) -> bool:
        return self.progress.stalled(goal, plan.distance_to_goal_m, self._mapped)

    def done_with(self, goal: Cell, plan: Plan) -> bool:
        """Reached, unreachable, or no nearer for the patience: time for another goal."""
        return plan.reached or not plan.reachable or self.stalled(goal, plan)

    def turn_towards(self, sem_map: SemanticMap, cell: Cell) -> Action | None:
        """The turn that brings ``cell`` within ``look_tolerance_deg`` of the view's centre (None: it is)."""
        return turn_towards(sem_map, cell, math.radians(self.cfg.look_tolerance_deg))

    def other_side(self, sem_map: SemanticMap, target: np.ndarray) -> Cell | None:
        """Another pose to look at a candidate from, while it has views left (``candidate_views``)."""
        if len(self.search.views) >= self.cfg.candidate_views:
            return None
        return self.search.pick_viewpoint(sem_map, target, self.planner)


def straight_m(sem_map: SemanticMap, mask: np.ndarray) -> float:
    """Straight-line distance from the agent to the nearest cell of ``mask`` (the success rule's),
    rounded to the micrometre: a whole number of cells is not exact in floats (19 cells of 0.05 m are
    0.9500000000000001 m), and a stop bound of 0.95 m must take them."""
    rows, cols = np.nonzero(mask)
    r, c = sem_map.agent_cell
    return round(float(np.sqrt(((rows - r) ** 2 + (cols - c) ** 2).min())) * sem_map.resolution_m, 6)


def _within(mask: np.ndarray, radius_cells: float) -> np.ndarray:
    """Cells whose centre lies within ``radius_cells`` (straight line) of a cell of ``mask``."""
    return distance_to(mask, radius_cells) <= radius_cells

"""The map agent's goal modes: one small object per kind of long-term goal.

Each step the agent asks the modes in priority order which one ``wants`` the step (a manual goal,
then a confirmed target, another view of a candidate, the candidate itself, the initial look around,
a glimpse beyond the depth range, exploration). That mode ``pursue``s its goal: it plans the way and
may hand the step to another kind (a viewpoint that cannot be reached falls back to its candidate; a
glimpse that leads nowhere gives way to exploration). The agent then settles the step: the mode's own
rules first (stop at the target, set a candidate aside), then the escape every kind shares, then what
the mode does once its goal is reached.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from l3mvn.agent.decision import EXPLORING, GoalKind
from l3mvn.agent.looking import mask_centre, unknown_near
from l3mvn.agent.mapping import SemanticMap
from l3mvn.agent.modular.exploration import ExplorationGoals
from l3mvn.agent.modular.target import TargetSearch
from l3mvn.agent.modular.wayfinder import Cell, Goal, Wayfinder, straight_m
from l3mvn.agent.planning import Plan
from l3mvn.core.config import Config
from l3mvn.core.errors import L3MVNError
from l3mvn.core.types import Action


@dataclass
class Step:
    """What this step's modes share: the map and what the agent saw on it."""

    sem_map: SemanticMap
    goal: str  # the target category
    target: np.ndarray | None  # the largest blob of goal cells on the map (None: none)
    confirmed: bool  # ... and whether it has enough cells to stop at
    last_move: float | None  # metres the last forward step moved (None: the last action was no forward step)
    steps: int  # steps the agent has taken this episode
    rng: np.random.Generator
    frontiers_ms: float = 0.0  # time spent extracting frontiers and choosing among them this step
    policy_ms: float = 0.0

    def reselect(self, explore: ExplorationGoals) -> None:
        frontiers_ms, policy_ms = explore.reselect(self.sem_map, self.goal, self.rng)
        self.frontiers_ms += frontiers_ms
        self.policy_ms += policy_ms


@dataclass(frozen=True)
class Pursuit:
    """The goal a mode walks to this step, of which kind, why, and the plan there; or an ``action``
    taken without a plan (the initial look around)."""

    goal: Goal | None
    kind: GoalKind
    reason: str
    plan: Plan | None = None
    action: Action | None = None
    override: str | None = None  # a researcher's command in force (the dashboard's manual goal)


class GoalMode:
    """One kind of long-term goal (see the module docstring). The base settles nothing itself."""

    kinds: frozenset[GoalKind] = frozenset()

    def __init__(self, config: Config, wayfinder: Wayfinder, search: TargetSearch, explore: ExplorationGoals) -> None:
        self.cfg = config.agent
        self.wayfinder, self.search, self.explore = wayfinder, search, explore
        self.reset()

    def reset(self) -> None:
        """Forget the episode (most modes keep no state of their own)."""

    def wants(self, step: Step) -> bool:
        raise NotImplementedError

    def pursue(self, step: Step) -> Pursuit:
        raise NotImplementedError

    def settle(self, step: Step, p: Pursuit) -> tuple[Action, str] | None:
        """This kind's own end of the step, before the shared escape rule; None: not decided here."""
        return None

    def before_escape(self, step: Step, p: Pursuit) -> None:
        """Bookkeeping when the shared rule escapes from this kind's goal."""

    def arrived(self, step: Step, p: Pursuit) -> str:
        """What to do once the plan reached the goal; returns the step's reason."""
        return p.reason

    def _plan(self, step: Step, goal: Goal, kind: GoalKind, last_move: float | None) -> Plan:
        return self.wayfinder.plan(step.sem_map, goal, kind, last_move)


class ManualMode(GoalMode):
    """A cell picked in the dashboard, pursued until reached."""

    kinds = frozenset({GoalKind.MANUAL})
    cell: Cell | None

    def reset(self) -> None:
        self.cell: Cell | None = None

    def set(self, cell: Cell | None, map_cells: int) -> None:
        if cell is not None:
            if not (0 <= cell[0] < map_cells and 0 <= cell[1] < map_cells):
                raise L3MVNError(f"cell {cell} lies outside the {map_cells}x{map_cells} map")
            cell = (int(cell[0]), int(cell[1]))
        self.cell = cell

    def wants(self, step: Step) -> bool:
        return self.cell is not None

    def pursue(self, step: Step) -> Pursuit:
        cell = self.cell
        assert cell is not None
        return Pursuit(
            cell,
            GoalKind.MANUAL,
            f"manual goal {cell} set in the dashboard",
            self._plan(step, cell, GoalKind.MANUAL, step.last_move),
            override=f"manual:{cell[0]},{cell[1]}",
        )

    def arrived(self, step: Step, p: Pursuit) -> str:
        self.cell = None
        self.explore.force()
        return p.reason


class TargetMode(GoalMode):
    """The target, confirmed on the map: walk to it and stop."""

    kinds = frozenset({GoalKind.TARGET})

    def wants(self, step: Step) -> bool:
        return step.target is not None and step.confirmed

    def pursue(self, step: Step) -> Pursuit:
        assert step.target is not None
        return Pursuit(
            step.target,
            GoalKind.TARGET,
            f"{step.goal} seen: heading to it",
            self._plan(step, step.target, GoalKind.TARGET, step.last_move),
        )

    def settle(self, step: Step, p: Pursuit) -> tuple[Action, str] | None:
        plan, target = p.plan, p.goal
        assert plan is not None and isinstance(target, np.ndarray)
        if plan.reached:
            return Action.STOP, f"{step.goal} {straight_m(step.sem_map, target):.2f} m away: stop"
        if (not plan.reachable or plan.stuck) and (
            near := straight_m(step.sem_map, target)
        ) <= self.cfg.blocked_stop_distance_m:
            # Seen over a counter or through a gap the map closes, or the floor ends short of it:
            # as near as the free space allows.
            return Action.STOP, f"{step.goal} {near:.2f} m away (no path closer): stop"
        if (
            self.wayfinder.unreachable >= self.cfg.escape_after_unreachable
            and self.search.escapes >= self.cfg.target_escapes
        ):
            return plan.action, _set_aside_unreachable(self, step, target)
        return None

    def before_escape(self, step: Step, p: Pursuit) -> None:
        assert p.plan is not None
        if not p.plan.reachable:
            self.search.escapes += 1


class CandidateMode(GoalMode):
    """Goal cells too few to stop at: go closer, face them, look from other sides, or set them aside."""

    kinds = frozenset({GoalKind.CANDIDATE})

    def wants(self, step: Step) -> bool:
        return step.target is not None

    def pursue(self, step: Step) -> Pursuit:
        target = step.target
        assert target is not None
        reason = f"{int(target.sum())} {step.goal} cell(s) seen: too few to stop, going closer to confirm"
        return self.look_closer(
            step,
            Pursuit(target, GoalKind.CANDIDATE, reason, self._plan(step, target, GoalKind.CANDIDATE, step.last_move)),
        )

    def look_closer(self, step: Step, p: Pursuit) -> Pursuit:
        """Up close: face the cells, else look from another side. No nearer for the patience: look
        from another side, else set them aside."""
        target, plan, wayfinder = step.target, p.plan, self.wayfinder
        assert target is not None and plan is not None
        if plan.reached:
            turn = wayfinder.turn_towards(step.sem_map, mask_centre(target))
            if turn is not None:
                return replace(
                    p, plan=replace(plan, action=turn, reached=False), reason=f"{p.reason}; turning to look at it"
                )
            if (view := wayfinder.other_side(step.sem_map, target)) is not None:
                reason = f"{int(target.sum())} {step.goal} cell(s) still too few up close: looking from another side"
                return Pursuit(view, GoalKind.VIEWPOINT, reason, self._plan(step, view, GoalKind.VIEWPOINT, None))
            return p
        if wayfinder.stalled(mask_centre(target), plan):
            patience = self.cfg.goal_patience_steps
            if (view := wayfinder.other_side(step.sem_map, target)) is not None:
                return Pursuit(
                    view,
                    GoalKind.VIEWPOINT,
                    f"{p.reason}; no nearer in {patience} steps: looking from another side",
                    self._plan(step, view, GoalKind.VIEWPOINT, None),
                )
            self.search.set_aside(target)
            self.explore.force()
            return replace(
                p,
                reason=f"{step.goal} cells no nearer in {patience} steps from "
                f"{len(self.search.views) + 1} views: set aside",
            )
        return p

    def settle(self, step: Step, p: Pursuit) -> tuple[Action, str] | None:
        assert p.plan is not None and isinstance(p.goal, np.ndarray)
        if self.wayfinder.unreachable >= self.cfg.escape_after_unreachable:
            return p.plan.action, _set_aside_unreachable(self, step, p.goal)
        return None

    def arrived(self, step: Step, p: Pursuit) -> str:
        # Seen up close, faced and from other sides, and it never grew into a target: mapping noise.
        assert step.target is not None
        self.search.set_aside(step.target)
        self.explore.force()
        return f"{step.goal} cells never grew into a target from {len(self.search.views) + 1} views: set aside"


class ViewpointMode(GoalMode):
    """Another pose to look at a candidate from; once there (or it cannot be reached), face the
    candidate, then approach it again."""

    kinds = frozenset({GoalKind.VIEWPOINT})

    def wants(self, step: Step) -> bool:
        return step.target is not None and self.search.viewpoint is not None

    def pursue(self, step: Step) -> Pursuit:
        target, view, wayfinder = step.target, self.search.viewpoint, self.wayfinder
        assert target is not None and view is not None
        reason = (
            f"{int(target.sum())} {step.goal} cell(s) seen, still too few up close: looking from another "
            f"side ({len(self.search.views)} of {self.cfg.candidate_views})"
        )
        plan = self._plan(step, view, GoalKind.VIEWPOINT, step.last_move)
        if wayfinder.done_with(view, plan):
            turn = wayfinder.turn_towards(step.sem_map, mask_centre(target))
            if turn is None or not plan.reachable:
                self.search.viewpoint = None
                return Pursuit(target, GoalKind.CANDIDATE, reason, self._plan(step, target, GoalKind.CANDIDATE, None))
            plan = replace(plan, action=turn, reached=False)
        return Pursuit(view, GoalKind.VIEWPOINT, reason, plan)


class LookAroundMode(GoalMode):
    """The initial turn in place (``look_around_steps`` turns), unless the target is already in view."""

    kinds = frozenset({GoalKind.LOOK_AROUND})

    def wants(self, step: Step) -> bool:
        return step.steps < self.cfg.look_around_steps

    def pursue(self, step: Step) -> Pursuit:
        return Pursuit(None, GoalKind.LOOK_AROUND, "initial 360-degree look", action=Action.TURN_LEFT)


class ExploreMode(GoalMode):
    """Frontiers (or sampled cells, look goals, random cells) chosen by the global policy: walk there,
    look beyond it once reached, and choose again when it is done."""

    kinds = EXPLORING

    def wants(self, step: Step) -> bool:
        return True

    def pursue(self, step: Step) -> Pursuit:
        if self.explore.due(step.sem_map):
            step.reselect(self.explore)
        return self.walk_on(step, self._current(step, step.last_move))

    def walk_on(self, step: Step, p: Pursuit) -> Pursuit:
        """An exploration goal reached is looked beyond first; a goal done (reached, unreachable or no
        nearer for a while) is never come back to, and the next one is chosen now, up to
        ``max_reselect`` times, rather than spending this step on a goal that is done."""
        assert p.plan is not None
        if p.plan.reached:
            p = self.finish_looking(step, p)
        retries = 0
        # Exploration goals are cells, planned every step (``_current``).
        assert p.goal is not None and not isinstance(p.goal, np.ndarray) and p.plan is not None
        while self.wayfinder.done_with(p.goal, p.plan) and retries < self.cfg.max_reselect:
            self.explore.done(p.plan.reached)
            step.reselect(self.explore)
            p = self._current(step, None)
            retries += 1
            assert p.goal is not None and not isinstance(p.goal, np.ndarray) and p.plan is not None
        return p

    def finish_looking(self, step: Step, p: Pursuit) -> Pursuit:
        """An exploration goal reached within its radius is done only once the agent has looked into
        the unknown beyond it: face that unknown first, and if a frontier goal still borders it, walk
        on to the frontier itself (``frontier_press_m``). A door read as reached from beside it would
        otherwise be blocked for good with the room behind it never seen."""
        goal, plan, explore = p.goal, p.plan, self.explore
        assert isinstance(goal, tuple) and plan is not None
        # The unknown the goal borders, within half the radius a done goal blocks.
        beyond = unknown_near(step.sem_map, goal, explore.blocked_radius_cells(step.sem_map.resolution_m) / 2)
        turn = self.wayfinder.turn_towards(step.sem_map, goal if beyond is None else beyond)
        if turn is not None:
            return replace(
                p, plan=replace(plan, action=turn, reached=False), reason=f"{p.reason}; turning to look at it"
            )
        if p.kind == GoalKind.FRONTIER and beyond is not None and explore.pressing != goal:
            explore.pressing = goal
            pressed = self._plan(step, goal, p.kind, step.last_move)
            if pressed.reachable and not pressed.reached:
                return replace(p, plan=pressed, reason=f"{p.reason}; still unknown beyond it: walking up to it")
        return p

    def before_escape(self, step: Step, p: Pursuit) -> None:
        assert self.explore.cell is not None  # the goal this step escapes from
        self.explore.done(reached=False)

    def _current(self, step: Step, last_move: float | None) -> Pursuit:
        explore = self.explore
        assert explore.cell is not None
        return Pursuit(
            explore.cell, explore.kind, explore.reason, self._plan(step, explore.cell, explore.kind, last_move)
        )


class GlimpseMode(GoalMode):
    """The target seen beyond the depth range: walk towards it; there (or no way there, or no nearer)
    with still no goal cells on the map, explore on."""

    kinds = frozenset({GoalKind.GLIMPSE})

    def __init__(
        self,
        config: Config,
        wayfinder: Wayfinder,
        search: TargetSearch,
        explore: ExplorationGoals,
        exploring: ExploreMode,
    ) -> None:
        super().__init__(config, wayfinder, search, explore)
        self.exploring = exploring

    def wants(self, step: Step) -> bool:
        return self.search.glimpse is not None

    def pursue(self, step: Step) -> Pursuit:
        glimpse = self.search.glimpse
        assert glimpse is not None
        plan = self._plan(step, glimpse, GoalKind.GLIMPSE, step.last_move)
        if self.wayfinder.done_with(glimpse, plan):
            self.explore.blocked.append(glimpse)
            self.search.glimpse = None
            step.reselect(self.explore)
            explore = self.explore
            assert explore.cell is not None
            return self.exploring.walk_on(
                step,
                Pursuit(explore.cell, explore.kind, explore.reason, self._plan(step, explore.cell, explore.kind, None)),
            )
        return Pursuit(glimpse, GoalKind.GLIMPSE, f"{step.goal} seen beyond the depth range: walking towards it", plan)


def _set_aside_unreachable(mode: GoalMode, step: Step, target: np.ndarray) -> str:
    """Goal cells unreachable for ``escape_after_unreachable`` steps (and, for a confirmed target,
    after ``target_escapes`` escapes): never the target again this episode."""
    mode.search.set_aside(target)
    mode.wayfinder.unreachable, mode.search.escapes = 0, 0
    mode.explore.force()
    return f"{step.goal} cells unreachable: set aside, exploring on"


def goal_modes(config: Config, wayfinder: Wayfinder, search: TargetSearch, explore: ExplorationGoals) -> list[GoalMode]:
    """Every mode, in the order the agent asks them which wants the step."""
    parts = (config, wayfinder, search, explore)
    exploring = ExploreMode(*parts)
    return [
        ManualMode(*parts),
        TargetMode(*parts),
        ViewpointMode(*parts),
        CandidateMode(*parts),
        LookAroundMode(*parts),
        GlimpseMode(*parts, exploring),
        exploring,
    ]

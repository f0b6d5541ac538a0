"""The modular L3MVN agent: observation -> semantic map -> frontiers -> long-term goal -> action.

The global policy (nearest frontier, cost-utility, random sample, language-scored) only chooses the
long-term goal; mapping, target detection, commitment, stopping and the FMM local policy are shared,
so policies differ only where the paper says they do. Every step returns a ``Decision`` that explains
itself (map, frontiers with their scores, chosen goal and why) for the dashboard and the recorder.

This module runs the step: perceive, let the first goal mode that wants the step pursue its goal
(``modes``), settle it (the mode's own rules, then the shared escape), explain it. The target search
(``target``), the exploration goals (``exploration``) and the way there (``wayfinder``) keep their
own state.
"""

from __future__ import annotations

import math
import time
import zlib

import numpy as np

from l3mvn.agent.decision import Decision, GoalKind
from l3mvn.agent.looking import mask_centre
from l3mvn.agent.mapping import SemanticMap
from l3mvn.agent.modular.exploration import ExplorationGoals
from l3mvn.agent.modular.modes import GoalMode, ManualMode, Pursuit, Step, goal_modes
from l3mvn.agent.modular.target import TargetSearch
from l3mvn.agent.modular.wayfinder import Cell, Wayfinder
from l3mvn.agent.perception import Perception
from l3mvn.agent.planning import LocalPlanner
from l3mvn.agent.policies.global_policies import GlobalPolicy
from l3mvn.core.config import Config
from l3mvn.core.errors import L3MVNError
from l3mvn.core.types import Action, EpisodeBrief, Observation, Pose


class MapAgent:
    """A policy for ``EpisodeSession``: ``reset(episode)``, ``act(obs) -> Decision``."""

    def __init__(self, global_policy: GlobalPolicy, categories: tuple[str, ...], config: Config, seed: int = 0) -> None:
        """``config``: the whole tree (the agent reads its sim, task, map, frontiers, planner, agent and
        policy sections; ``Config`` has checked them against each other)."""
        self.config, self.cfg = config, config.agent
        self.global_policy = global_policy
        self.categories = categories
        self.sim = config.sim
        self.seed = seed
        self.planner = LocalPlanner.for_sim(config.planner, config.map.resolution_m, config.sim)
        self.perception = Perception(config, categories, seed)
        self.target = TargetSearch(config.agent)
        self.explore = ExplorationGoals(global_policy, config, self.planner)
        self.wayfinder = Wayfinder(config, self.planner, self.target, self.explore)
        self.modes = goal_modes(config, self.wayfinder, self.target, self.explore)
        self._mode_of = {kind: mode for mode in self.modes for kind in mode.kinds}
        self._manual = next(m for m in self.modes if isinstance(m, ManualMode))

    # --- episode lifecycle -------------------------------------------------------------------
    def reset(self, episode: EpisodeBrief) -> None:
        self.goal = episode.goal
        self.planner.reset()
        ep_seed = zlib.crc32(episode.key.encode())
        self.rng = np.random.default_rng([self.seed, ep_seed])
        self.perception.reset(episode.start, ep_seed)
        self.target.reset()
        self.explore.reset()
        self.wayfinder.reset()
        for mode in self.modes:
            mode.reset()
        self._steps = 0
        self._prev_pose: Pose | None = None
        self._prev_action: Action | None = None
        self._stuck = False  # the local planner's stuck signal at the last planned step

    def change_target(self, goal: str) -> None:
        if goal not in self.categories:
            raise L3MVNError(f"unknown target {goal!r}; valid: {', '.join(self.categories)}")
        self.goal = goal
        self.explore.force()

    def set_scorer(self, name: str) -> None:
        """Swap the language scorer of a language policy (the dashboard's scorer choice)."""
        setter = getattr(self.global_policy, "set_scorer", None)
        if setter is None:
            raise L3MVNError(f"policy {self.global_policy.name!r} uses no language scorer")
        setter(name)

    def set_manual_goal(self, cell: Cell | None) -> None:
        """Pursue this map cell until reached, or clear the override with None."""
        self._manual.set(cell, self.config.map.map_cells)

    # --- one step ----------------------------------------------------------------------------
    def act(self, obs: Observation) -> Decision:
        # The pixels the mapper reads are made before the clock starts: rendering is the simulator's time.
        obs.frame.strided(self.config.agent.downsample_factor(*obs.frame.shape))
        t0 = time.perf_counter()
        sem_map = self.perception.update(obs.frame, obs.pose, obs.tilt)
        mapping_ms = (time.perf_counter() - t0) * 1e3
        last_move = None
        if self._prev_action == Action.MOVE_FORWARD and self._prev_pose is not None:
            last_move = math.hypot(obs.pose.x - self._prev_pose.x, obs.pose.y - self._prev_pose.y)
        if self.wayfinder.escape.active:
            self._steps += 1
            return self._decide(
                obs,
                sem_map,
                self.wayfinder.escape.next(),
                Pursuit(
                    self.explore.cell, GoalKind.ESCAPE, "escaping: cleared collision marks, random turn then forward"
                ),
                t0,
                mapping_ms,
            )
        target, confirmed = self.target.mask(sem_map, self.goal)
        self.target.observe(target, confirmed, self._far_sighting(sem_map) if target is None else None)
        step = Step(sem_map, self.goal, target, confirmed, last_move, self._steps, self.rng)
        t1 = time.perf_counter()
        mode = next(m for m in self.modes if m.wants(step))
        pursuit = mode.pursue(step)
        if pursuit.action is not None:  # no plan: the look around
            self._steps += 1
            return self._decide(obs, sem_map, pursuit.action, pursuit, t0, mapping_ms)
        planning_ms = (time.perf_counter() - t1) * 1e3 - step.frontiers_ms - step.policy_ms
        pursuit = self._with_marks(pursuit)
        action, reason = self._settle(step, pursuit)
        self.explore.tick()
        self._steps += 1
        return self._decide(
            obs,
            sem_map,
            action,
            Pursuit(pursuit.goal, pursuit.kind, reason, pursuit.plan, override=pursuit.override),
            t0,
            mapping_ms,
            {"planning": planning_ms, "frontiers": step.frontiers_ms, "policy": step.policy_ms},
        )

    def _with_marks(self, p: Pursuit) -> Pursuit:
        """The reason says when the planner's collision marks changed under this step."""
        plan, reason, detour = p.plan, p.reason, self.config.planner.target_mark_detour_m
        assert plan is not None
        if plan.marked_beside:
            reason = (
                f"{reason}; collision marked beside the mapped obstacle it ran into: across the way "
                f"it lengthened it by over {detour:g} m"
            )
        if plan.marks_cleared:
            reason = f"{reason}; collision marks cleared: they lengthened the way by over {detour:g} m"
        return Pursuit(p.goal, p.kind, reason, plan, override=p.override)

    def _settle(self, step: Step, p: Pursuit) -> tuple[Action, str]:
        """The step's action: the pursuing kind's own rules, else an escape when the goal has been
        unreachable ``escape_after_unreachable`` steps or the planner is stuck, else the plan's step
        (and the kind's business once its goal is reached)."""
        plan, wayfinder = p.plan, self.wayfinder
        assert plan is not None
        self._stuck = plan.stuck
        wayfinder.unreachable = 0 if plan.reachable else wayfinder.unreachable + 1
        mode: GoalMode = self._mode_of[p.kind]
        if (settled := mode.settle(step, p)) is not None:
            return settled
        if wayfinder.unreachable >= self.cfg.escape_after_unreachable or plan.stuck:
            mode.before_escape(step, p)
            self.planner.clear_collisions()
            wayfinder.unreachable = 0
            self.explore.force()
            return wayfinder.escape.start(self.rng), "goal unreachable or stuck: clearing collision marks, escaping"
        if plan.reached:
            return plan.action, mode.arrived(step, p)
        return plan.action, p.reason

    def _far_sighting(self, sem_map: SemanticMap) -> Cell | None:
        if self.goal not in self.categories:
            return None
        frame = self.perception.frame
        assert frame is not None
        return self.target.far_sighting(
            sem_map,
            frame.depth,
            frame.semantic,
            self.categories.index(self.goal) + 1,
            frame.intrinsics.focal_px,
            self.sim.max_depth_m,
            self.explore.blocked,
        )

    def _decide(
        self,
        obs: Observation,
        sem_map: SemanticMap,
        action: Action,
        p: Pursuit,
        t0: float,
        mapping_ms: float,
        stage_ms: dict[str, float] | None = None,
    ) -> Decision:
        self._prev_pose, self._prev_action = obs.pose, action
        timings = {
            "mapping": mapping_ms,
            "planning": 0.0,
            "total": (time.perf_counter() - t0) * 1e3,
            **(stage_ms or {}),
        }
        goal = p.goal
        explore = self.explore
        return Decision(
            action=action,
            reason=p.reason,
            map=sem_map,
            frontiers=explore.frontiers,
            long_term_goal=goal if isinstance(goal, tuple) or goal is None else mask_centre(goal),
            goal_kind=p.kind,
            chosen_frontier=explore.frontier if p.kind == GoalKind.FRONTIER else None,
            short_term_goal=None if p.plan is None else p.plan.short_term_goal,
            override=p.override,
            target_seen=p.kind == GoalKind.TARGET,
            stuck=self._stuck,
            timings_ms=timings,
            collision_marks=self.planner.collision_cells,
        )

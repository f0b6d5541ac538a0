"""The modular L3MVN agent: observation -> semantic map -> frontiers -> long-term goal -> action.

The global policy (nearest frontier, cost-utility, random sample, language-scored) only chooses the
long-term goal; mapping, target detection, commitment, stopping and the FMM local policy are shared,
so policies differ only where the paper says they do. Every step returns a ``Decision`` that explains
itself (map, frontiers with their scores, chosen goal and why) for the dashboard and the recorder.
"""

from __future__ import annotations

import math
import time
import zlib
from dataclasses import replace

import cv2
import numpy as np

from l3mvn.config import Config
from l3mvn.errors import L3MVNError
from l3mvn.events import EXPLORING, Decision, GoalKind
from l3mvn.frontiers import Frontier, extract_frontiers
from l3mvn.looking import distance_to, far_sighting, look_goal, mask_centre, pick_viewpoint, turn_towards, unknown_near
from l3mvn.mapping import SemanticMap, SemanticMapper
from l3mvn.mapping.projection import downsample_frame
from l3mvn.perception import SegmentationNoise
from l3mvn.planning import LocalPlanner
from l3mvn.policies.global_policies import GlobalPolicy, Selection
from l3mvn.types import Action, Episode, Observation, Pose




class MapAgent:
    """A policy object for ``EpisodeSession``: ``reset(episode)``, ``act(obs) -> Decision``."""

    def __init__(self, global_policy: GlobalPolicy, categories: tuple[str, ...], config: Config,
                 seed: int = 0) -> None:
        """``config``: the whole tree (the agent reads its sim, task, map, frontiers, planner, agent and
        policy sections; ``Config`` has checked them against each other)."""
        self.config, self.cfg = config, config.agent
        self.global_policy = global_policy
        self.categories = categories
        self.sim = config.sim
        self.seed = seed
        self.planner = LocalPlanner(config.planner, config.map.resolution_m)
        self.noise = SegmentationNoise(config.policy.seg_noise, len(categories), seed)
        self._mapper: SemanticMapper | None = None
        self._frame_shape: tuple[int, int] | None = None
        self.stuck = False

    # --- episode lifecycle -------------------------------------------------------------------
    def reset(self, episode: Episode) -> None:
        self.goal = episode.goal
        self.planner.reset()
        ep_seed = zlib.crc32(episode.key.encode())
        self.rng = np.random.default_rng([self.seed, ep_seed])
        self.noise.reset(ep_seed)
        self._mapper = None  # built on the first frame, sized from it
        self._start = episode.start
        self._steps = 0
        self._since_select = math.inf
        self._ltg: tuple[int, int] | None = None
        self._ltg_kind = GoalKind.NONE
        self._ltg_frontier: int | None = None
        self._ltg_reason = ""
        self._manual: tuple[int, int] | None = None
        self._blocked: list[tuple[int, int]] = []
        self._prev_pose: Pose | None = None
        self._prev_action: Action | None = None
        self._frontiers: list[Frontier] = []
        self._unreachable = 0
        self._escape: list[Action] = []
        self._rejected: np.ndarray | None = None
        self._target_escapes = 0
        self._viewpoint: tuple[int, int] | None = None
        self._pressing: tuple[int, int] | None = None  # frontier goal walked up to (frontier_press_m)
        self._stood: set[tuple[int, int]] = set()  # done goals the agent stood on and looked beyond
        self._views: list[float] = []  # bearings (from the glimpsed target) it was looked at from
        self._glimpse: tuple[int, int] | None = None  # where a sighting beyond the depth range points
        self._frame: tuple[np.ndarray, np.ndarray] | None = None  # the last mapped depth and labels
        self._progress: tuple[tuple[int, int] | None, float, int] = (None, math.inf, 0)  # goal, best m, steps
        self.stuck = False

    def change_target(self, goal: str) -> None:
        if goal not in self.categories:
            raise L3MVNError(f"unknown target {goal!r}; valid: {', '.join(self.categories)}")
        self.goal = goal
        self._since_select = math.inf

    def set_scorer(self, name: str) -> None:
        """Swap the language scorer of a language policy (the dashboard's scorer choice)."""
        setter = getattr(self.global_policy, "set_scorer", None)
        if setter is None:
            raise L3MVNError(f"policy {self.global_policy.name!r} uses no language scorer")
        setter(name)

    def set_manual_goal(self, cell: tuple[int, int] | None) -> None:
        """Pursue this map cell until reached, or clear the override with None."""
        if cell is not None:
            size = self.config.map.map_cells
            if not (0 <= cell[0] < size and 0 <= cell[1] < size):
                raise L3MVNError(f"cell {cell} lies outside the {size}x{size} map")
            cell = (int(cell[0]), int(cell[1]))
        self._manual = cell

    # --- one step ----------------------------------------------------------------------------
    def act(self, obs: Observation) -> Decision:
        t = {"start": time.perf_counter()}
        sem_map = self._update_map(obs)
        t["mapping"] = time.perf_counter()
        last_move = None
        if self._prev_action == Action.MOVE_FORWARD and self._prev_pose is not None:
            last_move = math.hypot(obs.pose.x - self._prev_pose.x, obs.pose.y - self._prev_pose.y)

        if self._escape:
            self._steps += 1
            return self._decide(obs, self._escape.pop(), sem_map, self._ltg, "escape",
                                "escaping: cleared collision marks, random turn then forward", t, None, None)
        target, confirmed = self._target_mask(sem_map)
        if target is None or confirmed:  # nothing glimpsed, or confirmed: no other views needed
            self._viewpoint, self._views = None, []
        if target is None:
            self._glimpse = self._far_sighting(sem_map) or self._glimpse
        else:
            self._glimpse = None
        override = None
        frontiers_ms = policy_ms = 0.0
        if self._manual is not None:
            goal, kind, reason = self._manual, GoalKind.MANUAL, f"manual goal {self._manual} set in the dashboard"
            override = f"manual:{self._manual[0]},{self._manual[1]}"
        elif target is not None and confirmed:
            goal, kind, reason = target, GoalKind.TARGET, f"{self.goal} seen: heading to it"
        elif target is not None and self._viewpoint is not None:
            goal, kind = self._viewpoint, GoalKind.VIEWPOINT
            reason = (f"{int(target.sum())} {self.goal} cell(s) seen, still too few up close: looking from "
                      f"another side ({len(self._views)} of {self.cfg.candidate_views})")
        elif target is not None:
            goal, kind = target, GoalKind.CANDIDATE
            reason = f"{int(target.sum())} {self.goal} cell(s) seen: too few to stop, going closer to confirm"
        elif self._steps < self.cfg.look_around_steps:
            self._steps += 1
            return self._decide(obs, Action.TURN_LEFT, sem_map, None, GoalKind.LOOK_AROUND,
                                "initial 360-degree look", t, None, None)
        elif self._glimpse is not None:
            goal, kind = self._glimpse, GoalKind.GLIMPSE
            reason = f"{self.goal} seen beyond the depth range: walking towards it"
        else:
            if self._reselect_due():
                frontiers_ms, policy_ms = self._reselect(sem_map)
            goal, kind, reason = self._ltg, self._ltg_kind, self._ltg_reason
        t["select"] = time.perf_counter()

        plan = self._plan(sem_map, goal, kind, last_move)
        if kind == GoalKind.GLIMPSE and (plan.reached or not plan.reachable or self._stalled(goal, plan)):
            # There, and the target still maps to nothing (or no way there): explore on.
            self._blocked.append(goal)
            self._glimpse = None
            more_f, more_p = self._reselect(sem_map)
            frontiers_ms, policy_ms = frontiers_ms + more_f, policy_ms + more_p
            goal, kind, reason = self._ltg, self._ltg_kind, self._ltg_reason
            plan = self._plan(sem_map, goal, kind, None)
        if kind in EXPLORING and plan.reached:
            plan, reason = self._finish_looking(sem_map, goal, kind, plan, reason, last_move)
        retries = 0
        while kind in EXPLORING and (plan.reached or not plan.reachable or self._stalled(goal, plan)) \
                and retries < self.cfg.max_reselect:
            # Reached (or found unreachable, or no nearer for a while) an exploration goal: never come
            # back to it, and pick the next one now rather than spending this step on a goal that is done.
            self._blocked.append(self._ltg)
            if self._ltg == self._pressing and plan.reached:
                self._stood.add(self._ltg)
            more_f, more_p = self._reselect(sem_map)
            frontiers_ms, policy_ms = frontiers_ms + more_f, policy_ms + more_p
            goal, kind, reason = self._ltg, self._ltg_kind, self._ltg_reason
            plan = self._plan(sem_map, goal, kind, None)
            retries += 1
        if kind == GoalKind.VIEWPOINT and (plan.reached or not plan.reachable or self._stalled(goal, plan)):
            # At the other pose (or it cannot be reached): face the sighting, then approach it again.
            turn = self._turn_towards(sem_map, mask_centre(target))
            if turn is None or not plan.reachable:
                self._viewpoint = None
                goal, kind = target, GoalKind.CANDIDATE
                plan = self._plan(sem_map, goal, kind, None)
            else:
                plan = replace(plan, action=turn, reached=False)
        elif kind == GoalKind.CANDIDATE and plan.reached:
            turn = self._turn_towards(sem_map, mask_centre(target))
            if turn is not None:
                plan = replace(plan, action=turn, reached=False)
                reason = f"{reason}; turning to look at it"
            elif len(self._views) < self.cfg.candidate_views \
                    and (view := self._pick_viewpoint(sem_map, target)) is not None:
                self._viewpoint = view
                goal, kind = view, GoalKind.VIEWPOINT
                reason = f"{int(target.sum())} {self.goal} cell(s) still too few up close: looking from another side"
                plan = self._plan(sem_map, goal, kind, None)
        t["planning"] = time.perf_counter()
        self.stuck = plan.stuck
        action = plan.action
        self._unreachable = 0 if plan.reachable else self._unreachable + 1
        if plan.reached and kind == GoalKind.TARGET:
            action, reason = Action.STOP, f"{self.goal} {_straight_m(sem_map, goal):.2f} m away: stop"
        elif kind == GoalKind.TARGET and (not plan.reachable or plan.stuck) \
                and (near := _straight_m(sem_map, goal)) <= self.cfg.blocked_stop_distance_m:
            # Seen over a counter or through a gap the map closes, or the floor ends short of it
            # (Hiteman: pushed 380 steps along the navmesh edge 0.90 m from a toilet): as near as
            # the free space allows.
            action, reason = Action.STOP, f"{self.goal} {near:.2f} m away (no path closer): stop"
        elif kind in (GoalKind.CANDIDATE, GoalKind.TARGET) and self._unreachable >= self.cfg.escape_after_unreachable and (
            kind == GoalKind.CANDIDATE or self._target_escapes >= self.cfg.target_escapes
        ):
            self._rejected |= goal
            self._unreachable, self._target_escapes, self._since_select = 0, 0, math.inf
            self._viewpoint, self._views = None, []
            reason = f"{self.goal} cells unreachable: set aside, exploring on"
        elif self._unreachable >= self.cfg.escape_after_unreachable or plan.stuck:
            if kind == GoalKind.TARGET and not plan.reachable:
                self._target_escapes += 1
            if kind in EXPLORING:
                self._blocked.append(self._ltg)
            self._start_escape()
            action, reason = self._escape.pop(), "goal unreachable or stuck: clearing collision marks, escaping"
        elif plan.reached and kind == GoalKind.CANDIDATE:
            # Seen up close, faced and from other sides, and it never grew into a target: mapping noise.
            self._rejected |= target
            reason = f"{self.goal} cells never grew into a target from {len(self._views) + 1} views: set aside"
            self._since_select, self._views = math.inf, []
        elif plan.reached and kind == GoalKind.MANUAL:
            self._manual = None
            self._since_select = math.inf
        self._since_select += 1
        self._steps += 1
        return self._decide(obs, action, sem_map, goal if isinstance(goal, tuple) else mask_centre(goal), kind,
                            reason, t, plan.short_term_goal, override,
                            extra_ms={"frontiers": frontiers_ms, "policy": policy_ms})

    # --- pieces ------------------------------------------------------------------------------
    def _reselect_due(self) -> bool:
        """Every ``replan_every`` steps, at once when forced (inf), never while a policy that keeps
        its goal (random sample) still pursues one or while walking up to a frontier."""
        if self._ltg is None or self._since_select == math.inf:
            return True
        keeps = self._ltg_kind == GoalKind.RANDOM and getattr(self.global_policy, "keeps_goal", False)
        keeps = keeps or (self._ltg_kind == GoalKind.FRONTIER and self._ltg == self._pressing)  # nearly there
        return self._since_select >= self.cfg.replan_every and not keeps

    def _reselect(self, sem_map: SemanticMap) -> tuple[float, float]:
        """Extract frontiers and let the global policy choose; returns (frontier ms, policy ms).
        With no frontier left, look at what was only seen from afar before revisiting old goals."""
        t0 = time.perf_counter()
        self._frontiers = self._extract(sem_map)
        if not self._frontiers and (look := self._look_goal(sem_map)) is not None:
            self._since_select = 0
            self._ltg, self._ltg_kind, self._ltg_frontier = look, GoalKind.LOOK, None
            self._ltg_reason = "no frontier left: looking at floor seen only from afar"
            return (time.perf_counter() - t0) * 1e3, 0.0
        if not self._frontiers and self._blocked:
            # Every frontier left was reached once and is still there (the camera could not clear
            # it from where the agent stood): visiting them again beats wandering at random.
            self._blocked.clear()
            self._frontiers = self._extract(sem_map)
        t1 = time.perf_counter()
        self._select(sem_map)
        return (t1 - t0) * 1e3, (time.perf_counter() - t1) * 1e3

    def _stalled(self, goal: tuple[int, int], plan) -> bool:
        """True once ``goal`` has gone ``goal_patience_steps`` steps without coming ``goal_progress_m`` closer."""
        last_goal, best, since = self._progress
        if goal != last_goal or plan.distance_to_goal_m < best - self.cfg.goal_progress_m:
            self._progress = (goal, plan.distance_to_goal_m, 0)
            return False
        self._progress = (goal, best, since + 1)
        return since + 1 >= self.cfg.goal_patience_steps

    def _plan(self, sem_map: SemanticMap, goal, kind: str, last_move: float | None):
        if kind == GoalKind.TARGET and self.config.task.success_rule == "semexp":
            # That rule measures straight-line distance, through walls: head for the nearest cell
            # within stop distance of the target, which may be the far side of its room's wall
            # (Pinesdale: a TV seen through a doorway sent the agent round the house's outside).
            goal, radius, dilation = _within(goal, self.cfg.stop_distance_m / sem_map.resolution_m), 0.0, 0.0
        elif kind == GoalKind.TARGET:
            radius, dilation = self.cfg.stop_distance_m, None
        elif kind == GoalKind.CANDIDATE:
            radius, dilation = self.cfg.candidate_reached_m, None
        else:
            radius, dilation = self.cfg.frontier_reached_m, self.cfg.explore_goal_dilation_m
            if kind == GoalKind.FRONTIER and goal == self._pressing:
                radius = self.cfg.frontier_press_m
        return self.planner.plan(sem_map.obstacle, sem_map.agent_cell, sem_map.agent_heading, goal,
                                 last_move_m=last_move, goal_reached_radius_m=radius,
                                 goal_dilation_m=dilation)

    def _finish_looking(self, sem_map: SemanticMap, goal: tuple[int, int], kind: str, plan, reason: str,
                        last_move: float | None):
        """An exploration goal reached within its radius is done only once the agent has looked into
        the unknown beyond it: face that unknown first, and if a frontier goal still borders it,
        walk on to the frontier itself (``frontier_press_m``). On the Gibson dev houses the door of
        a bathroom read as reached from 0.75 m beside it, its frontier was blocked for good, and
        the toilet behind was never seen (Stockman)."""
        # The unknown the goal borders, within half the radius a done goal blocks.
        beyond = unknown_near(sem_map, goal, self.cfg.blocked_radius_m / sem_map.resolution_m / 2)
        turn = self._turn_towards(sem_map, goal if beyond is None else beyond)
        if turn is not None:
            return replace(plan, action=turn, reached=False), f"{reason}; turning to look at it"
        if kind == GoalKind.FRONTIER and beyond is not None and self._pressing != goal:
            self._pressing = goal
            pressed = self._plan(sem_map, goal, kind, last_move)
            if pressed.reachable and not pressed.reached:
                return pressed, f"{reason}; still unknown beyond it: walking up to it"
        return plan, reason

    def _turn_towards(self, sem_map: SemanticMap, cell: tuple[int, int]) -> Action | None:
        return turn_towards(sem_map, cell, math.radians(self.cfg.look_tolerance_deg))

    def _pick_viewpoint(self, sem_map: SemanticMap, target: np.ndarray) -> tuple[int, int] | None:
        """Another pose to look at a glimpsed target from (``looking.pick_viewpoint``); the view from
        here is remembered so the next one differs from it too."""
        res = sem_map.resolution_m
        found = pick_viewpoint(sem_map, target, self.planner, self._views, self.cfg.viewpoint_min_m / res,
                               self.cfg.viewpoint_max_m / res)
        if found is None:
            return None
        self._views.append(found[1])
        return found[0]

    def _look_goal(self, sem_map: SemanticMap) -> tuple[int, int] | None:
        return look_goal(sem_map, self.planner, self._blocked, self.cfg.blocked_radius_m / sem_map.resolution_m,
                         self.cfg.look_min_area_m2)

    def _far_sighting(self, sem_map: SemanticMap) -> tuple[int, int] | None:
        if self.goal not in self.categories:
            return None
        depth, semantic = self._frame
        return far_sighting(sem_map, depth, semantic, self.categories.index(self.goal) + 1,
                            self._mapper.intrinsics.focal_px, self.sim.max_depth_m / sem_map.resolution_m,
                            (self.cfg.glimpse_min_fraction, self.cfg.glimpse_max_fraction), self._blocked,
                            self.cfg.blocked_radius_m / sem_map.resolution_m)

    def _start_escape(self) -> None:
        self.planner.clear_collisions()
        self._unreachable = 0
        self._since_select = math.inf
        turn = Action.TURN_LEFT if self.rng.random() < 0.5 else Action.TURN_RIGHT
        moves = [turn] * int(self.rng.integers(1, 7)) + [Action.MOVE_FORWARD] * 2
        self._escape = moves[::-1]  # popped from the end

    def _update_map(self, obs: Observation) -> SemanticMap:
        factor = self.cfg.downsample_factor(*obs.depth.shape)
        depth, semantic = (obs.depth, obs.semantic) if factor == 1 else downsample_frame(obs.depth, obs.semantic, factor)
        semantic = self.noise(semantic)
        if self._mapper is None or self._frame_shape != depth.shape:
            self._mapper = SemanticMapper.for_sim(self.config.map, self.sim, depth.shape[0], depth.shape[1],
                                                  self.categories)
            self._mapper.reset(self._start)
            self._frame_shape = depth.shape
        self._frame = (depth, semantic)
        return self._mapper.update(depth, semantic, obs.pose, obs.tilt)

    def _target_mask(self, sem_map: SemanticMap) -> tuple[np.ndarray | None, bool]:
        """The largest connected blob of the goal channel (rejected cells aside) and whether it has
        enough cells to stop at; a smaller one is worth a closer look (a far plant maps to 1-2 cells)."""
        if self.goal not in sem_map.category_names:
            return None, False
        channel = sem_map.category(self.goal)
        if self._rejected is None or self._rejected.shape != channel.shape:
            self._rejected = np.zeros_like(channel)
        channel = channel & ~self._rejected
        rows, cols = np.nonzero(channel.any(axis=1))[0], np.nonzero(channel.any(axis=0))[0]
        if len(rows) == 0:
            return None, False
        r0, r1, c0, c1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
        crop = channel[r0:r1, c0:c1].astype(np.uint8)
        n, labels, stats, _ = cv2.connectedComponentsWithStats(crop, connectivity=8)
        if n <= 1:
            return None, False
        best = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
        mask = np.zeros_like(channel)
        mask[r0:r1, c0:c1] = labels == best
        return mask, bool(stats[best, cv2.CC_STAT_AREA] >= self.cfg.target_min_cells)

    def _extract(self, sem_map: SemanticMap) -> list[Frontier]:
        # The field must cover every explored cell: frontiers far from any obstacle (the open end of
        # a corridor) would otherwise read as unreachable and be dropped.
        rows = np.flatnonzero(sem_map.explored.any(axis=1))
        cols = np.flatnonzero(sem_map.explored.any(axis=0))
        last = sem_map.size - 1
        corners = np.array([[max(rows[0] - 1, 0), max(cols[0] - 1, 0)],
                            [min(rows[-1] + 1, last), min(cols[-1] + 1, last)]])
        field_ = self.planner.distance_from_agent(sem_map.obstacle, sem_map.agent_cell, targets=corners).full()
        return extract_frontiers(sem_map.explored, sem_map.obstacle, sem_map.agent_cell, field_,
                                 sem_map.categories, sem_map.category_names, self.config.frontiers, resolution_m=sem_map.resolution_m,
                                 blocked=np.array(self._blocked, dtype=np.int64).reshape(-1, 2),
                                 blocked_radius_cells=self._blocked_radii(sem_map.resolution_m),
                                 agent_heading=sem_map.agent_heading)

    def _blocked_radii(self, resolution_m: float) -> np.ndarray:
        """Cells around each done goal where frontiers are dropped: ``blocked_radius_m``, halved for a
        frontier the agent stood on and looked beyond (only that spot is done: Lakeville/0/1's
        bathroom door lay 0.7 m from such a spot and the full radius dropped it for good)."""
        full = self.cfg.blocked_radius_m / resolution_m
        return np.array([full / 2 if cell in self._stood else full for cell in self._blocked], dtype=np.float64)

    def _select(self, sem_map: SemanticMap) -> None:
        self._since_select = 0
        sel = self.global_policy.select(self._frontiers, sem_map, self.goal, self.rng)
        if sel is not None and sel.language:
            self._frontiers = _with_language(self._frontiers, sel)
        if sel is None:  # nothing left to explore: wander to a random free cell of the local map
            win = sem_map.local_window()
            free = np.argwhere(~win.obstacle & ~win.explored) if (~win.explored).any() else np.argwhere(~win.obstacle)
            r, c = free[self.rng.integers(len(free))]
            self._ltg = (int(r) + win.bounds[0], int(c) + win.bounds[2])
            self._ltg_kind, self._ltg_frontier = GoalKind.EXPLORE, None
            self._ltg_reason = "no frontier: exploring a random free cell"
            return
        sel = self._commit(sel)
        self._ltg, self._ltg_frontier = sel.cell, sel.frontier
        self._ltg_kind = GoalKind.FRONTIER if sel.frontier is not None else GoalKind.RANDOM
        self._ltg_reason = sel.reason

    def _commit(self, sel: Selection) -> Selection:
        """Hysteresis: stay with the frontier pursued so far unless the new best is clearly better
        (re-selecting every 10 steps with position-dependent scores otherwise flips between targets)."""
        if self._ltg is None or self._ltg_frontier is None or sel.frontier is None or not self._frontiers:
            return sel
        centres = np.array([f.center for f in self._frontiers])
        d = np.hypot(*(centres - np.array(self._ltg)).T)
        j = int(np.argmin(d))
        if j == sel.frontier or d[j] > self.cfg.commitment_radius_m / self.config.map.resolution_m:  # or it is gone
            return sel
        if sel.scores[sel.frontier] - sel.scores[j] < self.cfg.commitment_margin:
            f = self._frontiers[j]
            return Selection(j, f.center, sel.scores, f"kept frontier {f.id} (commitment): {self._ltg_reason}")
        return sel

    def _decide(self, obs, action, sem_map, ltg, kind, reason, t, stg, override, extra_ms=None) -> Decision:
        self._prev_pose, self._prev_action = obs.pose, action
        now = time.perf_counter()
        timings = {
            "mapping": (t["mapping"] - t["start"]) * 1e3,
            "planning": (t["planning"] - t["select"]) * 1e3 if "planning" in t else 0.0,
            "total": (now - t["start"]) * 1e3,
        }
        timings.update(extra_ms or {})
        return Decision(
            action=action, reason=reason, map=sem_map, frontiers=self._frontiers, long_term_goal=ltg,
            goal_kind=kind, chosen_frontier=self._ltg_frontier if kind == GoalKind.FRONTIER else None,
            short_term_goal=stg, override=override, target_seen=kind == GoalKind.TARGET, stuck=self.stuck,
            timings_ms=timings,
        )


def _straight_m(sem_map: SemanticMap, mask: np.ndarray) -> float:
    """Straight-line distance from the agent to the nearest cell of ``mask`` (the success rule's)."""
    rows, cols = np.nonzero(mask)
    r, c = sem_map.agent_cell
    return float(np.sqrt(((rows - r) ** 2 + (cols - c) ** 2).min())) * sem_map.resolution_m


def _within(mask: np.ndarray, radius_cells: float) -> np.ndarray:
    """Cells whose centre lies within ``radius_cells`` (straight line) of a cell of ``mask``."""
    return distance_to(mask, radius_cells) <= radius_cells


def _with_language(frontiers: list[Frontier], sel: Selection) -> list[Frontier]:
    """The frontiers as the decision shows them: each with its language scores, the chosen one with
    the policy's reason."""
    return [replace(f, queries=ls.queries, llm_scores=ls.llm_scores, s_llm=ls.s_llm, fused=ls.fused,
                    reason=sel.reason if k == sel.frontier else f.reason)
            for k, (f, ls) in enumerate(zip(frontiers, sel.language))]

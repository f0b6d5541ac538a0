"""Exploration goals: which frontier (or sampled cell, or glimpsed area) the agent walks to next.

The global policy only ranks; this module owns what the ranking is applied to and how long a
choice lasts: frontiers extracted away from goals already done, re-selection every
``replan_every`` steps with commitment to the goal pursued so far, look goals at floor only seen
from afar once frontiers run out, and the record of done goals (those the agent stood on and
looked beyond block a smaller radius, and a done frontier blocks only what is left of itself).
"""

from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np

from l3mvn.agent.decision import GoalKind
from l3mvn.agent.frontiers import Frontier, extract_frontiers
from l3mvn.agent.looking import look_goal
from l3mvn.agent.mapping import SemanticMap
from l3mvn.agent.planning import LocalPlanner
from l3mvn.agent.policies.global_policies import GlobalPolicy, Selection
from l3mvn.core.config import Config

Cell = tuple[int, int]


class ExplorationGoals:
    """Per-episode state of the exploration goal: the current one, the frontiers it was chosen
    from, and every goal already done."""

    def __init__(self, global_policy: GlobalPolicy, config: Config, planner: LocalPlanner) -> None:
        self.global_policy = global_policy
        self.config, self.cfg = config, config.agent
        self.planner = planner
        self.reset()

    def reset(self) -> None:
        self.cell: Cell | None = None
        self.kind = GoalKind.NONE
        self.frontier: int | None = None  # index into ``frontiers`` of the chosen frontier
        self.reason = ""
        self.chosen_reason = ""  # why the frontier being kept was first chosen
        self.frontiers: list[Frontier] = []
        self.blocked: list[Cell] = []  # done goals: no frontier is taken near them again
        self.done_frontiers: dict[Cell, np.ndarray] = {}  # done frontier goals: the frontier's cells
        self.stood: set[Cell] = set()  # done goals the agent stood on and looked beyond
        self.pressing: Cell | None = None  # frontier goal walked up to (``frontier_press_m``)
        self.since_select = math.inf

    def force(self) -> None:
        """Choose afresh on the next step that explores (new target, escape, a goal set aside)."""
        self.since_select = math.inf

    def tick(self) -> None:
        self.since_select += 1

    def done(self, reached: bool) -> None:
        """The current goal is done (reached, unreachable or stalled): never come back to it."""
        assert self.cell is not None  # only a goal being pursued is done
        self.blocked.append(self.cell)
        if self.kind == GoalKind.FRONTIER and self.frontier is not None:
            self.done_frontiers[self.cell] = self.frontiers[self.frontier].cells
        if self.cell == self.pressing and reached:
            self.stood.add(self.cell)

    def due(self, sem_map: SemanticMap) -> bool:
        """Every ``replan_every`` steps, at once when forced (inf), never while a policy that keeps
        its goal (random sample) still pursues one, while walking up to a frontier, or once nearer
        its frontier than ``min_distance_m``: a new list would leave that frontier out, unexplored,
        and it would come back once the agent had walked away, so the agent could walk back and
        forth between two frontiers for hundreds of steps. This step's plan reads it as reached
        instead, and the agent looks beyond it before choosing again."""
        if self.cell is None or self.since_select == math.inf:
            return True
        keeps = self.kind == GoalKind.RANDOM and getattr(self.global_policy, "keeps_goal", False)
        keeps = keeps or (self.kind == GoalKind.FRONTIER and self.cell == self.pressing)  # nearly there
        keeps = keeps or (self.kind == GoalKind.FRONTIER and self._too_near_to_list(sem_map))
        return self.since_select >= self.cfg.replan_every and not keeps

    def _too_near_to_list(self, sem_map: SemanticMap) -> bool:
        assert self.cell is not None  # asked by ``due`` only while there is a goal
        (r, c), (gr, gc) = sem_map.agent_cell, self.cell
        return math.hypot(r - gr, c - gc) * sem_map.resolution_m < self.config.frontiers.min_distance_m

    def reselect(self, sem_map: SemanticMap, goal: str, rng: np.random.Generator) -> tuple[float, float]:
        """Extract frontiers and let the global policy choose; returns (frontier ms, policy ms).
        With no frontier left, look at what was only seen from afar before revisiting old goals."""
        t0 = time.perf_counter()
        self.frontiers = self.extract(sem_map)
        if not self.frontiers and (look := self._look_goal(sem_map)) is not None:
            self.since_select = 0
            self.cell, self.kind, self.frontier = look, GoalKind.LOOK, None
            self.reason = "no frontier left: looking at floor seen only from afar"
            return (time.perf_counter() - t0) * 1e3, 0.0
        if not self.frontiers and sem_map.inferred is not None and sem_map.inferred.any():
            # Nothing left unknown but beyond guessed obstacles (depth nearer than the sensor reads),
            # the weakest evidence on the map: through a door frame they cut its frontier below
            # ``min_cluster_cells``, leaving no frontier, and the agent would draw unreachable random
            # cells for a long time. The edge beside a guess is a frontier then; the planner still
            # walks round the guesses, and seeing the floor beyond takes them back.
            self.frontiers = self.extract(sem_map, sem_map.seen_obstacle)
        if not self.frontiers and self.blocked:
            # Every frontier left was reached once and is still there (the camera could not clear
            # it from where the agent stood): visiting them again beats wandering at random.
            self.blocked.clear()
            self.done_frontiers.clear()
            self.frontiers = self.extract(sem_map)
        t1 = time.perf_counter()
        self._select(sem_map, goal, rng)
        return (t1 - t0) * 1e3, (time.perf_counter() - t1) * 1e3

    def blocked_radius_cells(self, resolution_m: float) -> float:
        return self.cfg.blocked_radius_m / resolution_m

    def _look_goal(self, sem_map: SemanticMap) -> Cell | None:
        return look_goal(
            sem_map,
            self.planner,
            self.blocked,
            self.blocked_radius_cells(sem_map.resolution_m),
            self.cfg.look_min_area_m2,
        )

    def extract(self, sem_map: SemanticMap, obstacle: np.ndarray | None = None) -> list[Frontier]:
        """Frontiers of the map, cut where ``obstacle`` (default: the map's, guesses included) lies."""
        obstacle = sem_map.obstacle if obstacle is None else obstacle
        # The field must cover every explored cell: frontiers far from any obstacle (the open end of
        # a corridor) would otherwise read as unreachable and be dropped.
        rows = np.flatnonzero(sem_map.explored.any(axis=1))
        cols = np.flatnonzero(sem_map.explored.any(axis=0))
        last = sem_map.size - 1
        corners = np.array(
            [[max(rows[0] - 1, 0), max(cols[0] - 1, 0)], [min(rows[-1] + 1, last), min(cols[-1] + 1, last)]]
        )
        field_ = self.planner.distance_from_agent(sem_map.obstacle, sem_map.agent_cell, targets=corners).full()
        return extract_frontiers(
            sem_map.explored,
            obstacle,
            sem_map.agent_cell,
            field_,
            sem_map.categories,
            sem_map.category_names,
            self.config.frontiers,
            resolution_m=sem_map.resolution_m,
            blocked=np.array(self.blocked, dtype=np.int64).reshape(-1, 2),
            blocked_radius_cells=self.blocked_radii(sem_map.resolution_m),
            blocked_frontiers=[self.done_frontiers.get(cell) for cell in self.blocked],
            blocked_gap_cells=self.cfg.blocked_frontier_gap_m / sem_map.resolution_m,
            agent_heading=sem_map.agent_heading,
        )

    def blocked_radii(self, resolution_m: float) -> np.ndarray:
        """Cells around each done goal where frontiers are dropped: ``blocked_radius_m``, halved for a
        frontier the agent stood on and looked beyond (only that spot is done: the full radius
        would drop for good a door that lies just beside such a spot)."""
        full = self.blocked_radius_cells(resolution_m)
        return np.array([full / 2 if cell in self.stood else full for cell in self.blocked], dtype=np.float64)

    def _select(self, sem_map: SemanticMap, goal: str, rng: np.random.Generator) -> None:
        self.since_select = 0
        sel = self.global_policy.select(self.frontiers, sem_map, goal, rng)
        if sel is not None and sel.language:
            self.frontiers = _with_language(self.frontiers, sel)
        if sel is None:  # nothing left to explore: wander to a random free cell of the local map
            win = sem_map.local_window()
            free = np.argwhere(~win.obstacle & ~win.explored) if (~win.explored).any() else np.argwhere(~win.obstacle)
            r, c = free[rng.integers(len(free))]
            self.cell = (int(r) + win.bounds[0], int(c) + win.bounds[2])
            self.kind, self.frontier = GoalKind.EXPLORE, None
            self.reason = "no frontier: exploring a random free cell"
            return
        kept = self.commit(sel)
        if kept is sel:  # a new choice: what a later keep quotes
            self.chosen_reason = sel.reason
        self.cell, self.frontier = kept.cell, kept.frontier
        self.kind = GoalKind.FRONTIER if kept.frontier is not None else GoalKind.RANDOM
        self.reason = kept.reason

    def commit(self, sel: Selection) -> Selection:
        """Hysteresis: stay with the frontier pursued so far unless the new best is clearly better
        (re-selecting every 10 steps with position-dependent scores otherwise flips between targets)."""
        if self.cell is None or self.frontier is None or sel.frontier is None or not self.frontiers:
            return sel
        centres = np.array([f.center for f in self.frontiers])
        d = np.hypot(*(centres - np.array(self.cell)).T)
        j = int(np.argmin(d))
        if j == sel.frontier or d[j] > self.cfg.commitment_radius_m / self.config.map.resolution_m:  # or it is gone
            return sel
        if sel.scores[sel.frontier] - sel.scores[j] < self.cfg.commitment_margin:
            f = self.frontiers[j]
            return Selection(j, f.center, sel.scores, f"kept frontier {f.id} (commitment): {self.chosen_reason}")
        return sel


def _with_language(frontiers: list[Frontier], sel: Selection) -> list[Frontier]:
    """The frontiers as the decision shows them: each with its language scores, the chosen one with
    the policy's reason."""
    return [
        replace(
            f,
            queries=ls.queries,
            llm_scores=ls.llm_scores,
            s_llm=ls.s_llm,
            fused=ls.fused,
            expected_m=ls.expected_m,
            fusion=sel.fusion,
            reason=sel.reason if k == sel.frontier else f.reason,
        )
        for k, (f, ls) in enumerate(zip(frontiers, sel.language))
    ]

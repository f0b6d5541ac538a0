"""Global policies: which long-term goal to pursue, given the frontiers of the current map.

Each returns a ``Selection``: a frontier (or a free map cell for random sampling) and one score per
frontier in [0, 1] (higher is better) that the agent uses for commitment: it keeps its current
frontier unless another one scores clearly higher.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import cv2
import numpy as np
import numpy.typing as npt

from l3mvn.agent.frontiers import Frontier, Fusion
from l3mvn.agent.mapping import LocalWindow, SemanticMap
from l3mvn.agent.planning import distance_field
from l3mvn.core.grid import disk


@dataclass(frozen=True)
class LanguageScore:
    """What a language policy concluded about one frontier: the sentence asked per goal, the model's
    p(goal | frontier) for every goal, the target's S_LLM and the fused score the choice used; with a
    head that predicts distances, its metres from the frontier to every goal."""

    queries: dict[str, str]
    llm_scores: dict[str, float]
    s_llm: float
    fused: float
    expected_m: dict[str, float] = field(default_factory=dict)


@dataclass
class Selection:
    frontier: int | None  # index into the frontier list, or None for a free-standing cell
    cell: tuple[int, int]
    scores: np.ndarray  # one per frontier, in [0, 1]
    reason: str
    language: tuple[LanguageScore, ...] = ()  # one per frontier (language policies only)
    fusion: Fusion | None = None  # the language policy's rule and the numbers it compared


class GlobalPolicy(Protocol):
    name: str

    def select(
        self, frontiers: list[Frontier], sem_map: SemanticMap, goal: str, rng: np.random.Generator
    ) -> Selection | None:
        """None when there is nothing to choose (no frontier)."""


def unit_scores(scores: np.ndarray) -> np.ndarray:
    """Scores (higher is better) min-max scaled into [0, 1] over the list: the scale the agent's
    commitment margin reads, whatever a rule's own scale (a fixed margin on a narrow scale, such as
    the paper rule's bound, would keep the current frontier against nearly any other)."""
    span = float(scores.max() - scores.min())
    return np.ones_like(scores) if span <= 0 else 1.0 - (scores.max() - scores) / span


def least_total(total: np.ndarray) -> tuple[int, np.ndarray]:
    """The frontier with the least total metres, and the totals flipped into [0, 1] scores (1 = least,
    0 = most): the scale the agent's commitment margin reads."""
    return int(np.argmin(total)), unit_scores(-total)


def size_bonus_m(frontiers: list[Frontier], cu_lambda: float) -> np.ndarray:
    """Each frontier's size bonus in metres, cost-utility's utility over its lambda: what the policies
    that compare metres (the expected rule, PONI) credit a wide frontier with."""
    return np.array([f.utility / cu_lambda for f in frontiers], dtype=np.float64)


def _pick(frontiers: list[Frontier], scores: np.ndarray, reason: str) -> Selection:
    i = int(np.argmax(scores))
    return Selection(i, frontiers[i].center, scores, reason.format(f=frontiers[i]))


class NearestFrontier:
    """Yamauchi (1997): the nearest frontier, by travel cost (geodesic distance, plus turning when the
    agent charges for it: see FrontierConfig.turn_cost_m_per_rad)."""

    name = "frontier"

    def select(
        self, frontiers: list[Frontier], sem_map: SemanticMap, goal: str, rng: np.random.Generator
    ) -> Selection | None:
        if not frontiers:
            return None
        d = np.array([f.cost for f in frontiers], dtype=np.float64)
        scores = 1.0 - d / max(d.max(), 1e-9) if len(d) > 1 else np.ones(1)
        return _pick(frontiers, scores, "nearest frontier ({f.distance_m:.1f} m)")


class CostUtility:
    """The paper's "Exp": the frontier with the highest normalised S_CU = U - lambda C."""

    name = "cost-utility"

    def select(
        self, frontiers: list[Frontier], sem_map: SemanticMap, goal: str, rng: np.random.Generator
    ) -> Selection | None:
        if not frontiers:
            return None
        scores = np.array([f.s_cu for f in frontiers], dtype=np.float64)
        return _pick(
            frontiers, scores, "highest cost-utility (S_CU {f.s_cu:.2f}, {f.size} cells, {f.distance_m:.1f} m)"
        )


class RandomSample:
    """The paper's "random samples on map": a uniformly random cell of the local window that is
    neither an obstacle nor explored yet, so a sample is a place worth going to rather than one
    already seen; the map must not wall it off from the agent, and it must lie within ``band_m`` of
    explored floor, where the floor evidently goes on (any such cell once none is left).

    Walls close as the planner sees them: obstacles grow by its ``obstacle_dilation_cells``. At
    120x160 a mapped wall has gaps of a cell or two; measured through them, a large share of the
    band lies behind walls, reached only by a detour round the house (a sample a few metres away
    behind a wall can cost dozens of steps).
    """

    name = "random-sample"
    # A sampled goal stands until reached or found unreachable: re-sampled every 10 steps (the
    # frontier policies' period), the agent walks 10-step legs in random directions and runs out of
    # steps with much of the floor still unmapped.
    keeps_goal = True
    # Unknown cells deep beyond the explored floor are mostly outside the house (its outer wall not
    # yet mapped): a goal there costs a walk to the wall. 1.5 m keeps the next room's worth of floor.
    band_m = 1.5

    def __init__(self, obstacle_dilation_cells: int) -> None:
        self.dilation = obstacle_dilation_cells
        self._kernel = disk(obstacle_dilation_cells).astype(np.uint8)

    def select(
        self, frontiers: list[Frontier], sem_map: SemanticMap, goal: str, rng: np.random.Generator
    ) -> Selection | None:
        win = sem_map.local_window()
        r0, _, c0, _ = win.bounds
        walls = self._walls(win)
        # Only cells the map does not already wall off from the agent (the outside of a house whose
        # outer wall is mapped, a closed room): a goal there costs steps until found unreachable.
        _, labels = cv2.connectedComponents((~walls).view(np.uint8), connectivity=4)
        own = labels[win.agent_cell]
        reachable = labels == own if own else ~win.obstacle  # (0: the agent stands on a mapped obstacle)
        unknown = reachable & ~win.explored
        # Measured around mapped walls, not through them: the unknown just behind an outer wall is
        # near the floor in a straight line, yet reached only by walking around the house.
        near_floor = np.isfinite(
            distance_field(~walls, win.explored & ~walls, resolution_m=sem_map.resolution_m, limit_m=self.band_m)
        )
        for candidates in (unknown & near_floor, unknown, reachable):
            cells = np.argwhere(candidates)
            if len(cells):
                break
        r, c = cells[rng.integers(len(cells))]
        cell = (int(r) + r0, int(c) + c0)
        return Selection(None, cell, np.zeros(len(frontiers)), f"random map cell {cell}")

    def _walls(self, win: LocalWindow) -> np.ndarray:
        """Obstacles dilated as the planner dilates them, the agent's own surroundings left open (the
        planner's escape does the same: dilation never traps the agent where it stands)."""
        if not self.dilation:
            return win.obstacle
        walls: npt.NDArray[np.bool_] = cv2.dilate(win.obstacle.view(np.uint8), self._kernel).astype(bool)
        k, (r, c) = self.dilation, win.agent_cell
        near = (slice(max(r - k, 0), r + k + 1), slice(max(c - k, 0), c + k + 1))
        walls[near] = win.obstacle[near]
        return walls


GLOBAL_POLICIES = {p.name: p for p in (NearestFrontier, CostUtility, RandomSample)}

"""PONI as a global policy: the frontier with the least (travel + expected metres on to the goal, less
the bonuses of an exploring agent), read from the potentials the network predicts on the agent's map.

A frontier's potentials are the best over its cells (its label in training is the best over its
cells too: the cell nearest the goal, the cell that opens the most floor). The object potential p of
the goal becomes metres as the training defined it, ``range_m x (1 - p)``; the area potential earns a
bonus of ``area_bonus_m`` metres at 1, the part of PONI that prefers frontiers opening onto much
unexplored floor when no goal is expected near any of them; with ``size_bonus`` a frontier also earns
cost-utility's size bonus U / lambda, the preference for wide openings that cost-utility owes its
SPL to. This is the frontier oracle's criterion with the network in place of the ground truth, and the
"expected" rule of the language policies with the area potential beside the frontier's size.

With a map head (``words``, ``l3mvn.agent.potentials.language_map``) the expected metres on also
carry what the head reads in each frontier's window objects: that is l3mvn-ff's head on the map.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from l3mvn.agent.frontiers import Frontier, Fusion
from l3mvn.agent.frontiers.types import POTENTIALS_RULE
from l3mvn.agent.mapping import SemanticMap
from l3mvn.agent.policies.global_policies import LanguageScore, Selection, least_total, size_bonus_m
from l3mvn.agent.potentials.features import OUTPUTS, WindowGrid, objects_hot, window_features
from l3mvn.agent.potentials.language_map import LanguageMapHead, window_sentences
from l3mvn.agent.potentials.model import PotentialModel
from l3mvn.core.config import PotentialConfig
from l3mvn.core.errors import L3MVNError


def expected_totals(cost: Any, potentials: Any, cfg: PotentialConfig, size_m: Any) -> Any:
    """(F, goals) metres the policy minimises, per frontier and goal: travel ``cost`` (F,) less the
    area bonus and, where ``cfg.size_bonus``, the size bonus ``size_m`` (F,), plus the expected metres
    on, from ``potentials`` (F, len(OUTPUTS)). Plain arithmetic, so numpy arrays (the policy) and
    torch tensors (the training loss) give the same numbers."""
    if cfg.size_bonus:
        cost = cost - size_m
    return cost[:, None] - cfg.area_bonus_m * potentials[:, :1] + cfg.range_m * (1.0 - potentials[:, 1:])


class PotentialPolicy:
    def __init__(
        self,
        model: PotentialModel,
        cfg: PotentialConfig,
        cu_lambda: float,
        words: LanguageMapHead | None = None,
        name: str = "poni",
    ) -> None:
        if cfg.size_bonus and not (np.isfinite(cu_lambda) and cu_lambda > 0):
            raise L3MVNError(
                f"poni.size_bonus reads the size bonus as U / lambda: frontiers.cu_lambda must be positive, "
                f"got {cu_lambda} (or set poni.size_bonus=false with a checkpoint trained without it)"
            )
        self.model, self.cfg, self.cu_lambda, self.words, self.name = model, cfg, cu_lambda, words, name

    def frontier_potentials(self, frontiers: list[Frontier], sem_map: SemanticMap) -> np.ndarray:
        """(len(frontiers), len(OUTPUTS)): each frontier's best potential over its cells in the window
        (0 for a frontier wholly outside it)."""
        grid = WindowGrid.around(sem_map.agent_cell, sem_map.resolution_m, self.cfg)
        features = window_features(sem_map.explored, sem_map.obstacle, sem_map.categories, sem_map.category_names, grid)
        predicted = self.model.predict(features).reshape(len(OUTPUTS), -1)
        out = np.zeros((len(frontiers), len(OUTPUTS)), dtype=np.float64)
        for k, f in enumerate(frontiers):
            cells = grid.flat_cells(f.cells)
            if len(cells):
                out[k] = predicted[:, cells].max(axis=1)
        return out

    def select(
        self, frontiers: list[Frontier], sem_map: SemanticMap, goal: str, rng: np.random.Generator
    ) -> Selection | None:
        if not frontiers:
            return None
        if goal not in OUTPUTS[1:]:
            raise L3MVNError(f"PONI predicts potentials for {', '.join(OUTPUTS[1:])}, not {goal!r}")
        potentials = self.frontier_potentials(frontiers, sem_map)
        area, objects = potentials[:, 0], potentials[:, 1:]
        sentences = window_sentences(objects_hot([f.objects for f in frontiers])) if self.words else []
        words = self.words.metres(sentences) if self.words else np.zeros(objects.shape)
        metres = self.cfg.range_m * (1.0 - objects) + words
        on = metres[:, OUTPUTS.index(goal) - 1]
        cost = np.array([f.cost for f in frontiers], dtype=np.float64)
        size = size_bonus_m(frontiers, self.cu_lambda) if self.cfg.size_bonus else np.zeros(len(frontiers))
        bonus = self.cfg.area_bonus_m * area + size
        total = (expected_totals(cost, potentials, self.cfg, size) + words)[:, OUTPUTS.index(goal) - 1]
        i, fused = least_total(total)
        target = objects[:, OUTPUTS.index(goal) - 1]
        fusion = Fusion(
            rule=POTENTIALS_RULE,
            branch="least total",
            choice=i,
            ids=tuple(f.id for f in frontiers),
            s_llm=tuple(map(float, target)),
            explore=tuple(map(float, area)),
            compared=tuple(map(float, total)),
            exploration="area potential and frontier size" if self.cfg.size_bonus else "area potential",
            cost_m=tuple(map(float, cost)),
            bonus_m=tuple(map(float, bonus)),
            expected_m=tuple(map(float, on)),
            scorer=self.model.label + (f" + {self.words.label}" if self.words else ""),
            words=self.words.encoder if self.words else "",
        )
        goals = OUTPUTS[1:]
        scores = tuple(
            LanguageScore(
                queries={goal: sentence} if sentence else {},
                llm_scores={g: round(float(p), 4) for g, p in zip(goals, row)},
                s_llm=float(p_goal),
                fused=float(v),
                expected_m={g: round(float(m), 3) for g, m in zip(goals, far)},
            )
            for row, p_goal, v, far, sentence in zip(objects, target, fused, metres, sentences or [""] * len(frontiers))
        )
        reason = (
            f"{'PONI + words' if self.words else 'PONI'}: {cost[i]:.1f} m to frontier - {bonus[i]:.1f} m bonus "
            f"+ {on[i]:.1f} m expected on = {total[i]:.1f} m (least)"
        )
        return Selection(i, frontiers[i].center, fused, reason, scores, fusion)

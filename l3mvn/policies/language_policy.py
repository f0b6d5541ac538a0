"""L3MVN's global policy: fuse a language model's frontier score S_LLM with an exploration score.

Paper rule (bound B = [PolicyConfig.bound_low, bound_high], [0.15, 0.30] in the paper): if max S_LLM >
sup B take argmax S_LLM; if it is below inf B take argmax of the exploration score; in between, S_CU
is rescaled into B (inf B + S_CU * (sup B - inf B)) and each frontier's fused score is
max(S_LLM, rescaled S_CU): a frontier wins on language only where the model is more confident about
it than exploration is about the best alternative.

``selection="official_code"`` reproduces the authors' code instead: feed-forward takes argmax S_LLM if
its max > 0.2, else the best-utility frontier; zero-shot takes argmax if max > 0.3, else the first
frontier by utility whose score is > 0.1, else the best-utility one; a frontier with no objects scores
0.1 + 0.1 * U / max U.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from l3mvn.config import SELECTIONS, PolicyConfig
from l3mvn.errors import L3MVNError
from l3mvn.frontiers import Frontier
from l3mvn.policies.global_policies import LanguageScore, Selection



@lru_cache(maxsize=4)
def shared_scorer(name: str):
    """One scorer per process and name: models load once and the (object set, goal) cache is shared
    across episodes, where the same object sets keep recurring."""
    from l3mvn.language import make_scorer

    return make_scorer(name)


class LanguageFrontierPolicy:
    """Scores every frontier's objects with a language scorer and fuses with an exploration score."""

    def __init__(self, name: str, scorer: str, exploration: str = "cost-utility", selection: str = "paper",
                 paradigm: str = "feedforward",
                 bound: tuple[float, float] = (PolicyConfig.bound_low, PolicyConfig.bound_high)) -> None:
        if selection not in SELECTIONS:
            raise L3MVNError(f"unknown selection {selection!r}; valid: {', '.join(SELECTIONS)}")
        if exploration not in ("cost-utility", "nearest"):
            raise L3MVNError(f"unknown exploration score {exploration!r}; valid: cost-utility, nearest")
        self.name, self.scorer_name = name, scorer
        self.exploration, self.selection, self.paradigm = exploration, selection, paradigm
        self.bound = bound
        self.scorer = shared_scorer(scorer)

    def set_scorer(self, scorer: str) -> None:
        self.scorer_name, self.scorer = scorer, shared_scorer(scorer)

    def select(self, frontiers: list[Frontier], sem_map, goal: str, rng) -> Selection | None:
        if not frontiers:
            return None
        objects = [f.objects for f in frontiers]
        dists = self.scorer.score(objects)
        s_llm = np.array([d[goal] for d in dists])
        explore = self._exploration(frontiers)
        if self.selection == "official_code":
            i, reason = self._official(frontiers, s_llm, explore)
            fused = s_llm
        else:
            i, reason, fused = self._paper(s_llm, explore)
        language = tuple(
            LanguageScore(queries=self.scorer.queries(objs), llm_scores={g: round(p, 4) for g, p in d.items()},
                          s_llm=float(d[goal]), fused=float(v))
            for objs, d, v in zip(objects, dists, fused)
        )
        return Selection(i, frontiers[i].center, np.asarray(fused, dtype=np.float64), reason, language)

    def _exploration(self, frontiers: list[Frontier]) -> np.ndarray:
        if self.exploration == "cost-utility":
            return np.array([f.s_cu for f in frontiers], dtype=np.float64)
        d = np.array([f.distance_m for f in frontiers], dtype=np.float64)
        return 1.0 - d / max(d.max(), 1e-9) if len(d) > 1 else np.ones(1)

    def _paper(self, s_llm: np.ndarray, explore: np.ndarray) -> tuple[int, str, np.ndarray]:
        lo, hi = self.bound
        top = float(s_llm.max())
        if top > hi:
            i = int(np.argmax(s_llm))
            return i, f"language: S_LLM {top:.2f} > {hi} (bound)", s_llm
        if top < lo:
            i = int(np.argmax(explore))
            return i, f"exploration: S_LLM {top:.2f} < {lo} (bound), best {self.exploration}", lo + explore * (hi - lo)
        fused = np.maximum(s_llm, lo + explore * (hi - lo))
        i = int(np.argmax(fused))
        why = "language" if s_llm[i] >= lo + explore[i] * (hi - lo) else "exploration"
        return i, f"fused ({why} wins): S_LLM {s_llm[i]:.2f}, {self.exploration} {explore[i]:.2f}", fused

    def _official(self, frontiers: list[Frontier], s_llm: np.ndarray, explore: np.ndarray) -> tuple[int, str]:
        u = np.array([f.utility for f in frontiers], dtype=np.float64)
        no_objects = np.array([not self.scorer.query_objects(f.objects) for f in frontiers])
        s = np.where(no_objects, 0.1 + 0.1 * u / max(u.max(), 1e-9), s_llm)
        threshold = 0.2 if self.paradigm == "feedforward" else 0.3
        if s.max() > threshold:
            return int(np.argmax(s)), f"official code: S_LLM {s.max():.2f} > {threshold}"
        order = np.argsort(-explore, kind="stable")
        if self.paradigm != "feedforward":
            for i in order:
                if s[i] > 0.1:
                    return int(i), f"official code: first by utility with S_LLM {s[i]:.2f} > 0.1"
        return int(order[0]), "official code: best utility"

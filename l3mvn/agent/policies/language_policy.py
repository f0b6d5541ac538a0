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

With the feed-forward head trained on frontiers (``head="frontiers"``), which predicts the metres from
each frontier to each goal, S_LLM is that head's listwise reading: softmax over the frontiers of
-metres / 1 m, the probability that a frontier is the one nearest the goal (what its loss trained).
``selection="expected"`` uses the metres directly: the frontier with the least C - U / lambda + expected
metres on to the goal. C - U / lambda is cost-utility's own criterion in metres (argmax S_CU = argmin
of it, ``FrontierConfig.cu_lambda``), so a flat prior gives exactly cost-utility's choice and the head
only moves it by the metres it expects; it is the frontier oracle's criterion with the prior (plus
cost-utility's size bonus) in place of the ground truth. It needs no bound, so it suits a calibrated
prior; the bound rule suits a weak one, whose scores only matter above sup B (numbers: the regret
bench, bench/bench_frontier_regret.py).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from functools import lru_cache
from typing import TYPE_CHECKING, Any, Protocol, TypeGuard

import numpy as np

from l3mvn.agent.frontiers import Frontier, Fusion
from l3mvn.agent.mapping import SemanticMap
from l3mvn.agent.policies.global_policies import LanguageScore, Selection, least_total, size_bonus_m, unit_scores
from l3mvn.core.config import SELECTIONS, FrontierConfig, PolicyConfig
from l3mvn.core.config.policy import HEAD_SCORER, LLM_SCORER
from l3mvn.core.errors import L3MVNError

if TYPE_CHECKING:  # the language package loads its models' libraries: only on first use
    from l3mvn.agent.language import Scorer


LISTWISE_TEMPERATURE_M = 1.0  # the frontier head's training tau (frontier_head.train_frontier_head)


class _DistanceScorer(Protocol):
    """A scorer whose head predicts the metres from each frontier to each goal (``predicts_distance``)."""

    goals: tuple[str, ...]

    def expected_distance(self, object_sets: Sequence[Iterable[str]]) -> np.ndarray: ...


def _predicts_distance(scorer: Scorer) -> TypeGuard[_DistanceScorer]:
    return bool(getattr(scorer, "predicts_distance", False))


def shared_scorer(
    name: str, head: str | None = None, llm: tuple[str, str] | None = None, embedder: str | None = None
) -> Scorer:
    """One scorer per process, name and options: models load once and the (object set, goal) cache is
    shared across episodes, where the same object sets keep recurring. ``head`` and ``embedder`` apply
    to the feed-forward scorer only, ``llm`` (model, prompt) to the llm scorer only."""
    _refuse_head_options(name, head, embedder)
    options: tuple[tuple[str, str], ...] = ()
    if name == HEAD_SCORER:
        options = tuple((k, v) for k, v in (("head", head), ("model", embedder)) if v is not None)
    elif name == LLM_SCORER and llm is not None:
        options = (("model", llm[0]), ("prompt", llm[1]))
    return _shared_scorer(name, options)


def _refuse_head_options(scorer: str, head: str | None, embedder: str | None) -> None:
    for option, value in (("head", head), ("embedder", embedder)):
        if value is not None and scorer != HEAD_SCORER:
            raise L3MVNError(f"the {option} {value!r} applies to the {HEAD_SCORER} scorer only, not {scorer!r}")


@lru_cache(maxsize=4)
def _shared_scorer(name: str, options: tuple[tuple[str, str], ...]) -> Scorer:
    from l3mvn.agent.language import make_scorer

    return make_scorer(name, **dict(options))


class LanguageFrontierPolicy:
    """Scores every frontier's objects with a language scorer and fuses with an exploration score."""

    def __init__(
        self,
        name: str,
        scorer: str,
        exploration: str = "cost-utility",
        selection: str = "paper",
        paradigm: str = "feedforward",
        bound: tuple[float, float] = (PolicyConfig.bound_low, PolicyConfig.bound_high),
        head: str | None = None,
        cu_lambda: float = FrontierConfig.cu_lambda,
        llm: tuple[str, str] = (PolicyConfig.llm, PolicyConfig.llm_prompt),
        embedder: str | None = None,
    ) -> None:
        if selection not in SELECTIONS:
            raise L3MVNError(f"unknown selection {selection!r}; valid: {', '.join(SELECTIONS)}")
        if exploration not in ("cost-utility", "nearest"):
            raise L3MVNError(f"unknown exploration score {exploration!r}; valid: cost-utility, nearest")
        self.name, self.scorer_name = name, scorer
        self.exploration, self.selection, self.paradigm = exploration, selection, paradigm
        _refuse_head_options(scorer, head, embedder)
        if selection == "expected" and not cu_lambda > 0:
            raise L3MVNError(
                f"selection 'expected' needs frontiers.cu_lambda > 0 (cost-utility in metres), got {cu_lambda}"
            )
        self.bound, self.head, self.cu_lambda, self.llm, self.embedder = bound, head, cu_lambda, llm, embedder
        self.scorer = self._make(scorer)

    def _make(self, scorer: str) -> Scorer:
        reads_head = scorer == HEAD_SCORER
        made = shared_scorer(scorer, self.head if reads_head else None, self.llm, self.embedder if reads_head else None)
        if self.selection == "expected" and not getattr(made, "predicts_distance", False):
            raise L3MVNError(
                f"selection 'expected' needs a scorer that predicts distances (feedforward with "
                f"head 'frontiers' or 'frontiers-bag'), not {scorer!r}; valid selections for it: paper, official_code"
            )
        return made

    def set_scorer(self, scorer: str) -> None:
        self.scorer_name, self.scorer = scorer, self._make(scorer)

    def select(
        self, frontiers: list[Frontier], sem_map: SemanticMap, goal: str, rng: np.random.Generator
    ) -> Selection | None:
        if not frontiers:
            return None
        objects = [f.objects for f in frontiers]
        dists = self.scorer.score(objects)
        s_llm = np.array([d[goal] for d in dists])
        explore = self._exploration(frontiers)
        metres: np.ndarray | None = None
        all_metres: np.ndarray | None = None
        if _predicts_distance(self.scorer):
            all_metres = self.scorer.expected_distance(objects)
            metres = all_metres[:, self.scorer.goals.index(goal)]
            z = -metres / LISTWISE_TEMPERATURE_M
            s_llm = np.exp(z - z.max()) / np.exp(z - z.max()).sum()
        if self.selection == "expected":
            assert metres is not None  # ``_make`` gives selection "expected" a scorer that predicts distances
            i, reason, fused, fusion = self._expected(frontiers, metres, s_llm, explore)
        elif self.selection == "official_code":
            i, reason, fusion = self._official(frontiers, s_llm, explore)
            fused = s_llm
        else:
            i, reason, fused, fusion = self._paper(frontiers, s_llm, explore)
        # The paper rule's fused scores live on the bound's narrow scale: commitment reads them in [0, 1].
        keep = unit_scores(np.asarray(fused, dtype=np.float64)) if self.selection == "paper" else fused
        expected = (
            [{} for _ in frontiers]
            if all_metres is None
            else [{g: round(float(m), 3) for g, m in zip(self.scorer.goals, row)} for row in all_metres]
        )
        language = tuple(
            LanguageScore(
                queries=self.scorer.queries(objs),
                llm_scores={g: round(p, 4) for g, p in d.items()},
                s_llm=float(p),
                fused=float(v),
                expected_m=e,
            )
            for objs, d, p, v, e in zip(objects, dists, s_llm, fused, expected)
        )
        return Selection(i, frontiers[i].center, np.asarray(keep, dtype=np.float64), reason, language, fusion)

    def _fusion(
        self,
        frontiers: list[Frontier],
        branch: str,
        choice: int,
        s_llm: np.ndarray,
        explore: np.ndarray,
        compared: np.ndarray,
        **numbers: Any,
    ) -> Fusion:
        """The record of what the rule compared (the same arrays it ranked, as plain floats)."""
        return Fusion(
            rule=self.selection,
            branch=branch,
            choice=choice,
            ids=tuple(f.id for f in frontiers),
            s_llm=tuple(map(float, s_llm)),
            explore=tuple(map(float, explore)),
            compared=tuple(map(float, compared)),
            exploration=self.exploration,
            scorer=self.scorer.label,
            **numbers,
        )

    def _expected(
        self, frontiers: list[Frontier], metres: np.ndarray, s_llm: np.ndarray, explore: np.ndarray
    ) -> tuple[int, str, np.ndarray, Fusion]:
        """argmin of C - U / lambda + expected metres on; fused = that total min-max flipped into [0, 1]
        (1 = best), the scale the agent's commitment margin reads."""
        cost = np.array([f.cost for f in frontiers], dtype=np.float64)
        bonus = size_bonus_m(frontiers, self.cu_lambda)
        total = (cost - bonus) + metres
        i, fused = least_total(total)
        fusion = self._fusion(
            frontiers,
            "least total",
            i,
            s_llm,
            explore,
            total,
            cost_m=tuple(map(float, cost)),
            bonus_m=tuple(map(float, bonus)),
            expected_m=tuple(map(float, metres)),
        )
        return (
            i,
            (
                f"expected: {frontiers[i].cost:.1f} m to frontier - {bonus[i]:.1f} m "
                f"size bonus + {metres[i]:.1f} m expected on = {total[i]:.1f} m (least)"
            ),
            fused,
            fusion,
        )

    def _exploration(self, frontiers: list[Frontier]) -> np.ndarray:
        if self.exploration == "cost-utility":
            return np.array([f.s_cu for f in frontiers], dtype=np.float64)
        d = np.array([f.distance_m for f in frontiers], dtype=np.float64)
        return 1.0 - d / max(d.max(), 1e-9) if len(d) > 1 else np.ones(1)

    def _paper(
        self, frontiers: list[Frontier], s_llm: np.ndarray, explore: np.ndarray
    ) -> tuple[int, str, np.ndarray, Fusion]:
        lo, hi = self.bound
        top = float(s_llm.max())
        if top > hi:
            i = int(np.argmax(s_llm))
            return (
                i,
                f"language: S_LLM {top:.2f} > {hi} (bound)",
                s_llm,
                self._fusion(frontiers, "language", i, s_llm, explore, s_llm, bound=(lo, hi)),
            )
        if top < lo:
            i = int(np.argmax(explore))
            fused = lo + explore * (hi - lo)
            return (
                i,
                f"exploration: S_LLM {top:.2f} < {lo} (bound), best {self.exploration}",
                fused,
                self._fusion(frontiers, "exploration", i, s_llm, explore, fused, bound=(lo, hi)),
            )
        fused = np.maximum(s_llm, lo + explore * (hi - lo))
        i = int(np.argmax(fused))
        why = "language" if s_llm[i] >= lo + explore[i] * (hi - lo) else "exploration"
        return (
            i,
            f"fused ({why} wins): S_LLM {s_llm[i]:.2f}, {self.exploration} {explore[i]:.2f}",
            fused,
            self._fusion(frontiers, "fused", i, s_llm, explore, fused, bound=(lo, hi)),
        )

    def _official(self, frontiers: list[Frontier], s_llm: np.ndarray, explore: np.ndarray) -> tuple[int, str, Fusion]:
        u = np.array([f.utility for f in frontiers], dtype=np.float64)
        no_objects = np.array([not self.scorer.query_objects(f.objects) for f in frontiers])
        s = np.where(no_objects, 0.1 + 0.1 * u / max(u.max(), 1e-9), s_llm)
        threshold = 0.2 if self.paradigm == "feedforward" else 0.3

        def chose(branch: str, i: int, reason: str) -> tuple[int, str, Fusion]:
            return i, reason, self._fusion(frontiers, branch, i, s_llm, explore, s, threshold=threshold)

        if s.max() > threshold:
            return chose("language", int(np.argmax(s)), f"official code: S_LLM {s.max():.2f} > {threshold}")
        order = np.argsort(-explore, kind="stable")
        if self.paradigm != "feedforward":
            for i in order:
                if s[i] > 0.1:
                    return chose(
                        "first above 0.1", int(i), f"official code: first by utility with S_LLM {s[i]:.2f} > 0.1"
                    )
        return chose("utility", int(order[0]), "official code: best utility")

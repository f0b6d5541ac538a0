"""The one interface every language scorer satisfies, its cache, and the registry.

``Scorer.score(object_sets)`` takes the objects mapped around each frontier (any spelling) and
returns, per frontier, a distribution over the six goals. Subclasses only turn (object tuple, goal)
pairs into raw scores (``_raw_scores``); this class keeps the informative objects, caches raw scores
by (sorted object tuple, goal), and normalises with ``softmax(raw / temperature)`` over the goals.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from functools import cache
from typing import Any, TypeVar

import numpy as np

from l3mvn.agent.language.cooccurrence import CooccurrenceStats, load_stats
from l3mvn.agent.language.queries import zero_shot_query
from l3mvn.agent.language.vocabulary import GOALS, canonical, check_goal
from l3mvn.core.errors import L3MVNError
from l3mvn.core.plugins import discover

ObjectKey = tuple[str, ...]
OBJECT_FILTERS = ("entropy", "all")


@dataclass(frozen=True)
class CacheInfo:
    """Counts of (object set, goal) raw scores served from the cache vs computed."""

    hits: int
    misses: int
    size: int


class Scorer(ABC):
    """Base of all scorers. ``object_filter="entropy"`` keeps only the informative list's objects (the
    paper); ``"all"`` passes every object (used by the benchmark to show what the list costs)."""

    name: str = ""
    temperature: float = 1.0

    def __init__(
        self, stats: CooccurrenceStats | None = None, object_filter: str = "entropy", temperature: float | None = None
    ):
        if object_filter not in OBJECT_FILTERS:
            raise L3MVNError(f"unknown object filter {object_filter!r}; valid: {', '.join(OBJECT_FILTERS)}")
        if temperature is not None:
            if not temperature > 0:
                raise L3MVNError(f"temperature must be positive, got {temperature}")
            self.temperature = float(temperature)
        self.stats = stats or load_stats()
        self.object_filter = object_filter
        self.goals: tuple[str, ...] = GOALS
        self._cache: dict[tuple[ObjectKey, str], float] = {}
        self._hits = 0
        self._misses = 0

    # --- public ---------------------------------------------------------------------------------
    @property
    def label(self) -> str:
        """What scores, for people: the scorer's name, and its model where it has one."""
        return self.name

    def query_objects(self, objects: Iterable[str]) -> ObjectKey:
        """The objects a query about this frontier names, in query order."""
        if self.object_filter == "entropy":
            return self.stats.informative_in(objects)
        return tuple(sorted({canonical(o) for o in objects}))

    def queries(self, objects: Iterable[str]) -> dict[str, str]:
        """The sentences scored for a frontier, by goal (empty when it names no informative object)."""
        key = self.query_objects(objects)
        return {g: zero_shot_query(key, g) for g in self.goals} if key else {}

    def score(self, object_sets: Sequence[Iterable[str]]) -> list[dict[str, float]]:
        """Per frontier, ``{goal: p}`` over the six goals (non-negative, sums to 1). A frontier with
        no object to talk about gets the uniform distribution without a model call."""
        return [dict(zip(self.goals, map(float, row))) for row in self.score_matrix(object_sets)]

    def score_goal(self, object_sets: Sequence[Iterable[str]], goal: str) -> np.ndarray:
        """p(goal) per frontier: the number the frontier policy ranks by."""
        return self.score_matrix(object_sets)[:, self.goals.index(check_goal(goal))]

    def score_matrix(self, object_sets: Sequence[Iterable[str]]) -> np.ndarray:
        keys = [self.query_objects(s) for s in object_sets]
        missing = list(
            dict.fromkeys((k, g) for k in keys if k for g in self.goals if (tuple(sorted(k)), g) not in self._cache)
        )
        n_pairs = sum(len(self.goals) for k in keys if k)
        self._misses += len(missing)
        self._hits += n_pairs - len(missing)
        if missing:
            raw = self._raw_scores(missing)
            for (k, g), value in zip(missing, raw):
                self._cache[(tuple(sorted(k)), g)] = float(value)
        out = np.full((len(keys), len(self.goals)), 1.0 / len(self.goals))
        for i, k in enumerate(keys):
            if k:
                out[i] = self._normalise(np.array([self._cache[(tuple(sorted(k)), g)] for g in self.goals]))
        return out

    def cache_info(self) -> CacheInfo:
        return CacheInfo(self._hits, self._misses, len(self._cache))

    def clear_cache(self) -> None:
        self._cache.clear()
        self._hits = self._misses = 0

    # --- for subclasses ------------------------------------------------------------------------
    @abstractmethod
    def _raw_scores(self, pairs: list[tuple[ObjectKey, str]]) -> Sequence[float]:
        """One raw score per (objects in query order, goal); higher means the goal fits better."""

    def _normalise(self, raw: np.ndarray) -> np.ndarray:
        z = raw / self.temperature
        e = np.exp(z - z.max())
        p: np.ndarray = e / e.sum()  # numpy types the division as Any
        return p


_REGISTRY: dict[str, Callable[..., Scorer]] = {}
PLUGIN_GROUP = "l3mvn.scorers"  # a researcher's own scorers: entry points naming a Scorer subclass
_ScorerClass = TypeVar("_ScorerClass", bound=type[Scorer])


def register(name: str) -> Callable[[_ScorerClass], _ScorerClass]:
    def wrap(cls: _ScorerClass) -> _ScorerClass:
        cls.name = name
        _REGISTRY[name] = cls
        return cls

    return wrap


def scorer_names() -> tuple[str, ...]:
    """The built-in scorers, then the installed plugins' (``l3mvn.core.plugins``)."""
    return tuple(sorted(_built_in())) + tuple(_plugins()[0])


def make_scorer(name: str, **options: Any) -> Scorer:
    """A scorer by registry name (``mlm``, ``causal``, ``embedding``, ``roomtype``, ``feedforward``, or a
    plugin's) with its options (``model=...``, ``temperature=...``, ``object_filter=...``, ...)."""
    plugins, problems = _plugins()
    known = {**_built_in(), **plugins}
    if name not in known:
        why = f" ({problems[name]})" if name in problems else ""
        raise L3MVNError(f"unknown language scorer {name!r}{why}; valid: {', '.join(scorer_names())}")
    try:
        return known[name](**options)
    except TypeError as exc:
        raise L3MVNError(f"bad options for scorer {name!r}: {exc}") from None


def _built_in() -> dict[str, Callable[..., Scorer]]:
    from l3mvn.agent.language.scorers import causal, embedding, feedforward, llm, mlm  # noqa: F401  (registers)

    return _REGISTRY


@cache
def _plugins() -> tuple[dict[str, Callable[..., Scorer]], dict[str, str]]:
    def accept(name: str, obj: object) -> str | None:
        if not (isinstance(obj, type) and issubclass(obj, Scorer)):
            return "is not a subclass of l3mvn.agent.language.scorers.Scorer"
        obj.name = name
        return None

    found = discover(PLUGIN_GROUP, accept, frozenset(_built_in()))
    return found.objects, found.problems


__all__ = ["Scorer", "CacheInfo", "OBJECT_FILTERS", "register", "make_scorer", "scorer_names"]

"""Language scorers behind one interface; pick one by name with ``make_scorer``."""

from l3mvn.agent.language.scorers.base import CacheInfo, Scorer, make_scorer, scorer_names

__all__ = ["Scorer", "CacheInfo", "make_scorer", "scorer_names"]

"""The sentences a language model reads about a frontier.

Only informative objects enter (``CooccurrenceStats.informative_in``), in the list's order (most
informative first), so a set of objects always gives the same sentence. Phrases come from
``vocabulary.query_phrase``.

Empty case: a frontier with no informative object gives ``"A frontier area containing <goal>."``
and ``"This frontier contains nothing."``; the scorers never send these to a model and return the
uniform distribution instead (no evidence), leaving the fallback to the frontier policy.
"""

from __future__ import annotations

from collections.abc import Sequence

from l3mvn.agent.language.vocabulary import check_goal, query_phrase


def object_list(objects: Sequence[str], conjunction: str = "") -> str:
    """``"a, b, c"``; with ``conjunction="and"``: ``"a"``, ``"a and b"``, ``"a, b, and c"``."""
    words = [query_phrase(o) for o in objects]
    if not conjunction or len(words) < 2:
        return ", ".join(words)
    if len(words) == 2:
        return f"{words[0]} {conjunction} {words[1]}"
    return f"{', '.join(words[:-1])}, {conjunction} {words[-1]}"


def zero_shot_query(objects: Sequence[str], goal: str) -> str:
    """The paper's zero-shot string: ``"A frontier area containing o1, o2, ..., t."``."""
    return f"A frontier area containing {object_list([*objects, check_goal(goal)])}."


def feedforward_query(objects: Sequence[str]) -> str:
    """The paper's feed-forward string: ``"This frontier contains o1, ..., and ok."``."""
    if not objects:
        return "This frontier contains nothing."
    return f"This frontier contains {object_list(objects, 'and')}."


__all__ = ["object_list", "zero_shot_query", "feedforward_query"]

"""p(goal | object) from real rooms, its entropy, and the list of informative objects.

How the numbers are made (``build_stats``):

- For each goal ``t`` only rooms whose source labels ``t`` count (Gibson has no tv, so tv rates come
  from the AI2-THOR rooms alone). Among those rooms, ``n_t(o)`` contain object ``o`` and ``c_t(o)``
  contain both ``o`` and ``t``. A goal co-occurs with itself: ``c_t(t) = n_t(t)``, which is why
  "toilet" and "bed" are themselves informative.
- The rate ``r_t(o) = (c_t(o) + alpha * b_t) / (n_t(o) + alpha)`` shrinks towards the goal's base
  rate ``b_t`` (share of non-empty rooms holding ``t``) by ``alpha`` pseudo-rooms, so an object seen
  in two rooms cannot claim certainty; an object no room of that source holds gets ``b_t``.
- ``p(t | o) = r_t(o) / sum_t' r_t'(o)`` (the paper's "normalise the counts over targets", done on
  rates so sources of different sizes and label sets mix), ``H(o) = -sum_t p log p`` in nats.
- The informative list is the ``list_size`` lowest-entropy objects among ``candidates`` (objects a
  semantic map can hold) seen in at least ``min_rooms`` rooms; ties break by name.

The shipped ``l3mvn/data/language/cooccurrence.json`` is the output of ``build_stats`` over both
sources with the defaults below; it records the command and sources that made it.
"""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from l3mvn.agent.language.rooms import Room
from l3mvn.agent.language.vocabulary import GOALS, canonical
from l3mvn.core.categories import GIBSON_CATEGORIES
from l3mvn.core.errors import L3MVNError
from l3mvn.core.paths import PACKAGE_DATA
from l3mvn.core.writing import write_file

DATA_DIR = PACKAGE_DATA / "language"
STATS_PATH = DATA_DIR / "cooccurrence.json"
BUILD_COMMAND = "l3mvn language build-stats"

# Categories a semantic map can hold: the SemExp/Gibson channels plus the household objects of the
# procedural scenes (the categories of ``l3mvn.world.scenes.room_contents``). Only these may enter the
# informative list: a potato or a plunger is very informative but no map of ours ever shows one.
MAPPABLE_OBJECTS: tuple[str, ...] = tuple(
    dict.fromkeys(
        [canonical(c) for c in GIBSON_CATEGORIES]
        + [
            "bathtub",
            "shower",
            "towel",
            "dresser",
            "side table",
            "desk",
            "coffee table",
            "tv stand",
            "shelving unit",
            "counter",
            "lamp",
            "microwave",
            "toaster",
            "coffee machine",
            "garbage can",
            "laptop",
            "laundry hamper",
        ]
    )
)
DEFAULT_ALPHA = 2.0
DEFAULT_MIN_ROOMS = 10
DEFAULT_LIST_SIZE = 15


@dataclass(frozen=True)
class ObjectStats:
    name: str
    rooms: int
    p_goal: dict[str, float]
    entropy: float


@dataclass(frozen=True)
class CooccurrenceStats:
    """Per-object goal distributions plus the ordered informative list (lowest entropy first)."""

    objects: dict[str, ObjectStats]
    informative: tuple[str, ...]
    goals: tuple[str, ...] = GOALS
    provenance: dict[str, Any] = field(default_factory=dict)

    def p_goal(self, name: str) -> dict[str, float]:
        key = canonical(name)
        if key not in self.objects:
            raise L3MVNError(f"no co-occurrence statistics for {name!r}; known: {', '.join(sorted(self.objects))}")
        return self.objects[key].p_goal

    def informative_in(self, names: Iterable[str]) -> tuple[str, ...]:
        """The informative objects among ``names``, in the list's order (most informative first)."""
        present = {canonical(n) for n in names}
        return tuple(o for o in self.informative if o in present)

    def to_json(self) -> dict[str, Any]:
        return {
            "provenance": self.provenance,
            "goals": list(self.goals),
            "informative": list(self.informative),
            "objects": {
                o.name: {
                    "rooms": o.rooms,
                    "entropy": round(o.entropy, 6),
                    "p_goal": {g: round(p, 6) for g, p in o.p_goal.items()},
                }
                for o in sorted(self.objects.values(), key=lambda s: (s.entropy, s.name))
            },
        }

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> CooccurrenceStats:
        try:
            objects = {
                name: ObjectStats(
                    name, int(v["rooms"]), {g: float(p) for g, p in v["p_goal"].items()}, float(v["entropy"])
                )
                for name, v in data["objects"].items()
            }
            return cls(objects, tuple(data["informative"]), tuple(data["goals"]), dict(data.get("provenance", {})))
        except (KeyError, TypeError, ValueError) as exc:
            raise L3MVNError(f"malformed co-occurrence statistics ({exc})") from None


def build_stats(
    rooms: list[Room],
    candidates: tuple[str, ...] = MAPPABLE_OBJECTS,
    alpha: float = DEFAULT_ALPHA,
    min_rooms: int = DEFAULT_MIN_ROOMS,
    list_size: int = DEFAULT_LIST_SIZE,
    provenance: dict[str, Any] | None = None,
) -> CooccurrenceStats:
    """Co-occurrence statistics of every object in ``rooms`` (see the module docstring)."""
    if alpha <= 0 or min_rooms < 1 or list_size < 1:
        raise L3MVNError(f"need alpha > 0, min_rooms >= 1, list_size >= 1; got {alpha}, {min_rooms}, {list_size}")
    rooms = [r for r in rooms if r.objects]
    if not rooms:
        raise L3MVNError("no non-empty room to count co-occurrences in")
    rooms_with = Counter(o for r in rooms for o in r.objects)
    names = sorted(rooms_with)
    index = {o: i for i, o in enumerate(names)}
    rates = np.zeros((len(names), len(GOALS)))
    for j, goal in enumerate(GOALS):
        labelled = [r for r in rooms if goal in r.labelled_goals]
        if not labelled:
            raise L3MVNError(f"no room source labels the goal {goal!r}")
        n = np.zeros(len(names))
        c = np.zeros(len(names))
        for r in labelled:
            idx = [index[o] for o in r.objects]
            n[idx] += 1
            if goal in r.objects:
                c[idx] += 1
        base = sum(goal in r.objects for r in labelled) / len(labelled)
        rates[:, j] = (c + alpha * base) / (n + alpha)
    p = rates / rates.sum(axis=1, keepdims=True)
    entropy = -(p * np.log(np.clip(p, 1e-12, None))).sum(axis=1)
    objects = {
        o: ObjectStats(o, rooms_with[o], dict(zip(GOALS, map(float, p[index[o]]))), float(entropy[index[o]]))
        for o in names
    }
    wanted = {canonical(c) for c in candidates}
    eligible = [o for o in names if o in wanted and rooms_with[o] >= min_rooms]
    informative = tuple(sorted(eligible, key=lambda o: (objects[o].entropy, o))[:list_size])
    prov = {
        "alpha": alpha,
        "min_rooms": min_rooms,
        "list_size": list_size,
        "candidates": sorted(wanted),
        "rooms": len(rooms),
        "rooms_by_source": dict(Counter(r.source for r in rooms)),
    }
    prov.update(provenance or {})
    return CooccurrenceStats(objects, informative, GOALS, prov)


def save_stats(stats: CooccurrenceStats, path: str | Path = STATS_PATH) -> Path:
    return write_file(path, json.dumps(stats.to_json(), indent=1) + "\n", "co-occurrence statistics")


def load_stats(path: str | Path | None = None) -> CooccurrenceStats:
    """The shipped statistics (cached), or those in ``path``."""
    return _load_stats(str(Path(path).resolve()) if path else str(STATS_PATH))


@lru_cache(maxsize=4)
def _load_stats(path: str) -> CooccurrenceStats:
    p = Path(path)
    if not p.exists():
        raise L3MVNError(f"co-occurrence statistics {p} not found; run `{BUILD_COMMAND}` to create them")
    try:
        data = json.loads(p.read_text())
    except json.JSONDecodeError as exc:
        raise L3MVNError(f"{p}: not JSON ({exc})") from None
    return CooccurrenceStats.from_json(data)


def stats_table(stats: CooccurrenceStats | None = None, min_rooms: int = 1) -> str:
    """Markdown table for ``l3mvn language stats``: every object seen in ``min_rooms`` rooms or more,
    lowest entropy first, with its rank in the informative list (blank when it is not in it)."""
    stats = stats or load_stats()
    rank = {o: i + 1 for i, o in enumerate(stats.informative)}
    head = ["object", "rooms", *[f"p({g})" for g in stats.goals], "H (nats)", "list"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    rows = sorted((o for o in stats.objects.values() if o.rooms >= min_rooms), key=lambda o: (o.entropy, o.name))
    for o in rows:
        cells = [
            o.name,
            str(o.rooms),
            *[f"{o.p_goal[g]:.2f}" for g in stats.goals],
            f"{o.entropy:.3f}",
            str(rank.get(o.name, "")),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    lines.append(f"\ninformative list ({len(stats.informative)}): {', '.join(stats.informative)}")
    return "\n".join(lines)


__all__ = [
    "ObjectStats",
    "CooccurrenceStats",
    "MAPPABLE_OBJECTS",
    "STATS_PATH",
    "build_stats",
    "save_stats",
    "load_stats",
    "stats_table",
]

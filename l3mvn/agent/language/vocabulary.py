"""One spelling per object category, and the explicit maps between the vocabularies we meet.

Four vocabularies name the same things differently:

- SemExp/Gibson map channels (``GIBSON_CATEGORIES``): ``"dining-table"``, ``"potted plant"``, ``"tv"``;
- the Gibson room data (COCO style): ``"potted_plant"``, ``"dining_table"``;
- AI2-THOR object types (CamelCase): ``"HousePlant"``, ``"Sofa"``, ``"Television"``, ``"SinkBasin"``;
- the richer procedural scenes: ``"bathtub"``, ``"shower"``, ``"towel"``, ``"dresser"``, ...

``canonical()`` folds all of them into one *canonical* name: lower case, words separated by single
spaces, synonyms resolved by ``ALIASES`` (so ``"Sofa"``, ``"sofa"`` and ``"couch"`` are all ``"couch"``).
The goals keep their ``GOAL_CATEGORIES`` spelling. Unknown names are accepted as they are (after
folding) so a new scene source needs no code change, only an alias when it spells a known thing
differently. The aliases follow the procedural scenes' object names (``l3mvn.world.scenes.room_contents``
maps AI2-THOR the same way: an armchair is a chair, a countertop a counter, any lamp a lamp).

Queries use the canonical name, except where ``QUERY_PHRASES`` gives a more natural phrase. We keep
``"couch"`` (the goal's own word; MiniLM puts "couch" and "sofa" at cosine 0.86) and spell ``"tv"`` as
``"television"`` because a sentence encoder tokenises "tv" as a rare word piece.
"""

from __future__ import annotations

import re
from collections.abc import Iterable

from l3mvn.core.categories import GIBSON_CATEGORIES, GOAL_CATEGORIES
from l3mvn.core.errors import L3MVNError

GOALS: tuple[str, ...] = GOAL_CATEGORIES

# Folded spelling (left) -> canonical name (right). Only entries whose meaning is the same object
# for our purpose: a shower head, door, curtain or glass all say "there is a shower here".
ALIASES: dict[str, str] = {
    "sofa": "couch",
    "plant": "potted plant",
    "house plant": "potted plant",
    "houseplant": "potted plant",
    "television": "tv",
    "tv monitor": "tv",
    "tvmonitor": "tv",
    "fridge": "refrigerator",
    "chest of drawers": "dresser",
    "sink basin": "sink",
    "bathtub basin": "bathtub",
    "bath tub": "bathtub",
    "bath": "bathtub",
    "shower head": "shower",
    "shower door": "shower",
    "shower curtain": "shower",
    "shower glass": "shower",
    "hand towel": "towel",
    "mug": "cup",
    "wine bottle": "bottle",
    "alarm clock": "clock",
    "stove": "oven",
    "stove burner": "oven",
    "remote control": "remote",
    "arm chair": "chair",
    "armchair": "chair",
    "soap bottle": "bottle",
    "counter top": "counter",
    "countertop": "counter",
    "floor lamp": "lamp",
    "desk lamp": "lamp",
    "shelf": "shelving unit",
    "night stand": "nightstand",
    "diningtable": "dining table",
    "pottedplant": "potted plant",
    "cellphone": "cell phone",
}

QUERY_PHRASES: dict[str, str] = {"tv": "television"}

_CAMEL = re.compile(r"(?<=[a-z0-9])(?=[A-Z])|(?<=[A-Z])(?=[A-Z][a-z])")
_SEPARATORS = re.compile(r"[\s_\-]+")


def canonical(name: str) -> str:
    """Fold any spelling (``"potted_plant"``, ``"dining-table"``, ``"HousePlant"``) to its canonical name."""
    if not isinstance(name, str) or not name.strip():
        raise L3MVNError(f"an object category must be a non-empty string, got {name!r}")
    folded = _SEPARATORS.sub(" ", _CAMEL.sub(" ", name.strip())).strip().lower()
    return ALIASES.get(folded, folded)


def canonical_set(names: Iterable[str]) -> frozenset[str]:
    return frozenset(canonical(n) for n in names)


def check_goal(goal: str) -> str:
    """The canonical goal name, or an L3MVNError listing the six goals."""
    name = canonical(goal)
    if name not in GOALS:
        raise L3MVNError(f"unknown goal {goal!r}; valid goals: {', '.join(GOALS)}")
    return name


def query_phrase(name: str) -> str:
    """The words a query uses for a category."""
    key = canonical(name)
    return QUERY_PHRASES.get(key, key)


_GIBSON_BY_CANONICAL = {canonical(c): c for c in GIBSON_CATEGORIES}


def to_gibson(name: str) -> str:
    """The SemExp map-channel spelling of a category (``"dining table"`` -> ``"dining-table"``)."""
    key = canonical(name)
    if key not in _GIBSON_BY_CANONICAL:
        raise L3MVNError(f"{name!r} is not a SemExp/Gibson map category; valid: {', '.join(GIBSON_CATEGORIES)}")
    return _GIBSON_BY_CANONICAL[key]


def to_coco(name: str) -> str:
    """The room-data (COCO) spelling: canonical words joined by underscores."""
    return canonical(name).replace(" ", "_")


__all__ = [
    "GOALS",
    "ALIASES",
    "QUERY_PHRASES",
    "canonical",
    "canonical_set",
    "check_goal",
    "query_phrase",
    "to_gibson",
    "to_coco",
]

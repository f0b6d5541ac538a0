"""Category names of the official ObjectNav datasets and scan annotations, mapped to ours.

Three vocabularies meet when a scan is loaded: the goal names of the episode files (HM3D's six,
MP3D's 21, Gibson's six), the free-text object names of HM3D's ``.semantic.txt`` ("kitchen chair",
"tv", "flower pot") and our own categories (Gibson's 15, which the agent's semantic map and the
language priors know). Every mapping is an explicit table, so a name we do not know is background,
never a guess; goal instances listed in an episode file take their category from the file instead.
"""

from __future__ import annotations

from l3mvn.core.categories import GIBSON_CATEGORIES
from l3mvn.core.errors import L3MVNError

# MP3D ObjectNav's goals that Gibson's 15 lack (mpcat40 names, underscores as spaces).
MP3D_EXTRA_CATEGORIES: tuple[str, ...] = (
    "table",
    "picture",
    "cabinet",
    "cushion",
    "chest of drawers",
    "stool",
    "towel",
    "shower",
    "bathtub",
    "counter",
    "fireplace",
    "gym equipment",
    "seating",
    "clothes",
)
# The channels of a scan floor: Gibson's order first (so the agent's map and the priors read a scan
# as they read a Gibson map), then what MP3D episodes may ask for.
SCAN_CATEGORIES: tuple[str, ...] = GIBSON_CATEGORIES + MP3D_EXTRA_CATEGORIES

# Episode-file goal names (``object_category``) of every format -> our category.
GOAL_NAMES: dict[str, str] = {
    # objectnav_hm3d v1 / v2
    "chair": "chair",
    "bed": "bed",
    "plant": "potted plant",
    "toilet": "toilet",
    "tv_monitor": "tv",
    "sofa": "couch",
    # objectnav_mp3d (the 21 mpcat40 goals; chair, bed, plant, toilet, tv_monitor, sofa above)
    "table": "table",
    "picture": "picture",
    "cabinet": "cabinet",
    "cushion": "cushion",
    "chest_of_drawers": "chest of drawers",
    "sink": "sink",
    "stool": "stool",
    "towel": "towel",
    "shower": "shower",
    "bathtub": "bathtub",
    "counter": "counter",
    "fireplace": "fireplace",
    "gym_equipment": "gym equipment",
    "seating": "seating",
    "clothes": "clothes",
    # Gibson ObjectNav (SemExp's names)
    "couch": "couch",
    "potted plant": "potted plant",
    "tv": "tv",
}

# Raw annotation names (``.semantic.txt``, lower case) -> our category. Only names that mean the
# category without doubt: "stand" or "frame" could be anything and stay background.
RAW_NAMES: dict[str, str] = {
    **{name: name for name in SCAN_CATEGORIES},
    "chair": "chair",
    "armchair": "chair",
    "kitchen chair": "chair",
    "office chair": "chair",
    "dining chair": "chair",
    "desk chair": "chair",
    "rocking chair": "chair",
    "folding chair": "chair",
    "high chair": "chair",
    "sofa chair": "chair",
    "lounge chair": "chair",
    "couch": "couch",
    "sofa": "couch",
    "sectional": "couch",
    "loveseat": "couch",
    "sofa bed": "couch",
    "plant": "potted plant",
    "potted plant": "potted plant",
    "flower pot": "potted plant",
    "plant pot": "potted plant",
    "houseplant": "potted plant",
    "indoor plant": "potted plant",
    "bed": "bed",
    "double bed": "bed",
    "single bed": "bed",
    "bunk bed": "bed",
    "king bed": "bed",
    "toilet": "toilet",
    "toilet bowl": "toilet",
    "tv": "tv",
    "television": "tv",
    "tv monitor": "tv",
    "tv screen": "tv",
    "flat screen tv": "tv",
    "dining table": "dining-table",
    "dining-table": "dining-table",
    "kitchen table": "dining-table",
    "oven": "oven",
    "stove": "oven",
    "sink": "sink",
    "kitchen sink": "sink",
    "bathroom sink": "sink",
    "refrigerator": "refrigerator",
    "fridge": "refrigerator",
    "book": "book",
    "books": "book",
    "clock": "clock",
    "wall clock": "clock",
    "vase": "vase",
    "cup": "cup",
    "mug": "cup",
    "bottle": "bottle",
    "coffee table": "table",
    "side table": "table",
    "end table": "table",
    "desk": "table",
    "painting": "picture",
    "photo": "picture",
    "poster": "picture",
    "kitchen cabinet": "cabinet",
    "pillow": "cushion",
    "chest of drawers": "chest of drawers",
    "dresser": "chest of drawers",
    "bath towel": "towel",
    "shower stall": "shower",
    "bath": "bathtub",
    "bathtub": "bathtub",
    "kitchen counter": "counter",
    "countertop": "counter",
    "bench": "seating",
}


def normalise(name: str) -> str:
    """Annotation names differ in case, separators and padding: "Kitchen_Chair " is "kitchen chair"."""
    return " ".join(name.strip().lower().replace("_", " ").split())


def goal_category(name: object, where: str) -> str:
    """Our category for an episode file's ``object_category``, or a one-line error naming the valid ones."""
    if not isinstance(name, str) or name not in GOAL_NAMES:
        raise L3MVNError(f"{where}: unknown object_category {name!r}; valid: {', '.join(sorted(GOAL_NAMES))}")
    return GOAL_NAMES[name]


def raw_category(name: str) -> str | None:
    """Our category for a raw annotation name (None: background, a wall or an object we do not track)."""
    return RAW_NAMES.get(normalise(name))

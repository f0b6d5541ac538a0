"""The object categories every side names alike: the six ObjectNav goals and SemExp's map channels.

Scenes label their maps with these names, the simulator renders their ids, the language prior scores
them; a scan's own names are mapped onto them (``l3mvn.world.scenes.categories``).
"""

from __future__ import annotations

GOAL_CATEGORIES: tuple[str, ...] = ("chair", "couch", "potted plant", "bed", "toilet", "tv")

# Channels 1..15 of SemExp maps (the COCO-derived ObjectNav categories).
GIBSON_CATEGORIES: tuple[str, ...] = (
    "chair",
    "couch",
    "potted plant",
    "bed",
    "toilet",
    "tv",
    "dining-table",
    "oven",
    "sink",
    "refrigerator",
    "book",
    "clock",
    "vase",
    "cup",
    "bottle",
)

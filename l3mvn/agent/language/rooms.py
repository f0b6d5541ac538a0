"""Real rooms and the objects in them: the data behind the entropy list, the head and the benchmark.

Two sources, folded to canonical names (``vocabulary.canonical``):

- Gibson 3D scene graphs (``room_objects/gibson_3dsg_rooms.jsonl``, 2,306 rooms of 117 buildings).
  It has no tv class, so its rooms label five of the six goals.
- AI2-THOR's 120 hand-built single rooms (30 each of bathroom, bedroom, kitchen, living room) from the
  ``procthor`` wheel's ``databases/ai2thor-object-metadata.json``; they label all six goals. Its 75
  RoboTHOR entries are whole apartments, not rooms (every one has a tv, a bed and a sofa together),
  so they are left out. Each THOR room is its own "building".

Splits are by building, from a hash of the building's name: stable across runs, machines and
subsets of the data, with no seed to forget.
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
from dataclasses import dataclass
from pathlib import Path

from l3mvn.agent.language.vocabulary import GOALS, canonical
from l3mvn.core.errors import L3MVNError
from l3mvn.core.paths import SHARED_DATA

GIBSON_SOURCE = "gibson-3dsg"
THOR_SOURCE = "ai2thor"
_THOR_ROOM_KINDS = ("bathrooms", "bedrooms", "kitchens", "living_rooms")
SPLITS = ("train", "val", "test")
# Percent of buildings per split: the head trains on train, picks its checkpoint on val, and the
# ranking benchmark reports on test only.
_SPLIT_PERCENT = {"train": 70, "val": 15, "test": 15}


@dataclass(frozen=True)
class Room:
    """One room: where it comes from, its objects (canonical names) and the goals its source labels."""

    source: str
    building: str
    room_type: str
    objects: frozenset[str]
    labelled_goals: tuple[str, ...]

    @property
    def goals(self) -> frozenset[str]:
        return self.objects & frozenset(self.labelled_goals)


def default_gibson_rooms_path() -> Path:
    """``<repo>/../shared/data/room_objects/gibson_3dsg_rooms.jsonl`` (may not exist)."""
    return SHARED_DATA / "room_objects" / "gibson_3dsg_rooms.jsonl"


def default_thor_metadata_path() -> Path | None:
    """The metadata file inside the installed ``procthor`` wheel, or None when it is not installed."""
    spec = importlib.util.find_spec("procthor")  # located, not imported: its __init__ needs pandas
    if spec is None or not spec.submodule_search_locations:
        return None
    for root in spec.submodule_search_locations:
        path = Path(root) / "databases" / "ai2thor-object-metadata.json"
        if path.exists():
            return path
    return None


def load_gibson_rooms(path: str | Path) -> list[Room]:
    path = Path(path)
    if not path.exists():
        raise L3MVNError(f"room file {path} not found (expected shared/data/room_objects/gibson_3dsg_rooms.jsonl)")
    labelled = tuple(g for g in GOALS if g != "tv")
    rooms = []
    with path.open() as fh:
        for line_no, line in enumerate(fh, 1):
            if not line.strip():
                continue
            try:
                rec = json.loads(line)
                rooms.append(
                    Room(
                        source=GIBSON_SOURCE,
                        building=str(rec["building"]),
                        room_type=str(rec["room_type"]),
                        objects=frozenset(canonical(o) for o in rec["objects"]),
                        labelled_goals=labelled,
                    )
                )
            except (ValueError, KeyError, TypeError) as exc:
                raise L3MVNError(f"{path}:{line_no}: not a room record ({exc})") from None
    return rooms


def load_thor_rooms(path: str | Path) -> list[Room]:
    path = Path(path)
    if not path.exists():
        raise L3MVNError(f"AI2-THOR metadata {path} not found (pip install procthor==0.0.1.dev2)")
    data = json.loads(path.read_text())
    missing = [k for k in _THOR_ROOM_KINDS if k not in data]
    if missing:
        raise L3MVNError(f"{path}: missing room lists {', '.join(missing)}")
    rooms = []
    for kind in _THOR_ROOM_KINDS:
        for i, objects in enumerate(data[kind]):
            rooms.append(
                Room(
                    source=THOR_SOURCE,
                    building=f"thor-{kind}-{i:02d}",
                    room_type=kind[:-1],
                    objects=frozenset(canonical(o["objectType"]) for o in objects),
                    labelled_goals=GOALS,
                )
            )
    return rooms


def load_rooms(gibson_path: str | Path | None = None, thor_path: str | Path | None = None) -> list[Room]:
    """Both sources; a default path that does not exist is skipped, an explicit one must exist."""
    rooms: list[Room] = []
    gibson = Path(gibson_path) if gibson_path else default_gibson_rooms_path()
    if gibson_path or gibson.exists():
        rooms += load_gibson_rooms(gibson)
    thor = Path(thor_path) if thor_path else default_thor_metadata_path()
    if thor_path or thor is not None:
        assert thor is not None  # the path given, or the default found
        rooms += load_thor_rooms(thor)
    if not rooms:
        raise L3MVNError("no room data: pass the Gibson rooms .jsonl or install procthor for AI2-THOR rooms")
    return rooms


def split_of(building: str) -> str:
    """``"train"``, ``"val"`` or ``"test"`` for a building, from the first bytes of its SHA-1."""
    bucket = int.from_bytes(hashlib.sha1(building.encode()).digest()[:4], "big") % 100
    edge = 0
    for name in SPLITS:
        edge += _SPLIT_PERCENT[name]
        if bucket < edge:
            return name
    raise AssertionError("split percentages must sum to 100")


def rooms_in(rooms: list[Room], *splits: str) -> list[Room]:
    for s in splits:
        if s not in SPLITS:
            raise L3MVNError(f"unknown split {s!r}; valid: {', '.join(SPLITS)}")
    return [r for r in rooms if split_of(r.building) in splits]


__all__ = [
    "Room",
    "SPLITS",
    "GIBSON_SOURCE",
    "THOR_SOURCE",
    "load_rooms",
    "load_gibson_rooms",
    "load_thor_rooms",
    "default_gibson_rooms_path",
    "default_thor_metadata_path",
    "split_of",
    "rooms_in",
]

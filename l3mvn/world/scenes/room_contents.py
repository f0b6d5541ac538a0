"""What real rooms contain, per room type: the statistics the procedural house generator samples.

Derived once from the 120 hand-built AI2-THOR iTHOR rooms (30 each of bathrooms, bedrooms, kitchens,
living rooms) shipped in the ``procthor`` wheel (Apache-2.0), so our package needs neither procthor
nor any research data at run time: ``python -m l3mvn.world.scenes.room_contents`` rewrites
``l3mvn/data/room_contents.json`` from an installed ``procthor==0.0.1.dev2``.
"""

from __future__ import annotations

import json
import sys
from collections import Counter, defaultdict
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from l3mvn.core.errors import L3MVNError
from l3mvn.core.paths import PACKAGE_DATA
from l3mvn.core.writing import write_file

ROOM_CONTENTS_PATH = PACKAGE_DATA / "room_contents.json"
SOURCE_PACKAGE = "procthor==0.0.1.dev2"
_METADATA_FILE = "databases/ai2thor-object-metadata.json"

# The wheel's keys for the iTHOR rooms -> our room types (its "robothor" apartments mix room types).
ROOM_TYPES: dict[str, str] = {
    "bathrooms": "bathroom",
    "bedrooms": "bedroom",
    "kitchens": "kitchen",
    "living_rooms": "living room",
}

# AI2-THOR objectType -> our category. Only objects with a footprint on the floor plan or standing
# on furniture; wall decor, structure and clutter (Painting, Window, Cabinet, Pillow, ...) are left out.
AI2THOR_TO_CATEGORY: dict[str, str] = {
    "Chair": "chair",
    "ArmChair": "chair",
    "Sofa": "couch",
    "HousePlant": "potted plant",
    "Bed": "bed",
    "Toilet": "toilet",
    "Television": "tv",
    "DiningTable": "dining-table",
    "StoveBurner": "oven",
    "Sink": "sink",
    "SinkBasin": "sink",
    "Fridge": "refrigerator",
    "Book": "book",
    "AlarmClock": "clock",
    "Vase": "vase",
    "Cup": "cup",
    "Mug": "cup",
    "Bottle": "bottle",
    "WineBottle": "bottle",
    "SoapBottle": "bottle",
    "Bathtub": "bathtub",
    "BathtubBasin": "bathtub",
    "ShowerHead": "shower",
    "ShowerDoor": "shower",
    "ShowerGlass": "shower",
    "ShowerCurtain": "shower",
    "Towel": "towel",
    "HandTowel": "towel",
    "Dresser": "dresser",
    "SideTable": "side table",
    "Desk": "desk",
    "CoffeeTable": "coffee table",
    "TVStand": "tv stand",
    "ShelvingUnit": "shelving unit",
    "CounterTop": "counter",
    "FloorLamp": "lamp",
    "DeskLamp": "lamp",
    "Microwave": "microwave",
    "Toaster": "toaster",
    "CoffeeMachine": "coffee machine",
    "GarbageCan": "garbage can",
    "Laptop": "laptop",
    "LaundryHamper": "laundry hamper",
}

# Parts of one physical object listed as separate AI2-THOR objects: they never add to a count.
_PARTS = frozenset({"SinkBasin", "BathtubBasin", "ShowerDoor", "ShowerGlass", "ShowerCurtain"})
# Several AI2-THOR objects form one of ours (four burners are one stove): at most one per room,
# its footprint the union of these types' boxes.
_ONE_PER_ROOM: dict[str, tuple[str, ...]] = {
    "oven": ("StoveBurner",),
    "shower": ("ShowerGlass", "ShowerDoor", "ShowerCurtain"),
}
FLOOR = "floor"
# Resting on something we do not model (a wall shelf, a towel holder, a wall cabinet).
WALL = "wall"


@dataclass(frozen=True)
class ObjectStats:
    """One category in one room type. ``sizes`` are footprints (long side, short side, height) in
    metres of the real instances, rounded to map cells; ``on`` is how often an instance stands on
    each receptacle category, on the ``"floor"`` or against a ``"wall"`` (shelf, holder)."""

    frequency: float
    mean_count: float
    on: dict[str, float]
    sizes: tuple[tuple[float, float, float], ...]


@dataclass(frozen=True)
class RoomStats:
    """Object statistics of one room type over ``n_rooms`` real rooms."""

    room_type: str
    n_rooms: int
    objects: dict[str, ObjectStats]

    def frequency(self, category: str) -> float:
        stats = self.objects.get(category)
        return stats.frequency if stats else 0.0


def category_of(ai2thor_type: str) -> str:
    """Our category for an AI2-THOR object type."""
    try:
        return AI2THOR_TO_CATEGORY[ai2thor_type]
    except KeyError:
        raise L3MVNError(
            f"AI2-THOR type {ai2thor_type!r} has no category; mapped types: {', '.join(sorted(AI2THOR_TO_CATEGORY))}"
        ) from None


def room_categories() -> tuple[str, ...]:
    """Every category the room data can produce, in first-mention order of the mapping."""
    return tuple(dict.fromkeys(AI2THOR_TO_CATEGORY.values()))


@lru_cache(maxsize=4)
def load_room_contents(path: str | Path = ROOM_CONTENTS_PATH) -> dict[str, RoomStats]:
    """The shipped statistics: ``{room_type: RoomStats}``."""
    try:
        raw = json.loads(Path(path).read_text())
        rooms = raw["rooms"]
        return {
            room: RoomStats(
                room_type=room,
                n_rooms=int(rec["n_rooms"]),
                objects={
                    cat: ObjectStats(
                        frequency=float(o["frequency"]),
                        mean_count=float(o["mean_count"]),
                        on={k: float(v) for k, v in o["on"].items()},
                        sizes=tuple((float(a), float(b), float(c)) for a, b, c in o["sizes"]),
                    )
                    for cat, o in rec["objects"].items()
                },
            )
            for room, rec in rooms.items()
        }
    except FileNotFoundError:
        raise L3MVNError(
            f"room contents file {path} is missing; regenerate it: python -m l3mvn.world.scenes.room_contents"
        ) from None
    except (json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
        raise L3MVNError(f"room contents file {path} is malformed ({type(exc).__name__}: {exc})") from None


def procthor_metadata_path() -> Path:
    """The AI2-THOR room metadata inside an installed procthor wheel (found without importing it:
    importing ``procthor.databases`` would need ai2thor and pandas)."""
    import importlib.util

    spec = importlib.util.find_spec("procthor")
    if spec is None or not spec.submodule_search_locations:
        raise L3MVNError(f"procthor is not installed; pip install {SOURCE_PACKAGE} to rebuild the room contents")
    path = Path(next(iter(spec.submodule_search_locations))) / _METADATA_FILE
    if not path.is_file():
        raise L3MVNError(f"{path} is missing; the room contents are built from {SOURCE_PACKAGE}")
    return path


def build_room_contents(metadata_path: str | Path | None = None) -> dict:
    """Count, per room type, which of our categories the real rooms contain, how many, on what, and how big."""
    path = Path(metadata_path) if metadata_path else procthor_metadata_path()
    metadata = json.loads(path.read_text())
    rooms = {}
    for key, room_type in ROOM_TYPES.items():
        scenes = metadata[key]
        counts: dict[str, list[int]] = defaultdict(list)
        on: dict[str, Counter] = defaultdict(Counter)
        sizes: dict[str, list[tuple[float, float, float]]] = defaultdict(list)
        for scene in scenes:
            for cat, n in _scene_counts(scene).items():
                counts[cat].append(n)
            _scene_receptacles(scene, on)
            _scene_sizes(scene, sizes)
        objects = {}
        for cat in sorted(counts):
            total = sum(on[cat].values())
            objects[cat] = {
                "frequency": round(len(counts[cat]) / len(scenes), 4),
                "mean_count": round(float(np.mean(counts[cat])), 3),
                "on": {k: round(v / total, 3) for k, v in sorted(on[cat].items()) if total},
                "sizes": sorted(set(sizes[cat])),
            }
        rooms[room_type] = {"n_rooms": len(scenes), "objects": objects}
    return {
        "source": f"{SOURCE_PACKAGE}: {_METADATA_FILE} (AI2-THOR iTHOR rooms), Apache-2.0",
        "rooms": rooms,
    }


def _scene_counts(scene: list[dict]) -> dict[str, int]:
    types = Counter(o["objectType"] for o in scene)
    counts: Counter = Counter()
    for t, n in types.items():
        cat = AI2THOR_TO_CATEGORY.get(t)
        if cat is None:
            continue
        if cat in _ONE_PER_ROOM:
            counts[cat] = 1
        elif t not in _PARTS:
            counts[cat] += n
        else:
            counts[cat] = max(counts[cat], 1)
    return dict(counts)


def _scene_receptacles(scene: list[dict], on: dict[str, Counter]) -> None:
    type_of = {o["objectId"]: o["objectType"] for o in scene}
    for o in scene:
        t = o["objectType"]
        if t in _PARTS or t not in AI2THOR_TO_CATEGORY:
            continue
        parents = [type_of.get(p, p.split("|")[0]) for p in (o["parentReceptacles"] or [])]
        mapped = [AI2THOR_TO_CATEGORY[p] for p in parents if p in AI2THOR_TO_CATEGORY]
        if mapped:
            where = mapped[0]
        elif not parents or "Floor" in parents:
            where = FLOOR
        else:
            where = WALL
        on[AI2THOR_TO_CATEGORY[t]][where] += 1


def _scene_sizes(scene: list[dict], sizes: dict[str, list]) -> None:
    unions: dict[str, list[np.ndarray]] = defaultdict(list)
    for o in scene:
        t = o["objectType"]
        cat = AI2THOR_TO_CATEGORY.get(t)
        box = o["axisAlignedBoundingBox"]
        lo = np.array([box["center"][a] - box["size"][a] / 2 for a in "xyz"])
        hi = np.array([box["center"][a] + box["size"][a] / 2 for a in "xyz"])
        if cat in _ONE_PER_ROOM:
            if t in _ONE_PER_ROOM[cat]:
                unions[cat].append(np.stack([lo, hi]))
        elif cat is not None and t not in _PARTS:
            sizes[cat].append(_footprint(hi - lo))
    for cat, boxes in unions.items():
        b = np.stack(boxes)
        sizes[cat].append(_footprint(b[:, 1].max(0) - b[:, 0].min(0)))


def _footprint(extent: np.ndarray) -> tuple[float, float, float]:
    """(long side, short side, height) rounded to 5 cm map cells (at least one); AI2-THOR's y is up."""
    x, y, z = (max(0.05, round(float(v) * 20) / 20) for v in extent)
    return round(max(x, z), 2), round(min(x, z), 2), round(y, 2)


def dump_room_contents(contents: dict) -> str:
    """The JSON text as shipped: one object category per line keeps it small and diffable."""
    lines = [f'{{"source": {json.dumps(contents["source"])}, "rooms": {{']
    rooms = list(contents["rooms"].items())
    for i, (room, rec) in enumerate(rooms):
        lines.append(f' {json.dumps(room)}: {{"n_rooms": {rec["n_rooms"]}, "objects": {{')
        objs = list(rec["objects"].items())
        for j, (cat, o) in enumerate(objs):
            body = json.dumps(o, sort_keys=True, separators=(",", ":"))
            lines.append(f"  {json.dumps(cat)}: {body}" + ("," if j < len(objs) - 1 else ""))
        lines.append(" }}" + ("," if i < len(rooms) - 1 else ""))
    lines.append("}}")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    out = Path(args[0]) if args else ROOM_CONTENTS_PATH
    write_file(out, dump_room_contents(build_room_contents()), "room contents")
    print(f"wrote {out} ({out.stat().st_size // 1024} KiB)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

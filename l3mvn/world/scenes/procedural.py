"""Seeded procedural houses in the SemExp map format, so the built-in simulator needs no research data.

A rectangular footprint is split recursively into 4-8 rooms (a binary space partition); every split
gets a door, so the rooms form a tree and the house is connected; the living room also opens onto
its neighbours. Each room is furnished by sampling what real AI2-THOR rooms of its type contain
(``room_contents``) and placing footprints the way furniture stands: beds and couches against walls,
tables in the middle with chairs around them, small items on tables and counters. Every floor object
is kept only if the room's navmesh stays one piece and the object stays within reach, so a house is
connected and every goal can be reached by construction; all six goal categories are guaranteed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy import ndimage as ndi

from l3mvn.core.categories import GIBSON_CATEGORIES, GOAL_CATEGORIES
from l3mvn.core.config import SimConfig
from l3mvn.core.errors import L3MVNError
from l3mvn.core.grid import disk
from l3mvn.world.scenes.room_contents import RoomStats, load_room_contents, room_categories
from l3mvn.world.scenes.scene import SceneMap

# Gibson's 15 first, in SemExp channel order (so channels 1..15 export as they are), then the rest
# of what the room data contains.
PROCEDURAL_CATEGORIES: tuple[str, ...] = GIBSON_CATEGORIES + tuple(
    c for c in room_categories() if c not in GIBSON_CATEGORIES
)
MIN_ROOMS, MAX_ROOMS = 4, 8

_RES = 0.05
_RADIUS = math.ceil(SimConfig().agent_radius_m / _RES - 1e-9)  # navmesh erosion, cells (0.18 m -> 4)
_EXTERIOR_WALL = 4  # cells (0.20 m)
_INTERIOR_WALL = 3  # cells (0.15 m): the navmesh regrown by 2 cells from both sides never meets
_MARGIN = 6  # empty cells around the house
_MIN_HOUSE_SIDE = 8.5  # metres, the longer side of even a 4-room house
_MIN_ROOM_SIDE = 2.4  # metres, between wall centre lines
_BATHROOM_DEPTH = (2.0, 2.6)  # metres
_DOOR_WIDTH = (0.95, 1.15)  # metres: the 0.36 m agent passes with the navmesh >= 0.55 m wide
_OPENING_WIDTH = (1.4, 2.2)  # metres, between the living room and its neighbours
_DOOR_CLEARANCE = 0.6  # metres kept free of furniture in front of each door, both sides
_REACH = 1.0  # metres: an object counts as reachable with a navmesh cell this close (success radius)
_PLACEMENT_CHECKS = 12  # navmesh checks per object and size before it is left out
_SIZE_DRAWS = 3  # real sizes tried per object: a smaller bed may fit where a king-size did not
_FURNISH_ATTEMPTS = 8
_LAYOUT_ATTEMPTS = 50
_PUBLICNESS = {"living room": 3, "kitchen": 2, "bedroom": 1, "bathroom": 0}

# How each category stands in a room (AI2-THOR's placement annotations mostly say "edge"/"corner").
# wall: back against a wall; corner: in a corner; middle: free-standing; in: part of its _HOST
# (standing alone against a wall without one);
# around: at a dining table or desk; front: in front of the couch; beside: next to a bed or couch;
# opposite: on the wall facing the couch; on: on a surface (or against a wall when the data says so).
_MODE: dict[str, str] = {
    "bed": "wall",
    "toilet": "wall",
    "couch": "wall",
    "counter": "wall",
    "refrigerator": "corner",
    "oven": "in",
    "sink": "in",
    "bathtub": "wall",
    "shower": "in",
    "dining-table": "middle",
    "desk": "wall",
    "dresser": "wall",
    "tv stand": "opposite",
    "shelving unit": "wall",
    "coffee table": "front",
    "side table": "beside",
    "chair": "around",
    "laundry hamper": "corner",
    "garbage can": "corner",
    "potted plant": "on",
    "lamp": "on",
    "tv": "on",
    "towel": "on",
    "microwave": "on",
    "toaster": "on",
    "coffee machine": "on",
    "laptop": "on",
    "book": "on",
    "clock": "on",
    "vase": "on",
    "cup": "on",
    "bottle": "on",
}
# A sink or stove sits in a counter run; most AI2-THOR shower heads hang over a bathtub.
_HOST = {"sink": "counter", "oven": "counter", "shower": "bathtub"}
# Placed in this order: what anchors others first, small items last.
_ORDER = tuple(_MODE)
# Long side across the wall rather than along it (a bed's head, a toilet's back against the wall).
_PERPENDICULAR = frozenset({"bed", "toilet"})
# Surfaces small items stand on.
_SURFACES = frozenset(
    {
        "counter",
        "dining-table",
        "coffee table",
        "side table",
        "desk",
        "dresser",
        "tv stand",
        "shelving unit",
    }
)
# A tv stand is there for the tv.
_PREFERRED_SURFACE = {"tv": "tv stand"}
# Items that never stand alone on the floor in a house (the data's few floor cases are built-ins).
_SURFACE_ONLY = frozenset(
    {
        "microwave",
        "toaster",
        "coffee machine",
        "laptop",
        "book",
        "clock",
        "cup",
        "bottle",
        "vase",
    }
)
# AI2-THOR boxes include surrounds (tub decks, L-shaped counter blocks): clip to single units.
_MAX_FOOTPRINT: dict[str, tuple[float, float]] = {
    "counter": (3.0, 0.65),
    "bathtub": (1.8, 0.85),
    "shower": (1.2, 1.2),
    "oven": (0.8, 0.65),
    "sink": (0.9, 0.6),
    "dining-table": (2.0, 1.1),
    "desk": (1.6, 0.8),
    "dresser": (1.6, 0.6),
    "shelving unit": (1.6, 0.5),
    "tv stand": (1.8, 0.55),
    "side table": (0.7, 0.6),
    "couch": (2.6, 1.0),
    "coffee table": (1.3, 0.8),
    "tv": (1.4, 0.25),
    "towel": (0.6, 0.1),
    "toilet": (0.95, 0.6),
    "chair": (1.0, 0.9),
}
_MIN_FOOTPRINT: dict[str, tuple[float, float]] = {
    "counter": (1.2, 0.55),
    "shower": (0.9, 0.9),
    "bathtub": (1.5, 0.7),
}
# Instances per room at most (3 for the rest): one dining set, one tv, up to six chairs.
_MAX_COUNT = {
    "chair": 6,
    "counter": 2,
    "side table": 2,
    "couch": 2,
    "bed": 2,
    "sink": 2,
    "dining-table": 1,
    "tv": 1,
    "refrigerator": 1,
    "oven": 1,
    "toilet": 1,
    "bathtub": 1,
    "shower": 1,
    "coffee table": 1,
    "tv stand": 1,
    "desk": 1,
    "dresser": 1,
}


@dataclass(frozen=True)
class Rect:
    """Half-open cell rectangle ``[r0, r1) x [c0, c1)``."""

    r0: int
    c0: int
    r1: int
    c1: int

    @property
    def slices(self) -> tuple[slice, slice]:
        return slice(self.r0, self.r1), slice(self.c0, self.c1)

    @property
    def height(self) -> int:
        return self.r1 - self.r0

    @property
    def width(self) -> int:
        return self.c1 - self.c0

    def grown(self, n: int) -> Rect:
        return Rect(self.r0 - n, self.c0 - n, self.r1 + n, self.c1 + n)

    def contains(self, other: Rect) -> bool:
        return self.r0 <= other.r0 and self.c0 <= other.c0 and other.r1 <= self.r1 and other.c1 <= self.c1


@dataclass(frozen=True)
class Door:
    """An opening in the wall between two rooms; ``cells`` spans the wall's full thickness."""

    rooms: tuple[int, int]
    cells: Rect
    width_m: float


@dataclass(frozen=True)
class Room:
    """A room type (a key of ``load_room_contents()``) and its floor rectangle inside the walls."""

    kind: str
    interior: Rect


@dataclass(frozen=True)
class ProceduralHouse:
    """A generated house: the map plus the layout that made it. ``floor`` is the exact free floor
    (room interiors and doorways, furniture included), which the map only implies."""

    scene: SceneMap
    rooms: tuple[Room, ...]
    doors: tuple[Door, ...]
    floor: np.ndarray


def generate_house(seed: int, *, n_rooms: int | None = None) -> SceneMap:
    """The house of this seed (bit for bit the same every time), as one SceneMap floor."""
    return build_house(seed, n_rooms=n_rooms).scene


def generate_houses(n: int, seed: int = 0) -> list[SceneMap]:
    """``n`` houses with consecutive seeds from ``seed``."""
    if n < 0:
        raise L3MVNError(f"number of houses must be >= 0, got {n}")
    return [generate_house(seed + i) for i in range(n)]


def procedural_split(n: int, seed: int = 0) -> dict[str, dict[int, SceneMap]]:
    """``{name: {0: SceneMap}}``, the shape ``semexp.load_split`` returns."""
    return {s.name: {s.floor: s} for s in generate_houses(n, seed)}


def build_house(seed: int, *, n_rooms: int | None = None) -> ProceduralHouse:
    """The house of this seed with its layout; a draw that fails a check is redrawn from the same stream."""
    if not isinstance(seed, (int, np.integer)) or seed < 0:
        raise L3MVNError(f"seed must be a non-negative integer, got {seed!r}")
    if n_rooms is not None and not MIN_ROOMS <= n_rooms <= MAX_ROOMS:
        raise L3MVNError(f"n_rooms must lie in {MIN_ROOMS}..{MAX_ROOMS}, got {n_rooms}")
    rng = np.random.default_rng(int(seed))
    stats = load_room_contents()
    count = int(n_rooms) if n_rooms is not None else int(rng.integers(MIN_ROOMS, MAX_ROOMS + 1))
    for _ in range(_LAYOUT_ATTEMPTS):
        layout = _layout(rng, count)
        if layout is None:
            continue
        for _ in range(_FURNISH_ATTEMPTS):
            placed = _Furnisher(rng, stats, layout).furnish()
            if placed is None:
                continue
            house = _finish(seed, layout, placed)
            if ndi.label(house.scene.navigable)[1] == 1:
                return house
    raise L3MVNError(f"seed {seed}: no valid house with {count} rooms after {_LAYOUT_ATTEMPTS} layouts")


# --- layout ---------------------------------------------------------------------------------------
@dataclass
class _Layout:
    floor: np.ndarray  # True on floor cells inside the house (walls and outside False)
    rooms: list[Room]
    doors: list[Door]


def _layout(rng: np.random.Generator, n_rooms: int) -> _Layout | None:
    """Split a footprint into rooms, type them and cut doors; None when this draw does not work."""
    area = n_rooms * rng.uniform(13.0, 19.0)
    aspect = rng.uniform(1.0, 1.6)
    w_m = max(math.sqrt(area * aspect), _MIN_HOUSE_SIDE)
    h_m = area / w_m
    H, W = int(h_m / _RES), int(w_m / _RES)
    n_bath = _bathrooms(n_rooms)
    leaves: list[Rect] = [Rect(0, 0, H, W)]  # wall centre lines
    splits: list[tuple[str, int, Rect]] = []
    while len(leaves) < n_rooms:
        small = len(leaves) >= n_rooms - n_bath  # the last cuts carve a bathroom off a room
        order = sorted(range(len(leaves)), key=lambda i: -(leaves[i].height * leaves[i].width))
        if small:
            order = order[1:] + order[:1]  # spare the largest room (the living room) if possible
        for i in order:
            cut = _split(rng, leaves[i], small)
            if cut is not None:
                break
        else:
            return None
        axis, pos = cut
        r = leaves.pop(i)
        if axis == "h":
            leaves += [Rect(r.r0, r.c0, pos, r.c1), Rect(pos, r.c0, r.r1, r.c1)]
        else:
            leaves += [Rect(r.r0, r.c0, r.r1, pos), Rect(r.r0, pos, r.r1, r.c1)]
        splits.append((axis, pos, r))
    kinds = _room_kinds(rng, leaves)
    if kinds is None:
        return None
    doors = _doors(rng, leaves, kinds, splits)
    if doors is None:
        return None
    m = _MARGIN
    floor = np.zeros((H + 2 * m, W + 2 * m), dtype=bool)
    rooms = []
    for rect, kind in zip(leaves, kinds):
        inner = _interior(rect, H, W)
        inner = Rect(inner.r0 + m, inner.c0 + m, inner.r1 + m, inner.c1 + m)
        floor[inner.slices] = True
        rooms.append(Room(kind, inner))
    shifted = []
    for d in doors:
        c = Rect(d.cells.r0 + m, d.cells.c0 + m, d.cells.r1 + m, d.cells.c1 + m)
        floor[c.slices] = True
        shifted.append(Door(d.rooms, c, d.width_m))
    return _Layout(floor, rooms, shifted)


def _split(rng: np.random.Generator, r: Rect, small: bool) -> tuple[str, int] | None:
    """Cut across the longer side: near the middle, or 2.0-2.6 m from one end to carve a bathroom."""
    axis = "h" if r.height > r.width or (r.height == r.width and rng.random() < 0.5) else "v"
    lo, hi = (r.r0, r.r1) if axis == "h" else (r.c0, r.c1)
    min_side = int(_MIN_ROOM_SIDE / _RES)
    if small:
        depth = int(rng.uniform(*_BATHROOM_DEPTH) / _RES)
        if hi - lo < depth + min_side:
            return None
        return axis, (lo + depth if rng.random() < 0.5 else hi - depth)
    if hi - lo < 2 * min_side:
        return None
    pos = int(lo + (hi - lo) * rng.uniform(0.35, 0.65))
    return axis, min(max(pos, lo + min_side), hi - min_side)


def _bathrooms(n_rooms: int) -> int:
    return 1 if n_rooms <= 5 else 2


def _interior(r: Rect, H: int, W: int) -> Rect:
    """Floor cells of a room: exterior walls lie inside the footprint, interior ones straddle the line."""
    lo = _INTERIOR_WALL // 2
    hi = _INTERIOR_WALL - lo
    return Rect(
        _EXTERIOR_WALL if r.r0 == 0 else r.r0 + hi,
        _EXTERIOR_WALL if r.c0 == 0 else r.c0 + hi,
        H - _EXTERIOR_WALL if r.r1 == H else r.r1 - lo,
        W - _EXTERIOR_WALL if r.c1 == W else r.c1 - lo,
    )


def _shared_wall(a: Rect, b: Rect) -> tuple[str, int, int, int] | None:
    """(axis, line, start, end) of the wall segment two rooms share, if any."""
    if a.r1 == b.r0 or b.r1 == a.r0:
        lo, hi = max(a.c0, b.c0), min(a.c1, b.c1)
        return ("h", a.r1 if a.r1 == b.r0 else a.r0, lo, hi) if hi > lo else None
    if a.c1 == b.c0 or b.c1 == a.c0:
        lo, hi = max(a.r0, b.r0), min(a.r1, b.r1)
        return ("v", a.c1 if a.c1 == b.c0 else a.c0, lo, hi) if hi > lo else None
    return None


def _room_kinds(rng: np.random.Generator, leaves: list[Rect]) -> list[str] | None:
    """Largest room is the living room, its largest neighbour the kitchen, the smallest bathrooms."""
    area = [r.height * r.width for r in leaves]
    living = int(np.argmax(area))
    neighbours = [
        i for i in range(len(leaves)) if i != living and _usable_door_span(leaves[living], leaves[i], _OPENING_WIDTH[0])
    ]
    if not neighbours:
        return None
    kitchen = max(neighbours, key=lambda i: area[i] + rng.uniform(0, 1e-3))
    rest = sorted((i for i in range(len(leaves)) if i not in (living, kitchen)), key=lambda i: area[i])
    n_bath = _bathrooms(len(leaves))
    kinds = ["bedroom"] * len(leaves)
    kinds[living], kinds[kitchen] = "living room", "kitchen"
    for i in rest[:n_bath]:
        kinds[i] = "bathroom"
    return kinds


def _usable_door_span(a: Rect, b: Rect, width_m: float) -> tuple[str, int, int, int] | None:
    """The shared wall of two rooms if a door of this width fits, clear of the walls meeting it."""
    wall = _shared_wall(a, b)
    if wall is None:
        return None
    axis, line, lo, hi = wall
    keep = _EXTERIOR_WALL + int(0.3 / _RES)  # a door frame's width from any wall meeting this one
    lo, hi = lo + keep, hi - keep
    return (axis, line, lo, hi) if hi - lo >= int(width_m / _RES) else None


def _doors(rng: np.random.Generator, leaves: list[Rect], kinds: list[str], splits) -> list[Door] | None:
    """One door per split (a spanning tree), plus wide openings from the living room."""
    doors: list[Door] = []
    for axis, pos, parent in splits:
        pairs = []
        for i, a in enumerate(leaves):
            for j, b in enumerate(leaves):
                if i >= j or not (parent.contains(a) and parent.contains(b)):
                    continue
                width = rng.uniform(*_DOOR_WIDTH)
                span = _usable_door_span(a, b, width)
                if span is None or span[0] != axis or span[1] != pos:
                    continue
                bath_pair = kinds[i] == kinds[j] == "bathroom"
                score = _PUBLICNESS[kinds[i]] + _PUBLICNESS[kinds[j]] - 10 * bath_pair + rng.uniform(0, 0.5)
                pairs.append((score, i, j, span, width))
        if not pairs:
            return None
        _, i, j, span, width = max(pairs, key=lambda p: p[0])
        doors.append(_cut(rng, (i, j), span, width))
    living = kinds.index("living room")
    linked = {frozenset(d.rooms) for d in doors}
    for j, kind in enumerate(kinds):
        if j == living or frozenset((living, j)) in linked or kind == "bathroom":
            continue
        wide = kind == "kitchen"
        width = rng.uniform(*(_OPENING_WIDTH if wide else _DOOR_WIDTH))
        span = _usable_door_span(leaves[living], leaves[j], width)
        if span is not None and (wide or rng.random() < 0.5):
            doors.append(_cut(rng, (living, j), span, width))
    return doors


def _cut(rng: np.random.Generator, rooms: tuple[int, int], span, width_m: float) -> Door:
    axis, line, lo, hi = span
    # The span was checked against the width rounded down; rounded to nearest it may be a cell wider
    # than the span, and then the door takes the whole span.
    w = min(int(round(width_m / _RES)), hi - lo)
    start = int(rng.integers(lo, hi - w + 1))
    a, b = line - _INTERIOR_WALL // 2, line - _INTERIOR_WALL // 2 + _INTERIOR_WALL
    cells = Rect(a, start, b, start + w) if axis == "h" else Rect(start, a, start + w, b)
    return Door(rooms, cells, w * _RES)


# --- furnishing -----------------------------------------------------------------------------------
@dataclass
class _Placed:
    category: str
    rect: Rect
    side: int | None = None  # wall it backs onto: 0 top, 1 bottom, 2 left, 3 right
    on_surface: bool = False


@dataclass
class _RoomState:
    room: Room
    doors: list[Door]
    placed: list[_Placed] = field(default_factory=list)

    def first(self, category: str) -> _Placed | None:
        return next((p for p in self.placed if p.category == category), None)


class _Furnisher:
    """Places sampled objects room by room, keeping each room's navmesh whole and every object reachable."""

    def __init__(self, rng: np.random.Generator, stats: dict[str, RoomStats], layout: _Layout) -> None:
        self.rng, self.stats = rng, stats
        self.blocked = ~layout.floor  # walls, outside and floor furniture
        self.reserved = np.zeros_like(layout.floor)  # kept clear in front of doors
        self.on_top = np.zeros_like(layout.floor)  # items standing on surfaces
        self.checks_left = _PLACEMENT_CHECKS
        clear = int(_DOOR_CLEARANCE / _RES)
        for d in layout.doors:
            c = d.cells
            if c.height == _INTERIOR_WALL:
                self.reserved[Rect(c.r0 - clear, c.c0 - _RADIUS, c.r1 + clear, c.c1 + _RADIUS).slices] = True
            else:
                self.reserved[Rect(c.r0 - _RADIUS, c.c0 - clear, c.r1 + _RADIUS, c.c1 + clear).slices] = True
        self.states = [
            _RoomState(room, [d for d in layout.doors if i in d.rooms]) for i, room in enumerate(layout.rooms)
        ]

    def furnish(self) -> list[_Placed] | None:
        wishes = [self._sample(s.room.kind) for s in self.states]
        self._ensure_goals(wishes)
        for state, wish in zip(self.states, wishes):
            for category in wish:
                self._place(state, category)
        placed = [p for s in self.states for p in s.placed]
        present = {p.category for p in placed}
        return placed if all(g in present for g in GOAL_CATEGORIES) else None

    def _sample(self, kind: str) -> list[str]:
        room = self.stats[kind]
        wish = []
        for cat, o in room.objects.items():
            if self.rng.random() >= o.frequency:
                continue
            n = 1 + int(self.rng.poisson(max(o.mean_count - 1.0, 0.0)))
            wish += [cat] * min(n, _MAX_COUNT.get(cat, 3))
        return sorted(wish, key=_ORDER.index)

    def _ensure_goals(self, wishes: list[list[str]]) -> None:
        """A goal no room drew goes to the room whose type holds it most often (largest first)."""
        for goal in GOAL_CATEGORIES:
            if any(goal in w for w in wishes):
                continue
            best = max(
                range(len(self.states)),
                key=lambda i: (
                    self.stats[self.states[i].room.kind].frequency(goal),
                    self.states[i].room.interior.height * self.states[i].room.interior.width,
                ),
            )
            wishes[best].append(goal)
            wishes[best].sort(key=_ORDER.index)

    # --- one object ---
    def _place(self, state: _RoomState, category: str) -> None:
        mode = _MODE[category]
        if mode == "on":
            if self._place_on(state, category):
                return
            if category in _SURFACE_ONLY:
                return
            mode = {"potted plant": "corner", "tv": "opposite"}.get(category, "wall")
        for _ in range(_SIZE_DRAWS):
            long_c, short_c = self._size(state.room.kind, category)
            self.checks_left = _PLACEMENT_CHECKS
            for cand in self._candidates(state, category, mode, long_c, short_c):
                if self._try(state, cand):
                    return
                if self.checks_left <= 0:
                    break

    def _size(self, kind: str, category: str) -> tuple[int, int]:
        sizes = self.stats[kind].objects.get(category)
        pool = sizes.sizes if sizes and sizes.sizes else _any_sizes(self.stats, category)
        long_m, short_m, _ = pool[int(self.rng.integers(len(pool)))]
        hi = _MAX_FOOTPRINT.get(category, (9.0, 9.0))
        lo = _MIN_FOOTPRINT.get(category, (_RES, _RES))
        long_m, short_m = min(max(long_m, lo[0]), hi[0]), min(max(short_m, lo[1]), hi[1])
        return max(1, round(long_m / _RES)), max(1, round(short_m / _RES))

    def _candidates(self, state: _RoomState, category: str, mode: str, long_c: int, short_c: int):
        box = state.room.interior
        if mode == "in":
            host = [p for p in state.placed if p.category == _HOST[category]]
            if host:
                yield from (self._inside(h, long_c, short_c, category) for h in host for _ in range(4))
            mode = "corner" if category == "shower" else "wall"
        if mode == "around":
            table = state.first("dining-table") or state.first("desk")
            if table is not None:
                yield from self._around(table, long_c, short_c)
            mode = "corner"
        if mode == "front":
            couch = state.first("couch")
            if couch is not None:
                yield from self._in_front(couch, long_c, short_c)
            mode = "middle"
        if mode == "beside":
            anchor = state.first("bed") or state.first("couch")
            if anchor is not None:
                yield from self._beside(anchor, long_c, short_c)
            mode = "wall"
        sides = [0, 1, 2, 3]
        if mode == "opposite":
            couch = state.first("couch")
            if couch is not None and couch.side is not None:
                sides = [couch.side ^ 1]  # facing the couch first, any wall after
                yield from self._along_walls(box, category, "wall", sides, long_c, short_c)
                sides = [0, 1, 2, 3]
            mode = "wall"
        if mode == "middle":
            yield from self._in_middle(box, category, long_c, short_c)
        else:
            yield from self._along_walls(box, category, mode, sides, long_c, short_c)

    def _along_walls(self, box: Rect, category: str, mode: str, sides: list[int], long_c: int, short_c: int):
        """Every position against the given walls (every 3 cells, or the two ends for a corner),
        shuffled; the usual orientation first, then turned by 90 degrees."""
        usual = (short_c, long_c) if category in _PERPENDICULAR else (long_c, short_c)
        for along, depth in dict.fromkeys((usual, usual[::-1])):
            cands = []
            for side in sides:
                lo, hi = (box.c0, box.c1) if side < 2 else (box.r0, box.r1)
                if hi - lo < along:
                    continue
                starts = (lo, hi - along) if mode == "corner" else range(lo, hi - along + 1, 3)
                cands += [(side, start) for start in starts]
            for i in self.rng.permutation(len(cands)):
                side, start = cands[i]
                yield _Placed(category, _against(box, side, start, along, depth), side)

    def _in_middle(self, box: Rect, category: str, long_c: int, short_c: int):
        """Free-standing positions in the central half of the room, shuffled."""
        cands = []
        for h, w in ((long_c, short_c), (short_c, long_c)):
            if box.height - h < 2 or box.width - w < 2:
                continue
            rows = range(box.r0 + (box.height - h) // 4, box.r0 + 3 * (box.height - h) // 4 + 1, 3)
            cols = range(box.c0 + (box.width - w) // 4, box.c0 + 3 * (box.width - w) // 4 + 1, 3)
            cands += [Rect(r, c, r + h, c + w) for r in rows for c in cols]
        for i in self.rng.permutation(len(cands)):
            yield _Placed(category, cands[i])

    def _inside(self, host: _Placed, long_c: int, short_c: int, category: str) -> _Placed:
        """A footprint within a surface, lined up with its long side (a sink in a counter)."""
        h, w = (short_c, long_c) if host.rect.width >= host.rect.height else (long_c, short_c)
        h, w = min(h, host.rect.height), min(w, host.rect.width)
        r = int(self.rng.integers(host.rect.r0, host.rect.r1 - h + 1))
        c = int(self.rng.integers(host.rect.c0, host.rect.c1 - w + 1))
        return _Placed(category, Rect(r, c, r + h, c + w), host.side, on_surface=True)

    def _around(self, table: _Placed, long_c: int, short_c: int):
        """Chair slots along the table's sides (the desk side facing the room for a desk)."""
        t, s, gap = table.rect, short_c, 1
        slots = []
        if table.category == "desk" and table.side is not None:
            mid_r, mid_c = (t.r0 + t.r1 - s) // 2, (t.c0 + t.c1 - s) // 2
            slots.append(
                {
                    0: (t.r1 + gap, mid_c),
                    1: (t.r0 - gap - s, mid_c),
                    2: (mid_r, t.c1 + gap),
                    3: (mid_r, t.c0 - gap - s),
                }[table.side]
            )
        else:
            for k in range(max(1, t.width // (s + 4))):
                c = t.c0 + (2 * k + 1) * t.width // (2 * max(1, t.width // (s + 4))) - s // 2
                slots += [(t.r0 - gap - s, c), (t.r1 + gap, c)]
            for k in range(max(1, t.height // (s + 4))):
                r = t.r0 + (2 * k + 1) * t.height // (2 * max(1, t.height // (s + 4))) - s // 2
                slots += [(r, t.c0 - gap - s), (r, t.c1 + gap)]
        for i in self.rng.permutation(len(slots)):
            r, c = slots[i]
            yield _Placed("chair", Rect(r, c, r + s, c + s))

    def _in_front(self, couch: _Placed, long_c: int, short_c: int):
        gap = int(0.45 / _RES)
        t = couch.rect
        if couch.side in (0, 1):
            c = (t.c0 + t.c1 - long_c) // 2
            r = t.r1 + gap if couch.side == 0 else t.r0 - gap - short_c
            yield _Placed("coffee table", Rect(r, c, r + short_c, c + long_c))
        elif couch.side in (2, 3):
            r = (t.r0 + t.r1 - long_c) // 2
            c = t.c1 + gap if couch.side == 2 else t.c0 - gap - short_c
            yield _Placed("coffee table", Rect(r, c, r + long_c, c + short_c))

    def _beside(self, anchor: _Placed, long_c: int, short_c: int):
        """Next to the anchor's end on the same wall (a nightstand by the bed's head)."""
        t, side = anchor.rect, anchor.side
        if side is None:
            return
        w = short_c
        for end in self.rng.permutation(2):
            if side in (0, 1):
                r = t.r0 if side == 0 else t.r1 - w
                c = t.c0 - w if end == 0 else t.c1
            else:
                c = t.c0 if side == 2 else t.c1 - w
                r = t.r0 - w if end == 0 else t.r1
            yield _Placed("side table", Rect(r, c, r + w, c + w), side)

    def _place_on(self, state: _RoomState, category: str) -> bool:
        """On a surface the data puts this category on; False when it should stand on its own."""
        weights = self.stats[state.room.kind].objects.get(category)
        on = weights.on if weights else {}
        present = {p.category for p in state.placed if p.category in _SURFACES and not p.on_surface}
        if _PREFERRED_SURFACE.get(category) in present:
            on = {_PREFERRED_SURFACE[category]: 1.0}
        choices = {k: v for k, v in on.items() if k in present}
        standalone = sum(v for k, v in on.items() if k not in _SURFACES)
        if category not in _SURFACE_ONLY and self.rng.random() * (standalone + sum(choices.values())) < standalone:
            return False
        if not choices:
            if category not in _SURFACE_ONLY or not present:
                return False
            choices = {k: 1.0 for k in present}
        keys = sorted(choices)
        p = np.array([choices[k] for k in keys])
        long_c, short_c = self._size(state.room.kind, category)
        located = self._room_nav(state)
        for _ in range(4):
            surface = keys[int(self.rng.choice(len(keys), p=p / p.sum()))]
            hosts = [q for q in state.placed if q.category == surface and not q.on_surface]
            item = self._inside(hosts[int(self.rng.integers(len(hosts)))], long_c, short_c, category)
            if _within_reach(located, item.rect) and self._try(state, item):
                return True
        return False

    def _try(self, state: _RoomState, cand: _Placed) -> bool:
        rect = cand.rect
        if cand.on_surface:
            if self.on_top[rect.slices].any():
                return False
            self.on_top[rect.slices] = True
            state.placed.append(cand)
            return True
        if not state.room.interior.contains(rect):
            return False
        if self.blocked[rect.slices].any() or self.reserved[rect.slices].any():
            return False
        self.blocked[rect.slices] = True
        self.checks_left -= 1
        if self._room_ok(state, cand):
            state.placed.append(cand)
            return True
        self.blocked[rect.slices] = False
        return False

    def _room_nav(self, state: _RoomState) -> tuple[np.ndarray, tuple[int, int]]:
        """The navmesh of one room and its doorways (a crop of the house), and the crop's offset."""
        g = state.room.interior.grown(_INTERIOR_WALL + 2 * _RADIUS)
        H, W = self.blocked.shape
        box = Rect(max(g.r0, 0), max(g.c0, 0), min(g.r1, H), min(g.c1, W))
        nav = _erode(~self.blocked[box.slices])
        mask = np.zeros_like(nav)
        for c in (state.room.interior, *(d.cells for d in state.doors)):
            mask[c.r0 - box.r0 : c.r1 - box.r0, c.c0 - box.c0 : c.c1 - box.c0] = True
        return nav & mask, (box.r0, box.c0)

    def _room_ok(self, state: _RoomState, cand: _Placed) -> bool:
        """One navmesh piece through every door, and every floor object within reach of it."""
        located = self._room_nav(state)
        nav, (r0, c0) = located
        if ndi.label(nav)[1] != 1:
            return False
        for d in state.doors:
            c = d.cells
            if not nav[(c.r0 + c.r1) // 2 - r0, (c.c0 + c.c1) // 2 - c0]:
                return False
        return all(_within_reach(located, p.rect) for p in (*state.placed, cand))


def _erode(free: np.ndarray) -> np.ndarray:
    """Free floor eroded by the agent radius (a disk, outside the array counts as blocked)."""
    kernel = disk(_RADIUS).astype(np.uint8)
    out = cv2.erode(free.astype(np.uint8), kernel, borderType=cv2.BORDER_CONSTANT, borderValue=0)
    return out.astype(bool)


def _within_reach(located: tuple[np.ndarray, tuple[int, int]], rect: Rect) -> bool:
    """Whether some navmesh cell lies within ``_REACH`` of the rectangle."""
    nav, (r0, c0) = located
    reach = int(_REACH / _RES)
    rr = np.arange(max(rect.r0 - reach, r0), min(rect.r1 + reach, r0 + nav.shape[0]))
    cc = np.arange(max(rect.c0 - reach, c0), min(rect.c1 + reach, c0 + nav.shape[1]))
    if rr.size == 0 or cc.size == 0:
        return False
    dr = np.maximum(np.maximum(rect.r0 - rr, rr - (rect.r1 - 1)), 0)
    dc = np.maximum(np.maximum(rect.c0 - cc, cc - (rect.c1 - 1)), 0)
    near = dr[:, None] ** 2 + dc[None, :] ** 2 <= reach * reach
    return bool((near & nav[rr[0] - r0 : rr[-1] - r0 + 1, cc[0] - c0 : cc[-1] - c0 + 1]).any())


def _against(box: Rect, side: int, start: int, along: int, depth: int) -> Rect:
    if side == 0:
        return Rect(box.r0, start, box.r0 + depth, start + along)
    if side == 1:
        return Rect(box.r1 - depth, start, box.r1, start + along)
    if side == 2:
        return Rect(start, box.c0, start + along, box.c0 + depth)
    return Rect(start, box.c1 - depth, start + along, box.c1)


def _any_sizes(stats: dict[str, RoomStats], category: str) -> tuple[tuple[float, float, float], ...]:
    pool = tuple(s for room in stats.values() if category in room.objects for s in room.objects[category].sizes)
    if not pool:
        raise L3MVNError(
            f"room contents hold no sizes for {category!r}; rebuild them: python -m l3mvn.world.scenes.room_contents"
        )
    return pool


def _finish(seed: int, layout: _Layout, placed: list[_Placed]) -> ProceduralHouse:
    objects = np.zeros((len(PROCEDURAL_CATEGORIES), *layout.floor.shape), dtype=bool)
    for p in placed:
        objects[PROCEDURAL_CATEGORIES.index(p.category)][p.rect.slices] = True
    navigable = _erode(layout.floor & ~objects.any(axis=0))
    scene = SceneMap(
        name=f"procedural-{seed:04d}",
        floor=0,
        categories=PROCEDURAL_CATEGORIES,
        navigable=navigable,
        objects=objects,
        resolution_m=_RES,
    )
    return ProceduralHouse(scene, tuple(layout.rooms), tuple(layout.doors), layout.floor)

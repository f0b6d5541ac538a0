"""A SceneMap extruded to a triangle mesh: floor, walls, ceiling and one prism per object footprint.

The map is the only truth we have, so the world is its most literal 3D reading: free floor stays
floor, object footprints become boxes at category-typical heights, everything else is wall. Two map
artefacts are repaired first, because the camera would otherwise show them to the agent:

* the navmesh is eroded around objects too, leaving a thin non-free ring between each footprint and
  the free floor; read literally it would wall every object in. A non-free cell lying on a gap of at
  most ``_MARGIN_GAP_CELLS`` between an object and the free floor is that ring and becomes floor. A real
  wall behind an object is further from the free floor (the navmesh is eroded from walls too), so it
  survives;
* an object farther from the free floor than that ring stands in floor the navmesh lost (a bathroom
  too narrow for it, a niche): a door-wide opening between the object and its nearest floor becomes
  floor (``view_corridors``), so the object shows from the house as it would through a door;
* footprints of two categories may overlap: the smaller instance keeps the shared cells, and another
  object standing between a goal object and its floor is cut below the goal's top
  (``_object_boxes``), so no goal object is erased or hidden behind taller furniture;
* wall components smaller than ``_SPECK_MAX_M2`` are rasterisation specks and become floor, while a
  one-cell wall line between rooms is long and stays. Compact free-standing components up to
  ``_FURNITURE_MAX_M2`` are unlabelled furniture (a kitchen island, a cabinet) and are built to table
  height, below the camera.

Meshing emits only boundary faces and merges them into runs (walls) and rectangles (tops), so a
500x700-cell Gibson floor stays at tens of thousands of triangles. The floor is triangles 0 and 1.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass

import numpy as np
from scipy import ndimage as ndi

from l3mvn.core.categories import GOAL_CATEGORIES
from l3mvn.core.config import SimConfig
from l3mvn.world.scenes.scan import ScanFloor
from l3mvn.world.scenes.scene import SceneMap

_MARGIN_GAP_CELLS = 3.2  # d(object) + d(free) of a ring cell; a 2-cell ring scores 3, a wall >= 4
# An object farther than the ring from free floor (a plant in a corner, a tv in a niche, a toilet in a
# bathroom whose floor the navmesh lost) gets a view corridor: the cells between it and its nearest free
# floor, up to this far (farther: left as is), and a door-wide passage along it. A slit only as wide
# as the eroded margin shows such an object from a few cells of the house only: the agent can map the
# whole floor around it and never see it.
_CORRIDOR_MAX_CELLS = 20
_CORRIDOR_SLACK_CELLS = 1.5
_CORRIDOR_HALF_WIDTH_CELLS = 8  # a 0.8 m door
# An object standing in a goal object's view corridor is cut to this far below the goal's top, and
# never lower than this above its own base (a tv stays a tv on its stand).
_OCCLUDER_BELOW_M = 0.3
_OCCLUDER_MIN_M = 0.2
_SPECK_MAX_M2 = 0.04  # smaller than a 20 x 20 cm pillar
_FURNITURE_MAX_M2 = 1.5
_FURNITURE_MIN_THICKNESS_M = 0.25  # thinner free-standing pieces are partition walls, kept full height
# Unlabelled furniture is built to table height, the height at which an item with no labelled
# furniture below it stands. At 0.9 m (a counter) it would rise above the 0.88 m camera and hide every
# object behind it: a toilet behind a bathroom partition would be mapped around and never seen.
_ITEM_SUPPORT_M = 0.75
_FURNITURE_HEIGHT_M = _ITEM_SUPPORT_M

_WALL_RGB = (0.86, 0.83, 0.76)
_FLOOR_RGB = (0.62, 0.52, 0.42)
_CEILING_RGB = (0.93, 0.93, 0.91)
_FURNITURE_RGB = (0.55, 0.42, 0.30)
_STAND_RGB = (0.30, 0.28, 0.27)


@dataclass(frozen=True)
class _Profile:
    """How a category stands: ``floor`` boxes span [base, base + height] (a stand fills [0, base]),
    ``top`` items sit on whatever is below them, ``wall`` items hang at [base, base + height]."""

    kind: str
    height: float
    base: float = 0.0
    rgb: tuple[float, float, float] = (0.6, 0.6, 0.6)


_PROFILES: dict[str, _Profile] = {
    # The 15 Gibson / SemExp categories.
    "chair": _Profile("floor", 0.9, rgb=(0.65, 0.38, 0.20)),
    "couch": _Profile("floor", 0.8, rgb=(0.30, 0.42, 0.62)),
    "potted plant": _Profile("floor", 0.8, rgb=(0.25, 0.58, 0.25)),
    "bed": _Profile("floor", 0.6, rgb=(0.88, 0.88, 0.95)),
    "toilet": _Profile("floor", 0.8, rgb=(0.97, 0.97, 0.97)),
    "tv": _Profile("floor", 0.6, base=0.5, rgb=(0.10, 0.10, 0.12)),
    "dining table": _Profile("floor", 0.75, rgb=(0.50, 0.33, 0.18)),
    "oven": _Profile("floor", 0.9, rgb=(0.45, 0.45, 0.48)),
    "sink": _Profile("floor", 0.9, rgb=(0.80, 0.85, 0.88)),
    "refrigerator": _Profile("floor", 1.8, rgb=(0.90, 0.90, 0.92)),
    "book": _Profile("top", 0.22, rgb=(0.70, 0.20, 0.20)),
    "clock": _Profile("wall", 0.3, base=1.45, rgb=(0.95, 0.85, 0.40)),
    "vase": _Profile("top", 0.3, rgb=(0.30, 0.55, 0.75)),
    "cup": _Profile("top", 0.12, rgb=(0.95, 0.95, 0.85)),
    "bottle": _Profile("top", 0.28, rgb=(0.20, 0.60, 0.45)),
    # The richer vocabulary of procedural houses.
    "sofa": _Profile("floor", 0.8, rgb=(0.30, 0.42, 0.62)),
    "armchair": _Profile("floor", 0.9, rgb=(0.55, 0.30, 0.35)),
    "stool": _Profile("floor", 0.65, rgb=(0.60, 0.40, 0.22)),
    "bench": _Profile("floor", 0.45, rgb=(0.55, 0.38, 0.22)),
    "table": _Profile("floor", 0.75, rgb=(0.50, 0.33, 0.18)),
    "coffee table": _Profile("floor", 0.45, rgb=(0.45, 0.30, 0.18)),
    "desk": _Profile("floor", 0.75, rgb=(0.58, 0.42, 0.26)),
    "nightstand": _Profile("floor", 0.55, rgb=(0.52, 0.36, 0.22)),
    "dresser": _Profile("floor", 1.0, rgb=(0.48, 0.32, 0.20)),
    "cabinet": _Profile("floor", 0.9, rgb=(0.62, 0.50, 0.36)),
    "counter": _Profile("floor", 0.9, rgb=(0.75, 0.72, 0.66)),
    "wardrobe": _Profile("floor", 2.0, rgb=(0.45, 0.30, 0.20)),
    "bookshelf": _Profile("floor", 1.8, rgb=(0.42, 0.28, 0.16)),
    "shelf": _Profile("floor", 1.6, rgb=(0.42, 0.28, 0.16)),
    "bathtub": _Profile("floor", 0.55, rgb=(0.95, 0.95, 0.97)),
    "shower": _Profile("floor", 2.0, rgb=(0.75, 0.85, 0.90)),
    "washing machine": _Profile("floor", 0.85, rgb=(0.92, 0.92, 0.94)),
    "dishwasher": _Profile("floor", 0.85, rgb=(0.80, 0.80, 0.82)),
    "stove": _Profile("floor", 0.9, rgb=(0.45, 0.45, 0.48)),
    "fireplace": _Profile("floor", 1.1, rgb=(0.55, 0.30, 0.25)),
    "piano": _Profile("floor", 1.0, rgb=(0.08, 0.08, 0.08)),
    "lamp": _Profile("floor", 1.5, rgb=(0.95, 0.90, 0.70)),
    "plant": _Profile("floor", 0.8, rgb=(0.25, 0.58, 0.25)),
    "rug": _Profile("floor", 0.02, rgb=(0.60, 0.25, 0.25)),
    "laptop": _Profile("top", 0.03, rgb=(0.25, 0.25, 0.28)),
    "monitor": _Profile("top", 0.4, rgb=(0.10, 0.10, 0.12)),
    "microwave": _Profile("top", 0.3, rgb=(0.30, 0.30, 0.32)),
    "towel": _Profile("wall", 0.6, base=0.9, rgb=(0.85, 0.75, 0.60)),
    "mirror": _Profile("wall", 0.8, base=1.0, rgb=(0.75, 0.82, 0.88)),
    "picture": _Profile("wall", 0.5, base=1.3, rgb=(0.70, 0.55, 0.35)),
    "painting": _Profile("wall", 0.6, base=1.2, rgb=(0.70, 0.55, 0.35)),
}
_DEFAULT_PROFILE = _Profile("floor", 0.8)


@dataclass(frozen=True)
class World:
    """A triangle mesh in world metres (x = col * res, y = row * res, z up, floor at z = 0).

    ``tri_category`` is 0 for background (floor, wall, ceiling, unlabelled furniture) and k + 1 for
    ``scene.categories[k]``; ``tri_color`` is the unshaded base colour in [0, 1]; ``tri_normal`` the
    outward unit shading normal (for walls, that of the smoothed outline the cell staircase follows).
    ``walls`` / ``furniture`` are the (H, W) grids extruded full height / low.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    tri_category: np.ndarray
    tri_color: np.ndarray
    tri_normal: np.ndarray
    walls: np.ndarray
    furniture: np.ndarray

    @property
    def num_triangles(self) -> int:
        return int(self.triangles.shape[0])


def category_profile(name: str) -> _Profile:
    """Height and placement of a category; unknown names get a generic 0.8 m floor box."""
    key = name.strip().lower().replace("_", " ").replace("-", " ")
    if key in _PROFILES:
        return _PROFILES[key]
    return _Profile(_DEFAULT_PROFILE.kind, _DEFAULT_PROFILE.height, rgb=_name_rgb(key))


def build_world(scene: SceneMap, cfg: SimConfig, *, rooms_only: bool = False) -> World:
    """The scene's 3D world: a scan's own triangles, or the map extruded (see the module docstring).

    ``rooms_only`` lays floor and ceiling only where there is no wall, as a scan has them (the HM3D
    export: rays down through a wall or outside the house must find no floor); by default both span
    the whole grid, so a renderer never sees through a gap."""
    if isinstance(scene, ScanFloor) and scene.mesh is not None:
        return scan_world(scene)
    res = float(scene.resolution_m)
    top = float(cfg.wall_height_m)
    corridors = view_corridors(scene)
    walls, furniture = wall_grids(scene, corridors)
    mesh = _MeshBuilder(res)
    h, w = scene.shape
    if rooms_only:
        rooms = _rectangles(~walls) * res
        mesh._rects(rooms, 0.0, True, 0, _FLOOR_RGB)
        mesh._rects(rooms, top, False, 0, _CEILING_RGB)
    else:
        mesh.horizontal_quad(0.0, 0.0, w * res, h * res, 0.0, up=True, category=0, rgb=_FLOOR_RGB)
        mesh.horizontal_quad(0.0, 0.0, w * res, h * res, top, up=False, category=0, rgb=_CEILING_RGB)
    # Outside the grid counts as wall, so a free cell on the border is still closed in.
    mesh.prism(walls, 0.0, top, category=0, rgb=_WALL_RGB, outside_solid=True, tops=False, smooth=True)
    mesh.prism(
        furniture,
        0.0,
        min(_FURNITURE_HEIGHT_M, top),
        category=0,
        rgb=_FURNITURE_RGB,
        blocked=walls,
        smooth=True,
    )
    for mask, z0, z1, category, rgb in _object_boxes(scene, top, corridors):
        mesh.prism(mask, z0, z1, category=category, rgb=rgb, blocked=walls, bottoms=z0 > 0.0)
    return mesh.build(walls, furniture)


def scan_world(scene: ScanFloor) -> World:
    """A scan floor's triangles as they are (texture colour and category per triangle), shaded by
    their geometric normals; cells off the free floor count as walls for pose checks."""
    mesh = scene.mesh
    assert mesh is not None
    corners = mesh.vertices[mesh.triangles].astype(np.float64)
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    length = np.linalg.norm(normal, axis=1, keepdims=True)
    normal = np.where(length > 1e-12, normal / np.maximum(length, 1e-12), (0.0, 0.0, 1.0))
    return World(
        vertices=mesh.vertices,
        triangles=mesh.triangles,
        tri_category=mesh.tri_category,
        tri_color=mesh.tri_color,
        tri_normal=np.ascontiguousarray(normal, np.float32),
        walls=~scene.free & ~scene.object_any,
        furniture=np.zeros(scene.shape, bool),
    )


@dataclass(frozen=True, eq=False)
class Corridor:
    """The cells between one object instance and its nearest free floor (``cells``, in ``window``;
    the instance itself excluded) that must stay see-through for the object to show from that floor."""

    channel: int
    window: tuple[slice, slice]
    cells: np.ndarray


def wall_grids(scene: SceneMap, corridors: list[Corridor] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(walls, furniture): non-free, non-object cells cleaned of the object ring, view corridors and
    specks. ``corridors``: ``view_corridors(scene)`` when the caller has them already."""
    free, objects = scene.free, scene.object_any
    solid = ~free & ~objects
    d_obj = ndi.distance_transform_edt(~objects) if objects.any() else np.full(free.shape, np.inf)
    if free.any():
        d_free = ndi.distance_transform_edt(~free)
        solid &= d_free + d_obj > _MARGIN_GAP_CELLS
        for c in view_corridors(scene) if corridors is None else corridors:
            solid[c.window] &= ~c.cells
    labels, n = ndi.label(solid, structure=np.ones((3, 3), dtype=bool))
    if n == 0:
        return solid, np.zeros_like(solid)
    ids = np.arange(1, n + 1)
    cell_m2 = scene.resolution_m**2
    area = ndi.sum_labels(np.ones_like(solid, dtype=np.float64), labels, ids) * cell_m2
    thickness = 2.0 * ndi.maximum(ndi.distance_transform_edt(solid), labels, ids) * scene.resolution_m
    border = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
    on_border = np.isin(ids, border)
    speck = area < _SPECK_MAX_M2
    low = ~speck & ~on_border & (area <= _FURNITURE_MAX_M2) & (thickness >= _FURNITURE_MIN_THICKNESS_M)
    kind = np.zeros(n + 1, dtype=np.int8)  # 0 floor, 1 wall, 2 furniture
    kind[1:] = np.where(speck, 0, np.where(low, 2, 1))
    grid = kind[labels]
    return grid == 1, grid == 2


def view_corridors(scene: SceneMap) -> list[Corridor]:
    """Never wall in or hide an object: for each footprint (per category, so a plant beside a couch
    counts on its own) whose nearest free floor lies beyond the ring, two sets of cells must stay
    see-through: the band d(footprint) + d(free) <= that distance + slack (the navmesh's eroded
    margin between the two) and, widened to a door, the room the navmesh lost between them (a
    bathroom around its toilet). Real walls are thin lines; solid this thick next to an object is
    floor too narrow for the navmesh or clutter, so ``wall_grids`` opens it; another object standing
    in it (a sink in front of a plant) is cut down by ``_object_boxes``. A wall behind the object
    (seen from the floor) or farther than half the gap from both stays."""
    free = scene.free
    out: list[Corridor] = []
    if not free.any():
        return out
    d_free, nearest = ndi.distance_transform_edt(~free, return_indices=True)
    w = _CORRIDOR_HALF_WIDTH_CELLS
    shape = free.shape
    for k, channel in enumerate(scene.objects):
        if not channel.any():
            continue
        labels, _ = ndi.label(channel, structure=np.ones((3, 3), dtype=bool))
        for n, box in enumerate(ndi.find_objects(labels), start=1):
            if box is None:
                continue
            member = labels[box] == n
            gap = float(d_free[box][member].min())
            if gap <= 2.0 or gap > _CORRIDOR_MAX_CELLS:  # 2 cells: the plain ring already opens it
                continue
            pad = int(np.ceil(gap + 2 * w)) + 1
            r0, c0 = max(box[0].start - pad, 0), max(box[1].start - pad, 0)
            r1, c1 = min(box[0].stop + pad, shape[0]), min(box[1].stop + pad, shape[1])
            own = labels[r0:r1, c0:c1] == n
            d_obj = ndi.distance_transform_edt(~own)
            d_fl = d_free[r0:r1, c0:c1]
            band = d_obj + d_fl <= gap + _CORRIDOR_SLACK_CELLS
            # The lost room: the same band with a door's slack (its half-width at the middle is
            # sqrt(slack (2 gap + slack)) / 2), kept to cells within gap / 2 of the footprint or of the
            # floor (every cell of the shortest line is) and not behind the footprint seen from the floor.
            slack = max(_CORRIDOR_SLACK_CELLS, float(np.sqrt(gap * gap + 4 * w * w) - gap))
            i = int(np.argmin(np.where(member, d_free[box], np.inf)))
            edge = np.array(np.unravel_index(i, member.shape)) + (box[0].start, box[1].start)
            v = nearest[:, edge[0], edge[1]] - (np.argwhere(member).mean(axis=0) + (box[0].start, box[1].start))
            rows, cols = np.mgrid[r0:r1, c0:c1]
            ahead = (rows - edge[0]) * v[0] + (cols - edge[1]) * v[1] >= -float(np.hypot(*v))
            passage = (d_obj + d_fl <= gap + slack) & (np.minimum(d_obj, d_fl) <= gap / 2) & ahead
            out.append(Corridor(k, (slice(r0, r1), slice(c0, c1)), (band | passage) & ~own))
    return out


def _object_boxes(scene: SceneMap, ceiling: float, corridors: list[Corridor]):
    """Yield (mask, z0, z1, category_id, rgb) boxes, one category per cell and layer.

    Floor-standing footprints that overlap give the cell to the smaller instance: a chair tucked
    under a table keeps its whole seat, and a toilet drawn inside an oven's footprint stays a toilet
    instead of vanishing (tallest-wins would erase it: no pose would ever see it).
    Another object standing in a goal object's view corridor is cut to ``_OCCLUDER_BELOW_M`` under
    the goal's top (never below its own stand), so a plant behind a sink shows over it. Items
    stack on the winner's top, except on a goal object or in its corridor (a vase drawn over a plant
    would stack on it and ring it, burying it); wall items hang above both.
    """
    profiles = [category_profile(c) for c in scene.categories]
    shape = scene.shape
    goal_ids = {scene.categories.index(g) for g in GOAL_CATEGORIES if g in scene.categories}
    clear = np.zeros(shape, dtype=bool)  # goal footprints and their view corridors: no items there
    for k in goal_ids:
        clear |= scene.objects[k]
    for c in corridors:
        if c.channel in goal_ids:
            clear[c.window] |= c.cells
    floor_top = np.zeros(shape, dtype=np.float64)
    floor_ids = [k for k, p in enumerate(profiles) if p.kind == "floor" and scene.objects[k].any()]
    if floor_ids:
        size = np.stack([_instance_areas(scene.objects[k]) for k in floor_ids])
        winner = np.argmin(size, axis=0)
        has = np.isfinite(size.min(axis=0))
        tops = np.array([min(profiles[k].base + profiles[k].height, ceiling) for k in floor_ids])
        bases = np.array([profiles[k].base for k in floor_ids])
        top = np.where(has, tops[winner], 0.0)
        cap = np.full(shape, np.inf)
        for c in corridors:
            if c.channel not in goal_ids:
                continue
            p = profiles[c.channel]
            view = c.cells & has[c.window]
            if c.channel in floor_ids:  # cells its own category won are the goal object's, not in front
                view &= winner[c.window] != floor_ids.index(c.channel)
            cap[c.window][view] = np.minimum(cap[c.window][view], p.base + p.height - _OCCLUDER_BELOW_M)
        top = np.minimum(top, np.maximum(cap, bases[winner] + _OCCLUDER_MIN_M))
        for i, k in enumerate(floor_ids):
            mine = has & (winner == i)
            if not mine.any():
                continue
            p = profiles[k]
            for z1 in np.unique(top[mine]):
                mask = mine & (top == z1)
                if p.base > 0.0:
                    yield mask, 0.0, p.base, 0, _STAND_RGB
                yield mask, p.base, float(z1), k + 1, p.rgb
                floor_top[mask] = z1
    stack_top = floor_top.copy()
    for kind in ("top", "wall"):
        ids = [k for k, p in enumerate(profiles) if p.kind == kind and scene.objects[k].any()]
        if not ids:
            continue
        heights = np.array([profiles[k].height for k in ids])
        drawn = scene.objects[ids] & ~clear if kind == "top" else scene.objects[ids]
        score = np.where(drawn, heights[:, None, None], -1.0)
        winner = np.argmax(score, axis=0)
        has = score.max(axis=0) >= 0.0
        for i, k in enumerate(ids):
            mask = has & (winner == i)
            if not mask.any():
                continue
            p = profiles[k]
            if kind == "top":
                unsupported = mask & (floor_top <= 0.0)
                if unsupported.any():
                    yield unsupported, 0.0, _ITEM_SUPPORT_M, 0, _FURNITURE_RGB
                base = np.where(unsupported, _ITEM_SUPPORT_M, stack_top)
            else:
                base = np.maximum(p.base, stack_top)
            for z0 in np.unique(base[mask]):
                part = mask & (base == z0)
                z1 = min(float(z0) + p.height, ceiling)
                if z1 > z0:
                    yield part, float(z0), z1, k + 1, p.rgb
                    stack_top[part] = z1


def _instance_areas(mask: np.ndarray) -> np.ndarray:
    """Per cell, the area (cells) of the 8-connected instance it belongs to; inf off the mask."""
    labels, _ = ndi.label(mask, structure=np.ones((3, 3), dtype=bool))
    area = np.bincount(labels.ravel()).astype(np.float64)
    area[0] = np.inf
    return area[labels]


class _MeshBuilder:
    """Accumulates axis-aligned quads (4 own vertices, 2 triangles each) in world metres."""

    def __init__(self, res: float) -> None:
        self.res = res
        self._quads: list[np.ndarray] = []  # (n, 4, 3) corners, counter-clockwise seen from outside
        self._normals: list[np.ndarray] = []
        self._cats: list[np.ndarray] = []
        self._rgbs: list[np.ndarray] = []

    def _add(self, corners: np.ndarray, normal, category: int, rgb) -> None:
        n = corners.shape[0]
        if n == 0:
            return
        self._quads.append(corners.astype(np.float32))
        self._normals.append(np.broadcast_to(np.asarray(normal, np.float32), (n, 3)))
        self._cats.append(np.full(n, category, np.int32))
        self._rgbs.append(np.broadcast_to(np.asarray(rgb, np.float32), (n, 3)))

    def horizontal_quad(self, x0, y0, x1, y1, z, up: bool, category: int, rgb) -> None:
        self._rects(np.array([[x0, y0, x1, y1]], np.float64), z, up, category, rgb)

    def _rects(self, xyxy: np.ndarray, z: float, up: bool, category: int, rgb) -> None:
        x0, y0, x1, y1 = xyxy.T
        zz = np.full_like(x0, z)
        a, b, c, d = (np.stack(p, axis=1) for p in ((x0, y0, zz), (x1, y0, zz), (x1, y1, zz), (x0, y1, zz)))
        corners = np.stack([a, b, c, d] if up else [a, d, c, b], axis=1)
        self._add(corners, (0.0, 0.0, 1.0 if up else -1.0), category, rgb)

    def prism(
        self,
        mask: np.ndarray,
        z0: float,
        z1: float,
        category: int,
        rgb,
        blocked: np.ndarray | None = None,
        outside_solid: bool = False,
        tops: bool = True,
        bottoms: bool = False,
        smooth: bool = False,
    ) -> None:
        """Boundary faces of the cells in ``mask`` extruded over [z0, z1]. Side faces towards cells in
        ``blocked`` (taller solids) are hidden and skipped. ``smooth`` shades each side face with the
        normal of the blurred outline, so a staircase of cells reads as the slanted wall it stands for
        instead of stripes of alternating brightness."""
        if not mask.any() or z1 <= z0:
            return
        res = self.res
        cover = mask if blocked is None else (mask | blocked)
        padded = np.pad(cover, 1, constant_values=outside_solid)
        m = np.pad(mask, 1, constant_values=False)
        inner = (slice(1, -1), slice(1, -1))
        field = _outline_normals(mask) if smooth else None
        # x-facing faces: runs along rows (y) for each column boundary.
        for dc, sign in ((1, 1.0), (-1, -1.0)):
            faces = m[inner] & ~padded[1:-1, 1 + dc : padded.shape[1] - 1 + dc]
            col, r0, r1 = _runs(faces.T)
            x = (col + (1 if dc > 0 else 0)) * res
            ya, yb = r0 * res, r1 * res
            if sign > 0:
                pts = ((x, ya, z0), (x, yb, z0), (x, yb, z1), (x, ya, z1))
            else:
                pts = ((x, yb, z0), (x, ya, z0), (x, ya, z1), (x, yb, z1))
            normal = _side_normal(field, (r0 + r1 - 1) // 2, col + dc, (sign, 0.0))
            self._add(_corners(pts), normal, category, rgb)
        # y-facing faces: runs along columns (x) for each row boundary.
        for dr, sign in ((1, 1.0), (-1, -1.0)):
            faces = m[inner] & ~padded[1 + dr : padded.shape[0] - 1 + dr, 1:-1]
            row, c0, c1 = _runs(faces)
            y = (row + (1 if dr > 0 else 0)) * res
            xa, xb = c0 * res, c1 * res
            if sign > 0:
                pts = ((xb, y, z0), (xa, y, z0), (xa, y, z1), (xb, y, z1))
            else:
                pts = ((xa, y, z0), (xb, y, z0), (xb, y, z1), (xa, y, z1))
            normal = _side_normal(field, row + dr, (c0 + c1 - 1) // 2, (0.0, sign))
            self._add(_corners(pts), normal, category, rgb)
        if tops or bottoms:
            rects = _rectangles(mask) * res
            if tops:
                self._rects(rects, z1, True, category, rgb)
            if bottoms:
                self._rects(rects, z0, False, category, rgb)

    def build(self, walls: np.ndarray, furniture: np.ndarray) -> World:
        quads = np.concatenate(self._quads)
        n = quads.shape[0]
        vertices = quads.reshape(-1, 3)
        base = (np.arange(n, dtype=np.int32) * 4)[:, None]
        triangles = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]], axis=1).reshape(-1, 3)
        twice = lambda parts: np.repeat(np.concatenate(parts), 2, axis=0)  # noqa: E731
        return World(
            vertices=np.ascontiguousarray(vertices, np.float32),
            triangles=np.ascontiguousarray(triangles, np.int32),
            tri_category=twice(self._cats).astype(np.int32),
            tri_color=np.ascontiguousarray(twice(self._rgbs), np.float32),
            tri_normal=np.ascontiguousarray(twice(self._normals), np.float32),
            walls=walls,
            furniture=furniture,
        )


def _outline_normals(mask: np.ndarray) -> np.ndarray:
    """(H, W, 2) unit outward normals (x, y) of ``mask``'s outline blurred over ~3 cells, so that
    single-cell jaggies vanish."""
    blurred = ndi.gaussian_filter(mask.astype(np.float32), sigma=3.0, mode="nearest")
    gy, gx = np.gradient(blurred)
    normals = -np.stack([gx, gy], axis=-1)
    norm = np.linalg.norm(normals, axis=-1, keepdims=True)
    return np.where(norm > 1e-6, normals / np.maximum(norm, 1e-6), 0.0).astype(np.float32)


def _side_normal(field: np.ndarray | None, row: np.ndarray, col: np.ndarray, axis: tuple[float, float]):
    """Per-face (n, 3) shading normals: the outline normal at the face's outside cell, or ``axis``
    where there is no field or the outline normal points away from the face."""
    if field is None:
        return (axis[0], axis[1], 0.0)
    h, w = field.shape[:2]
    sampled = field[np.clip(row, 0, h - 1), np.clip(col, 0, w - 1)]
    agree = sampled @ np.asarray(axis, np.float32) > 0.0
    xy = np.where(agree[:, None], sampled, np.asarray(axis, np.float32))
    return np.concatenate([xy, np.zeros((xy.shape[0], 1), np.float32)], axis=1)


def _corners(pts) -> np.ndarray:
    """Four corner points (each a tuple of scalars or (n,) arrays) -> (n, 4, 3)."""
    n = len(pts[0][0])
    return np.stack([np.stack([np.broadcast_to(v, n) for v in p], axis=1) for p in pts], axis=1)


def _runs(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Maximal runs of True along axis 1: (line index, start, end exclusive)."""
    padded = np.pad(faces, ((0, 0), (1, 1)), constant_values=False).astype(np.int8)
    d = np.diff(padded, axis=1)
    line, start = np.nonzero(d == 1)
    _, end = np.nonzero(d == -1)
    return line, start, end


def _rectangles(mask: np.ndarray) -> np.ndarray:
    """Cover ``mask`` with rectangles (x0, y0, x1, y1) in cells: row runs, merged down identical rows."""
    row, c0, c1 = _runs(mask)
    if row.size == 0:
        return np.zeros((0, 4))
    order = np.lexsort((row, c1, c0))
    row, c0, c1 = row[order], c0[order], c1[order]
    new = np.ones(row.size, dtype=bool)
    new[1:] = (c0[1:] != c0[:-1]) | (c1[1:] != c1[:-1]) | (row[1:] != row[:-1] + 1)
    first = np.nonzero(new)[0]
    last = np.r_[first[1:], row.size] - 1
    return np.stack([c0[first], row[first], c1[first], row[last] + 1], axis=1).astype(np.float64)


def _name_rgb(name: str) -> tuple[float, float, float]:
    """A muted, stable colour for a category we have no material for."""
    h = zlib.crc32(name.encode())
    return tuple(0.35 + 0.45 * ((h >> s) & 0xFF) / 255.0 for s in (0, 8, 16))  # type: ignore[return-value]

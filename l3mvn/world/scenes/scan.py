"""A scanned house (HM3D's layout: a GLB stage, a ``.semantic.glb`` and its ``.semantic.txt``) as floors.

The triangles themselves become the rendered world (``ScanFloor.mesh``: a colour per triangle sampled
from the texture at its UVs, a category per triangle from the semantic mesh), so frames show the
scan, not a reconstruction of it. The ground truth the task needs is derived from the same mesh:

* floors: downward rays through the house; every horizontal, upward-facing surface with room for
  the agent's body above it is standing room, and the heights holding most of it are the floors
  (two heights closer than ``STOREY_MIN_M`` are a floor and its furniture);
* navigable grid per floor: standing room within ``max_climb_m`` of the floor, minus every cell a
  triangle crosses between the climb height and the body's height (walls are vertical: rays never
  hit them, but their footprint does), eroded by the agent radius, without islands (a hollow box's
  inside) smaller than ``ISLAND_MIN_M2``;
* object footprints per floor: the footprints of each category's triangles on that floor.

Habitat's frame is Y-up (``[x, y (up), z]``); ours puts habitat ``x`` on rows and ``z`` on columns,
as SemExp's maps do (``SceneMap.pose_from_habitat``), and every floor's mesh at z = 0.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TypeVar

import numba as nb
import numpy as np
from scipy import ndimage as ndi

from l3mvn.core.config import SimConfig
from l3mvn.core.errors import L3MVNError
from l3mvn.core.writing import write_file
from l3mvn.world.scenes.categories import SCAN_CATEGORIES, raw_category
from l3mvn.world.scenes.scene import SceneMap

GRID_M = 0.05  # ground-truth cell, as SemExp's maps
RAY_TOP_MARGIN_M = 1.0  # rays start this far above the highest vertex
FLOOR_MIN_AREA_M2 = 2.0  # less standing room than this at one height is a landing or a table, not a floor
STOREY_MIN_M = 1.5  # floor heights closer than this are one floor (the other is its furniture)
HORIZONTAL_MIN_NY = 0.7  # a surface within ~45 degrees of level is something to stand on
ISLAND_MIN_M2 = 1.0  # navigable pieces smaller than this are inside furniture or on it, not rooms
BELOW_FLOOR_M = 1.0  # a floor's world keeps geometry this far below it (stairs down), and all up to the next
GRID_MARGIN_M = 0.5
_UNKNOWN_RGB = (0.6, 0.6, 0.6)  # a material whose texture cannot be decoded (Basis Universal)
_Floor = TypeVar("_Floor", bound=SceneMap)


@dataclass(frozen=True, eq=False)
class ScanMesh:
    """One floor's triangles in our frame (metres, floor at z = 0): ``tri_category`` is 0 for
    background and k + 1 for ``categories[k]``; ``tri_color`` the texture colour in [0, 1]."""

    vertices: np.ndarray
    triangles: np.ndarray
    tri_category: np.ndarray
    tri_color: np.ndarray


@dataclass(frozen=True, eq=False)
class ScanFloor(SceneMap):
    """A SceneMap derived from a scan, with the scan's own triangles and the episode file's view
    points (``view_points[category]``: (n, 2) world x, y of the agent positions from which an
    instance is in view, HM3D's success targets)."""

    mesh: ScanMesh | None = None
    view_points: dict[str, np.ndarray] = field(default_factory=dict)
    source: str = ""


@dataclass(frozen=True)
class ScanFiles:
    """Where one scene's files are: the stage GLB, and HM3D's semantic mesh and table (optional)."""

    stage: Path
    semantic_glb: Path | None
    semantic_txt: Path | None
    up: tuple[float, float, float] = (0.0, 1.0, 0.0)


@dataclass(frozen=True)
class SemanticObject:
    """A line of ``.semantic.txt``: ``id,HEXCOLOR,"name",region``."""

    object_id: int
    rgb: int  # 0xRRGGBB
    name: str
    region: int


_SEMANTIC_LINE = re.compile(r'^\s*(\d+)\s*,\s*([0-9A-Fa-f]{6})\s*,\s*"(.*)"\s*,\s*(-?\d+)\s*$')


def read_semantic_txt(path: str | Path) -> dict[int, SemanticObject]:
    """HM3D's annotation table (a title line, then one object per line); a malformed line is an error
    naming its number."""
    path = Path(path)
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise L3MVNError(f"cannot read {path} ({getattr(exc, 'strerror', None) or exc})") from None
    objects: dict[int, SemanticObject] = {}
    for number, line in enumerate(lines, start=1):
        if not line.strip() or (number == 1 and not _SEMANTIC_LINE.match(line)):
            continue  # "HM3D Semantic Annotations"
        m = _SEMANTIC_LINE.match(line)
        if m is None:
            raise L3MVNError(f'{path}:{number}: expected id,HEXCOLOR,"name",region, got {line[:80]!r}')
        oid = int(m.group(1))
        if oid in objects:
            raise L3MVNError(f"{path}:{number}: object id {oid} appears twice")
        objects[oid] = SemanticObject(oid, int(m.group(2), 16), m.group(3), int(m.group(4)))
    return objects


def write_semantic_txt(path: str | Path, objects: list[SemanticObject]) -> None:
    lines = ["HM3D Semantic Annotations"]
    lines += [f'{o.object_id},{o.rgb:06X},"{o.name}",{o.region}' for o in objects]
    write_file(path, "\n".join(lines) + "\n", "semantic table")


def scene_up_axis(config: Path | None) -> tuple[float, float, float]:
    """The stage's up axis from a ``*.scene_dataset_config.json`` (HM3D: Y, MP3D: Z); Y without one."""
    if config is None:
        return (0.0, 1.0, 0.0)
    try:
        data = json.loads(config.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise L3MVNError(f"{config} is not a readable scene dataset config ({exc})") from None
    stages = data.get("stages") if isinstance(data, dict) else None
    defaults = stages.get("default_attributes") if isinstance(stages, dict) else None
    up = defaults.get("up", [0, 1, 0]) if isinstance(defaults, dict) else [0, 1, 0]
    if not (isinstance(up, list) and len(up) == 3 and all(isinstance(v, (int, float)) for v in up)):
        raise L3MVNError(f"{config}: stages.default_attributes.up must be 3 numbers, got {up!r}")
    if [float(v) for v in up] not in ([0.0, 1.0, 0.0], [0.0, 0.0, 1.0]):
        raise L3MVNError(f"{config}: up axis {up} is not supported; valid: [0, 1, 0] (HM3D) or [0, 0, 1] (MP3D)")
    return tuple(float(v) for v in up)  # type: ignore[return-value]


# --- mesh reading -----------------------------------------------------------------------------


@dataclass
class _Mesh:
    vertices: np.ndarray  # (n, 3) float64, habitat frame (Y up)
    faces: np.ndarray  # (m, 3) int64
    face_rgb: np.ndarray  # (m, 3) uint8


def _trimesh():
    try:
        import trimesh
    except ImportError:
        raise L3MVNError("loading scans needs trimesh and embreex: pip install trimesh embreex") from None
    return trimesh


def _read_glb(path: Path, up: tuple[float, float, float], *, ids: bool = False) -> _Mesh:
    """Every triangle of a GLB in its scene graph's placement, with a colour per triangle: the
    texture (times the material's base colour) averaged over four points inside the triangle, or
    with ``ids`` (a semantic mesh, whose colours are object ids) the exact colour at its centre."""
    trimesh = _trimesh()
    try:
        scene = trimesh.load(str(path), force="scene", process=False)
    except Exception as exc:  # trimesh raises anything from a malformed file: make it one line
        raise L3MVNError(f"{path} is not a readable GLB ({type(exc).__name__}: {str(exc)[:120]})") from None
    parts_v, parts_f, parts_c, offset = [], [], [], 0
    for node in scene.graph.nodes_geometry:
        transform, name = scene.graph[node]
        mesh = scene.geometry.get(name)
        if mesh is None or not hasattr(mesh, "faces") or len(mesh.faces) == 0:
            continue
        vertices = trimesh.transform_points(np.asarray(mesh.vertices, np.float64), transform)
        faces = np.asarray(mesh.faces, np.int64)
        parts_v.append(vertices)
        parts_f.append(faces + offset)
        parts_c.append(_face_rgb(mesh, faces, ids))
        offset += len(vertices)
    if not parts_f:
        raise L3MVNError(f"{path} holds no triangles")
    vertices = np.concatenate(parts_v)
    if up[2] == 1.0:  # Z-up (MP3D): habitat turns it Y-up, (x, y, z) -> (x, z, -y)
        vertices = np.stack([vertices[:, 0], vertices[:, 2], -vertices[:, 1]], axis=1)
    return _Mesh(vertices, np.concatenate(parts_f), np.concatenate(parts_c))


def _face_rgb(mesh, faces: np.ndarray, ids: bool) -> np.ndarray:
    """(m, 3) uint8 per triangle: from the texture, else the vertex colours, else the base colour."""
    visual = mesh.visual
    kind = getattr(visual, "kind", None)
    if kind == "vertex":
        colours = np.asarray(visual.vertex_colors)[faces, :3]
        return colours[:, 0].astype(np.uint8) if ids else colours.mean(axis=1).round().astype(np.uint8)
    if kind == "face":
        return np.asarray(visual.face_colors)[:, :3].astype(np.uint8)
    material = getattr(visual, "material", None)
    factor = np.ones(3)
    image = None
    if material is not None:
        image = getattr(material, "baseColorTexture", None) or getattr(material, "image", None)
        base = getattr(material, "baseColorFactor", None)
        if base is None:
            base = getattr(material, "main_color", None)
        if base is not None and image is None:
            return np.broadcast_to(np.asarray(base)[:3].astype(np.uint8), (len(faces), 3)).copy()
        if base is not None and not ids:
            factor = np.asarray(base, np.float64)[:3] / 255.0
    uv = getattr(visual, "uv", None)
    if image is None or uv is None or len(uv) == 0:
        return np.full((len(faces), 3), np.uint8(255 * _UNKNOWN_RGB[0]), np.uint8)
    texels = np.asarray(image.convert("RGB"))
    corners = np.asarray(uv, np.float64)[faces]
    centre = corners.mean(axis=1)
    # The centre, and for colour the points halfway to each corner: inside the triangle's own patch
    # of the atlas (a corner may sit on a seam), and smoother than one texel.
    points = [centre] if ids else [centre] + [(centre + corners[:, k]) / 2.0 for k in range(3)]
    rgb = np.mean([_texel(texels, p) for p in points], axis=0)
    return (rgb * factor).round().clip(0, 255).astype(np.uint8)


def _texel(texels: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Nearest texel at each (u, v), v counted up from the image's bottom (trimesh's convention)."""
    h, w = texels.shape[:2]
    cols = np.floor(np.mod(uv[:, 0], 1.0) * w).astype(np.int64).clip(0, w - 1)
    rows = np.floor(np.mod(1.0 - uv[:, 1], 1.0) * h).astype(np.int64).clip(0, h - 1)
    return texels[rows, cols].astype(np.float64)


# --- per-triangle categories ------------------------------------------------------------------


def triangle_instances(stage: _Mesh, semantic: _Mesh, objects: dict[int, SemanticObject]) -> np.ndarray:
    """The semantic object id of every stage triangle (0: none): the nearest semantic triangle's
    (by centroid and facing) colour looked up in the annotation table (exact 8-bit match; the two
    meshes of a scan are separate but cover the same surfaces). HM3D's semantic meshes carry the
    colours twice, painted in a texture (sRGB, as the table) and as linear vertex colours for
    habitat-sim; trimesh reads the texture, which is exact."""
    from scipy.spatial import cKDTree

    by_rgb = {o.rgb: o.object_id for o in objects.values()}
    packed = (
        (semantic.face_rgb[:, 0].astype(np.int64) << 16)
        | (semantic.face_rgb[:, 1].astype(np.int64) << 8)
        | semantic.face_rgb[:, 2].astype(np.int64)
    )
    keys, inverse = np.unique(packed, return_inverse=True)
    sem_ids = np.array([by_rgb.get(int(k), 0) for k in keys], np.int64)[inverse]
    _, nearest = cKDTree(_face_keys(semantic)).query(_face_keys(stage), workers=1)
    return sem_ids[nearest]


def _face_keys(mesh: _Mesh) -> np.ndarray:
    """(m, 6) centroid and a tenth of the unit normal: two faces back to back (a shelf's top and the
    underside of what stands on it) are told apart by the side they face."""
    corners = mesh.vertices[mesh.faces]
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    return np.concatenate([corners.mean(axis=1), 0.1 * normal], axis=1)


def instance_categories(objects: dict[int, SemanticObject], goal_instances: dict[int, str]) -> dict[int, str]:
    """Object id -> our category: the episode file's goal instances first, then the raw-name table."""
    out = {oid: cat for oid, o in objects.items() if (cat := raw_category(o.name)) is not None}
    out.update(goal_instances)
    return out


# --- floors and grids -------------------------------------------------------------------------


@dataclass(frozen=True)
class _Grid:
    """The top-down grid of a scene in habitat's frame: rows along x, columns along z."""

    x0: float
    z0: float
    rows: int
    cols: int

    def centres(self) -> tuple[np.ndarray, np.ndarray]:
        r, c = np.mgrid[0 : self.rows, 0 : self.cols]
        return self.x0 + (r.ravel() + 0.5) * GRID_M, self.z0 + (c.ravel() + 0.5) * GRID_M


def _grid_of(vertices: np.ndarray) -> _Grid:
    """A grid over the scan whose cell borders lie half a cell off round coordinates: a wall modelled
    on a round coordinate (an exported map's cell border) then falls inside one cell instead of on a
    border, where which side it marks would depend on rounding."""
    lo = (np.floor((vertices.min(axis=0) - GRID_MARGIN_M) / GRID_M) - 0.5) * GRID_M
    hi = vertices.max(axis=0) + GRID_MARGIN_M
    return _Grid(
        float(lo[0]), float(lo[2]), int(math.ceil((hi[0] - lo[0]) / GRID_M)), int(math.ceil((hi[2] - lo[2]) / GRID_M))
    )


@dataclass(frozen=True)
class _Hits:
    """Every surface a downward ray crosses: per hit its ray (cell), height, and the height of the
    next surface above it on that ray (inf: none), and whether it is a floor-like surface."""

    cell: np.ndarray
    height: np.ndarray
    above: np.ndarray
    level: np.ndarray


def _downward_hits(mesh: _Mesh, grid: _Grid, body_m: float) -> _Hits:
    trimesh = _trimesh()
    tm = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    try:
        from trimesh.ray.ray_pyembree import RayMeshIntersector
    except ImportError:
        raise L3MVNError("loading scans needs embreex for its ray casts: pip install embreex") from None
    xs, zs = grid.centres()
    top = float(mesh.vertices[:, 1].max()) + RAY_TOP_MARGIN_M
    origins = np.stack([xs, np.full_like(xs, top), zs], axis=1)
    directions = np.broadcast_to(np.array([0.0, -1.0, 0.0]), origins.shape)
    locations, rays, tris = RayMeshIntersector(tm).intersects_location(origins, directions, multiple_hits=True)
    height = locations[:, 1] if len(locations) else np.zeros(0)
    order = np.lexsort((height, rays))
    rays, height, tris = rays[order], height[order], tris[order]
    above = np.full(height.shape, np.inf)
    same = rays[1:] == rays[:-1]
    above[:-1][same] = height[1:][same]
    ny = tm.face_normals[tris, 1] if len(tris) else np.zeros(0)
    level = (ny > HORIZONTAL_MIN_NY) & (above - height >= body_m)
    return _Hits(rays, height, above, level)


def find_floors(hits: _Hits) -> list[float]:
    """Floor heights, lowest first: heights holding the most standing room, ``STOREY_MIN_M`` apart."""
    stand = hits.height[hits.level]
    if stand.size == 0:
        return []
    bins = np.round(stand / GRID_M).astype(np.int64)
    values, counts = np.unique(bins, return_counts=True)
    area = counts * GRID_M**2
    levels: list[float] = []
    for i in np.argsort(-area, kind="stable"):
        if area[i] < FLOOR_MIN_AREA_M2:
            break
        h = float(np.median(stand[bins == values[i]]))
        if all(abs(h - other) >= STOREY_MIN_M for other in levels):
            levels.append(h)
    return sorted(levels)


@dataclass(frozen=True)
class _Projection:
    """A scan's triangles seen from above, computed once: vertex (row, col) in grid cells, and each
    triangle's height span and centre height."""

    xy: np.ndarray
    faces: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    centre: np.ndarray

    @classmethod
    def of(cls, mesh: _Mesh, grid: _Grid) -> _Projection:
        xy = np.stack([(mesh.vertices[:, 0] - grid.x0) / GRID_M, (mesh.vertices[:, 2] - grid.z0) / GRID_M], axis=1)
        y = mesh.vertices[:, 1][mesh.faces]
        return cls(
            np.ascontiguousarray(xy), np.ascontiguousarray(mesh.faces), y.min(axis=1), y.max(axis=1), y.mean(axis=1)
        )

    def footprints(
        self, grid: _Grid, channel: np.ndarray, channels: int, band: tuple[np.ndarray, np.ndarray] | None = None
    ) -> np.ndarray:
        """(channels, rows, cols): the cells covered by the top-down projection of each triangle with
        ``channel[t] >= 0``, in its channel; with ``band`` (per-cell height limits) only where the
        triangle's height span meets the cell's band."""
        out = np.zeros((channels, grid.rows, grid.cols), np.bool_)
        if band is None:
            band = (np.full(out.shape[1:], -np.inf), np.full(out.shape[1:], np.inf))
        _rasterise_footprints(
            self.xy,
            self.faces,
            np.ascontiguousarray(channel, np.int64),
            self.lo,
            self.hi,
            np.ascontiguousarray(band[0], np.float64),
            np.ascontiguousarray(band[1], np.float64),
            out,
        )
        return out


@nb.njit(cache=True)
def _mark(r, c, k, t, zlo, zhi, band_lo, band_hi, out):
    if 0 <= r < out.shape[1] and 0 <= c < out.shape[2] and zhi[t] > band_lo[r, c] and zlo[t] < band_hi[r, c]:
        out[k, r, c] = True


@nb.njit(cache=True)
def _rasterise_footprints(xy, tris, channel, zlo, zhi, band_lo, band_hi, out):
    """Mark in ``out[channel[t]]`` every cell the xy projection of triangle t covers (cells whose
    centre lies inside it, and cells its edges pass through: a vertical wall projects to a line),
    where its height span [zlo, zhi] meets the cell's band (band_lo, band_hi); channel -1 skips it."""
    rows, cols = out.shape[1], out.shape[2]
    for t in range(tris.shape[0]):
        k = channel[t]
        if k < 0:
            continue
        ax, ay = xy[tris[t, 0], 0], xy[tris[t, 0], 1]
        bx, by = xy[tris[t, 1], 0], xy[tris[t, 1], 1]
        cx, cy = xy[tris[t, 2], 0], xy[tris[t, 2], 1]
        for e in range(3):
            px, py, qx, qy = (ax, ay, bx, by) if e == 0 else ((bx, by, cx, cy) if e == 1 else (cx, cy, ax, ay))
            n = int(max(abs(qx - px), abs(qy - py)) * 2.0) + 1
            for i in range(n + 1):
                s = i / n
                _mark(
                    int(math.floor(px + s * (qx - px))),
                    int(math.floor(py + s * (qy - py))),
                    k,
                    t,
                    zlo,
                    zhi,
                    band_lo,
                    band_hi,
                    out,
                )
        area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
        if abs(area) < 1e-12:
            continue
        r0 = max(0, int(math.floor(min(ax, bx, cx))))
        r1 = min(rows - 1, int(math.floor(max(ax, bx, cx))))
        c0 = max(0, int(math.floor(min(ay, by, cy))))
        c1 = min(cols - 1, int(math.floor(max(ay, by, cy))))
        for r in range(r0, r1 + 1):
            for c in range(c0, c1 + 1):
                x, y = r + 0.5, c + 0.5
                w0 = (bx - x) * (cy - y) - (by - y) * (cx - x)
                w1 = (cx - x) * (ay - y) - (cy - y) * (ax - x)
                w2 = (ax - x) * (by - y) - (ay - y) * (bx - x)
                if (w0 >= 0 and w1 >= 0 and w2 >= 0) or (w0 <= 0 and w1 <= 0 and w2 <= 0):
                    _mark(r, c, k, t, zlo, zhi, band_lo, band_hi, out)


def _floor_heights(grid: _Grid, hits: _Hits, level: float, max_climb: float) -> np.ndarray:
    """(rows, cols) height of the floor at ``level``, NaN off it: per cell the standing surface nearest
    the level within half a storey, kept where steps of at most ``max_climb`` lead from surfaces
    within ``max_climb`` of the level (raised rooms, steps and ramps belong to the floor they join,
    as on a navmesh; a bed or a sill does not)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    near = hits.level & (np.abs(hits.height - level) <= STOREY_MIN_M / 2)
    cells, heights = hits.cell[near], hits.height[near]
    order = np.lexsort((np.abs(heights - level), cells))
    cells, heights = cells[order], heights[order]
    first = np.r_[True, cells[1:] != cells[:-1]]
    height: np.ndarray = np.full(grid.rows * grid.cols, np.nan)
    height[cells[first]] = heights[first]
    height = height.reshape(grid.rows, grid.cols)
    index = np.arange(height.size).reshape(height.shape)
    edges = []
    for a, b in ((height[:, :-1], height[:, 1:]), (height[:-1, :], height[1:, :])):
        ok = np.abs(a - b) <= max_climb  # False where either is NaN
        ia = index[:, :-1] if a.shape[1] < height.shape[1] else index[:-1, :]
        ib = index[:, 1:] if a.shape[1] < height.shape[1] else index[1:, :]
        edges.append((ia[ok], ib[ok]))
    src = np.concatenate([e[0] for e in edges])
    dst = np.concatenate([e[1] for e in edges])
    graph = coo_matrix((np.ones(src.size, np.int8), (src, dst)), shape=(height.size, height.size))
    _, labels = connected_components(graph, directed=False)
    labels = labels.reshape(height.shape)
    main = np.unique(labels[np.abs(height - level) <= max_climb])
    return np.where(np.isin(labels, main) & np.isfinite(height), height, np.nan)


def _navigable(proj: _Projection, grid: _Grid, hits: _Hits, level: float, cfg: SimConfig) -> np.ndarray:
    """The floor at ``level`` with nothing between the climb and body heights above it, eroded by the
    agent radius, islands dropped."""
    height = _floor_heights(grid, hits, level, cfg.max_climb_m)
    standing = np.isfinite(height)
    band = (
        np.where(standing, height + cfg.max_climb_m, np.inf),
        np.where(standing, height + cfg.camera_height_m, -np.inf),
    )
    clear = standing & ~proj.footprints(grid, np.zeros(len(proj.faces), np.int64), 1, band)[0]
    navigable = ndi.distance_transform_edt(clear) * GRID_M > cfg.agent_radius_m
    labels, n = ndi.label(navigable, structure=np.ones((3, 3), bool))
    if n:
        area = np.bincount(labels.ravel()) * GRID_M**2
        area[0] = 0.0
        navigable = (area >= ISLAND_MIN_M2)[labels]
    return navigable


def load_scan(
    name: str,
    files: ScanFiles,
    cfg: SimConfig,
    *,
    goal_instances: dict[int, str],
    view_points: list[tuple[str, tuple[float, float, float]]],
) -> dict[int, ScanFloor]:
    """The floors of one scan, each with its world mesh, ground-truth grid and view points.

    ``goal_instances``: object id -> our category for the instances an episode file names as goals;
    ``view_points``: (our category, habitat position) of their view points, placed on the floor
    below them."""
    stage = _read_glb(files.stage, files.up)
    if files.semantic_glb is not None and files.semantic_txt is not None:
        annotated = read_semantic_txt(files.semantic_txt)
        instances = triangle_instances(stage, _read_glb(files.semantic_glb, files.up, ids=True), annotated)
        categories = instance_categories(annotated, goal_instances)
    else:
        instances, categories = np.zeros(len(stage.faces), np.int64), {}
    index = {c: k + 1 for k, c in enumerate(SCAN_CATEGORIES)}
    lookup = np.zeros(int(instances.max(initial=0)) + 1, np.int32)
    for oid, cat in categories.items():
        if oid < lookup.size:
            lookup[oid] = index[cat]
    tri_category = lookup[instances]
    grid = _grid_of(stage.vertices)
    hits = _downward_hits(stage, grid, cfg.camera_height_m)
    levels = find_floors(hits)
    if not levels:
        raise L3MVNError(
            f"scan {name} ({files.stage}): no floor found (no level surface of {FLOOR_MIN_AREA_M2} m2 "
            f"with {cfg.camera_height_m} m of headroom); is the stage's up axis right?"
        )
    proj = _Projection.of(stage, grid)
    floors: dict[int, ScanFloor] = {}
    for f, level in enumerate(levels):
        top = levels[f + 1] if f + 1 < len(levels) else math.inf
        navigable = _navigable(proj, grid, hits, level, cfg)
        if not navigable.any():
            continue
        on_floor = (proj.hi > level - cfg.max_climb_m) & (proj.lo < min(top, level + cfg.wall_height_m + STOREY_MIN_M))
        objects = proj.footprints(grid, np.where(on_floor, tri_category - 1, -1), len(SCAN_CATEGORIES))
        shown = (proj.centre >= level - BELOW_FLOOR_M) & (proj.centre < top - 0.5 * cfg.max_climb_m)
        floors[f] = ScanFloor(
            name=name,
            floor=f,
            categories=SCAN_CATEGORIES,
            navigable=navigable,
            objects=objects,
            origin_cm=(grid.z0 * 100.0, grid.x0 * 100.0),
            floor_height_m=level,
            resolution_m=GRID_M,
            mesh=_floor_mesh(stage, shown, tri_category, grid, level, cfg.scan_vertex_merge_m),
            view_points=_floor_view_points(view_points, grid, level, top),
            source=str(files.stage),
        )
    if not floors:
        raise L3MVNError(f"scan {name}: no floor has navigable room for a {cfg.agent_radius_m} m agent")
    return floors


def _floor_mesh(
    stage: _Mesh, keep: np.ndarray, tri_category: np.ndarray, grid: _Grid, level: float, merge_m: float
) -> ScanMesh:
    """The kept triangles in our frame (x = habitat z, y = habitat x, from the grid origin; z up),
    vertices closer than ``merge_m`` merged (vertex clustering): the rasteriser's cost grows with the
    triangle count, and a scan's finest triangles are smaller than a pixel of the agent's frames.
    Triangles that collapse are dropped; the others keep their colour and category."""
    faces = stage.faces[keep]
    category, rgb = tri_category[keep], stage.face_rgb[keep]
    used, inverse = np.unique(faces, return_inverse=True)
    v = stage.vertices[used]
    faces = inverse.reshape(-1, 3)
    if merge_m > 0:
        cluster, faces_of = np.unique(np.round(v / merge_m).astype(np.int64), axis=0, return_inverse=True)
        merged = np.zeros((len(cluster), 3))
        np.add.at(merged, faces_of.ravel(), v)
        v = merged / np.bincount(faces_of.ravel(), minlength=len(cluster))[:, None]
        faces = faces_of.ravel()[faces]
        alive = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
        faces, category, rgb = faces[alive], category[alive], rgb[alive]
    ours = np.stack([v[:, 2] - grid.z0, v[:, 0] - grid.x0, v[:, 1] - level], axis=1)
    return ScanMesh(
        vertices=np.ascontiguousarray(ours, np.float32),
        triangles=np.ascontiguousarray(faces, np.int32),
        tri_category=np.ascontiguousarray(category, np.int32),
        tri_color=np.ascontiguousarray(rgb / 255.0, np.float32),
    )


def _floor_view_points(view_points, grid: _Grid, level: float, top: float) -> dict[str, np.ndarray]:
    """View points standing on this floor (between its height and the next), in our world x, y."""
    out: dict[str, list[tuple[float, float]]] = {}
    for category, (x, y, z) in view_points:
        if level - STOREY_MIN_M / 2 <= y < top - STOREY_MIN_M / 2:
            out.setdefault(category, []).append((z - grid.z0, x - grid.x0))
    return {c: np.asarray(p, np.float64) for c, p in out.items()}


def floor_at(floors: Mapping[int, _Floor], height: float) -> _Floor:
    """The floor an agent standing at habitat height ``height`` is on: the highest at or below it
    (within half a storey, for starts a little under the floor surface)."""
    below = [f for f in floors.values() if f.floor_height_m <= height + STOREY_MIN_M / 2]
    if not below:
        return min(floors.values(), key=lambda f: f.floor_height_m)
    return max(below, key=lambda f: f.floor_height_m)

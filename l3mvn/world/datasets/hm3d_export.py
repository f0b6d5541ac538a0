"""Export procedural houses as scans in HM3D's layout, with an ``objectnav_hm3d_v2`` episode file.

So every path that reads official data is exercised on files in the exact official schema, written
by the tests themselves, and the same episode can run on habitat-sim and on our renderer:

    OUT/scene_datasets/hm3d_v0.2/hm3d_annotated_basis.scene_dataset_config.json
    OUT/scene_datasets/hm3d_v0.2/<split>/00000-<name>/<name>.glb            stage, Y up, textured
    OUT/scene_datasets/hm3d_v0.2/<split>/00000-<name>/<name>.semantic.glb   object colours, painted texture
    OUT/scene_datasets/hm3d_v0.2/<split>/00000-<name>/<name>.semantic.txt   id,HEX,"name",region
    OUT/objectnav_hm3d_v2/<split>/<split>.json.gz                           category tables
    OUT/objectnav_hm3d_v2/<split>/content/<name>.json.gz                    episodes, goal instances

The episode files are written by ``objectnav_files``, which owns their format. A house of
``floors`` storeys stacks that many procedural floors ``STOREY_M`` apart (no stairs: every episode
starts on its goal's floor). View points are habitat's: positions on the floor from which a goal
instance is within ``success_distance_m`` (geodesic), on a ``VIEW_POINT_STEP_CELLS`` lattice; an
episode's geodesic distance is the geodesic from the start to the nearest one, measured on the
procedural map (the other simulator's ground truth, which the scan reader re-measures).
"""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import ndimage as ndi

from l3mvn.core.categories import GOAL_CATEGORIES
from l3mvn.core.config import Config, TaskConfig
from l3mvn.core.errors import L3MVNError
from l3mvn.core.grid import disk
from l3mvn.core.paths import plain_name
from l3mvn.core.writing import make_folder, write_file
from l3mvn.world.datasets.objectnav_files import (
    EpisodeRecord,
    GoalRecord,
    content_dir,
    write_scene_file,
    write_split_file,
)
from l3mvn.world.episodes import generate_episodes
from l3mvn.world.scenes.procedural import procedural_split
from l3mvn.world.scenes.scan import SemanticObject, write_semantic_txt
from l3mvn.world.scenes.scene import SceneMap
from l3mvn.world.sim.world import build_world
from l3mvn.world.task.regions import footprint_region, geodesic_field

STOREY_M = 3.0  # floor to floor: the 2.5 m walls and a slab
VIEW_POINT_STEP_CELLS = 2  # 0.1 m, habitat's view-point spacing
_PALETTE_BLOCK = 8  # texels per palette colour: nearest sampling at a block's centre is exact
SCENE_DIR = Path("scene_datasets") / "hm3d_v0.2"
EPISODE_DIR = Path("objectnav_hm3d_v2")


@dataclass(frozen=True)
class ExportSummary:
    """What an export wrote: ``--dataset`` and ``--scenes`` for ``l3mvn eval``, and how much."""

    dataset_dir: Path
    scenes_dir: Path
    scenes: int
    episodes: int


def export_hm3d(
    out: str | Path,
    houses: int,
    *,
    seed: int = 0,
    split: str = "val",
    floors: int = 1,
    episodes_per_floor: int = 6,
    cfg: Config | None = None,
) -> ExportSummary:
    """Write ``houses`` procedural houses of ``floors`` storeys and their episodes under ``out``."""
    for name, value in (("--houses", houses), ("--floors", floors), ("--episodes-per-floor", episodes_per_floor)):
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise L3MVNError(f"{name} must be a whole number >= 1, got {value!r}")
    plain_name(split, "--split", "val")
    cfg = cfg or Config()
    out = Path(out)
    scene_root, dataset = out / SCENE_DIR, out / EPISODE_DIR
    make_folder(content_dir(dataset, split), "--out")
    make_folder(scene_root / split, "--out")
    _write_dataset_config(scene_root)
    maps = procedural_split(houses * floors, seed)
    names = sorted(maps)
    total = 0
    for h in range(houses):
        storeys = [maps[n][0] for n in names[h * floors : (h + 1) * floors]]
        name = storeys[0].name
        folder = scene_root / split / f"{h:05d}-{name}"
        scene_id = f"hm3d_v0.2/{split}/{folder.name}/{name}.glb"
        goals, walkable = _write_scan(folder, name, storeys, cfg)
        episodes = _episodes(scene_id, storeys, walkable, goals, episodes_per_floor, seed, cfg)
        write_scene_file(dataset, split, scene_id, episodes, [_goal_record(g) for g in goals])
        total += len(episodes)
    write_split_file(dataset, split)
    return ExportSummary(dataset, out / "scene_datasets", houses, total)


def _write_dataset_config(root: Path) -> None:
    config = {
        "stages": {
            "default_attributes": {"up": [0, 1, 0], "front": [0, 0, -1], "origin": [0, 0, 0]},
            "paths": {".glb": ["*/*.glb"]},
        },
        "objects": {},
        "light_setups": {},
        "scene_instances": {},
    }
    write_file(
        root / "hm3d_annotated_basis.scene_dataset_config.json", json.dumps(config, indent=1), "scene dataset config"
    )


@dataclass
class _Goal:
    object_id: int
    category: str  # ours
    storey: int
    position: tuple[float, float, float]
    views: np.ndarray  # (n, 3) habitat positions of its view points
    view_cells: np.ndarray  # (n, 2) rows, cols on the storey's map


def _goal_record(goal: _Goal) -> GoalRecord:
    return GoalRecord(
        goal.object_id, goal.category, tuple((float(x), float(y), float(z)) for x, y, z in goal.views), goal.position
    )


def _habitat(scene: SceneMap, x: np.ndarray, y: np.ndarray, level: float) -> np.ndarray:
    """Our world x, y on ``scene`` at floor height ``level`` -> habitat [x, y up, z] (SemExp's axes)."""
    ox, oy = scene.origin_cm[0] / 100.0, scene.origin_cm[1] / 100.0
    return np.stack([np.asarray(y) + oy, np.full(np.shape(x), level), np.asarray(x) + ox], axis=-1)


def _write_scan(folder: Path, name: str, storeys: list[SceneMap], cfg: Config) -> tuple[list[_Goal], list[np.ndarray]]:
    """Stage, semantic mesh and table of one house; returns its goal instances and, per storey, the
    navigable cells of the exported geometry."""
    trimesh = _trimesh()
    objects = [SemanticObject(1, 0, "wall", 0), SemanticObject(2, 0, "floor", 0), SemanticObject(3, 0, "ceiling", 0)]
    goals: list[_Goal] = []
    walkables: list[np.ndarray] = []
    parts_v, parts_rgb, parts_id = [], [], []
    geodesic = Config(
        task=TaskConfig(success_rule="geodesic", success_distance_m=cfg.task.success_distance_m), sim=cfg.sim
    )
    for s, scene in enumerate(storeys):
        level = s * STOREY_M
        world = build_world(scene, cfg.sim, rooms_only=True)
        walkable = _mesh_navigable(scene, world, cfg)
        walkables.append(walkable)
        corners = world.vertices[world.triangles].astype(np.float64)  # (m, 3, 3), ours
        ids = np.where(world.tri_normal[:, 2] > 0.5, 2, np.where(world.tri_normal[:, 2] < -0.5, 3, 1))
        ids = np.where(world.tri_category > 0, 0, ids)
        for k, category in enumerate(scene.categories):
            tris = np.nonzero(world.tri_category == k + 1)[0]
            if not len(tris):
                continue
            labels, n = ndi.label(scene.objects[k], structure=np.ones((3, 3), bool))
            first = len(objects) + 1
            for i in range(n):
                objects.append(SemanticObject(first + i, 0, category, s))
            # A side face's centroid lies on a cell border: step half a cell inwards, then take the
            # nearest labelled cell (boxes cut down over a corridor keep their instance).
            inward = corners[tris].mean(axis=1)[:, :2] - 0.5 * scene.resolution_m * world.tri_normal[tris, :2]
            _, (near_r, near_c) = ndi.distance_transform_edt(labels == 0, return_indices=True)
            r = np.clip(np.floor(inward[:, 1] / scene.resolution_m).astype(int), 0, labels.shape[0] - 1)
            c = np.clip(np.floor(inward[:, 0] / scene.resolution_m).astype(int), 0, labels.shape[1] - 1)
            ids[tris] = first - 1 + labels[near_r[r, c], near_c[r, c]]
            if category in GOAL_CATEGORIES:
                goals += _instance_goals(scene, walkable, labels, n, first, category, s, level, geodesic)
        hab = _habitat(scene, corners[..., 0], corners[..., 1], 0.0)
        hab[..., 1] = corners[..., 2] + level
        parts_v.append(hab.reshape(-1, 3))
        parts_rgb.append(np.round(world.tri_color * 255).astype(np.uint8))
        parts_id.append(ids)
    objects = _coloured(objects)
    vertices = np.concatenate(parts_v)
    faces = np.arange(len(vertices)).reshape(-1, 3)
    tri_rgb, tri_id = np.concatenate(parts_rgb), np.concatenate(parts_id)
    palette, which = np.unique(tri_rgb, axis=0, return_inverse=True)
    image, uv_of = _palette_texture(palette)
    uv = np.repeat(uv_of[which.ravel()], 3, axis=0)
    material = trimesh.visual.material.PBRMaterial(baseColorTexture=image, baseColorFactor=[255, 255, 255, 255])
    stage = trimesh.Trimesh(
        vertices, faces, visual=trimesh.visual.TextureVisuals(uv=uv, material=material), process=False
    )
    write_file(folder / f"{name}.glb", stage.export(file_type="glb"), "stage mesh")
    # As HM3D's: the object colours of .semantic.txt painted into the semantic mesh's texture, and
    # per vertex as linear COLOR_0 (habitat-sim requires vertex colours and reads them as linear,
    # matching the table after converting them to sRGB).
    rgb_of = np.array([[(o.rgb >> 16) & 255, (o.rgb >> 8) & 255, o.rgb & 255] for o in objects], np.uint8)
    image, uv_of = _palette_texture(rgb_of)
    material = trimesh.visual.material.PBRMaterial(baseColorTexture=image, baseColorFactor=[255, 255, 255, 255])
    visual = trimesh.visual.TextureVisuals(uv=np.repeat(uv_of[tri_id - 1], 3, axis=0), material=material)
    semantic = trimesh.Trimesh(vertices, faces, visual=visual, process=False)
    glb = _with_vertex_colours(semantic.export(file_type="glb"), np.repeat(rgb_of[tri_id - 1], 3, axis=0))
    write_file(folder / f"{name}.semantic.glb", glb, "semantic mesh")
    write_semantic_txt(folder / f"{name}.semantic.txt", objects)
    return goals, walkables


def _mesh_navigable(scene: SceneMap, world, cfg: Config) -> np.ndarray:
    """The navigable cells of the exported geometry (habitat would build its navmesh from the mesh,
    not from our map): cells clear of walls, furniture and objects by more than the agent radius
    from their faces (a cell centre lies half a cell inside an obstacle cell's face)."""
    clear = ~world.walls & ~world.furniture & ~scene.object_any
    return ndi.distance_transform_edt(clear) - 0.5 > cfg.sim.agent_radius_m / scene.resolution_m


def _with_vertex_colours(glb: bytes, rgb: np.ndarray) -> bytes:
    """``glb`` (one mesh, one primitive, vertices in ``rgb``'s order) with ``rgb`` (n, 3 uint8 sRGB)
    added as a linear float ``COLOR_0`` (trimesh writes vertex colours or a texture, not both)."""
    import struct

    length, (json_len,) = struct.unpack_from("<I", glb, 8)[0], struct.unpack_from("<I", glb, 12)
    header = json.loads(glb[20 : 20 + json_len])
    binary = bytearray(glb[20 + json_len + 8 : length])
    srgb = rgb.astype(np.float64) / 255.0
    linear = np.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4)
    data = np.concatenate([linear, np.ones((len(rgb), 1))], axis=1).astype("<f4").tobytes()
    binary += b"\0" * (-len(binary) % 4)
    header["bufferViews"].append({"buffer": 0, "byteOffset": len(binary), "byteLength": len(data)})
    header["accessors"].append(
        {"bufferView": len(header["bufferViews"]) - 1, "componentType": 5126, "count": len(rgb), "type": "VEC4"}
    )
    (mesh,) = header["meshes"]
    (primitive,) = mesh["primitives"]
    primitive["attributes"]["COLOR_0"] = len(header["accessors"]) - 1
    binary += data
    header["buffers"][0]["byteLength"] = len(binary)
    text = json.dumps(header, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    body = struct.pack("<II", len(text), 0x4E4F534A) + text + struct.pack("<II", len(binary), 0x004E4942) + binary
    return struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body


def _trimesh():
    try:
        import trimesh
    except ImportError:
        raise L3MVNError("exporting scans needs trimesh: pip install trimesh") from None
    return trimesh


def _coloured(objects: list[SemanticObject]) -> list[SemanticObject]:
    """A distinct, non-black colour per object (a multiplicative hash of its id)."""
    out, used = [], set()
    for o in objects:
        rgb = (o.object_id * 2654435761) & 0xFFFFFF
        while rgb in used or rgb == 0:
            rgb = (rgb * 1103515245 + 12345) & 0xFFFFFF
        used.add(rgb)
        out.append(SemanticObject(o.object_id, rgb, o.name, o.region))
    return out


def _palette_texture(palette: np.ndarray):
    """A texture holding each palette colour in its own block, and the UV of each block's centre."""
    from PIL import Image

    side = max(1, math.ceil(math.sqrt(len(palette))))
    b = _PALETTE_BLOCK
    texels = np.zeros((side * b, side * b, 3), np.uint8)
    uv = np.zeros((len(palette), 2))
    for i, rgb in enumerate(palette):
        row, col = divmod(i, side)
        texels[row * b : (row + 1) * b, col * b : (col + 1) * b] = rgb
        uv[i] = ((col + 0.5) / side, 1.0 - (row + 0.5) / side)  # trimesh's UVs: v up from the bottom
    return Image.fromarray(texels), uv


def _instance_goals(
    scene: SceneMap,
    walkable: np.ndarray,
    labels: np.ndarray,
    n: int,
    first: int,
    category: str,
    storey: int,
    level: float,
    geodesic: Config,
) -> list[_Goal]:
    """Each instance's view points: walkable lattice cells within the success distance of it."""
    out = []
    lattice = np.zeros(scene.shape, bool)
    lattice[::VIEW_POINT_STEP_CELLS, ::VIEW_POINT_STEP_CELLS] = True
    for i in range(n):
        mask = labels == i + 1
        region = footprint_region(scene, mask, geodesic, category).region & walkable & lattice
        cells = np.argwhere(region)
        if not len(cells):
            continue
        xs, ys = scene.cell_center(cells[:, 0], cells[:, 1])
        rows, cols = np.nonzero(mask)
        cx, cy = scene.cell_center(rows.mean(), cols.mean())
        centre = _habitat(scene, np.array(cx), np.array(cy), level + 0.5)
        px, py, pz = (float(v) for v in centre)
        out.append(_Goal(first + i, category, storey, (px, py, pz), _habitat(scene, xs, ys, level), cells))
    return out


def _episodes(
    scene_id: str,
    storeys: list[SceneMap],
    walkables: list[np.ndarray],
    goals: list[_Goal],
    per_floor: int,
    seed: int,
    cfg: Config,
) -> list[EpisodeRecord]:
    """Episodes as habitat's files give them: starts from our generator where the exported geometry
    is navigable, the geodesic to the nearest view point over that geometry's traversible cells."""
    records: list[EpisodeRecord] = []
    for s, scene in enumerate(storeys):
        walkable = walkables[s]
        passable = ndi.binary_dilation(walkable, disk(scene.traversible_dilation_cells))
        by_category: dict[str, list[_Goal]] = {}
        for g in goals:
            if g.storey == s:
                by_category.setdefault(g.category, []).append(g)
        wanted = tuple(c for c in GOAL_CATEGORIES if c in by_category)
        if not wanted:
            continue
        for ep in generate_episodes(scene, per_floor, seed=seed, cfg=cfg, goals=wanted, first_id=len(records)):
            sources = np.zeros(scene.shape, bool)
            for g in by_category[ep.goal]:
                sources[g.view_cells[:, 0], g.view_cells[:, 1]] = True
            to_view = geodesic_field(passable, sources, scene.resolution_m)
            cell = scene.cell_of(ep.start.x, ep.start.y)
            distance = float(to_view[cell])
            if not (walkable[cell] and math.isfinite(distance)):
                continue
            position, (w, x, y, z) = scene.pose_to_habitat(ep.start)
            position[1] = s * STOREY_M
            start = np.array(position)
            nearest = [float(np.linalg.norm(g.views - start, axis=1).min()) for g in by_category[ep.goal]]
            records.append(
                EpisodeRecord(
                    ep.episode_id,
                    scene_id,
                    (position[0], position[1], position[2]),
                    (w, x, y, z),
                    ep.goal,
                    geodesic_m=round(distance, 4),
                    euclidean_m=round(min(nearest), 4),
                    closest_object_id=int(by_category[ep.goal][int(np.argmin(nearest))].object_id),
                )
            )
    return records


# --- the command ---------------------------------------------------------------------------------


def add_export_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--houses", type=int, default=1, help="procedural houses to export (default 1)")
    p.add_argument("--floors", type=int, default=1, help="storeys per house, stacked 3 m apart (default 1)")
    p.add_argument("--episodes-per-floor", type=int, default=6, help="episodes per storey (default 6)")
    p.add_argument("--split", default="val", help="split name (default val)")
    p.add_argument("--seed", type=int, default=0, help="seed of the houses and episodes")
    p.add_argument("--out", required=True, help="directory for scene_datasets/ and objectnav_hm3d_v2/")


def run_export(args: argparse.Namespace) -> int:
    summary = export_hm3d(
        args.out,
        args.houses,
        seed=args.seed,
        split=args.split,
        floors=args.floors,
        episodes_per_floor=args.episodes_per_floor,
    )
    print(
        f"wrote {summary.scenes} scans and {summary.episodes} episodes: l3mvn eval --dataset "
        f"{summary.dataset_dir} --scenes {summary.scenes_dir} --split {args.split} --policy oracle"
    )
    return 0

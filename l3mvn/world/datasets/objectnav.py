"""Official habitat ObjectNav datasets (``objectnav_hm3d`` v1/v2, ``objectnav_mp3d``, Gibson) on our renderer.

The episode files (their layout and fields: ``objectnav_files``) give each episode's start and goal
category, and per scene the goal instances with their view points. Scans are found under
``--scenes`` by the tail of each ``scene_id`` (``hm3d_v0.2/val/00800-X/X.basis.glb`` is found
under ``.../scene_datasets``, ``.../hm3d_v0.2`` or ``.../val``); for a ``.basis.glb`` the plain ``.glb``
beside it (HM3D's ``glb`` download) is preferred, because trimesh cannot decode Basis Universal
textures (such a stage renders in its materials' flat colours). The format is read from the scene ids.
"""

from __future__ import annotations

import logging
import math
import re
from pathlib import Path

import numpy as np

from l3mvn.core.config import Config
from l3mvn.core.errors import L3MVNError
from l3mvn.core.paths import relative_parts
from l3mvn.core.types import Pose
from l3mvn.world.datasets import EpisodeSet
from l3mvn.world.datasets.objectnav_files import EpisodeRecord, read_scenes, read_split, scene_name, split_file
from l3mvn.world.episode import Episode
from l3mvn.world.scenes.scan import ScanFiles, ScanFloor, floor_at, load_scan, scene_up_axis
from l3mvn.world.task.regions import GoalRegion, goal_region

# Format -> the success rule its papers report (the default when --rule is not given).
FORMAT_RULES: dict[str, str] = {
    "objectnav_hm3d_v1": "hm3d",
    "objectnav_hm3d_v2": "hm3d",
    "objectnav_mp3d": "mp3d",
    "objectnav_gibson": "semexp",
}
log = logging.getLogger(__name__)

# Habitat's navmesh and our grid disagree by a cell or two at walls: a start this close to our
# navigable floor moves onto it; farther is an error.
START_SNAP_M = 0.25


def is_objectnav(dataset: str | Path, split: str) -> bool:
    """A habitat ObjectNav split: ``<split>/<split>.json.gz`` without SemExp's ``<split>_info.pbz2``."""
    root = Path(dataset) / split
    try:
        return split_file(dataset, split).is_file() and not (root / f"{split}_info.pbz2").exists()
    except OSError:
        return False


def detect_format(scene_id: str) -> str:
    """The dataset format a ``scene_id`` belongs to (HM3D v2 scans live under ``hm3d_v0.2``)."""
    parts = [p.lower() for p in Path(scene_id).parts]
    if any(p.startswith("hm3d_v0.2") or p == "hm3d-v0.2" for p in parts):
        return "objectnav_hm3d_v2"
    if any(p.startswith("hm3d") for p in parts):
        return "objectnav_hm3d_v1"
    if any(p.startswith("mp3d") for p in parts):
        return "objectnav_mp3d"
    if any(p.startswith("gibson") for p in parts):
        return "objectnav_gibson"
    raise L3MVNError(
        f"scene_id {scene_id!r} names no known scan dataset; valid: paths under hm3d, hm3d_v0.2, mp3d or gibson"
    )


def dataset_rule(dataset: str | Path | None, split: str) -> str:
    """The success rule a source is reported under by default: habitat's view-point rule for HM3D and
    MP3D files, SemExp's for everything else."""
    if dataset is None or not is_objectnav(dataset, split):
        return "semexp"
    return FORMAT_RULES[detect_format(read_split(dataset, split).first_scene_id)]


def load_objectnav(
    dataset: str | Path, scenes_dir: str | Path | None, split: str, cfg: Config | None = None
) -> EpisodeSet:
    """Every episode of a habitat ObjectNav split on its scans (``scenes_dir``), scene by scene in
    name order; scans load through ``scenes.scan`` with the goal instances and view points the file
    gives."""
    cfg = cfg or Config()
    files = read_split(dataset, split)
    fmt = detect_format(files.first_scene_id)
    if scenes_dir is None:
        raise L3MVNError(f"{dataset} is an {fmt} dataset: give its scan root with --scenes DIR")
    scenes_root = Path(scenes_dir)
    if not scenes_root.is_dir():
        raise L3MVNError(f"--scenes {scenes_dir} is not a directory")
    parsed = read_scenes(files)
    scene_files = {scene_id: _scan_files(scene_id, scenes_root) for scene_id in parsed}
    scenes: dict[str, dict[int, ScanFloor]] = {}
    episodes: list[Episode] = []
    for scene_id in sorted(parsed, key=scene_name):
        name = scene_name(scene_id)
        if name in scenes:
            raise L3MVNError(f"two scene ids name scene {name!r}; the second is {scene_id}")
        goals = parsed[scene_id].goals
        instances = {goal.object_id: goal.goal for goal in goals}
        points = [(goal.goal, view) for goal in goals for view in goal.views]
        scenes[name] = load_scan(name, scene_files[scene_id], cfg.sim, goal_instances=instances, view_points=points)
        episodes += [_place(where, rec, scenes[name]) for where, rec in parsed[scene_id].episodes]
    return EpisodeSet(f"{Path(dataset).resolve().name}", split, scenes, episodes, fmt)


def _scan_files(scene_id: str, root: Path) -> ScanFiles:
    """The scan a ``scene_id`` names, looked up by its tails under ``root`` (see the module docstring);
    every candidate lies inside ``root``."""
    parts = relative_parts(scene_id, "scene_id", f"--scenes {root}")
    names = [parts[-1]]
    if parts[-1].endswith(".basis.glb"):  # the plain GLB's textures are JPEGs we can read; Basis ones we cannot
        names.insert(0, parts[-1][: -len(".basis.glb")] + ".glb")
    tried = []
    for start in range(len(parts)):
        for name in names:
            candidate = root.joinpath(*parts[start:-1], name)
            tried.append(candidate)
            if candidate.is_file():
                return _with_semantics(candidate, root)
    raise L3MVNError(
        f"scan {scene_id} is not under --scenes {root} (looked for {tried[-1]} and {len(tried) - 1} longer paths)"
    )


def _with_semantics(stage: Path, root: Path) -> ScanFiles:
    """HM3D's semantic files beside the stage (``X.semantic.glb``, ``X.semantic.txt``), and the up
    axis of the nearest ``*.scene_dataset_config.json`` between the stage and ``root``."""
    base = re.sub(r"(\.basis)?\.glb$", "", stage.name)
    semantic_glb, semantic_txt = stage.with_name(f"{base}.semantic.glb"), stage.with_name(f"{base}.semantic.txt")
    config = None
    for folder in [stage.parent, *stage.parent.parents]:
        found = sorted(folder.glob("*.scene_dataset_config.json"))
        if found:
            config = found[0]
            break
        if folder == root or root not in folder.parents:
            break
    if semantic_glb.is_file() != semantic_txt.is_file():
        missing = semantic_txt if semantic_glb.is_file() else semantic_glb
        raise L3MVNError(f"scan {stage}: {missing.name} is missing beside it (a semantic mesh needs its table)")
    has = semantic_glb.is_file()
    if not has:  # e.g. MP3D's .house or Gibson's 3DSceneGraph: formats this reader does not read yet
        log.warning(
            "scan %s has no HM3D semantic annotation (%s + %s): no goal object can be seen on our "
            "renderer, so its episodes cannot succeed; MP3D and Gibson semantics run with --sim habitat",
            stage,
            semantic_glb.name,
            semantic_txt.name,
        )
    return ScanFiles(stage, semantic_glb if has else None, semantic_txt if has else None, scene_up_axis(config))


def _place(where: str, rec: EpisodeRecord, floors: dict[int, ScanFloor]) -> Episode:
    """The episode in our frame, on the floor below its start."""
    floor = floor_at(floors, rec.position[1])
    start = _on_navigable(where, floor, floor.pose_from_habitat(list(rec.position), list(rec.rotation_wxyz)))
    return Episode(
        episode_id=rec.episode_id,
        scene=floor.name,
        floor=floor.floor,
        start=start,
        goal=rec.goal,
        object_id=-1,
        geodesic_distance_m=rec.geodesic_m,
    )


def _on_navigable(where: str, floor: ScanFloor, pose: Pose) -> Pose:
    """The start, moved onto our navigable grid when it lies within ``START_SNAP_M`` of it."""
    if not floor.contains(pose.x, pose.y):
        raise L3MVNError(f"{where}: start lies outside the scan's floor {floor.key}, which spans {floor.extent_text()}")
    r, c = floor.cell_of(pose.x, pose.y)
    if floor.navigable[r, c]:
        return pose
    cells = np.argwhere(floor.navigable)
    d = np.hypot(cells[:, 0] - r, cells[:, 1] - c) * floor.resolution_m
    k = int(np.argmin(d))
    if d[k] > START_SNAP_M:
        raise L3MVNError(
            f"{where}: start cell ({r}, {c}) of {floor.key} is {d[k]:.2f} m from our navigable floor "
            f"(more than {START_SNAP_M} m)"
        )
    x, y = floor.cell_center(int(cells[k, 0]), int(cells[k, 1]))
    return Pose(x, y, pose.heading)


def geodesic_agreement(eset: EpisodeSet, cfg: Config) -> list[tuple[str, float, float]]:
    """(episode key, the file's geodesic distance, ours) for every episode with a file distance, under
    ``cfg``'s rule (habitat's view-point rule measures what the file measured)."""
    regions: dict[tuple[str, str], GoalRegion] = {}
    out = []
    for ep in eset.episodes:
        if math.isfinite(ep.geodesic_distance_m):
            scene = eset.scene_of(ep)
            if (scene.key, ep.goal) not in regions:
                regions[scene.key, ep.goal] = goal_region(scene, ep.goal, cfg)
            region = regions[scene.key, ep.goal]
            out.append((ep.key, ep.geodesic_distance_m, region.shortest_path_length(ep.start.x, ep.start.y)))
    return out


def geodesic_report(eset: EpisodeSet, cfg: Config) -> str:
    """One line on how far our geodesics are from the file's (SPL takes the file's; see ObjectNavTask)."""
    pairs = geodesic_agreement(eset, cfg)
    if not pairs:
        return "geodesic check: the file gives no geodesic_distance"
    error = np.array([abs(ours / theirs - 1.0) if theirs > 0 else abs(ours) for _, theirs, ours in pairs])
    unreachable = int(np.isinf(error).sum())
    finite = error[np.isfinite(error)]
    worst = pairs[int(np.argmax(np.where(np.isfinite(error), error, -1.0)))][0] if finite.size else "-"
    text = (
        f"geodesic check: ours vs the file's on {len(pairs)} episodes: median {100 * np.median(finite):.1f}%, "
        f"max {100 * finite.max():.1f}% ({worst})"
        if finite.size
        else f"geodesic check: {len(pairs)} episodes"
    )
    return text + (f", {unreachable} without a path on our grid" if unreachable else "")

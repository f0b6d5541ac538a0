"""Official habitat ObjectNav datasets (``objectnav_hm3d`` v1/v2, ``objectnav_mp3d``, Gibson) on our renderer.

Layout (habitat-lab's ObjectNavDatasetV1): ``<dataset>/<split>/<split>.json.gz`` (category tables,
sometimes the episodes themselves) and ``<dataset>/<split>/content/<scene>.json.gz`` holding a scene's
``episodes`` (``scene_id``, ``start_position`` [x, y up, z], ``start_rotation`` (x, y, z, w),
``object_category``, ``info.geodesic_distance``) and ``goals_by_category`` (per
``<scene file>_<category>`` the goal instances: ``object_id`` and ``view_points``). Scans are found
under ``--scenes`` by the tail of each ``scene_id`` (``hm3d_v0.2/val/00800-X/X.basis.glb`` is found
under ``.../scene_datasets``, ``.../hm3d_v0.2`` or ``.../val``); for a ``.basis.glb`` the plain ``.glb``
beside it (HM3D's ``glb`` download) is preferred, because trimesh cannot decode Basis Universal
textures (such a stage renders in its materials' flat colours). The format is read from the scene ids.
"""

from __future__ import annotations

import logging
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from l3mvn.core.config import Config
from l3mvn.world.datasets import EpisodeSet
from l3mvn.world.episodes import _finite_numbers, _geodesic, _show, _whole_number, read_json_gz, yaw_quaternion
from l3mvn.core.errors import L3MVNError
from l3mvn.core.paths import relative_parts
from l3mvn.world.scenes.categories import goal_category
from l3mvn.world.scenes.scan import ScanFiles, ScanFloor, floor_at, load_scan, scene_up_axis
from l3mvn.world.task.regions import goal_region
from l3mvn.core.types import Pose
from l3mvn.world.episode import Episode

# Format -> the success rule its papers report (the default when --rule is not given).
FORMAT_RULES: dict[str, str] = {
    "objectnav_hm3d_v1": "hm3d", "objectnav_hm3d_v2": "hm3d", "objectnav_mp3d": "mp3d", "objectnav_gibson": "semexp",
}
log = logging.getLogger(__name__)

# Habitat's navmesh and our grid disagree by a cell or two at walls: a start this close to our
# navigable floor moves onto it; farther is an error.
START_SNAP_M = 0.25
_ID_LIMIT = 2**63


def split_file(dataset: str | Path, split: str) -> Path:
    return Path(dataset) / split / f"{split}.json.gz"


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
    raise L3MVNError(f"scene_id {scene_id!r} names no known scan dataset; valid: paths under hm3d, hm3d_v0.2, "
                     "mp3d or gibson")


def dataset_rule(dataset: str | Path | None, split: str) -> str:
    """The success rule a source is reported under by default: habitat's view-point rule for HM3D and
    MP3D files, SemExp's for everything else."""
    if dataset is None or not is_objectnav(dataset, split):
        return "semexp"
    return FORMAT_RULES[_read_split(dataset, split)[0]]


def _read_split(dataset: str | Path, split: str) -> tuple[str, list[tuple[Path, dict]]]:
    """(format, [(file, data)]) of the split file and every content file, each checked for shape."""
    files = [split_file(dataset, split)]
    content = Path(dataset) / split / "content"
    if content.is_dir():
        files += sorted(content.glob("*.json.gz"))
    loaded = []
    for path in files:
        data = read_json_gz(path)
        if not isinstance(data, dict) or not isinstance(data.get("episodes", []), list):
            raise L3MVNError(f"{path}: expected an object with an \"episodes\" list")
        goals = data.get("goals_by_category", {})
        if not isinstance(goals, dict):
            raise L3MVNError(f"{path}: goals_by_category must be an object, got {_show(goals)}")
        loaded.append((path, data))
    first = next((ep for _, d in loaded for ep in d.get("episodes", [])), None)
    if first is None:
        raise L3MVNError(f"{Path(dataset) / split} holds no episodes (in {files[0].name} or content/*.json.gz)")
    if not isinstance(first, dict) or not isinstance(first.get("scene_id"), str):
        raise L3MVNError(f"{files[0].parent}: episodes must be objects with a scene_id string, got {_show(first)}")
    return detect_format(first["scene_id"]), loaded


def load_objectnav(dataset: str | Path, scenes_dir: str | Path | None, split: str,
                   cfg: Config | None = None) -> EpisodeSet:
    """Every episode of a habitat ObjectNav split on its scans (``scenes_dir``), scene by scene in
    name order; scans load through ``scenes.scan`` with the goal instances and view points the file
    gives."""
    cfg = cfg or Config()
    fmt, loaded = _read_split(dataset, split)
    if scenes_dir is None:
        raise L3MVNError(f"{dataset} is an {fmt} dataset: give its scan root with --scenes DIR")
    scenes_root = Path(scenes_dir)
    if not scenes_root.is_dir():
        raise L3MVNError(f"--scenes {scenes_dir} is not a directory")
    records: dict[str, list[tuple[Path, int, dict]]] = {}
    goals: dict[str, list[tuple[Path, str, object]]] = {}
    for path, data in loaded:
        for index, rec in enumerate(data.get("episodes", [])):
            where = f"{path}: episode #{index}"
            if not isinstance(rec, dict) or not isinstance(rec.get("scene_id"), str):
                raise L3MVNError(f"{where} must be an object with a scene_id string, got {_show(rec)}")
            records.setdefault(rec["scene_id"], []).append((path, index, rec))
        for key, value in data.get("goals_by_category", {}).items():
            goals.setdefault(str(key), []).append((path, key, value))
    parsed = {scene_id: _records(scene_id, entries) for scene_id, entries in records.items()}
    scene_goals = {scene_id: _goals_of(scene_id, goals) for scene_id in parsed}
    scene_files = {scene_id: _scan_files(scene_id, scenes_root) for scene_id in parsed}
    scenes: dict[str, dict[int, ScanFloor]] = {}
    episodes: list[Episode] = []
    for scene_id in sorted(parsed, key=_scene_name):
        name = _scene_name(scene_id)
        if name in scenes:
            raise L3MVNError(f"two scene ids name scene {name!r}; the second is {scene_id}")
        instances, points = scene_goals[scene_id]
        scenes[name] = load_scan(name, scene_files[scene_id], cfg.sim, goal_instances=instances, view_points=points)
        episodes += [_place(rec, scenes[name]) for rec in parsed[scene_id]]
    return EpisodeSet(f"{Path(dataset).resolve().name}", split, scenes, episodes, fmt)


def _scene_name(scene_id: str) -> str:
    """``hm3d_v0.2/val/00800-TEEsavR23oF/TEEsavR23oF.basis.glb`` -> ``TEEsavR23oF``."""
    return Path(scene_id).name.split(".")[0]


def _goals_key_scene(key: str, scene_id: str) -> bool:
    """habitat-lab keys goals by ``<basename of scene_id>_<category>``."""
    return key.startswith(Path(scene_id).name + "_")


def _goals_of(scene_id: str, goals: dict[str, list[tuple[Path, str, object]]]):
    """(object id -> our category, [(our category, habitat position)] of view points) of one scene."""
    instances: dict[int, str] = {}
    points: list[tuple[str, tuple[float, float, float]]] = []
    for key, entries in goals.items():
        if not _goals_key_scene(key, scene_id):
            continue
        for path, _, value in entries:
            where = f"{path}: goals_by_category[{key!r}]"
            if not isinstance(value, list):
                raise L3MVNError(f"{where} must be a list of goals, got {_show(value)}")
            for i, goal in enumerate(value):
                here = f"{where}[{i}]"
                if not isinstance(goal, dict):
                    raise L3MVNError(f"{here} must be an object, got {_show(goal)}")
                category = goal_category(goal.get("object_category"), here)
                object_id = _whole_number(here, "object_id", goal.get("object_id"), 0, _ID_LIMIT)
                instances[object_id] = category
                views = goal.get("view_points", [])
                if not isinstance(views, list):
                    raise L3MVNError(f"{here}: view_points must be a list, got {_show(views)}")
                for j, view in enumerate(views):
                    state = view.get("agent_state") if isinstance(view, dict) else None
                    if not isinstance(state, dict):
                        raise L3MVNError(f"{here}: view_points[{j}] must hold an agent_state object, got {_show(view)}")
                    pos = _finite_numbers(f"{here}: view_points[{j}]", "agent_state.position", state.get("position"),
                                          3, "[x, y up, z]")
                    points.append((category, (pos[0], pos[1], pos[2])))
    return instances, points


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
    raise L3MVNError(f"scan {scene_id} is not under --scenes {root} (looked for {tried[-1]} and "
                     f"{len(tried) - 1} longer paths)")


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
        log.warning("scan %s has no HM3D semantic annotation (%s + %s): no goal object can be seen on our "
                    "renderer, so its episodes cannot succeed; MP3D and Gibson semantics run with --sim habitat",
                    stage, semantic_glb.name, semantic_txt.name)
    return ScanFiles(stage, semantic_glb if has else None, semantic_txt if has else None, scene_up_axis(config))


@dataclass(frozen=True)
class _Record:
    """An episode's fields, checked, before its scan is loaded (a bad file fails in seconds, not
    after a minute of loading scans)."""

    where: str
    episode_id: int
    position: list[float]
    rotation_wxyz: list[float]
    goal: str
    geodesic_m: float


def _records(scene_id: str, entries: list[tuple[Path, int, dict]]) -> list[_Record]:
    """The checked records of one scene; ids must be unique within it (results are keyed by them)."""
    out: list[_Record] = []
    seen: dict[int, str] = {}
    for path, index, rec in entries:
        where = f"{path}: episode #{index}"
        for key in ("start_position", "start_rotation", "object_category"):
            if key not in rec:
                raise L3MVNError(f"{where} lacks {key!r}")
        raw_id = rec.get("episode_id", index)
        if isinstance(raw_id, str) and raw_id.strip().isdigit():
            raw_id = int(raw_id)
        episode_id = _whole_number(where, "episode_id", raw_id, 0, _ID_LIMIT)
        if episode_id in seen:
            raise L3MVNError(f"{where}: episode_id {episode_id} repeats {seen[episode_id]} of scene "
                             f"{_scene_name(scene_id)}; ids must be unique within a scene")
        seen[episode_id] = where
        where = f"{where} (id {episode_id})"
        out.append(_Record(
            where, episode_id, _finite_numbers(where, "start_position", rec["start_position"], 3, "[x, y up, z]"),
            yaw_quaternion(where, rec["start_rotation"], order="xyzw"), goal_category(rec["object_category"], where),
            _geodesic(where, rec.get("info")),
        ))
    return out


def _place(rec: _Record, floors: dict[int, ScanFloor]) -> Episode:
    """The episode in our frame, on the floor below its start."""
    floor = floor_at(floors, rec.position[1])
    start = _on_navigable(rec.where, floor, floor.pose_from_habitat(rec.position, rec.rotation_wxyz))
    return Episode(episode_id=rec.episode_id, scene=floor.name, floor=floor.floor, start=start, goal=rec.goal,
                   object_id=-1, geodesic_distance_m=rec.geodesic_m)


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
        raise L3MVNError(f"{where}: start cell ({r}, {c}) of {floor.key} is {d[k]:.2f} m from our navigable floor "
                         f"(more than {START_SNAP_M} m)")
    x, y = floor.cell_center(int(cells[k, 0]), int(cells[k, 1]))
    return Pose(x, y, pose.heading)


def geodesic_agreement(eset: EpisodeSet, cfg: Config) -> list[tuple[str, float, float]]:
    """(episode key, the file's geodesic distance, ours) for every episode with a file distance, under
    ``cfg``'s rule (habitat's view-point rule measures what the file measured)."""
    regions: dict[tuple[str, str], object] = {}
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
    text = (f"geodesic check: ours vs the file's on {len(pairs)} episodes: median {100 * np.median(finite):.1f}%, "
            f"max {100 * finite.max():.1f}% ({worst})" if finite.size else f"geodesic check: {len(pairs)} episodes")
    return text + (f", {unreachable} without a path on our grid" if unreachable else "")

"""ObjectNav episodes: read and write SemExp ``<Scene>_episodes.json.gz`` files, generate new ones.

Files keep Habitat coordinates (``start_position`` [p0, p1 up, p2], ``start_rotation`` (w, x, y, z));
in memory an Episode holds our world-frame Pose (see ``SceneMap.pose_from_habitat``).
"""

from __future__ import annotations

import gzip
import json
import math
import zlib
from pathlib import Path

import numpy as np
from scipy import ndimage as ndi

from l3mvn.config import Config
from l3mvn.errors import L3MVNError
from l3mvn.task.regions import goal_region
from l3mvn.scenes.scene import GOAL_CATEGORIES, SceneMap
from l3mvn.types import Episode, Pose


def episode_file(dataset: str | Path, split: str, scene: str) -> Path:
    return Path(dataset) / split / "content" / f"{scene}_episodes.json.gz"


def read_episode_file(path: str | Path, floors: dict[int, SceneMap]) -> list[Episode]:
    """Episodes of one scene file, validated against that scene's floors."""
    path = Path(path)
    try:
        with gzip.open(path, "rt", encoding="utf-8") as fh:
            data = json.load(fh)
    except FileNotFoundError:
        raise L3MVNError(f"{path} does not exist") from None
    except (OSError, EOFError, json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise L3MVNError(f"{path} is corrupt or truncated ({type(exc).__name__}: {exc})") from None
    records = data.get("episodes") if isinstance(data, dict) else None
    if not isinstance(records, list):
        raise L3MVNError(f"{path}: expected {{\"episodes\": [...]}}")
    return [_episode_from_record(path, i, rec, floors) for i, rec in enumerate(records)]


def read_episodes(dataset: str | Path, split: str, scenes: dict[str, dict[int, SceneMap]]) -> list[Episode]:
    """Every episode of a split, scene by scene in name order (scenes without a file have none)."""
    content = Path(dataset) / split / "content"
    if not content.is_dir():
        raise L3MVNError(
            f"{content} does not exist: generate episodes with 'l3mvn episodes generate --dataset {dataset} --split {split} --out DIR'"
        )
    known = {p.name[: -len("_episodes.json.gz")] for p in content.glob("*_episodes.json.gz")}
    unknown = sorted(known - set(scenes))
    if unknown:
        raise L3MVNError(f"{content}: episode files for scenes not in the split's maps: {', '.join(unknown)}")
    episodes: list[Episode] = []
    for name in sorted(known):
        episodes.extend(read_episode_file(episode_file(dataset, split, name), scenes[name]))
    if not episodes:
        raise L3MVNError(f"{content} holds no episodes")
    return episodes


def _episode_from_record(path: Path, index: int, rec: object, floors: dict[int, SceneMap]) -> Episode:
    where = f"{path}: episode #{index}"
    if not isinstance(rec, dict):
        raise L3MVNError(f"{where} is not an object")
    for key in ("start_position", "start_rotation", "object_category"):
        if key not in rec:
            raise L3MVNError(f"{where} lacks {key!r}")
    scene_name = Path(str(rec.get("scene_id", path.name[: -len("_episodes.json.gz")]))).name.split(".")[0]
    floor_id = int(rec.get("floor_id", 0))
    if floor_id not in floors:
        raise L3MVNError(f"{where}: floor {floor_id} unknown; floors: {', '.join(map(str, sorted(floors)))}")
    scene = floors[floor_id]
    if scene_name != scene.name:
        raise L3MVNError(f"{where}: scene_id names {scene_name!r} but the file is for {scene.name!r}")
    goal = str(rec["object_category"])
    if goal not in GOAL_CATEGORIES:
        raise L3MVNError(f"{where}: unknown category {goal!r}; valid: {', '.join(GOAL_CATEGORIES)}")
    pos, rot = rec["start_position"], rec["start_rotation"]
    try:
        pos_f = [float(v) for v in pos]
        rot_f = [float(v) for v in rot]
    except (TypeError, ValueError):
        raise L3MVNError(f"{where}: start_position/start_rotation must be lists of numbers") from None
    if len(pos_f) != 3 or len(rot_f) != 4:
        raise L3MVNError(f"{where}: start_position needs 3 numbers and start_rotation 4 (w, x, y, z)")
    if not all(math.isfinite(v) for v in pos_f + rot_f):
        raise L3MVNError(f"{where}: non-finite start pose {pos_f} {rot_f}")
    start = scene.pose_from_habitat(pos_f, rot_f)
    r, c = scene.cell_of(start.x, start.y)
    if not (scene.in_bounds(r, c) and scene.navigable[r, c]):
        raise L3MVNError(f"{where} (id {rec.get('episode_id')}): start cell ({r}, {c}) is off the navigable area")
    info = rec.get("info") or {}
    return Episode(
        episode_id=int(rec.get("episode_id", index)), scene=scene.name, floor=floor_id, start=start, goal=goal,
        object_id=int(rec.get("object_id", -1)),
        geodesic_distance_m=float(info.get("geodesic_distance", float("nan"))) if isinstance(info, dict) else float("nan"),
    )


def episode_record(ep: Episode, scene: SceneMap) -> dict:
    position, rotation = scene.pose_to_habitat(ep.start)
    return {
        "episode_id": ep.episode_id, "scene_id": f"gibson_semantic/{ep.scene}.glb",
        "start_position": position, "start_rotation": rotation, "object_category": ep.goal,
        "object_id": ep.object_id, "floor_id": ep.floor,
        "info": {"geodesic_distance": ep.geodesic_distance_m},
    }


def write_episode_file(path: str | Path, episodes: list[Episode], floors: dict[int, SceneMap]) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    records = [episode_record(ep, floors[ep.floor]) for ep in episodes]
    with gzip.open(path, "wt", encoding="utf-8") as fh:
        json.dump({"episodes": records}, fh)
    return path


def generate_episodes(
    scene: SceneMap,
    count: int,
    seed: int = 0,
    cfg: Config | None = None,
    goals: tuple[str, ...] = GOAL_CATEGORIES,
    min_distance_m: float = 1.0,
    max_distance_m: float = 30.0,
    first_id: int = 0,
) -> list[Episode]:
    """Episodes with a start on the navmesh and a reachable goal, geodesic start distance in range.

    Deterministic for (scene name, floor, seed): goals cycle through those present in random order,
    starts are drawn uniformly among qualifying navmesh cells.
    """
    cfg = cfg or Config()
    rng = np.random.default_rng([seed, zlib.crc32(scene.key.encode())])
    present = [g for g in goals if g in scene.present_goals(goals)]
    candidates: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
    for goal in present:
        region = goal_region(scene, goal, cfg)
        d = region.distance_m
        ok = scene.navigable & np.isfinite(d) & (d >= min_distance_m) & (d <= max_distance_m)
        cells = np.argwhere(ok)
        if len(cells):
            labels, _ = ndi.label(scene.category_mask(goal), structure=np.ones((3, 3)))
            candidates[goal] = (cells, d[ok], labels)
    if not candidates:
        raise L3MVNError(
            f"scene {scene.key}: no goal category is reachable {min_distance_m}-{max_distance_m} m from the navmesh"
        )
    order = list(candidates)
    episodes: list[Episode] = []
    for i in range(count):
        if i % len(order) == 0:
            rng.shuffle(order)
        goal = order[i % len(order)]
        cells, dists, labels = candidates[goal]
        k = int(rng.integers(len(cells)))
        r, c = (int(v) for v in cells[k])
        x, y = scene.cell_center(r, c)
        heading = float(rng.uniform(-math.pi, math.pi))
        episodes.append(Episode(
            episode_id=first_id + i, scene=scene.name, floor=scene.floor, start=Pose(x, y, heading), goal=goal,
            object_id=_nearest_instance(labels, r, c), geodesic_distance_m=round(float(dists[k]), 3),
        ))
    return episodes


def _nearest_instance(labels: np.ndarray, r: int, c: int) -> int:
    """Label of the goal footprint component nearest (straight line) to a cell, as SemExp's object_id."""
    idx = np.argwhere(labels > 0)
    j = int(np.argmin((idx[:, 0] - r) ** 2 + (idx[:, 1] - c) ** 2))
    return int(labels[tuple(idx[j])])

"""ObjectNav episodes: read and write SemExp ``<Scene>_episodes.json.gz`` files, generate new ones.

Files keep Habitat coordinates (``start_position`` [p0, p1 up, p2], ``start_rotation`` (w, x, y, z));
in memory an Episode holds our world-frame Pose (see ``SceneMap.pose_from_habitat``).
"""

from __future__ import annotations

import gzip
import json
import math
import numbers
import zlib
from pathlib import Path
from typing import TypeGuard

import numpy as np
from scipy import ndimage as ndi

from l3mvn.core.categories import GOAL_CATEGORIES
from l3mvn.core.config import Config
from l3mvn.core.errors import L3MVNError, show_value
from l3mvn.core.types import Pose
from l3mvn.core.writing import write_file
from l3mvn.world.episode import Episode
from l3mvn.world.scenes.scene import SceneMap
from l3mvn.world.task.regions import goal_region


def episode_file(dataset: str | Path, split: str, scene: str) -> Path:
    return Path(dataset) / split / "content" / f"{scene}_episodes.json.gz"


# A start rotation is a unit quaternion about the up axis. Writers that round to a few digits leave
# its norm a little off 1 (normalised); beyond this it is not a rotation at all (an all-zero one).
ROTATION_NORM_TOLERANCE = 0.01
# The largest x or z component (after normalising) still read as a rotation about the up axis: about
# 1 degree of tilt. Anything larger is a tilted camera or a file in (x, y, z, w) order, which reading
# only w and y would silently turn into a wrong heading.
ROTATION_TILT_TOLERANCE = 0.01
_ID_LIMIT = 2**63  # ids are written to result files and used as keys: keep them 64-bit integers


def read_episode_file(path: str | Path, floors: dict[int, SceneMap]) -> list[Episode]:
    """Episodes of one scene file, validated against that scene's floors.

    Every field is typed: ids and floors are whole numbers (JSON has one number type, so an integral
    float such as 3.0 is read as 3, but 0.7 is an error rather than floor 0), positions and rotations
    are finite numbers, and no two episodes of a file share an id (results are keyed by it)."""
    path = Path(path)
    episodes = [_episode_from_record(path, i, rec, floors) for i, rec in enumerate(_read_records(path))]
    _check_unique_ids(path, episodes)
    return episodes


def _read_records(path: Path) -> list:
    """The ``episodes`` list of a gzip JSON file; every way the file can be unreadable is one line."""
    data = read_json_gz(path)
    records = data.get("episodes") if isinstance(data, dict) else None
    if not isinstance(records, list):
        raise L3MVNError(f'{path}: expected {{"episodes": [...]}}')
    return records


def read_json_gz(path: Path) -> object:
    """A gzip JSON file (SemExp's and habitat's episode files); every way it can be unreadable is one line."""
    try:
        with gzip.open(path, "rt", encoding="utf-8") as fh:
            data = json.load(fh)
    except FileNotFoundError:
        raise L3MVNError(f"{path} does not exist") from None
    except IsADirectoryError:
        raise L3MVNError(f"{path} is a directory, not an episode file") from None
    except (gzip.BadGzipFile, EOFError, zlib.error, ValueError, RecursionError) as exc:
        raise L3MVNError(f"{path} is corrupt or truncated ({type(exc).__name__}: {show_value(str(exc))})") from None
    except OSError as exc:
        raise L3MVNError(f"{path} cannot be read ({exc.strerror or exc})") from None
    return data


def _check_unique_ids(path: Path, episodes: list[Episode]) -> None:
    """Two episodes with one id would collapse into one result (and one resume key)."""
    first: dict[int, int] = {}
    for index, ep in enumerate(episodes):
        earlier = first.setdefault(ep.episode_id, index)
        if earlier != index:
            raise L3MVNError(
                f"{path}: episodes #{earlier} and #{index} both have episode_id {ep.episode_id}; "
                "ids must be unique within a scene file"
            )


def read_episodes(dataset: str | Path, split: str, scenes: dict[str, dict[int, SceneMap]]) -> list[Episode]:
    """Every episode of a split, scene by scene in name order (scenes without a file have none)."""
    content = Path(dataset) / split / "content"
    if not content.is_dir():
        raise L3MVNError(
            f"{content} does not exist: generate episodes with "
            f"'l3mvn episodes generate --dataset {dataset} --split {split} --out DIR'"
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
        raise L3MVNError(f"{where} is not an object, got {show_value(rec)}")
    for key in ("start_position", "start_rotation", "object_category"):
        if key not in rec:
            raise L3MVNError(f"{where} lacks {key!r}")
    episode_id = read_whole_number(where, "episode_id", rec.get("episode_id", index), 0, _ID_LIMIT)
    where = f"{where} (id {episode_id})"
    scene = _floor_of(where, rec, floors)
    _check_scene_id(where, path, rec, scene)
    goal = rec["object_category"]
    if not isinstance(goal, str) or goal not in GOAL_CATEGORIES:
        raise L3MVNError(f"{where}: unknown category {show_value(goal)}; valid: {', '.join(GOAL_CATEGORIES)}")
    return Episode(
        episode_id=episode_id,
        scene=scene.name,
        floor=scene.floor,
        start=_start_pose(where, scene, rec["start_position"], rec["start_rotation"]),
        goal=goal,
        object_id=read_whole_number(where, "object_id", rec.get("object_id", -1), -1, _ID_LIMIT),
        geodesic_distance_m=read_geodesic(where, rec.get("info")),
    )


def _floor_of(where: str, rec: dict, floors: dict[int, SceneMap]) -> SceneMap:
    """The map of the record's ``floor_id`` (0 when absent, as in single-floor SemExp files)."""
    valid = ", ".join(map(str, sorted(floors))) or "none"
    raw = rec.get("floor_id", 0)
    floor = _as_whole(raw)
    if floor is None or floor not in floors:
        raise L3MVNError(
            f"{where}: floor_id must be a floor of this scene (a whole number: {valid}), got {show_value(raw)}"
        )
    return floors[floor]


def _check_scene_id(where: str, path: Path, rec: dict, scene: SceneMap) -> None:
    """``scene_id`` (a path such as ``gibson_semantic/X.glb``) must name the scene the file is for."""
    scene_id = rec.get("scene_id", path.name[: -len("_episodes.json.gz")])
    if not isinstance(scene_id, str):
        raise L3MVNError(
            f"{where}: scene_id must be a string such as 'gibson_semantic/{scene.name}.glb', got {show_value(scene_id)}"
        )
    name = Path(scene_id).name.split(".")[0]
    if name != scene.name:
        raise L3MVNError(f"{where}: scene_id names {name!r} but the file is for {scene.name!r}")


def _start_pose(where: str, scene: SceneMap, position: object, rotation: object) -> Pose:
    """The start in our frame: 3 finite numbers on the map's navigable floor, a unit yaw quaternion."""
    pos = read_finite_numbers(where, "start_position", position, 3, "(p0, p1 up, p2)")
    rot = yaw_quaternion(where, rotation)
    try:
        start = scene.pose_from_habitat(pos, rot)
    except L3MVNError as exc:
        raise L3MVNError(f"{where}: {exc}") from None
    if not scene.contains(start.x, start.y):
        raise L3MVNError(
            f"{where}: start_position {show_value(position)} lies outside the map of {scene.key}, "
            f"which spans {scene.extent_text()}"
        )
    r, c = scene.cell_of(start.x, start.y)
    if not scene.navigable[r, c]:
        raise L3MVNError(f"{where}: start cell ({r}, {c}) is off the navigable area")
    return start


def yaw_quaternion(where: str, value: object, order: str = "wxyz") -> list[float]:
    """(w, x, y, z) of a rotation about the up axis, normalised; see the tolerances above. ``order``
    is how the file writes it: our files (w, x, y, z), habitat's ObjectNav files (x, y, z, w)."""
    shown = "(w, x, y, z)" if order == "wxyz" else "(x, y, z, w)"
    quat = read_finite_numbers(where, "start_rotation", value, 4, shown)
    norm = math.sqrt(sum(v * v for v in quat))
    if not abs(norm - 1.0) <= ROTATION_NORM_TOLERANCE:
        raise L3MVNError(
            f"{where}: start_rotation {show_value(value)} must be a unit quaternion {shown}; its norm is {norm:.3g}"
        )
    quat = [v / norm for v in quat]
    w, x, y, z = quat if order == "wxyz" else quat[3:] + quat[:3]
    if max(abs(x), abs(z)) > ROTATION_TILT_TOLERANCE:
        about_up = "w, 0, y, 0" if order == "wxyz" else "0, y, 0, w"
        hint = "; is the file in (x, y, z, w) order?" if order == "wxyz" else ""
        whose = "" if order == "wxyz" else "habitat's "
        raise L3MVNError(
            f"{where}: start_rotation {show_value(value)} must be a rotation about the up axis "
            f"({about_up} in {whose}{shown} order){hint}"
        )
    return [w, x, y, z]


def read_geodesic(where: str, info: object) -> float:
    """``info.geodesic_distance``: metres, or NaN when absent or null (files we wrote from such episodes)."""
    if info is None:
        return float("nan")
    if not isinstance(info, dict):
        raise L3MVNError(f"{where}: info must be an object, got {show_value(info)}")
    value = info.get("geodesic_distance")
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return float("nan")
    metres = _float_or_inf(value) if _is_number(value) else math.nan
    if not (math.isfinite(metres) and metres >= 0):
        raise L3MVNError(
            f"{where}: info.geodesic_distance must be a finite number >= 0 (metres), got {show_value(value)}"
        )
    return metres


def _is_number(value: object) -> TypeGuard[int | float]:
    """A JSON number: int or float, never a bool (``true`` is an int to Python) or a numeric string."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _as_whole(value: object) -> int | None:
    """An int, or an integral float (3.0) as an int; None for anything else (0.7, "3", true, 1e400)."""
    if isinstance(value, bool) or not _is_number(value):
        return None
    if isinstance(value, float):
        return int(value) if math.isfinite(value) and value.is_integer() else None
    return value


def read_whole_number(where: str, key: str, value: object, low: int, high: int) -> int:
    """``value`` as an int in ``[low, high)``, or an error naming the field and the range."""
    whole = _as_whole(value)
    if whole is None or not low <= whole < high:
        top = "2**63 - 1" if high == _ID_LIMIT else high - 1
        raise L3MVNError(f"{where}: {key} must be a whole number from {low} to {top}, got {show_value(value)}")
    return whole


def read_finite_numbers(where: str, key: str, value: object, count: int, layout: str) -> list[float]:
    """Exactly ``count`` finite JSON numbers (a numeric string or an int beyond float range is an error)."""
    if not (isinstance(value, list) and len(value) == count and all(_is_number(v) for v in value)):
        raise L3MVNError(f"{where}: {key} must be a list of {count} numbers {layout}, got {show_value(value)}")
    floats = [_float_or_inf(v) for v in value]
    if not all(math.isfinite(v) for v in floats):
        raise L3MVNError(f"{where}: non-finite {key} {show_value(value)}; it must be {count} finite numbers {layout}")
    return floats


def _float_or_inf(value: float) -> float:
    """``float(value)``, with an int literal of hundreds of digits as infinity (so: not finite)."""
    try:
        return float(value)
    except OverflowError:
        return math.inf


def episode_record(ep: Episode, scene: SceneMap) -> dict:
    position, rotation = scene.pose_to_habitat(ep.start)
    return {
        "episode_id": ep.episode_id,
        "scene_id": f"gibson_semantic/{ep.scene}.glb",
        "start_position": position,
        "start_rotation": rotation,
        "object_category": ep.goal,
        "object_id": ep.object_id,
        "floor_id": ep.floor,
        "info": {"geodesic_distance": ep.geodesic_distance_m},
    }


def write_episode_file(path: str | Path, episodes: list[Episode], floors: dict[int, SceneMap]) -> Path:
    records = [episode_record(ep, floors[ep.floor]) for ep in episodes]
    return write_file(path, gzip.compress(json.dumps({"episodes": records}).encode()), "episode file")


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
    _check_generation(count, seed, min_distance_m, max_distance_m)
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
        episodes.append(
            Episode(
                episode_id=first_id + i,
                scene=scene.name,
                floor=scene.floor,
                start=Pose(x, y, heading),
                goal=goal,
                object_id=_nearest_instance(labels, r, c),
                geodesic_distance_m=round(float(dists[k]), 3),
            )
        )
    return episodes


def _check_generation(count: int, seed: int, min_distance_m: float, max_distance_m: float) -> None:
    """A NaN or inverted distance range would otherwise read as "no goal is reachable" in the scene."""
    if isinstance(count, bool) or not isinstance(count, numbers.Integral) or count < 0:
        raise L3MVNError(f"episode count must be a whole number >= 0, got {count!r}")
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or seed < 0:
        raise L3MVNError(f"seed must be a whole number >= 0, got {seed!r}")
    if not (math.isfinite(min_distance_m) and math.isfinite(max_distance_m) and 0 <= min_distance_m <= max_distance_m):
        raise L3MVNError(
            f"geodesic start distances need 0 <= min <= max, both finite (metres); "
            f"got min {min_distance_m}, max {max_distance_m}"
        )


def _nearest_instance(labels: np.ndarray, r: int, c: int) -> int:
    """Label of the goal footprint component nearest (straight line) to a cell, as SemExp's object_id."""
    idx = np.argwhere(labels > 0)
    j = int(np.argmin((idx[:, 0] - r) ** 2 + (idx[:, 1] - c) ** 2))
    return int(labels[tuple(idx[j])])

"""Habitat's ObjectNav episode files (habitat-lab's ObjectNavDatasetV1), read and written in one place.

A split is ``<dataset>/<split>/<split>.json.gz`` (the category tables, sometimes the episodes
themselves) and ``<dataset>/<split>/content/<scene>.json.gz`` per scene, each holding ``episodes``
(``episode_id``, ``scene_id``, ``start_position`` [x, y up, z], ``start_rotation`` (x, y, z, w),
``object_category``, ``info.geodesic_distance``) and ``goals_by_category``: per
``<file name of the scene_id>_<category>`` the goal instances (``object_id``, ``object_category``,
``position``, ``view_points[].agent_state.position``). Every field name of the format is spelled
here, so the reader (``datasets.objectnav``) and the writer (``datasets.hm3d_export``) cannot drift
apart. Records hold our categories and habitat's axes; reading checks every field it takes and
reports a bad one in one line naming the file, the record and the field.
"""

from __future__ import annotations

import gzip
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from l3mvn.core.errors import L3MVNError, show_value
from l3mvn.core.writing import write_file
from l3mvn.world.episodes import (
    read_finite_numbers,
    read_geodesic,
    read_json_gz,
    read_whole_number,
    yaw_quaternion,
)
from l3mvn.world.scenes.categories import goal_category

# Our goal category -> HM3D's episode name (the inverse of categories.GOAL_NAMES for HM3D's six); the
# written category tables number the names in this order.
HM3D_GOAL_NAMES: dict[str, str] = {
    "chair": "chair",
    "couch": "sofa",
    "potted plant": "plant",
    "bed": "bed",
    "toilet": "toilet",
    "tv": "tv_monitor",
}
_ID_LIMIT = 2**63  # ids key results and resume files: keep them 64-bit integers
_AXES = "[x, y up, z]"

Vec3 = tuple[float, float, float]


def split_file(dataset: str | Path, split: str) -> Path:
    """The split's own file: the category tables, and in some datasets every episode."""
    return Path(dataset) / split / f"{split}.json.gz"


def content_dir(dataset: str | Path, split: str) -> Path:
    return Path(dataset) / split / "content"


def scene_name(scene_id: str) -> str:
    """``hm3d_v0.2/val/00800-TEEsavR23oF/TEEsavR23oF.basis.glb`` -> ``TEEsavR23oF``."""
    return Path(scene_id).name.split(".")[0]


@dataclass(frozen=True)
class EpisodeRecord:
    """One episode: its start in habitat's axes (position [x, y up, z], a (w, x, y, z) yaw quaternion,
    which the file writes as (x, y, z, w)), its goal as our category, and distances in metres (NaN
    where the file gives none). ``closest_object_id`` is the goal instance nearest the start."""

    episode_id: int
    scene_id: str
    position: Vec3
    rotation_wxyz: tuple[float, float, float, float]
    goal: str
    geodesic_m: float = math.nan
    euclidean_m: float = math.nan
    closest_object_id: int | None = None


@dataclass(frozen=True)
class GoalRecord:
    """One goal instance: its object id, our category, the habitat positions it counts as seen from
    (its view points) and its centre. The centre is written for habitat-sim; reading leaves it None,
    because our renderer finds an instance in the scan's semantic mesh by its id."""

    object_id: int
    goal: str
    views: tuple[Vec3, ...]
    centre: Vec3 | None = None


@dataclass(frozen=True)
class EpisodeFile:
    """One file of a split, its top level checked; its episodes and goal lists are checked as they
    are read into records (``read_scenes``)."""

    path: Path
    episodes: list[object]
    goals: dict[str, object]


@dataclass(frozen=True)
class SplitFiles:
    """A split's files in reading order (the split file, then ``content/`` by name); the first
    episode's ``first_scene_id`` names the dataset's format."""

    files: tuple[EpisodeFile, ...]
    first_scene_id: str


@dataclass(frozen=True)
class SceneRecords:
    """One scene's episodes, each with where the file holds it (for errors found later, on its
    scan), and its goal instances in file order."""

    episodes: tuple[tuple[str, EpisodeRecord], ...]
    goals: tuple[GoalRecord, ...]


def read_split(dataset: str | Path, split: str) -> SplitFiles:
    """Every file of a split, each checked for shape; a split without any episode is an error."""
    paths = [split_file(dataset, split)]
    content = content_dir(dataset, split)
    if content.is_dir():
        paths += sorted(content.glob("*.json.gz"))
    files = tuple(_read_file(path) for path in paths)
    first = next((ep for file in files for ep in file.episodes), None)
    if first is None:
        raise L3MVNError(f"{Path(dataset) / split} holds no episodes (in {paths[0].name} or content/*.json.gz)")
    if not isinstance(first, dict) or not isinstance(first.get("scene_id"), str):
        raise L3MVNError(f"{paths[0].parent}: episodes must be objects with a scene_id string, got {show_value(first)}")
    return SplitFiles(files, first["scene_id"])


def read_scenes(split: SplitFiles) -> dict[str, SceneRecords]:
    """The checked records of every scene, by scene id in the order the files first name them: a bad
    file fails here in seconds, not after minutes of loading scans."""
    entries: dict[str, list[tuple[Path, int, dict]]] = {}
    goals: dict[str, list[tuple[Path, object]]] = {}
    for file in split.files:
        for index, rec in enumerate(file.episodes):
            if not isinstance(rec, dict) or not isinstance(rec.get("scene_id"), str):
                raise L3MVNError(
                    f"{file.path}: episode #{index} must be an object with a scene_id string, got {show_value(rec)}"
                )
            entries.setdefault(rec["scene_id"], []).append((file.path, index, rec))
        for key, value in file.goals.items():
            goals.setdefault(str(key), []).append((file.path, value))
    episodes = {scene_id: _episodes(scene_id, found) for scene_id, found in entries.items()}
    return {scene_id: SceneRecords(records, _goals(scene_id, goals)) for scene_id, records in episodes.items()}


def write_scene_file(
    dataset: str | Path, split: str, scene_id: str, episodes: Sequence[EpisodeRecord], goals: Sequence[GoalRecord]
) -> Path:
    """``content/<scene>.json.gz``: a scene's episodes and goal instances under HM3D's names, with
    the category tables, written whole."""
    by_key: dict[str, list[dict]] = {}
    for goal in goals:
        by_key.setdefault(_goals_key(scene_id, HM3D_GOAL_NAMES[goal.goal]), []).append(_goal_json(goal))
    return _write(
        content_dir(dataset, split) / f"{scene_name(scene_id)}.json.gz",
        {
            "episodes": [_episode_json(ep) for ep in episodes],
            "goals_by_category": by_key,
            **_category_tables(),
        },
    )


def write_split_file(dataset: str | Path, split: str) -> Path:
    """``<split>.json.gz``: the category tables alone (the episodes are in ``content/``), written whole."""
    return _write(split_file(dataset, split), {"episodes": [], **_category_tables()})


# --- reading ------------------------------------------------------------------------------------


def _read_file(path: Path) -> EpisodeFile:
    data = read_json_gz(path)
    if not isinstance(data, dict) or not isinstance(data.get("episodes", []), list):
        raise L3MVNError(f'{path}: expected an object with an "episodes" list')
    goals = data.get("goals_by_category", {})
    if not isinstance(goals, dict):
        raise L3MVNError(f"{path}: goals_by_category must be an object, got {show_value(goals)}")
    return EpisodeFile(path, data.get("episodes", []), goals)


def _episodes(scene_id: str, entries: list[tuple[Path, int, dict]]) -> tuple[tuple[str, EpisodeRecord], ...]:
    """The checked episodes of one scene; ids must be unique within it (results are keyed by them)."""
    out: list[tuple[str, EpisodeRecord]] = []
    seen: dict[int, str] = {}
    for path, index, rec in entries:
        where = f"{path}: episode #{index}"
        for key in ("start_position", "start_rotation", "object_category"):
            if key not in rec:
                raise L3MVNError(f"{where} lacks {key!r}")
        raw_id = rec.get("episode_id", index)
        if isinstance(raw_id, str) and raw_id.strip().isdigit():  # habitat writes ids as strings
            raw_id = int(raw_id)
        episode_id = read_whole_number(where, "episode_id", raw_id, 0, _ID_LIMIT)
        if episode_id in seen:
            raise L3MVNError(
                f"{where}: episode_id {episode_id} repeats {seen[episode_id]} of scene "
                f"{scene_name(scene_id)}; ids must be unique within a scene"
            )
        seen[episode_id] = where
        where = f"{where} (id {episode_id})"
        x, y, z = read_finite_numbers(where, "start_position", rec["start_position"], 3, _AXES)
        w, qx, qy, qz = yaw_quaternion(where, rec["start_rotation"], order="xyzw")
        goal = goal_category(rec["object_category"], where)
        out.append(
            (
                where,
                EpisodeRecord(
                    episode_id, scene_id, (x, y, z), (w, qx, qy, qz), goal, read_geodesic(where, rec.get("info"))
                ),
            )
        )
    return tuple(out)


def _goals_key(scene_id: str, name: str) -> str:
    """habitat-lab keys a scene's goal lists by the file name of its ``scene_id`` and the category."""
    return f"{Path(scene_id).name}_{name}"


def _goals(scene_id: str, goals: dict[str, list[tuple[Path, object]]]) -> tuple[GoalRecord, ...]:
    """The checked goal instances of one scene, from every goal list keyed by its scene id."""
    out: list[GoalRecord] = []
    for key, found in goals.items():
        if not key.startswith(_goals_key(scene_id, "")):
            continue
        for path, value in found:
            where = f"{path}: goals_by_category[{key!r}]"
            if not isinstance(value, list):
                raise L3MVNError(f"{where} must be a list of goals, got {show_value(value)}")
            out += [_goal(f"{where}[{i}]", goal) for i, goal in enumerate(value)]
    return tuple(out)


def _goal(where: str, goal: object) -> GoalRecord:
    if not isinstance(goal, dict):
        raise L3MVNError(f"{where} must be an object, got {show_value(goal)}")
    category = goal_category(goal.get("object_category"), where)
    object_id = read_whole_number(where, "object_id", goal.get("object_id"), 0, _ID_LIMIT)
    views = goal.get("view_points", [])
    if not isinstance(views, list):
        raise L3MVNError(f"{where}: view_points must be a list, got {show_value(views)}")
    return GoalRecord(object_id, category, tuple(_view(f"{where}: view_points[{j}]", v) for j, v in enumerate(views)))


def _view(where: str, view: object) -> Vec3:
    state = view.get("agent_state") if isinstance(view, dict) else None
    if not isinstance(state, dict):
        raise L3MVNError(f"{where} must hold an agent_state object, got {show_value(view)}")
    x, y, z = read_finite_numbers(where, "agent_state.position", state.get("position"), 3, _AXES)
    return (x, y, z)


# --- writing ------------------------------------------------------------------------------------


def _episode_json(ep: EpisodeRecord) -> dict:
    w, x, y, z = ep.rotation_wxyz
    return {
        "episode_id": str(ep.episode_id),
        "scene_id": ep.scene_id,
        "start_position": list(ep.position),
        "start_rotation": [x, y, z, w],
        "info": {
            "geodesic_distance": ep.geodesic_m,
            "euclidean_distance": ep.euclidean_m,
            "closest_goal_object_id": ep.closest_object_id,
        },
        "goals": [],
        "start_room": None,
        "shortest_paths": None,
        "object_category": HM3D_GOAL_NAMES[ep.goal],
    }


def _goal_json(goal: GoalRecord) -> dict:
    return {
        "position": None if goal.centre is None else list(goal.centre),
        "radius": None,
        "object_id": goal.object_id,
        "object_name": f"{goal.goal}_{goal.object_id}",
        "object_name_id": None,
        "object_category": HM3D_GOAL_NAMES[goal.goal],
        "room_id": None,
        "room_name": None,
        "view_points": [
            {"agent_state": {"position": list(p), "rotation": [0.0, 0.0, 0.0, 1.0]}, "iou": 1.0} for p in goal.views
        ],
    }


def _category_tables() -> dict[str, dict[str, int]]:
    names = list(HM3D_GOAL_NAMES.values())
    return {
        "category_to_task_category_id": {n: i for i, n in enumerate(names)},
        "category_to_mp3d_category_id": {n: i + 1 for i, n in enumerate(names)},
    }


def _write(path: Path, data: dict) -> Path:
    return write_file(path, gzip.compress(json.dumps(data).encode()), "episode file")

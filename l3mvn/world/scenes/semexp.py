"""Load SemExp/L3MVN-format datasets: ``<root>/<split>/<split>_info.pbz2`` top-down maps.

Written against the format, never a list of scene names: any directory in that layout works.
"""

from __future__ import annotations

import bz2
import pickle
from pathlib import Path

import numpy as np

from l3mvn.core.categories import GIBSON_CATEGORIES
from l3mvn.core.errors import L3MVNError, show_value
from l3mvn.core.paths import plain_name
from l3mvn.core.writing import write_file
from l3mvn.world.scenes.decoded_maps import decoded
from l3mvn.world.scenes.map_pickle import load_map_pickle
from l3mvn.world.scenes.scene import SceneMap

# Coordinates (origin, floor height) beyond this many metres are no building's: they only turn
# later arithmetic into overflows (10,000 km is far past any real map and far below float range).
MAX_COORDINATE_M = 1e7
# The format's record of one floor (save_split writes all three).
RECORD_KEYS = ("sem_map", "origin", "floor_height")


def split_dir(dataset: str | Path, split: str) -> Path:
    root = Path(dataset)
    try:
        return _existing_split(root, split)
    except OSError as exc:  # a name too long, a loop of links: pathlib re-raises all but "missing"
        raise L3MVNError(f"cannot read split {split!r} of dataset {root} ({exc.strerror or exc})") from None


def _existing_split(root: Path, split: str) -> Path:
    """``root/split``, or an error naming what is wrong: the root is a file or missing, or the split
    is unknown (listing the splits there are)."""
    if root.exists() and not root.is_dir():
        raise L3MVNError(f"dataset {root} is a file; give the dataset directory (it holds <split>/<split>_info.pbz2)")
    if not root.is_dir():
        raise L3MVNError(f"dataset directory {root} does not exist")
    path = root / split
    if not path.is_dir():
        splits = sorted(p.name for p in root.iterdir() if p.is_dir() and (p / f"{p.name}_info.pbz2").exists())
        raise L3MVNError(f"unknown split {split!r} in {root}; available splits: {', '.join(splits) or 'none'}")
    return path


def info_path(dataset: str | Path, split: str) -> Path:
    path = split_dir(dataset, split) / f"{split}_info.pbz2"
    try:
        found = path.is_file()
    except OSError as exc:
        raise L3MVNError(f"cannot read {path} ({exc.strerror or exc})") from None
    if not found:
        raise L3MVNError(f"{path} is missing: a SemExp split needs <split>/<split>_info.pbz2")
    return path


def read_info(path: Path) -> object:
    """The raw ``{scene: {floor: record}}`` of a ``.pbz2`` file, read without executing anything (its
    decoded copy when one is kept: ``decoded_maps``)."""
    try:
        return decoded(path, lambda: _decode_info(path))
    except pickle.UnpicklingError as exc:
        raise L3MVNError(f"{path} is not a SemExp map file ({' '.join(str(exc).split())})") from None
    except (
        OSError,
        EOFError,
        ValueError,
        AttributeError,
        ImportError,
        TypeError,
        IndexError,
        KeyError,
        OverflowError,
        RecursionError,
        MemoryError,
    ) as exc:
        raise L3MVNError(f"{path} is corrupt or truncated ({type(exc).__name__}: {show_value(str(exc))})") from None


def _decode_info(path: Path) -> object:
    with bz2.BZ2File(path) as fh:
        return load_map_pickle(fh)


def load_split(dataset: str | Path, split: str, **scene_kwargs) -> dict[str, dict[int, SceneMap]]:
    """All scenes and floors of a split: ``{scene: {floor: SceneMap}}``."""
    path = info_path(dataset, split)
    raw = read_info(path)
    if not isinstance(raw, dict) or not raw:
        raise L3MVNError(f"{path}: expected a non-empty dict {{scene: {{floor: map}}}}, got {type(raw).__name__}")
    scenes: dict[str, dict[int, SceneMap]] = {}
    for key, floors in raw.items():
        name = _scene_name(path, key)
        if not isinstance(floors, dict) or not floors:
            raise L3MVNError(f"{path}: scene {name} has no floors (expected a non-empty dict {{floor: map}})")
        scenes[name] = {}
        for fkey, rec in floors.items():
            floor = _floor_id(path, name, fkey)
            scenes[name][floor] = _floor_from_record(path, name, floor, rec, scene_kwargs)
    return scenes


def _scene_name(path: Path, key: object) -> str:
    """A scene key names files (``<scene>_episodes.json.gz``) and keys (``scene/floor/id``), so it
    must be a plain printable name: no path separator, never ``.`` or ``..``."""
    return plain_name(key, f"{path}: a scene key", "Allensville")


def _floor_id(path: Path, name: str, key: object) -> int:
    """Floor keys are whole numbers (``floor_id`` in episode files refers to them)."""
    if isinstance(key, (bool, np.bool_)) or not isinstance(key, (int, np.integer)):
        raise L3MVNError(f"{path}: scene {name}: floor keys must be whole numbers such as 0, got {show_value(key)}")
    return int(key)


def load_scene(dataset: str | Path, split: str, scene: str, floor: int = 0, **scene_kwargs) -> SceneMap:
    scenes = load_split(dataset, split, **scene_kwargs)
    return pick_floor(scenes, scene, floor, where=f"{dataset}/{split}")


def pick_floor(scenes: dict[str, dict[int, SceneMap]], scene: str, floor: int, where: str = "dataset") -> SceneMap:
    if scene not in scenes:
        raise L3MVNError(f"unknown scene {scene!r} in {where}; available: {', '.join(sorted(scenes))}")
    floors = scenes[scene]
    if floor not in floors:
        raise L3MVNError(f"scene {scene} has no floor {floor}; floors: {', '.join(map(str, sorted(floors)))}")
    return floors[floor]


def _floor_from_record(path: Path, name: str, floor: int, rec: object, scene_kwargs: dict) -> SceneMap:
    """One floor's ``{"sem_map", "origin", "floor_height"}``, every field typed and finite."""
    where = f"{path}: scene {name} floor {floor}"
    if not isinstance(rec, dict) or "sem_map" not in rec:
        raise L3MVNError(f"{where}: record lacks 'sem_map' (a floor record is a dict of {', '.join(RECORD_KEYS)})")
    sem = _sem_map(where, rec["sem_map"])
    missing = [k for k in RECORD_KEYS if k not in rec]
    if missing:
        raise L3MVNError(
            f"{where}: record lacks {', '.join(map(repr, missing))} (the format has {', '.join(RECORD_KEYS)})"
        )
    origin = _numeric_array(where, "origin", rec["origin"]).astype(np.float64)
    if origin.shape != (2,) or not (np.abs(origin) <= MAX_COORDINATE_M * 100).all():
        raise L3MVNError(
            f"{where}: origin must be two finite numbers (ox_cm, oy_cm) within "
            f"{MAX_COORDINATE_M * 100:.0e} cm, got {show_value(rec['origin'])}"
        )
    height = _numeric_array(where, "floor_height", rec["floor_height"])
    if height.shape != () or not abs(float(height)) <= MAX_COORDINATE_M:
        raise L3MVNError(
            f"{where}: floor_height must be one finite number within {MAX_COORDINATE_M:.0e} m, "
            f"got {show_value(rec['floor_height'])}"
        )
    cats = GIBSON_CATEGORIES[: sem.shape[0] - 1]
    try:
        return SceneMap(
            name=name,
            floor=floor,
            categories=cats,
            navigable=sem[0] > 0.5,
            objects=sem[1:] > 0.5,
            origin_cm=(float(origin[0]), float(origin[1])),
            floor_height_m=float(height),
            **scene_kwargs,
        )
    except L3MVNError as exc:
        raise L3MVNError(f"{path}: {exc}") from None


def _sem_map(where: str, value: object) -> np.ndarray:
    """(1 + categories, H, W) of finite numbers: channel 0 navigable, then the format's categories."""
    sem = _numeric_array(where, "sem_map", value)
    if sem.ndim != 3 or sem.shape[0] < 2 or 0 in sem.shape:
        raise L3MVNError(
            f"{where}: sem_map must be (channels, H, W) with 2-{len(GIBSON_CATEGORIES) + 1} "
            f"channels, got shape {sem.shape}"
        )
    if sem.shape[0] - 1 > len(GIBSON_CATEGORIES):
        raise L3MVNError(f"{where}: {sem.shape[0] - 1} object channels, the format defines {len(GIBSON_CATEGORIES)}")
    if not np.isfinite(sem).all():
        raise L3MVNError(f"{where}: sem_map contains non-finite values")
    return sem


def _numeric_array(where: str, key: str, value: object) -> np.ndarray:
    """``value`` as an array of real numbers (bool, int or float dtype; bools are not numbers here
    except in sem_map, whose 0/1 cells they are)."""
    try:
        arr = np.asarray(value)
    except (ValueError, TypeError, OverflowError, RecursionError):
        arr = np.asarray(None)
    allowed = "biuf" if key == "sem_map" else "iuf"
    if arr.dtype.kind not in allowed:
        raise L3MVNError(f"{where}: {key} must be numeric, got {show_value(value)} ({type(value).__name__})")
    return arr


def to_semexp_channels(scene: SceneMap) -> SceneMap:
    """The same floor with only the 15 SemExp categories (richer vocabularies drop the rest)."""
    objects = np.stack(
        [scene.category_mask(c) if c in scene.categories else np.zeros(scene.shape, bool) for c in GIBSON_CATEGORIES]
    )
    return SceneMap(
        name=scene.name,
        floor=scene.floor,
        categories=GIBSON_CATEGORIES,
        navigable=scene.navigable,
        objects=objects,
        origin_cm=scene.origin_cm,
        floor_height_m=scene.floor_height_m,
        resolution_m=scene.resolution_m,
    )


def save_split(dataset: str | Path, split: str, scenes: list[SceneMap]) -> Path:
    """Write scenes in the SemExp format (used by tests and for exporting procedural houses)."""
    out = Path(dataset) / split
    raw: dict[str, dict[int, dict]] = {}
    for s in scenes:
        if s.categories != GIBSON_CATEGORIES[: len(s.categories)]:
            raise L3MVNError(f"scene {s.name}: only the SemExp categories can be written in this format")
        sem = np.concatenate([s.navigable[None], s.objects]).astype(np.float64)
        raw.setdefault(s.name, {})[s.floor] = {
            "sem_map": sem,
            "origin": np.asarray(s.origin_cm, dtype=np.int64),
            "floor_height": s.floor_height_m,
        }
    return write_file(out / f"{split}_info.pbz2", bz2.compress(pickle.dumps(raw)), "map file")

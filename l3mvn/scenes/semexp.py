"""Load SemExp/L3MVN-format datasets: ``<root>/<split>/<split>_info.pbz2`` top-down maps.

Written against the format, never a list of scene names: any directory in that layout works.
"""

from __future__ import annotations

import bz2
import pickle
from pathlib import Path

import numpy as np

from l3mvn.errors import L3MVNError
from l3mvn.scenes.scene import GIBSON_CATEGORIES, SceneMap


def split_dir(dataset: str | Path, split: str) -> Path:
    root = Path(dataset)
    if not root.is_dir():
        raise L3MVNError(f"dataset directory {root} does not exist")
    path = root / split
    if not path.is_dir():
        splits = sorted(p.name for p in root.iterdir() if p.is_dir() and (p / f"{p.name}_info.pbz2").exists())
        raise L3MVNError(f"unknown split {split!r} in {root}; available splits: {', '.join(splits) or 'none'}")
    return path


def info_path(dataset: str | Path, split: str) -> Path:
    path = split_dir(dataset, split) / f"{split}_info.pbz2"
    if not path.is_file():
        raise L3MVNError(f"{path} is missing: a SemExp split needs <split>/<split>_info.pbz2")
    return path


def _plain_dtype(*args, **kwargs) -> np.dtype:
    """``np.dtype`` for the unpickler, refusing object dtypes (their payload would be more pickles)."""
    dtype = np.dtype(*args, **kwargs)
    if dtype.hasobject:
        raise pickle.UnpicklingError("object arrays are not part of the SemExp format")
    return dtype


# The only globals a SemExp ``.pbz2`` names: dicts, lists, numbers and strings need none, and numpy
# arrays need these three (under ``numpy.core`` or, when written by numpy 2, ``numpy._core``).
_FORMAT_GLOBALS = {
    **{(mod, "_reconstruct"): np.ndarray.__reduce__(np.zeros(0))[0]
       for mod in ("numpy.core.multiarray", "numpy._core.multiarray")},
    **{(mod, "scalar"): np.float64(0).__reduce__()[0] for mod in ("numpy.core.multiarray", "numpy._core.multiarray")},
    ("numpy", "ndarray"): np.ndarray,
    ("numpy", "dtype"): _plain_dtype,
}


class _FormatUnpickler(pickle.Unpickler):
    """Unpickles only what the format holds, so a crafted map file cannot run code.

    ``pickle.load`` imports and calls any global a file names (``os.system`` included); these files
    are downloaded from third-party mirrors, so anything outside ``_FORMAT_GLOBALS`` is refused.
    """

    def find_class(self, module: str, name: str):
        try:
            return _FORMAT_GLOBALS[(module, name)]
        except KeyError:
            raise pickle.UnpicklingError(
                f"refuses {module}.{name}: a SemExp map holds only dicts, numbers and numpy arrays") from None


def read_info(path: Path) -> object:
    """The raw ``{scene: {floor: record}}`` of a ``.pbz2`` file, read without executing anything."""
    try:
        with bz2.BZ2File(path) as fh:
            return _FormatUnpickler(fh).load()
    except pickle.UnpicklingError as exc:
        raise L3MVNError(f"{path} is not a SemExp map file ({exc})") from None
    except (OSError, EOFError, ValueError, AttributeError, ImportError, TypeError, IndexError, KeyError) as exc:
        raise L3MVNError(f"{path} is corrupt or truncated ({type(exc).__name__}: {exc})") from None


def load_split(dataset: str | Path, split: str, **scene_kwargs) -> dict[str, dict[int, SceneMap]]:
    """All scenes and floors of a split: ``{scene: {floor: SceneMap}}``."""
    path = info_path(dataset, split)
    raw = read_info(path)
    if not isinstance(raw, dict) or not raw:
        raise L3MVNError(f"{path}: expected a non-empty dict {{scene: {{floor: map}}}}, got {type(raw).__name__}")
    scenes: dict[str, dict[int, SceneMap]] = {}
    for name, floors in raw.items():
        if not isinstance(floors, dict) or not floors:
            raise L3MVNError(f"{path}: scene {name!r} has no floors")
        scenes[str(name)] = {
            int(fid): _floor_from_record(path, str(name), int(fid), rec, scene_kwargs)
            for fid, rec in floors.items()
        }
    return scenes


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
    where = f"{path}: scene {name} floor {floor}"
    if not isinstance(rec, dict) or "sem_map" not in rec:
        raise L3MVNError(f"{where}: record lacks 'sem_map'")
    sem = np.asarray(rec["sem_map"])
    if sem.ndim != 3 or sem.shape[0] < 2:
        raise L3MVNError(f"{where}: sem_map must be (channels, H, W), got shape {sem.shape}")
    if sem.shape[0] - 1 > len(GIBSON_CATEGORIES):
        raise L3MVNError(f"{where}: {sem.shape[0] - 1} object channels, the format defines {len(GIBSON_CATEGORIES)}")
    if not np.isfinite(sem).all():
        raise L3MVNError(f"{where}: sem_map contains non-finite values")
    origin = np.asarray(rec.get("origin", (0, 0)), dtype=np.float64).reshape(-1)
    if origin.shape != (2,) or not np.isfinite(origin).all():
        raise L3MVNError(f"{where}: origin must be two finite numbers (ox_cm, oy_cm)")
    height = float(rec.get("floor_height", 0.0))
    cats = GIBSON_CATEGORIES[: sem.shape[0] - 1]
    try:
        return SceneMap(
            name=name, floor=floor, categories=cats, navigable=sem[0] > 0.5, objects=sem[1:] > 0.5,
            origin_cm=(float(origin[0]), float(origin[1])), floor_height_m=height, **scene_kwargs,
        )
    except L3MVNError as exc:
        raise L3MVNError(f"{path}: {exc}") from None


def to_semexp_channels(scene: SceneMap) -> SceneMap:
    """The same floor with only the 15 SemExp categories (richer vocabularies drop the rest)."""
    objects = np.stack([
        scene.category_mask(c) if c in scene.categories else np.zeros(scene.shape, bool) for c in GIBSON_CATEGORIES
    ])
    return SceneMap(name=scene.name, floor=scene.floor, categories=GIBSON_CATEGORIES, navigable=scene.navigable,
                    objects=objects, origin_cm=scene.origin_cm, floor_height_m=scene.floor_height_m,
                    resolution_m=scene.resolution_m)


def save_split(dataset: str | Path, split: str, scenes: list[SceneMap]) -> Path:
    """Write scenes in the SemExp format (used by tests and for exporting procedural houses)."""
    out = Path(dataset) / split
    out.mkdir(parents=True, exist_ok=True)
    raw: dict[str, dict[int, dict]] = {}
    for s in scenes:
        if s.categories != GIBSON_CATEGORIES[: len(s.categories)]:
            raise L3MVNError(f"scene {s.name}: only the SemExp categories can be written in this format")
        sem = np.concatenate([s.navigable[None], s.objects]).astype(np.float64)
        raw.setdefault(s.name, {})[s.floor] = {
            "sem_map": sem, "origin": np.asarray(s.origin_cm, dtype=np.int64), "floor_height": s.floor_height_m,
        }
    path = out / f"{split}_info.pbz2"
    with bz2.BZ2File(path, "wb") as fh:
        pickle.dump(raw, fh)
    return path

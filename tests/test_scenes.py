import bz2
import os
import pathlib
import pickle

import numpy as np
import pytest

from l3mvn.errors import L3MVNError
from l3mvn.scenes.semexp import load_split, pick_floor, save_split

from conftest import GIBSON, draw_two_room_house, needs_gibson


def test_saved_split_loads_back_identically(tmp_path):
    scene = draw_two_room_house()
    save_split(tmp_path, "val", [scene])
    back = pick_floor(load_split(tmp_path, "val"), "Tiny", 0)
    assert (back.navigable == scene.navigable).all() and (back.objects == scene.objects).all()
    assert back.origin_cm == scene.origin_cm


def test_free_floor_recovers_the_erosion_margin_but_never_covers_objects(tiny_scene):
    assert tiny_scene.free.sum() > tiny_scene.navigable.sum()
    assert not (tiny_scene.free & tiny_scene.object_any).any()
    assert (tiny_scene.traversible >= tiny_scene.navigable).all()


def test_unknown_split_lists_available_ones(tmp_path):
    save_split(tmp_path, "val", [draw_two_room_house()])
    with pytest.raises(L3MVNError, match="unknown split 'test'.*available splits: val"):
        load_split(tmp_path, "test")


def test_unknown_scene_lists_available_ones(tmp_path):
    save_split(tmp_path, "val", [draw_two_room_house()])
    with pytest.raises(L3MVNError, match="unknown scene 'Nope'.*available: Tiny"):
        pick_floor(load_split(tmp_path, "val"), "Nope", 0)


def test_truncated_pbz2_is_a_one_line_error_naming_the_file(tmp_path):
    path = save_split(tmp_path, "val", [draw_two_room_house()])
    path.write_bytes(path.read_bytes()[: len(path.read_bytes()) // 2])
    with pytest.raises(L3MVNError, match=r"val_info.pbz2 is corrupt or truncated"):
        load_split(tmp_path, "val")


def test_malformed_map_record_is_rejected(tmp_path):
    (tmp_path / "val").mkdir()
    with bz2.BZ2File(tmp_path / "val" / "val_info.pbz2", "wb") as fh:
        pickle.dump({"Bad": {0: {"sem_map": np.zeros((5, 5))}}}, fh)
    with pytest.raises(L3MVNError, match=r"sem_map must be \(channels, H, W\)"):
        load_split(tmp_path, "val")


class _Payload:
    """Pickles to "call this global with these arguments": what a crafted map file would hold."""

    def __init__(self, fn, *args):
        self.fn, self.args = fn, args

    def __reduce__(self):
        return self.fn, self.args


def _write_info(tmp_path, raw) -> None:
    (tmp_path / "val").mkdir(exist_ok=True)
    with bz2.BZ2File(tmp_path / "val" / "val_info.pbz2", "wb") as fh:
        pickle.dump(raw, fh)


@pytest.mark.parametrize("payload", [
    lambda marker: _Payload(os.system, f"touch {marker}"),
    lambda marker: _Payload(eval, f"open({str(marker)!r}, 'w')"),
    lambda marker: _Payload(pathlib.Path.touch, pathlib.Path(marker)),
])
def test_a_crafted_map_file_runs_nothing(tmp_path, payload):
    marker = tmp_path / "pwned"
    floor = {"sem_map": np.zeros((2, 4, 4)), "origin": payload(marker)}
    _write_info(tmp_path, {"Evil": {0: floor}})
    with pytest.raises(L3MVNError, match=r"val_info.pbz2 is not a SemExp map file \(refuses .*: a SemExp map holds"):
        load_split(tmp_path, "val")
    assert not marker.exists()


def test_object_arrays_are_refused(tmp_path):
    _write_info(tmp_path, {"Odd": {0: {"sem_map": np.array([None, 1], dtype=object)}}})
    with pytest.raises(L3MVNError, match="object arrays are not part of the SemExp format"):
        load_split(tmp_path, "val")


def test_the_format_still_loads_all_its_types(tmp_path):
    """Arrays of several dtypes, numpy scalars and plain numbers: what real SemExp files hold."""
    sem = np.zeros((3, 6, 6), np.float32)
    sem[0, 1:5, 1:5] = 1
    _write_info(tmp_path, {"Ok": {0: {"sem_map": sem, "origin": np.array([10, 20], np.int64),
                                      "floor_height": np.float64(0.25)}}})
    floor = load_split(tmp_path, "val")["Ok"][0]
    assert floor.origin_cm == (10.0, 20.0) and floor.floor_height_m == 0.25 and floor.navigable.sum() == 16


@needs_gibson
def test_every_gibson_floor_loads_with_its_goals():
    scenes = load_split(GIBSON, "train")
    assert len(scenes) == 25
    for floors in scenes.values():
        for s in floors.values():
            assert s.objects.shape[0] == 15 and len(s.present_goals()) >= 1

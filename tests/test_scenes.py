import bz2
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


@needs_gibson
def test_every_gibson_floor_loads_with_its_goals():
    scenes = load_split(GIBSON, "train")
    assert len(scenes) == 25
    for floors in scenes.values():
        for s in floors.values():
            assert s.objects.shape[0] == 15 and len(s.present_goals()) >= 1

import bz2
import os
import pathlib
import pickle

import numpy as np
import pytest
from conftest import GIBSON, draw_two_room_house, needs_gibson
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from l3mvn.core.errors import L3MVNError
from l3mvn.world.scenes.semexp import load_split, pick_floor, save_split


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


@pytest.mark.parametrize(
    "payload",
    [
        lambda marker: _Payload(os.system, f"touch {marker}"),
        lambda marker: _Payload(eval, f"open({str(marker)!r}, 'w')"),
        lambda marker: _Payload(pathlib.Path.touch, pathlib.Path(marker)),
    ],
)
def test_a_crafted_map_file_runs_nothing(tmp_path, payload):
    marker = tmp_path / "pwned"
    floor = {"sem_map": np.zeros((2, 4, 4)), "origin": payload(marker)}
    _write_info(tmp_path, {"Evil": {0: floor}})
    with pytest.raises(L3MVNError, match=r"val_info.pbz2 is not a SemExp map file \(refuses .*: a SemExp map holds"):
        load_split(tmp_path, "val")
    assert not marker.exists()


def test_object_arrays_are_refused(tmp_path):
    _write_info(tmp_path, {"Odd": {0: {"sem_map": np.array([None, 1], dtype=object)}}})
    with pytest.raises(
        L3MVNError,
        match=r"is not a SemExp map file \(an array of object: a SemExp map holds only "
        r"numeric arrays\)",
    ):
        load_split(tmp_path, "val")


def test_the_format_still_loads_all_its_types(tmp_path):
    """Arrays of several dtypes, numpy scalars and plain numbers: what real SemExp files hold."""
    sem = np.zeros((3, 6, 6), np.float32)
    sem[0, 1:5, 1:5] = 1
    _write_info(
        tmp_path,
        {"Ok": {0: {"sem_map": sem, "origin": np.array([10, 20], np.int64), "floor_height": np.float64(0.25)}}},
    )
    floor = load_split(tmp_path, "val")["Ok"][0]
    assert floor.origin_cm == (10.0, 20.0) and floor.floor_height_m == 0.25 and floor.navigable.sum() == 16


@needs_gibson
def test_every_gibson_floor_loads_with_its_goals():
    scenes = load_split(GIBSON, "train")
    assert len(scenes) == 25
    for floors in scenes.values():
        for s in floors.values():
            assert s.objects.shape[0] == 15 and len(s.present_goals()) >= 1


# --- crafted numpy state: the loader builds every array itself ---------------------------------------


def _valid_floor() -> dict:
    sem = np.zeros((3, 6, 6), np.float32)
    sem[0, 1:5, 1:5] = 1
    return {"sem_map": sem, "origin": np.array([10, 20], np.int64), "floor_height": np.float64(0.25)}


@pytest.mark.parametrize("protocol", range(pickle.HIGHEST_PROTOCOL + 1))
def test_valid_maps_load_at_every_pickle_protocol(tmp_path, protocol):
    (tmp_path / "val").mkdir()
    raw = {
        "Ok": {0: _valid_floor()},
        "Wide": {1: {**_valid_floor(), "sem_map": np.asfortranarray(_valid_floor()["sem_map"].astype(">f8"))}},
    }
    (tmp_path / "val" / "val_info.pbz2").write_bytes(bz2.compress(pickle.dumps(raw, protocol=protocol)))
    scenes = load_split(tmp_path, "val")
    assert scenes["Ok"][0].navigable.sum() == 16 and scenes["Wide"][1].navigable.sum() == 16
    assert scenes["Ok"][0].origin_cm == (10.0, 20.0) and scenes["Ok"][0].floor_height_m == 0.25


def _with_dtype_state(protocol: int, state: tuple) -> bytes:
    """A valid map's pickle whose sem_map dtype is given ``state`` (numpy's __setstate__ tuple)."""

    class Crafted:
        def __reduce__(self):
            return np.dtype, ("f4", False, True), state

    class Array:
        def __reduce__(self):
            return (
                np.ndarray.__reduce__(np.zeros(0))[0],
                (np.ndarray, (0,), b"b"),
                (1, (3, 6, 6), Crafted(), False, _valid_floor()["sem_map"].tobytes()),
            )

    return pickle.dumps({"Ok": {0: {**_valid_floor(), "sem_map": Array()}}}, protocol=protocol)


def _outcome(tmp_path, protocol: int, state: tuple) -> str:
    """What loading a map with this dtype state gives: its navigable cells, or the one-line error."""
    (tmp_path / "val").mkdir(exist_ok=True)
    (tmp_path / "val" / "val_info.pbz2").write_bytes(bz2.compress(_with_dtype_state(protocol, state)))
    try:
        return f"navigable {int(load_split(tmp_path, 'val')['Ok'][0].navigable.sum())}"
    except L3MVNError as exc:
        assert "\n" not in str(exc)
        return str(exc).split(": ", 1)[-1]


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    flags=st.integers(-(2**63), 2**63 - 1),
    order=st.sampled_from(["<", ">", "|", "=", "x", ""]),
    sizes=st.tuples(st.integers(-3, 64), st.integers(-3, 64)),
    protocol=st.integers(0, pickle.HIGHEST_PROTOCOL),
)
def test_crafted_dtype_state_never_reaches_numpy(tmp_path, flags, order, sizes, protocol):
    """Whatever flags and sizes a file gives a dtype (0x01 claims an array of objects, 0x3f makes
    numpy raise SystemError), the outcome is that of the plain dtype: only the byte order is read, and a
    byte order numpy never writes is refused in one line."""
    plain = _outcome(tmp_path, protocol, (3, order, None, None, None, -1, -1, 0))
    assert _outcome(tmp_path, protocol, (3, order, None, None, None, sizes[0], sizes[1], flags)) == plain
    if order in ("<", "|", "="):
        assert plain == "navigable 16"
    elif order != ">":
        assert "a dtype state numpy never writes" in plain

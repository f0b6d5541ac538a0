"""The decoded copies of SemExp map files: the same value back, never a stale one, nothing lost when
the cache folder cannot be written or a copy cannot be read."""

from __future__ import annotations

import bz2
import pickle

import numpy as np
import pytest
from conftest import draw_two_room_house

from l3mvn.core.paths import CACHE_ENV
from l3mvn.world.scenes import decoded_maps, semexp
from l3mvn.world.scenes.semexp import load_split, read_info, save_split


@pytest.fixture(autouse=True)
def cache(tmp_path, monkeypatch):
    """A cache folder of the test's own, keeping a copy of every value however small."""
    folder = tmp_path / "cache"
    monkeypatch.setenv(CACHE_ENV, str(folder))
    monkeypatch.setattr(decoded_maps, "_MIN_BYTES", 0)
    return folder


def _same(a, b) -> bool:
    if type(a) is not type(b):
        return False
    if isinstance(a, dict):
        return list(a) == list(b) and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, np.ndarray):
        return a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b, equal_nan=True)
    return a == b


def _write(path, value) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with bz2.BZ2File(path, "wb") as fh:
        pickle.dump(value, fh)


def _undecodable(monkeypatch) -> None:
    """From here on the map file itself cannot be decoded: only a kept copy can answer."""

    def refuse(path):
        raise AssertionError(f"{path} was decoded again")

    monkeypatch.setattr(semexp, "_decode_info", refuse)


def test_a_split_read_twice_is_the_same_value_the_second_time_from_its_kept_copy(tmp_path, monkeypatch):
    save_split(tmp_path / "data", "val", [draw_two_room_house("Tiny"), draw_two_room_house("Wee", 130, 210)])
    path = tmp_path / "data" / "val" / "val_info.pbz2"
    first = read_info(path)
    assert decoded_maps.cache_file(path).is_file()
    _undecodable(monkeypatch)
    second = read_info(path)
    assert _same(first, second)
    tiny = load_split(tmp_path / "data", "val")["Tiny"][0]
    assert (tiny.navigable == draw_two_room_house("Tiny").navigable).all()


def test_every_kind_of_value_the_format_holds_comes_back_exactly(tmp_path, monkeypatch):
    """Bits for 0/1 arrays of any dtype; every other array (-0.0, NaN, counts) as it was; numbers of
    every kind, int and str keys, an empty array."""
    value = {
        "Aloha": {
            0: {
                "sem_map": (np.arange(60).reshape(3, 4, 5) % 3 == 0).astype(np.float64),
                "counts": np.arange(12, dtype=np.int32).reshape(3, 4),
                "signed": np.array([0.0, -0.0, 1.0]),
                "odd": np.array([0.5, np.nan, np.inf]),
                "flags": np.array([True, False]),
                "none": np.zeros((0, 2)),
                "floor_height": -0.25,
                "level": 2,
                "open": True,
                "name": "Aloha",
            }
        }
    }
    path = tmp_path / "val_info.pbz2"
    _write(path, value)
    read_info(path)
    _undecodable(monkeypatch)
    back = read_info(path)
    assert _same(back, value)
    assert np.signbit(back["Aloha"][0]["signed"][1])


def test_an_edited_file_is_never_read_from_the_copy_of_its_old_bytes(tmp_path):
    path = tmp_path / "val_info.pbz2"
    _write(path, {"A": {0: {"floor_height": 0.0}}})
    read_info(path)
    _write(path, {"A": {0: {"floor_height": 3.0}}})
    assert read_info(path)["A"][0]["floor_height"] == 3.0


def test_a_copy_that_cannot_be_read_is_decoded_again_and_rewritten(tmp_path, monkeypatch):
    path = tmp_path / "val_info.pbz2"
    value = {"A": {0: {"sem_map": np.ones((2, 3, 3))}}}
    _write(path, value)
    read_info(path)
    kept = decoded_maps.cache_file(path)
    whole = kept.read_bytes()
    for broken in (b"not a zip file", whole[: len(whole) // 2], whole[:-30]):
        kept.write_bytes(broken)
        assert _same(read_info(path), value)
    _undecodable(monkeypatch)
    assert _same(read_info(path), value)


def test_an_unwritable_cache_costs_one_warning_line_and_nothing_else(tmp_path, monkeypatch):
    blocker = tmp_path / "a-file"
    blocker.write_text("in the way")
    monkeypatch.setenv(CACHE_ENV, str(blocker))
    path = tmp_path / "val_info.pbz2"
    value = {"A": {0: {"sem_map": np.ones((2, 3, 3))}}}
    _write(path, value)
    with pytest.warns(RuntimeWarning, match=r"decoded maps.*is a file.*will be decoded again") as caught:
        assert _same(read_info(path), value)
    assert all("\n" not in str(w.message) for w in caught)


def test_a_value_the_cache_could_not_give_back_exactly_is_not_kept(tmp_path):
    path = tmp_path / "val_info.pbz2"
    for value in ({"A": {0: [1, 2]}}, {"A": {(0, 1): 1.0}}, {"A": {0: np.float64(1.0)}}):
        _write(path, value)
        assert _same(read_info(path), value)
        assert not decoded_maps.cache_file(path).exists()


def test_a_small_file_decodes_without_leaving_a_copy(tmp_path, monkeypatch):
    monkeypatch.setattr(decoded_maps, "_MIN_BYTES", 4 * 2 * 3 * 3 * 8)  # the bytes of four floors below
    path = tmp_path / "val_info.pbz2"
    small = {"A": {f: {"sem_map": np.ones((2, 3, 3))} for f in range(3)}}
    _write(path, small)
    assert _same(read_info(path), small) and not decoded_maps.cache_file(path).exists()
    _write(path, {"A": {f: {"sem_map": np.ones((2, 3, 3))} for f in range(4)}})
    read_info(path)
    assert decoded_maps.cache_file(path).exists()

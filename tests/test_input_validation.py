"""Every bad input is one line naming the problem and the valid choices; nothing is silently wrong.

One test per rule of the episode and map formats and of ``render``'s paths and pose, each with the
input that used to give a traceback or a wrong result (tests/test_fuzz.py searches for more).
"""

from __future__ import annotations

import bz2
import gzip
import json
import math
import pickle
import re

import numpy as np
import pytest
from conftest import draw_two_room_house
from PIL import Image

from l3mvn.core.categories import GIBSON_CATEGORIES
from l3mvn.core.config import Config, override
from l3mvn.core.errors import L3MVNError
from l3mvn.core.types import Pose
from l3mvn.run.cli import main
from l3mvn.world.datasets import load_episode_set
from l3mvn.world.episodes import episode_record, generate_episodes, read_episode_file, write_episode_file
from l3mvn.world.scenes.scene import SceneMap
from l3mvn.world.scenes.semexp import load_split

SCENE = draw_two_room_house()
_DROP = object()  # a field value meaning "leave the field out"


def _record(**changes) -> dict:
    """A valid episode record of the two-room house (a navigable start, facing 0.3 rad), changed."""
    r, c = np.argwhere(SCENE.navigable)[len(np.argwhere(SCENE.navigable)) // 2]
    position, rotation = SCENE.pose_to_habitat(Pose(*SCENE.cell_center(int(r), int(c)), 0.3))
    rec = {
        "episode_id": 0,
        "scene_id": "gibson_semantic/Tiny.glb",
        "start_position": position,
        "start_rotation": rotation,
        "object_category": "toilet",
        "object_id": 1,
        "floor_id": 0,
        "info": {"geodesic_distance": 4.2},
    }
    rec.update(changes)
    return {k: v for k, v in rec.items() if v is not _DROP}


def _read(tmp_path, *records):
    path = tmp_path / "Tiny_episodes.json.gz"
    path.write_bytes(gzip.compress(json.dumps({"episodes": list(records)}).encode()))
    return read_episode_file(path, {0: SCENE})


def _refused(match: str, fn, *args):
    with pytest.raises(L3MVNError, match=match) as info:
        fn(*args)
    assert "\n" not in str(info.value)
    return str(info.value)


# --- episodes -------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "changes,message",
    [
        ({"episode_id": "abc"}, r"episode_id must be a whole number from 0 to 2\*\*63 - 1, got 'abc'"),
        ({"episode_id": 0.7}, r"episode_id must be a whole number .*got 0\.7"),
        ({"episode_id": True}, r"episode_id must be a whole number .*got True"),
        ({"episode_id": -1}, r"episode_id must be a whole number from 0"),
        ({"episode_id": 10**400}, r"episode_id must be a whole number"),
        ({"floor_id": 0.7}, r"floor_id must be a floor of this scene \(a whole number: 0\), got 0\.7"),
        ({"floor_id": "x"}, r"floor_id must be a floor of this scene \(a whole number: 0\), got 'x'"),
        ({"floor_id": 1}, r"floor_id must be a floor of this scene \(a whole number: 0\), got 1"),
        ({"object_id": "x"}, r"object_id must be a whole number from -1"),
        (
            {"start_position": [1e308, 0.0, 1e308]},
            r"lies outside the map of Tiny/0, which spans x 0\.\.10\.00 m, y 0\.\.6\.00 m",
        ),
        ({"start_position": ["1.5", 0.0, 2.0]}, r"start_position must be a list of 3 numbers \(p0, p1 up, p2\)"),
        ({"start_position": [1.0, 2.0]}, r"start_position must be a list of 3 numbers"),
        ({"start_position": [10**400, 0, 1]}, r"non-finite start_position"),
        (
            {"start_rotation": [0, 0, 0, 0]},
            r"start_rotation \[0, 0, 0, 0\] must be a unit quaternion \(w, x, y, z\); its norm is 0",
        ),
        ({"start_rotation": [2.0, 0, 0, 0]}, r"must be a unit quaternion .*its norm is 2"),
        ({"start_rotation": [0.0, 0.0, 0.0, 1.0]}, r"must be a rotation about the up axis .*\(x, y, z, w\) order\?"),
        ({"start_rotation": [1, 0, 0]}, r"start_rotation must be a list of 4 numbers \(w, x, y, z\)"),
        ({"object_category": ["toilet"]}, r"unknown category \['toilet'\]; valid: chair, couch"),
        ({"scene_id": 5}, r"scene_id must be a string such as 'gibson_semantic/Tiny.glb', got 5"),
        ({"info": "far"}, r"info must be an object, got 'far'"),
        ({"info": {"geodesic_distance": -1}}, r"info.geodesic_distance must be a finite number >= 0"),
        ({"info": {"geodesic_distance": "4"}}, r"info.geodesic_distance must be a finite number >= 0"),
        ({"start_position": _DROP}, r"lacks 'start_position'"),
    ],
)
def test_a_bad_episode_field_is_one_line_naming_it(tmp_path, changes, message):
    assert "Tiny_episodes.json.gz: episode #0" in _refused(message, _read, tmp_path, _record(**changes))


def test_a_valid_record_reads_back_exactly(tmp_path):
    (ep,) = _read(tmp_path, _record())
    assert (ep.episode_id, ep.floor, ep.goal, ep.object_id, ep.geodesic_distance_m) == (0, 0, "toilet", 1, 4.2)
    assert math.isclose(ep.start.heading, 0.3)


def test_integral_floats_are_whole_numbers_and_missing_ids_are_the_index(tmp_path):
    """JSON has one number type: 3.0 is the id 3, floor 0.0 is floor 0 (0.7 is an error above)."""
    a, b = _read(tmp_path, _record(episode_id=3.0, floor_id=0.0), _record(episode_id=_DROP, floor_id=_DROP))
    assert (a.episode_id, a.floor, b.episode_id, b.floor) == (3, 0, 1, 0)
    assert type(a.episode_id) is int and type(a.floor) is int


def test_a_slightly_off_unit_rotation_is_normalised(tmp_path):
    rot = _record()["start_rotation"]
    (exact,) = _read(tmp_path, _record())
    (scaled,) = _read(tmp_path, _record(start_rotation=[v * 1.004 for v in rot]))
    assert math.isclose(exact.start.heading, scaled.start.heading, abs_tol=1e-12)


def test_duplicate_episode_ids_name_both_indices(tmp_path):
    _refused(
        r"episodes #1 and #3 both have episode_id 7; ids must be unique within a scene file",
        _read,
        tmp_path,
        _record(episode_id=1),
        _record(episode_id=7),
        _record(episode_id=2),
        _record(episode_id=7.0),
    )


def test_unknown_geodesic_distance_round_trips(tmp_path):
    """Episodes read without ``info`` have NaN distance; writing and reading them must work."""
    (ep,) = _read(tmp_path, _record(info=None))
    assert math.isnan(ep.geodesic_distance_m)
    path = write_episode_file(tmp_path / "again" / "Tiny_episodes.json.gz", [ep], {0: SCENE})
    assert math.isnan(read_episode_file(path, {0: SCENE})[0].geodesic_distance_m)


@pytest.mark.parametrize(
    "blob,message",
    [
        (gzip.compress(b"[" * 100_000), "corrupt or truncated"),
        (gzip.compress(b"1" * 5000), "corrupt or truncated"),
        (gzip.compress(b'{"episodes": 3}'), r'expected \{"episodes": \[\.\.\.\]\}'),
        (b"not gzip", "corrupt or truncated"),
    ],
)
def test_an_unreadable_episode_file_is_one_line(tmp_path, blob, message):
    path = tmp_path / "Tiny_episodes.json.gz"
    path.write_bytes(blob)
    _refused(message, read_episode_file, path, {0: SCENE})


def test_an_episode_file_that_is_a_directory_says_so(tmp_path):
    (tmp_path / "Tiny_episodes.json.gz").mkdir()
    _refused("is a directory, not an episode file", read_episode_file, tmp_path / "Tiny_episodes.json.gz", {0: SCENE})


def test_writing_episodes_where_a_file_is_in_the_way_is_one_line(tmp_path):
    (tmp_path / "blocker").write_text("")
    _refused("cannot write", write_episode_file, tmp_path / "blocker" / "x.json.gz", [], {0: SCENE})


@pytest.mark.parametrize(
    "kwargs,message",
    [
        ({"min_distance_m": float("nan")}, "geodesic start distances need 0 <= min <= max"),
        ({"min_distance_m": 5.0, "max_distance_m": 1.0}, "got min 5.0, max 1.0"),
        ({"seed": -1}, "seed must be a whole number >= 0"),
    ],
)
def test_generation_refuses_impossible_settings(kwargs, message):
    _refused(message, lambda: generate_episodes(SCENE, 2, **kwargs))


# --- map files ------------------------------------------------------------------------------------


def _floor(**changes) -> dict:
    sem = np.zeros((3, 6, 6))
    sem[0, 1:5, 1:5] = 1
    rec = {"sem_map": sem, "origin": np.array([10, 20]), "floor_height": 0.5}
    rec.update(changes)
    return {k: v for k, v in rec.items() if v is not _DROP}


def _load(tmp_path, raw):
    (tmp_path / "val").mkdir(exist_ok=True)
    with bz2.BZ2File(tmp_path / "val" / "val_info.pbz2", "wb") as fh:
        pickle.dump(raw, fh)
    return load_split(tmp_path, "val")


@pytest.mark.parametrize(
    "raw,message",
    [
        ({"Ok": {"a": _floor()}}, r"scene Ok: floor keys must be whole numbers such as 0, got 'a'"),
        ({"Ok": {0.5: _floor()}}, r"floor keys must be whole numbers such as 0, got 0\.5"),
        ({"Ok": {True: _floor()}}, r"floor keys must be whole numbers such as 0, got True"),
        ({5: {0: _floor()}}, r"a scene key must be a plain name such as 'Allensville' .*got 5"),
        ({"../x": {0: _floor()}}, r"a scene key must be a plain name"),
        ({"Ok": {0: _floor(sem_map="abc")}}, r"scene Ok floor 0: sem_map must be numeric, got 'abc' \(str\)"),
        ({"Ok": {0: _floor(sem_map=[[[1, 0]], [[0]]])}}, r"sem_map must be numeric"),
        (
            {"Ok": {0: _floor(sem_map=np.zeros((3, 4, 4), complex))}},
            r"an array of complex128: a SemExp map holds only numeric",
        ),
        ({"Ok": {0: _floor(sem_map=np.zeros((3, 0, 4)))}}, r"sem_map must be \(channels, H, W\) with 2-16 channels"),
        ({"Ok": {0: _floor(origin="abc")}}, r"origin must be numeric"),
        ({"Ok": {0: _floor(origin=np.array([np.nan, 0.0]))}}, r"origin must be two finite numbers \(ox_cm, oy_cm\)"),
        ({"Ok": {0: _floor(origin=[1e308, 0.0])}}, r"origin must be two finite numbers .* within 1e\+09 cm"),
        (
            {"Ok": {0: _floor(origin=np.zeros((2, 1)))}},
            r"origin must be two finite numbers .*got an array of shape \(2, 1\)",
        ),
        ({"Ok": {0: _floor(floor_height="1.5")}}, r"floor_height must be numeric, got '1\.5'"),
        ({"Ok": {0: _floor(floor_height=float("nan"))}}, r"floor_height must be one finite number"),
        ({"Ok": {0: _floor(floor_height=True)}}, r"floor_height must be numeric"),
        ({"Ok": {0: _floor(origin=_DROP)}}, r"record lacks 'origin' \(the format has sem_map, origin, floor_height\)"),
        ({"Ok": {0: _floor(floor_height=_DROP)}}, r"record lacks 'floor_height'"),
    ],
)
def test_a_bad_map_record_is_one_line_naming_it(tmp_path, raw, message):
    _refused(message, _load, tmp_path, raw)


def test_map_records_of_every_plain_dtype_load(tmp_path):
    sem = np.zeros((2, 5, 5), np.uint8)
    sem[0, 1:4, 1:4] = 1
    floors = _load(
        tmp_path, {"Ok": {np.int64(2): _floor(sem_map=sem.astype(bool), origin=[1, 2], floor_height=np.int64(3))}}
    )["Ok"]
    assert list(floors) == [2] and type(next(iter(floors))) is int
    assert floors[2].origin_cm == (1.0, 2.0) and floors[2].floor_height_m == 3.0 and floors[2].navigable.sum() == 9


def test_a_dataset_that_is_a_file_or_an_overlong_name_is_one_line(tmp_path):
    (tmp_path / "file").write_text("")
    _refused("is a file; give the dataset directory", load_split, tmp_path / "file", "val")
    _refused("File name too long", load_split, tmp_path / ("a" * 300), "val")


def test_scene_maps_refuse_non_finite_geometry():
    nav = np.ones((4, 4), bool)
    with pytest.raises(L3MVNError, match="resolution_m must be a positive finite number"):
        SceneMap("S", 0, GIBSON_CATEGORIES[:1], nav, np.zeros((1, 4, 4), bool), resolution_m=float("nan"))
    with pytest.raises(L3MVNError, match="origin_cm must be two finite numbers"):
        SceneMap("S", 0, GIBSON_CATEGORIES[:1], nav, np.zeros((1, 4, 4), bool), origin_cm=(float("inf"), 0.0))


def test_scene_maps_know_their_extent(tiny_scene):
    assert tiny_scene.extent_m == (10.0, 6.0)
    assert tiny_scene.contains(0.0, 0.0) and tiny_scene.contains(9.99, 5.99)
    assert not any(tiny_scene.contains(x, y) for x, y in [(10.0, 1), (1, 6.0), (-0.01, 1), (1e308, 1), (math.nan, 1)])


# --- datasets ---------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "kwargs,message",
    [
        ({"houses": 2.5}, r"--houses must be a whole number >= 1, got 2\.5"),
        ({"episodes_per_house": 0}, r"--episodes-per-house must be a whole number >= 1, got 0"),
        ({"seed": True}, r"seed must be a whole number >= 0, got True"),
    ],
)
def test_procedural_episode_sets_refuse_non_whole_counts(kwargs, message):
    _refused(message, lambda: load_episode_set(None, "val", **kwargs))


# --- render ---------------------------------------------------------------------------------------


def _render(tiny_dataset, *extra) -> list[str]:
    return ["render", "--dataset", str(tiny_dataset), "--split", "val", "--scene", "Tiny", "--frame", "24x32", *extra]


@pytest.mark.parametrize(
    "pose,message",
    [
        (
            "1e6,1e6,0",
            r"--pose 1e\+06,1e\+06 lies outside the map of Tiny/0, which spans x 0\.\.10\.00 m, y 0\.\.6\.00 m",
        ),
        ("-0.5,2,0", r"--pose -0\.5,2 lies outside the map of Tiny/0"),
        ("0.1,0.1,0", r"--pose 0\.1,0\.1 is off the floor of Tiny/0: cell \(2, 2\) is a wall, furniture or an object"),
        ("5.0,1.0,0", r"is off the floor of Tiny/0: cell \(20, 100\)"),  # the wall between the rooms
        ("nan,2,0", r"--pose needs finite numbers, got 'nan,2,0'"),
        ("2,3", r"--pose must be X,Y,HEADING_DEG \(metres, degrees\), got '2,3'"),
        ("", r"--pose must be X,Y,HEADING_DEG \(metres, degrees\), got ''"),
    ],
)
def test_render_refuses_a_pose_off_the_map_or_floor(tiny_dataset, tmp_path, capsys, pose, message):
    assert main(_render(tiny_dataset, f"--pose={pose}", "--out", str(tmp_path / "a.png"))) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and len(err.splitlines()) == 1
    assert re.search(message, err), err
    assert not (tmp_path / "a.png").exists()


def _out_error(tiny_dataset, out, capsys) -> str:
    assert main(_render(tiny_dataset, "--out", str(out))) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and len(err.splitlines()) == 1
    return err


def test_render_names_the_valid_extensions(tiny_dataset, tmp_path, capsys):
    err = _out_error(tiny_dataset, tmp_path / "x.xyz", capsys)
    assert "unknown image extension '.xyz'; valid: " in err and ".png" in err and ".jpg" in err
    assert ".xbm" not in err  # PIL knows XBM but cannot write an RGB image in it
    assert "XBM cannot hold an RGB image" in _out_error(tiny_dataset, tmp_path / "x.xbm", capsys)
    assert "no image extension; valid: " in _out_error(tiny_dataset, tmp_path / "frame", capsys)


def test_render_refuses_a_directory_or_an_unwritable_out(tiny_dataset, tmp_path, capsys):
    assert f"--out {tmp_path} is a directory; give an image file such as {tmp_path / 'frame.png'}" in _out_error(
        tiny_dataset, tmp_path, capsys
    )
    (tmp_path / "blocker").write_text("")
    assert "cannot write there" in _out_error(tiny_dataset, tmp_path / "blocker" / "a.png", capsys)
    assert "File name too long" in _out_error(tiny_dataset, tmp_path / ("a" * 300 + ".png"), capsys)


def test_render_writes_the_format_its_extension_names(tiny_dataset, tmp_path):
    out = tmp_path / "deep" / "frame.JPG"
    assert main(_render(tiny_dataset, "--pose", "2.5,3.0,90", "--out", str(out))) == 0
    assert Image.open(out).format == "JPEG"


# --- defects the fuzzing found outside the parsers -----------------------------------------------


def test_config_refuses_a_zero_map_input_height():
    with pytest.raises(L3MVNError, match="map_input_height and map_input_width must be >= 1"):
        override(Config(), ["agent.map_input_height=0"])


def test_generate_into_a_file_is_one_line(tmp_path):
    (tmp_path / "file").write_text("")
    assert main(["episodes", "generate", "--houses", "1", "--per-scene", "1", "--out", str(tmp_path / "file")]) == 2


def test_episode_records_written_by_the_library_are_valid_input(tmp_path):
    """The writer and the reader agree on every field (the reader is strict, so check the writer)."""
    eps = generate_episodes(SCENE, 4, seed=2)
    records = [episode_record(ep, SCENE) for ep in eps]
    assert [e.episode_id for e in _read(tmp_path, *records)] == [e.episode_id for e in eps]

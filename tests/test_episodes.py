import gzip
import json
import math

import numpy as np
import pytest
from conftest import GIBSON, needs_gibson

from l3mvn.core.config import Config
from l3mvn.core.errors import L3MVNError
from l3mvn.core.types import Pose
from l3mvn.world.episodes import (
    episode_file,
    generate_episodes,
    read_episode_file,
    read_episodes,
    write_episode_file,
)
from l3mvn.world.scenes.semexp import load_split
from l3mvn.world.task.regions import goal_region


def test_habitat_pose_round_trips_through_our_frame(tiny_scene):
    pose = Pose(3.2, 1.7, 0.8)
    position, rotation = tiny_scene.pose_to_habitat(pose)
    back = tiny_scene.pose_from_habitat(position, rotation)
    assert math.isclose(back.x, pose.x) and math.isclose(back.y, pose.y)
    assert math.isclose(math.cos(back.heading - pose.heading), 1.0)


def test_habitat_position_maps_to_the_documented_cell(tiny_scene):
    ox, oy = tiny_scene.origin_cm
    p0, p2 = 1.33, 2.71
    pose = tiny_scene.pose_from_habitat([p0, 0.0, p2], [1, 0, 0, 0])
    assert tiny_scene.cell_of(pose.x, pose.y) == (int((p0 - oy / 100) * 20), int((p2 - ox / 100) * 20))


def test_habitat_identity_rotation_faces_minus_z_which_is_minus_columns(tiny_scene):
    pose = tiny_scene.pose_from_habitat([2.0, 0.0, 2.0], [1.0, 0.0, 0.0, 0.0])
    assert math.isclose(math.cos(pose.heading), -1.0, abs_tol=1e-9)


def test_generated_episodes_start_on_navmesh_with_reachable_goal_in_range(tiny_scene):
    eps = generate_episodes(tiny_scene, 12, seed=3)
    assert len(eps) == 12
    for ep in eps:
        r, c = tiny_scene.cell_of(ep.start.x, ep.start.y)
        assert tiny_scene.navigable[r, c]
        d = goal_region(tiny_scene, ep.goal, Config()).distance_at(ep.start.x, ep.start.y)
        assert 1.0 <= d <= 30.0 and math.isclose(d, ep.geodesic_distance_m, abs_tol=1e-3)
    assert {ep.goal for ep in eps} == set(tiny_scene.present_goals())


def test_generation_is_deterministic_for_a_seed(tiny_scene):
    a = generate_episodes(tiny_scene, 6, seed=5)
    b = generate_episodes(tiny_scene, 6, seed=5)
    c = generate_episodes(tiny_scene, 6, seed=6)
    assert a == b and a != c


def test_episode_files_round_trip_in_semexp_format(tiny_scene, tmp_path):
    eps = generate_episodes(tiny_scene, 5, seed=0)
    path = write_episode_file(tmp_path / "Tiny_episodes.json.gz", eps, {0: tiny_scene})
    raw = json.load(gzip.open(path, "rt"))["episodes"][0]
    assert raw["scene_id"] == "gibson_semantic/Tiny.glb" and len(raw["start_rotation"]) == 4
    back = read_episode_file(path, {0: tiny_scene})
    for a, b in zip(eps, back):
        assert (a.episode_id, a.goal) == (b.episode_id, b.goal)
        assert math.isclose(a.start.x, b.start.x, abs_tol=1e-9) and math.isclose(a.start.y, b.start.y, abs_tol=1e-9)


def _write_raw(path, episodes):
    with gzip.open(path, "wt") as fh:
        json.dump({"episodes": episodes}, fh)


def test_episode_with_unknown_category_is_a_one_line_error(tiny_scene, tmp_path):
    rec = {
        "episode_id": 0,
        "scene_id": "x/Tiny.glb",
        "start_position": [1.0, 0, 1.0],
        "start_rotation": [1, 0, 0, 0],
        "object_category": "piano",
        "floor_id": 0,
    }
    _write_raw(tmp_path / "Tiny_episodes.json.gz", [rec])
    with pytest.raises(L3MVNError, match="unknown category 'piano'.*valid: chair"):
        read_episode_file(tmp_path / "Tiny_episodes.json.gz", {0: tiny_scene})


def test_episode_start_off_the_navmesh_is_rejected_naming_the_file(tiny_scene, tmp_path):
    pos, rot = tiny_scene.pose_to_habitat(Pose(0.1, 0.1, 0.0))  # in the outer wall
    rec = {
        "episode_id": 7,
        "scene_id": "x/Tiny.glb",
        "start_position": pos,
        "start_rotation": rot,
        "object_category": "toilet",
        "floor_id": 0,
    }
    path = tmp_path / "Tiny_episodes.json.gz"
    _write_raw(path, [rec])
    with pytest.raises(L3MVNError, match=r"Tiny_episodes.json.gz.*off the navigable area"):
        read_episode_file(path, {0: tiny_scene})


def test_non_finite_start_is_rejected(tiny_scene, tmp_path):
    rec = {
        "episode_id": 0,
        "scene_id": "x/Tiny.glb",
        "start_position": [float("nan"), 0, 1.0],
        "start_rotation": [1, 0, 0, 0],
        "object_category": "toilet",
        "floor_id": 0,
    }
    path = tmp_path / "Tiny_episodes.json.gz"
    path.write_bytes(gzip.compress(json.dumps({"episodes": [rec]}).encode()))
    with pytest.raises(L3MVNError, match="non-finite"):
        read_episode_file(path, {0: tiny_scene})


def test_truncated_episode_file_is_reported_as_corrupt(tiny_scene, tmp_path):
    eps = generate_episodes(tiny_scene, 3, seed=0)
    path = write_episode_file(tmp_path / "Tiny_episodes.json.gz", eps, {0: tiny_scene})
    path.write_bytes(path.read_bytes()[:-10])
    with pytest.raises(L3MVNError, match="corrupt or truncated"):
        read_episode_file(path, {0: tiny_scene})


def test_tiny_dataset_loads_every_episode(tiny_dataset):
    scenes = load_split(tiny_dataset, "val")
    eps = read_episodes(tiny_dataset, "val", scenes)
    assert len(eps) == 8 and {e.scene for e in eps} == {"Tiny", "Wee"}


def test_missing_content_dir_says_how_to_generate(tiny_dataset):
    scenes = load_split(tiny_dataset, "val")
    (tiny_dataset / "val" / "content" / "Tiny_episodes.json.gz").unlink()
    (tiny_dataset / "val" / "content" / "Wee_episodes.json.gz").unlink()
    with pytest.raises(L3MVNError, match="holds no episodes"):
        read_episodes(tiny_dataset, "val", scenes)


@needs_gibson
def test_gibson_houses_each_get_episodes_with_a_path():
    scenes = load_split(GIBSON, "train")
    assert len(scenes) == 25
    for floors in scenes.values():
        eps = generate_episodes(floors[0], 6, seed=0)
        assert len(eps) == 6
        assert all(np.isfinite(e.geodesic_distance_m) for e in eps)
    assert episode_file(GIBSON, "train", "X").name == "X_episodes.json.gz"

"""Official ObjectNav episode files (habitat's schema): formats, the category tables, and every way a
file can be wrong as one line (issue 14 item 1). The files are written by the HM3D exporter."""

from __future__ import annotations

import gzip
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("trimesh")
pytest.importorskip("embreex")

from l3mvn.core.categories import GOAL_CATEGORIES
from l3mvn.core.config import SUCCESS_RULES  # noqa: E402
from l3mvn.core.errors import L3MVNError  # noqa: E402
from l3mvn.run.cli import main  # noqa: E402
from l3mvn.world.datasets import load_episode_set  # noqa: E402
from l3mvn.world.datasets.hm3d_export import export_hm3d  # noqa: E402
from l3mvn.world.datasets.objectnav import FORMAT_RULES, dataset_rule, detect_format  # noqa: E402
from l3mvn.world.datasets.objectnav_files import HM3D_GOAL_NAMES  # noqa: E402
from l3mvn.world.scenes.categories import GOAL_NAMES, SCAN_CATEGORIES, goal_category, raw_category  # noqa: E402

SCENE = "procedural-0000"
MP3D_GOALS = (
    "chair",
    "table",
    "picture",
    "cabinet",
    "cushion",
    "sofa",
    "bed",
    "chest_of_drawers",
    "plant",
    "sink",
    "toilet",
    "stool",
    "towel",
    "tv_monitor",
    "shower",
    "bathtub",
    "counter",
    "fireplace",
    "gym_equipment",
    "seating",
    "clothes",
)


@pytest.fixture(scope="module")
def exported(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("hm3d1")
    export_hm3d(out, 1, floors=1, episodes_per_floor=3, seed=0)
    return out


def _content(exported: Path) -> dict:
    with gzip.open(exported / "objectnav_hm3d_v2" / "val" / "content" / f"{SCENE}.json.gz", "rt") as fh:
        return json.load(fh)


def _dataset(tmp_path: Path, exported: Path, content: dict, name: str = "objectnav_hm3d_v2") -> Path:
    """A copy of the exported dataset with ``content`` as its scene file."""
    root = tmp_path / name
    shutil.copytree(exported / "objectnav_hm3d_v2", root)
    with gzip.open(root / "val" / "content" / f"{SCENE}.json.gz", "wt") as fh:
        json.dump(content, fh)
    return root


def _refused(match: str, dataset: Path, scenes: Path | None):
    with pytest.raises(L3MVNError, match=match) as info:
        load_episode_set(dataset, "val", scenes_dir=scenes)
    assert "\n" not in str(info.value)
    return str(info.value)


# --- tables -------------------------------------------------------------------------------------


def test_goal_tables_cover_every_format():
    for name in HM3D_GOAL_NAMES.values():  # HM3D's six are our six
        assert goal_category(name, "x") in GOAL_CATEGORIES
    assert {goal_category(n, "x") for n in HM3D_GOAL_NAMES.values()} == set(GOAL_CATEGORIES)
    assert all(GOAL_NAMES[v] == k for k, v in HM3D_GOAL_NAMES.items())
    for name in MP3D_GOALS:  # MP3D's 21 all have a channel on a scan floor
        assert goal_category(name, "x") in SCAN_CATEGORIES
    with pytest.raises(L3MVNError, match=r"f.json: unknown object_category 'lamp'; valid: .*tv_monitor"):
        goal_category("lamp", "f.json")


def test_raw_names_map_only_what_they_mean():
    assert raw_category("Kitchen_Chair ") == "chair"
    assert raw_category("sofa") == "couch" and raw_category("flower pot") == "potted plant"
    assert raw_category("television") == "tv" and raw_category("toilet") == "toilet"
    assert raw_category("wall") is None and raw_category("stand") is None and raw_category("frame") is None
    assert all(raw_category(c) == c for c in SCAN_CATEGORIES)


def test_formats_from_scene_ids():
    assert detect_format("hm3d/val/00800-TEEsavR23oF/TEEsavR23oF.basis.glb") == "objectnav_hm3d_v1"
    assert detect_format("hm3d_v0.2/val/00800-TEEsavR23oF/TEEsavR23oF.basis.glb") == "objectnav_hm3d_v2"
    assert detect_format("data/scene_datasets/mp3d/2azQ1b91cZZ/2azQ1b91cZZ.glb") == "objectnav_mp3d"
    assert detect_format("gibson/Allensville.glb") == "objectnav_gibson"
    with pytest.raises(L3MVNError, match="names no known scan dataset; valid: paths under hm3d"):
        detect_format("replica/room_0/mesh.ply")
    assert set(FORMAT_RULES.values()) <= set(SUCCESS_RULES)


def test_default_rule_follows_the_dataset(exported, tiny_dataset):
    assert dataset_rule(None, "val") == "semexp"
    assert dataset_rule(tiny_dataset, "val") == "semexp"
    assert dataset_rule(exported / "objectnav_hm3d_v2", "val") == "hm3d"


# --- reading ------------------------------------------------------------------------------------


def test_reads_habitat_episodes(exported):
    eset = load_episode_set(exported / "objectnav_hm3d_v2", "val", scenes_dir=exported / "scene_datasets")
    content = _content(exported)
    assert eset.format == "objectnav_hm3d_v2" and len(eset.episodes) == len(content["episodes"]) == 3
    for ep, rec in zip(eset.episodes, content["episodes"]):
        assert ep.episode_id == int(rec["episode_id"]) and ep.goal == GOAL_NAMES[rec["object_category"]]
        assert ep.geodesic_distance_m == rec["info"]["geodesic_distance"]
        floor = eset.scene_of(ep)
        position, rotation_wxyz = floor.pose_to_habitat(ep.start)
        assert np.allclose([position[0], position[2]], [rec["start_position"][0], rec["start_position"][2]])
        w, x, y, z = rotation_wxyz
        quat = np.array([x, y, z, w])
        assert np.allclose(quat, rec["start_rotation"]) or np.allclose(-quat, rec["start_rotation"])


def test_scans_are_found_by_the_tail_of_the_scene_id(exported):
    """``--scenes`` may be the scene_datasets root, the hm3d_v0.2 folder or the split folder."""
    for scenes in (
        exported / "scene_datasets",
        exported / "scene_datasets" / "hm3d_v0.2",
        exported / "scene_datasets" / "hm3d_v0.2" / "val",
    ):
        eset = load_episode_set(exported / "objectnav_hm3d_v2", "val", scenes_dir=scenes)
        assert list(eset.scenes) == [SCENE]


def test_mp3d_layout_with_a_z_up_stage(exported, tmp_path):
    """An MP3D file (``mp3d/<scene>/<scene>.glb``, stages Z-up per its scene dataset config) reads
    under MP3D's rule, the stage turned Y-up as habitat turns it."""
    import trimesh

    src = exported / "scene_datasets" / "hm3d_v0.2" / "val" / f"00000-{SCENE}"
    dst = tmp_path / "scans" / "mp3d" / SCENE
    dst.mkdir(parents=True)
    y_up_to_z_up = np.array([[1, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]], float)
    for suffix in (".glb", ".semantic.glb"):
        scene = trimesh.load(src / f"{SCENE}{suffix}", force="scene", process=False)
        scene.apply_transform(y_up_to_z_up)
        (dst / f"{SCENE}{suffix}").write_bytes(scene.export(file_type="glb"))
    shutil.copy(src / f"{SCENE}.semantic.txt", dst)
    (tmp_path / "scans" / "mp3d" / "mp3d.scene_dataset_config.json").write_text(
        json.dumps({"stages": {"default_attributes": {"up": [0, 0, 1], "front": [0, 1, 0]}}})
    )
    content = _content(exported)
    for rec in content["episodes"]:
        rec["scene_id"] = f"mp3d/{SCENE}/{SCENE}.glb"
    dataset = _dataset(tmp_path, exported, content, "objectnav_mp3d")
    eset = load_episode_set(dataset, "val", scenes_dir=tmp_path / "scans")
    assert eset.format == "objectnav_mp3d" and dataset_rule(dataset, "val") == "mp3d"
    hm3d = load_episode_set(exported / "objectnav_hm3d_v2", "val", scenes_dir=exported / "scene_datasets")
    a, b = eset.scenes[SCENE][0], hm3d.scenes[SCENE][0]
    assert a.shape == b.shape and (a.navigable == b.navigable).mean() > 0.99
    assert [ep.start for ep in eset.episodes] == [ep.start for ep in hm3d.episodes]


def test_a_scan_without_semantic_annotation_says_its_goals_cannot_be_seen(exported, tmp_path, caplog):
    """A stage with no ``.semantic.glb`` / ``.semantic.txt`` (MP3D's .house, Gibson's scene graphs)
    loads, and says that no goal can be seen rather than failing every episode silently."""
    scans = tmp_path / "scene_datasets"
    shutil.copytree(exported / "scene_datasets", scans)
    for suffix in (".semantic.glb", ".semantic.txt"):
        (scans / "hm3d_v0.2" / "val" / f"00000-{SCENE}" / f"{SCENE}{suffix}").unlink()
    with caplog.at_level("WARNING", logger="l3mvn.world.datasets.objectnav"):
        eset = load_episode_set(exported / "objectnav_hm3d_v2", "val", scenes_dir=scans)
    assert eset.episodes and "no goal object can be seen" in caplog.text and "--sim habitat" in caplog.text


# --- one line for every bad input ---------------------------------------------------------------


def test_corrupt_split_file(exported, tmp_path):
    dataset = _dataset(tmp_path, exported, _content(exported))
    (dataset / "val" / "val.json.gz").write_bytes(b"not gzip at all")
    _refused("val.json.gz is corrupt or truncated", dataset, exported / "scene_datasets")


def test_rotation_in_the_wrong_order(exported, tmp_path):
    content = _content(exported)
    x, y, z, w = content["episodes"][0]["start_rotation"]
    content["episodes"][0]["start_rotation"] = [w, x, y, z]
    if abs(w) < 0.02:  # a yaw of 180 degrees reads the same in both orders: make it a 90 degree one
        content["episodes"][0]["start_rotation"] = [0.7071, 0.0, 0.7071, 0.0]
    dataset = _dataset(tmp_path, exported, content)
    _refused(
        r"episode #0 \(id 0\): start_rotation .* must be a rotation about the up axis \(0, y, 0, w in habitat's "
        r"\(x, y, z, w\) order\)",
        dataset,
        exported / "scene_datasets",
    )


def test_unknown_category(exported, tmp_path):
    content = _content(exported)
    content["episodes"][1]["object_category"] = "lamp"
    _refused(
        r"episode #1 \(id 1\): unknown object_category 'lamp'; valid: bathtub, bed",
        _dataset(tmp_path, exported, content),
        exported / "scene_datasets",
    )


def test_duplicate_episode_ids(exported, tmp_path):
    content = _content(exported)
    content["episodes"][2]["episode_id"] = content["episodes"][0]["episode_id"]
    _refused(
        "episode #2: episode_id 0 repeats .*#0 of scene procedural-0000",
        _dataset(tmp_path, exported, content),
        exported / "scene_datasets",
    )


def test_bad_view_points(exported, tmp_path):
    content = _content(exported)
    key = next(iter(content["goals_by_category"]))
    content["goals_by_category"][key][0]["view_points"] = [{"agent_state": {"position": [0.0, "x", 0.0]}}]
    _refused(
        r"view_points\[0\]: agent_state.position must be a list of 3 numbers",
        _dataset(tmp_path, exported, content),
        exported / "scene_datasets",
    )


def test_start_outside_the_scan(exported, tmp_path):
    content = _content(exported)
    content["episodes"][0]["start_position"][0] += 100.0
    _refused(
        "start lies outside the scan's floor procedural-0000/0",
        _dataset(tmp_path, exported, content),
        exported / "scene_datasets",
    )


def test_missing_scans(exported, tmp_path):
    dataset = exported / "objectnav_hm3d_v2"
    _refused("is an objectnav_hm3d_v2 dataset: give its scan root with --scenes DIR", dataset, None)
    _refused(r"--scenes .* is not a directory", dataset, tmp_path / "nowhere")
    _refused(r"scan hm3d_v0.2/val/00000-procedural-0000/procedural-0000.glb is not under --scenes", dataset, tmp_path)
    scans = tmp_path / "scans"
    shutil.copytree(exported / "scene_datasets", scans)
    next(scans.rglob("*.semantic.txt")).unlink()
    _refused("procedural-0000.semantic.txt is missing beside it", dataset, scans)


def test_scenes_flag_needs_an_objectnav_dataset(tiny_dataset, tmp_path):
    with pytest.raises(L3MVNError, match="--scenes is for habitat ObjectNav datasets"):
        load_episode_set(tiny_dataset, "val", scenes_dir=tmp_path)
    with pytest.raises(L3MVNError, match="give --dataset too"):
        load_episode_set(None, "val", scenes_dir=tmp_path)


def test_cli_error_is_one_line(exported, capsys):
    code = main(["eval", "--dataset", str(exported / "objectnav_hm3d_v2"), "--split", "val", "--policy", "oracle"])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("error: ") and err.count("\n") == 1 and "--scenes DIR" in err


def test_a_scene_id_never_leaves_the_scan_root(exported, tmp_path):
    """A scan outside --scenes is not loaded, whether the scene_id climbs to it or names it outright."""
    root = tmp_path / "root"
    (root / "scene_datasets").mkdir(parents=True)
    outside = tmp_path / "outside"
    shutil.copytree(exported / "scene_datasets", outside)
    stage = next(outside.rglob("procedural-0000.glb"))
    for scene_id, match in (
        (
            f"../../outside/{stage.relative_to(outside)}",
            r"scene_id '\.\./\.\./outside/.*' would "
            r"leave --scenes .*root/scene_datasets: it must name a file inside it",
        ),
        (str(stage), r"scan /.*procedural-0000.glb is not under --scenes .*root/scene_datasets"),
    ):
        content = _content(exported)
        for episode in content["episodes"]:
            episode["scene_id"] = scene_id
        _refused(match, _dataset(tmp_path / str(len(scene_id)), exported, content), root / "scene_datasets")


def test_export_refuses_a_split_that_leaves_out(tmp_path):
    out = tmp_path / "out"
    for split in ("../../escape", "a/b", "..", ""):
        with pytest.raises(L3MVNError, match=r"^--split must be a plain name such as 'val'"):
            export_hm3d(out, 1, split=split)
    assert not out.exists() and not (tmp_path / "escape").exists()

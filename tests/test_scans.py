"""Scans on our renderer: a procedural house exported in HM3D's layout loads back as floors with the
scan's own triangles, and the official-schema episodes run on it (item 2 and 4 of issue 14)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("trimesh")
pytest.importorskip("embreex")

from l3mvn.core.categories import GOAL_CATEGORIES
from l3mvn.core.config import Config, TaskConfig  # noqa: E402
from l3mvn.core.errors import L3MVNError  # noqa: E402
from l3mvn.run.cli import main  # noqa: E402
from l3mvn.world.datasets import load_episode_set  # noqa: E402
from l3mvn.world.datasets.hm3d_export import STOREY_M, add_export_arguments, export_hm3d, run_export  # noqa: E402
from l3mvn.world.datasets.objectnav import geodesic_agreement  # noqa: E402
from l3mvn.world.scenes.categories import SCAN_CATEGORIES  # noqa: E402
from l3mvn.world.scenes.procedural import procedural_split  # noqa: E402
from l3mvn.world.scenes.scan import ScanFloor, find_floors, read_semantic_txt  # noqa: E402
from l3mvn.world.sim.simulator import BuiltinSimulator  # noqa: E402
from l3mvn.world.sim.world import build_world  # noqa: E402
from l3mvn.world.task.regions import goal_region  # noqa: E402

HM3D = Config(task=TaskConfig(success_rule="hm3d")).with_frame(120, 160)


@pytest.fixture(scope="module")
def exported(tmp_path_factory) -> Path:
    """One procedural house of two storeys, 4 episodes per storey, in HM3D's layout."""
    out = tmp_path_factory.mktemp("hm3d")
    export_hm3d(out, 1, floors=2, episodes_per_floor=4, seed=0)
    return out


@pytest.fixture(scope="module")
def eset(exported):
    return load_episode_set(exported / "objectnav_hm3d_v2", "val", scenes_dir=exported / "scene_datasets", cfg=HM3D)


def _source(exported: Path) -> list[str]:
    return [
        "--dataset",
        str(exported / "objectnav_hm3d_v2"),
        "--scenes",
        str(exported / "scene_datasets"),
        "--split",
        "val",
    ]


def test_export_writes_hm3d_layout(exported):
    scene = exported / "scene_datasets" / "hm3d_v0.2" / "val" / "00000-procedural-0000"
    names = sorted(p.name for p in scene.iterdir())
    assert names == ["procedural-0000.glb", "procedural-0000.semantic.glb", "procedural-0000.semantic.txt"]
    assert (exported / "scene_datasets" / "hm3d_v0.2" / "hm3d_annotated_basis.scene_dataset_config.json").is_file()
    lines = (scene / "procedural-0000.semantic.txt").read_text().splitlines()
    assert lines[0] == "HM3D Semantic Annotations" and lines[1].startswith("1,") and lines[1].endswith(',"wall",0')
    import gzip

    content = json.load(gzip.open(exported / "objectnav_hm3d_v2" / "val" / "content" / "procedural-0000.json.gz"))
    ep = content["episodes"][0]
    assert ep["scene_id"] == "hm3d_v0.2/val/00000-procedural-0000/procedural-0000.glb"
    assert isinstance(ep["episode_id"], str) and len(ep["start_rotation"]) == 4
    assert ep["object_category"] in {"chair", "sofa", "plant", "bed", "toilet", "tv_monitor"}
    key = f"procedural-0000.glb_{ep['object_category']}"
    assert content["goals_by_category"][key][0]["view_points"][0]["agent_state"]["position"]


def test_export_command_arguments(tmp_path, capsys):
    import argparse

    parser = argparse.ArgumentParser()
    add_export_arguments(parser)
    assert run_export(parser.parse_args(["--houses", "1", "--episodes-per-floor", "2", "--out", str(tmp_path)])) == 0
    assert "l3mvn eval --dataset" in capsys.readouterr().out
    with pytest.raises(L3MVNError, match="--floors must be a whole number >= 1"):
        export_hm3d(tmp_path, 1, floors=0)


def test_two_storeys_split_into_floors_found_by_rays(eset):
    floors = eset.scenes["procedural-0000"]
    assert sorted(floors) == [0, 1]
    assert [round(f.floor_height_m, 3) for f in floors.values()] == [0.0, STOREY_M]
    for floor in floors.values():
        assert isinstance(floor, ScanFloor) and floor.categories == SCAN_CATEGORIES
        assert set(floor.present_goals()) == set(GOAL_CATEGORIES)  # procedural houses hold all six
        assert floor.view_points and all(len(v) for v in floor.view_points.values())
        # The floor's world keeps its own storey only: nothing of the other one within the camera's reach.
        z = floor.mesh.vertices[:, 2]
        assert z.min() >= -1.01 and z.max() <= STOREY_M
    assert {ep.floor for ep in eset.episodes} == {0, 1}


def test_navigable_grid_matches_the_exported_map(eset):
    """The grid built from the mesh by rays covers the procedural map's navmesh (up to the cell
    borders a half-cell shift leaves ambiguous)."""
    maps = procedural_split(2, 0)
    for f, name in enumerate(sorted(maps)):
        ours, theirs = eset.scenes["procedural-0000"][f], maps[name][0]
        rows, cols = np.nonzero(theirs.navigable)
        x, y = theirs.cell_center(rows, cols)
        x = x + (theirs.origin_cm[0] - ours.origin_cm[0]) / 100.0
        y = y + (theirs.origin_cm[1] - ours.origin_cm[1]) / 100.0
        hit = np.zeros(len(rows), bool)
        for dx in (-0.01, 0.01):
            for dy in (-0.01, 0.01):
                hit |= ours.navigable[np.floor((y + dy) / 0.05).astype(int), np.floor((x + dx) / 0.05).astype(int)]
        assert hit.mean() > 0.95
        assert ours.navigable.sum() == pytest.approx(theirs.navigable.sum(), rel=0.08)


def test_find_floors_keeps_storeys_apart():
    from l3mvn.world.scenes.scan import _Hits

    heights = np.concatenate([np.zeros(2000), np.full(1200, 0.75), np.full(1500, 2.9), np.full(100, 1.5)])
    hits = _Hits(np.arange(heights.size), heights, heights + 2.0, np.ones(heights.size, bool))
    # 2000 and 1500 cells of 5 cm are 5 and 3.75 m2: floors; 0.75 m (a table) is too close to the
    # floor, 100 cells (0.25 m2, a landing) too small.
    assert find_floors(hits) == [0.0, 2.9]


def test_colours_from_the_texture_and_categories_from_the_semantic_mesh(eset):
    """Every triangle's colour is the exported material's (sampled from the texture at its UVs) and
    every goal triangle carries its goal category (semantic colour -> .semantic.txt -> table)."""
    maps = procedural_split(2, 0)
    scene = maps[sorted(maps)[0]][0]
    world = build_world(scene, HM3D.sim, rooms_only=True)
    floor = eset.scenes["procedural-0000"][0]
    mesh = floor.mesh
    exported_colours = {tuple(c) for c in np.round(world.tri_color * 255).astype(int)}
    loaded_colours = {tuple(c) for c in np.round(mesh.tri_color * 255).astype(int)}
    assert loaded_colours <= exported_colours and len(loaded_colours) > 10
    for goal in GOAL_CATEGORIES:
        exported_n = int((world.tri_category == scene.categories.index(goal) + 1).sum())
        loaded_n = int((mesh.tri_category == SCAN_CATEGORIES.index(goal) + 1).sum())
        assert exported_n > 0 and loaded_n == exported_n, goal


def test_simulator_renders_the_scan_labelled(eset):  # its speed is in docs/benchmarks.md, not timed here
    ep = next(e for e in eset.episodes if e.floor == 0)
    sim = BuiltinSimulator(eset.scene_of(ep), HM3D.sim)
    obs = sim.reset(ep)
    assert obs.rgb.shape == (120, 160, 3) and obs.rgb.std() > 5
    assert (obs.depth > 0).mean() > 0.5
    seen = set()
    for _ in range(12):  # a full turn shows some labelled object
        obs = sim.step("turn_left")
        seen |= set(np.unique(obs.semantic)) - {0}
    assert seen and max(seen) <= len(SCAN_CATEGORIES)


def test_geodesics_agree_with_the_file_within_5_percent(eset):
    pairs = geodesic_agreement(eset, HM3D)
    assert len(pairs) == len(eset.episodes)
    for key, theirs, ours in pairs:
        assert ours == pytest.approx(theirs, rel=0.05), key


def test_hm3d_rule_is_the_view_point_rule(eset):
    ep = eset.episodes[0]
    floor = eset.scene_of(ep)
    region = goal_region(floor, ep.goal, HM3D)
    points = floor.view_points[ep.goal]
    inside = region.distances_at(points[:, 0], points[:, 1])
    assert (inside == 0).mean() > 0.9  # the view points themselves succeed
    # Success is within 0.1 m of a view point (geodesic; a cell centre may lie a half-cell diagonal
    # off the point): nothing farther succeeds, however near the object it is.
    rows, cols = np.nonzero(region.region)
    x, y = floor.cell_center(rows, cols)
    d = np.min(np.hypot(x[:, None] - points[None, :, 0], y[:, None] - points[None, :, 1]), axis=1)
    assert d.max() <= 0.1 + 0.05 * math.sqrt(0.5) + 1e-6


def test_hm3d_rule_needs_view_points(tiny_scene):
    with pytest.raises(L3MVNError, match="needs the view points of an ObjectNav episode file"):
        goal_region(tiny_scene, "toilet", HM3D)


def test_oracle_succeeds_on_every_episode(exported, capsys):
    assert main(["eval", *_source(exported), "--policy", "oracle", "--frame", "120x160", "--json"]) == 0
    captured = capsys.readouterr()
    summary = json.loads(captured.out.strip().splitlines()[-1])
    assert summary["rule"] == "hm3d" and summary["success"] == 1.0 and summary["episodes"] == 8
    assert summary["dataset"]["format"] == "objectnav_hm3d_v2"
    assert "(objectnav_hm3d_v2)" in captured.err and "rule hm3d" in captured.err
    check = next(line for line in captured.err.splitlines() if line.startswith("geodesic check"))
    assert "on 8 episodes" in check and float(check.split("max ")[1].split("%")[0]) < 5.0
    assert 0.8 < summary["spl"] <= 1.0


def test_frontier_runs_to_the_end_under_the_hm3d_rule(exported, capsys):
    assert (
        main(
            [
                "eval",
                *_source(exported),
                "--policy",
                "frontier",
                "--frame",
                "120x160",
                "--episodes",
                "1",
                "--set",
                "sim.max_steps=80",
                "--json",
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert "success rule: hm3d" in out and "format objectnav_hm3d_v2" in out
    summary = json.loads(out.strip().splitlines()[-1])
    assert summary["episodes"] == 1 and summary["rule"] == "hm3d"


def test_render_and_list_a_scan(exported, tmp_path, capsys):
    png = tmp_path / "frame.png"
    assert main(["render", *_source(exported), "--frame", "60x80", "--floor", "1", "--out", str(png)]) == 0
    assert png.stat().st_size > 0
    assert main(["scenes", *_source(exported)]) == 0
    out = capsys.readouterr().out
    assert "objectnav_hm3d_v2" in out and "procedural-0000" in out


def test_semantic_txt_lines_are_checked(tmp_path):
    path = tmp_path / "x.semantic.txt"
    path.write_text('HM3D Semantic Annotations\n1,A0B1C2,"kitchen chair",3\n')
    (obj,) = read_semantic_txt(path).values()
    assert (obj.object_id, obj.rgb, obj.name, obj.region) == (1, 0xA0B1C2, "kitchen chair", 3)
    path.write_text('HM3D Semantic Annotations\n1,A0B1C2,"chair",3\n2,XYZ,"bed",1\n')
    with pytest.raises(L3MVNError, match=r"x.semantic.txt:3: expected id,HEXCOLOR"):
        read_semantic_txt(path)
    path.write_text('1,A0B1C2,"chair",3\n1,A0B1C3,"bed",1\n')
    with pytest.raises(L3MVNError, match="object id 1 appears twice"):
        read_semantic_txt(path)


def test_scene_shortest_path_uses_the_file_unless_unreachable(eset):
    from l3mvn.world.task import ObjectNavTask

    ep = eset.episodes[0]
    task = ObjectNavTask(eset.scene_of(ep), HM3D)
    assert task.shortest_path_length(ep) == ep.geodesic_distance_m
    other = next(g for g in GOAL_CATEGORIES if g != ep.goal)
    assert math.isfinite(task.shortest_path_length(ep, other))


def test_semantic_mesh_coloured_per_vertex(exported, eset, tmp_path):
    """HM3D paints object colours into the semantic mesh's texture (so does the export); a semantic
    mesh carrying them as vertex colours instead gives the same ids."""
    import shutil

    import trimesh

    from l3mvn.world.scenes.scan import _read_glb

    scans = tmp_path / "scans"
    shutil.copytree(exported / "scene_datasets", scans)
    path = next(scans.rglob("*.semantic.glb"))
    painted = _read_glb(path, (0.0, 1.0, 0.0), ids=True)  # one exact colour per triangle, from the texture
    vertices = painted.vertices[painted.faces.ravel()]
    colours = np.concatenate([np.repeat(painted.face_rgb, 3, axis=0), np.full((len(vertices), 1), 255)], axis=1)
    mesh = trimesh.Trimesh(
        vertices, np.arange(len(vertices)).reshape(-1, 3), vertex_colors=colours.astype(np.uint8), process=False
    )
    path.write_bytes(mesh.export(file_type="glb"))
    again = load_episode_set(exported / "objectnav_hm3d_v2", "val", scenes_dir=scans, cfg=HM3D)
    for f, floor in eset.scenes["procedural-0000"].items():
        assert np.array_equal(again.scenes["procedural-0000"][f].mesh.tri_category, floor.mesh.tri_category)


def _room(path: Path, step_m: float = 0.15, subdivisions: int = 0) -> Path:
    """A 6 x 4 m walled room with a raised half (``step_m`` up) and a 0.5 m bed, as a Y-up GLB."""
    import trimesh

    def box(lo, hi):
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        centre = trimesh.transformations.translation_matrix((lo + hi) / 2)
        return trimesh.creation.box(extents=hi - lo, transform=centre)

    parts = [box((0, -0.1, 0), (6, 0, 4)), box((4, 0, 0), (6, step_m, 4)), box((0.5, 0, 1), (1.7, 0.5, 3))]
    parts += [
        box((-0.1, 0, -0.1), (6.1, 2.5, 0)),
        box((-0.1, 0, 4), (6.1, 2.5, 4.1)),
        box((-0.1, 0, 0), (0, 2.5, 4)),
        box((6, 0, 0), (6.1, 2.5, 4)),
    ]
    mesh = trimesh.util.concatenate(parts)
    for _ in range(subdivisions):
        mesh = mesh.subdivide()
    path.write_bytes(mesh.export(file_type="glb"))
    return path


def test_steps_join_their_floor_and_furniture_does_not(tmp_path):
    """A room with a raised half (one 0.15 m step up: climbable) and a bed (0.5 m: not): the floor
    found by rays is the room's, the raised half is walkable from it, the bed is an obstacle."""
    from scipy import ndimage as ndi

    from l3mvn.world.scenes.scan import ScanFiles, load_scan

    path = _room(tmp_path / "room.glb")
    floors = load_scan("room", ScanFiles(path, None, None), HM3D.sim, goal_instances={}, view_points=[])
    assert list(floors) == [0] and floors[0].floor_height_m == pytest.approx(0.0, abs=1e-6)
    floor = floors[0]

    def navigable(x, z):  # habitat (x, z) -> our cell
        r, c = floor.cell_of(z - floor.origin_cm[0] / 100, x - floor.origin_cm[1] / 100)
        return bool(floor.navigable[r, c])

    assert navigable(2.8, 2.0) and navigable(5.0, 2.0)  # the room and its raised half
    assert not navigable(1.1, 2.0) and not navigable(-0.05, 2.0)  # the bed and a wall
    assert ndi.label(floor.navigable)[1] == 1  # one walkable piece: the step joins them


def test_rendered_mesh_merges_vertices_finer_than_the_setting(tmp_path):
    import dataclasses

    from l3mvn.world.scenes.scan import ScanFiles, load_scan

    # Subdivided 4 times, the 10 cm thick walls and 15 cm step have edges under a centimetre.
    files = ScanFiles(_room(tmp_path / "fine.glb", subdivisions=4), None, None)
    kept = load_scan(
        "room", files, dataclasses.replace(HM3D.sim, scan_vertex_merge_m=0.0), goal_instances={}, view_points=[]
    )[0]
    merged = load_scan("room", files, HM3D.sim, goal_instances={}, view_points=[])[0]
    assert merged.mesh.triangles.shape[0] < 0.8 * kept.mesh.triangles.shape[0]
    assert np.array_equal(merged.navigable, kept.navigable)  # the ground truth uses every triangle
    from l3mvn.core.types import Pose
    from l3mvn.world.sim.render import Renderer
    from l3mvn.world.sim.world import build_world

    view = Pose(*kept.cell_center(*np.argwhere(kept.navigable)[len(np.argwhere(kept.navigable)) // 2]), 0.0)
    a = Renderer(build_world(kept, HM3D.sim), HM3D.sim).render(view, 0.0)
    b = Renderer(build_world(merged, HM3D.sim), HM3D.sim).render(view, 0.0)
    assert np.abs(a.depth - b.depth).mean() < 0.02  # the same room, to a centimetre on average


def test_semantic_mesh_has_linear_vertex_colours_for_habitat(exported):
    """habitat-sim requires vertex colours on a semantic mesh and reads them as linear: converted back
    to sRGB bytes, every one is a colour of the .semantic.txt table."""
    import struct

    path = next(exported.rglob("*.semantic.glb"))
    glb = path.read_bytes()
    (json_len,) = struct.unpack_from("<I", glb, 12)
    header = json.loads(glb[20 : 20 + json_len])
    binary = glb[20 + json_len + 8 :]
    accessor = header["accessors"][header["meshes"][0]["primitives"][0]["attributes"]["COLOR_0"]]
    view = header["bufferViews"][accessor["bufferView"]]
    assert accessor["componentType"] == 5126 and accessor["type"] == "VEC4"
    linear = np.frombuffer(binary, "<f4", accessor["count"] * 4, view["byteOffset"]).reshape(-1, 4)[:, :3]
    srgb = np.where(linear <= 0.0031308, linear * 12.92, 1.055 * np.power(linear, 1 / 2.4) - 0.055)
    rgb = np.round(srgb * 255).astype(int)
    table = {o.rgb for o in read_semantic_txt(path.with_name(path.name.replace(".glb", ".txt"))).values()}
    assert {(r << 16) | (g << 8) | b for r, g, b in rgb} <= table

"""The scene audit: a goal in open floor is confirmable; one with no floor near it, one walled in and
one sealed in a closet each get their reason; the CLI; the 25 dev houses."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import draw_two_room_house
from scipy import ndimage as ndi

from l3mvn.core.categories import GIBSON_CATEGORIES
from l3mvn.core.config import Config
from l3mvn.core.grid import disk
from l3mvn.run.audit import REASONS, AuditConfig, FloorAuditor, audit_floor, audit_split
from l3mvn.run.cli import main
from l3mvn.world.scenes.scene import SceneMap
from l3mvn.world.sim.world import World, build_world
from l3mvn.world.task.regions import footprint_region, goal_region

CFG = Config().with_frame(120, 160)
DEV = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "gibson_semexp"


def draw(
    free_boxes: list[tuple[int, int, int, int]],
    objects: dict[str, list[tuple[int, int, int, int]]],
    shape: tuple[int, int] = (80, 80),
    walls: list[tuple[int, int, int, int]] = (),
) -> SceneMap:
    """Free floor and object footprints as (r0, r1, c0, c1) boxes; the navmesh is the free floor
    eroded by the agent radius, as in the real maps."""
    free = np.zeros(shape, bool)
    for r0, r1, c0, c1 in free_boxes:
        free[r0:r1, c0:c1] = True
    for r0, r1, c0, c1 in walls:
        free[r0:r1, c0:c1] = False
    obj = np.zeros((len(GIBSON_CATEGORIES), *shape), bool)
    for name, boxes in objects.items():
        for r0, r1, c0, c1 in boxes:
            obj[GIBSON_CATEGORIES.index(name), r0:r1, c0:c1] = True
    nav = ndi.binary_erosion(free & ~obj.any(0), disk(4))
    return SceneMap(name="Drawn", floor=0, categories=GIBSON_CATEGORIES, navigable=nav, objects=obj)


def only(floor, category: str):
    found = [i for i in floor.instances if i.category == category]
    assert len(found) == 1
    return found[0]


def test_objects_standing_in_open_floor_are_confirmable_with_pixels():
    floor = audit_floor(draw_two_room_house(), CFG)
    assert {i.category for i in floor.instances} == {"chair", "bed", "toilet", "tv"}
    for inst in floor.instances:
        assert inst.confirmable and inst.reason is None, inst
        assert inst.max_pixels > 0 and inst.max_mapped_cells > 0
        assert inst.nearest_confirmable_m is not None and inst.nearest_confirmable_m <= CFG.task.success_distance_m
        assert inst.confirmed_components and inst.best_pose is not None


def test_an_object_beyond_the_floor_has_no_floor_and_its_gap():
    # Floor ends at row 44 (navmesh row 39, walkable row 40); the toilet starts 35 cells further on.
    scene = draw([(4, 44, 4, 76)], {"toilet": [(75, 83, 36, 44)]}, shape=(90, 80))
    inst = only(audit_floor(scene, CFG), "toilet")
    assert not inst.confirmable and inst.reason == "no_floor"
    assert inst.gap_m == pytest.approx(35 * 0.05, abs=0.01) and inst.region_cells == 0


def test_an_object_walled_in_is_occluded():
    # The world builder never walls an object in (it opens a view corridor), so the walls come from
    # the same house without the toilet and the toilet's box from the house with it.
    # A 3-cell wall box around the toilet, tied to the outer wall (else it would be low furniture).
    ring = [(28, 31, 28, 52), (49, 52, 28, 52), (28, 52, 28, 31), (28, 52, 49, 52), (0, 28, 39, 41)]
    scene = draw([(4, 76, 4, 76)], {"toilet": [(36, 44, 36, 44)]}, walls=ring)
    walled = build_world(draw([(4, 76, 4, 76)], {}, walls=ring), CFG.sim)
    assert walled.walls[29, 40] and walled.walls[40, 29] and walled.walls[50, 40]
    world = _merge(walled, build_world(scene, CFG.sim), category=GIBSON_CATEGORIES.index("toilet") + 1)
    inst = only(FloorAuditor(scene, CFG, world=world).run(), "toilet")
    assert inst.reachable_region_cells > 0 and inst.max_pixels == 0 and inst.poses_tested > 1
    assert not inst.confirmable and inst.reason == "occluded"


def _merge(base: World, other: World, category: int) -> World:
    """``base`` plus the triangles of one category from ``other``."""
    keep = other.tri_category == category
    tris = other.triangles[keep] + len(base.vertices)
    return World(
        vertices=np.concatenate([base.vertices, other.vertices]),
        triangles=np.concatenate([base.triangles, tris]),
        tri_category=np.concatenate([base.tri_category, other.tri_category[keep]]),
        tri_color=np.concatenate([base.tri_color, other.tri_color[keep]]),
        tri_normal=np.concatenate([base.tri_normal, other.tri_normal[keep]]),
        walls=base.walls,
        furniture=base.furniture,
    )


def test_an_object_sealed_in_a_closet_is_unreachable_from_the_house():
    # A closet (rows 4-25) with its own bit of floor, behind a 2-cell wall from the main room: the
    # main room lies within the success distance, but only the closet's floor sees the toilet.
    scene = draw([(4, 26, 4, 40), (28, 76, 4, 76)], {"toilet": [(8, 14, 18, 26)]})
    inst = only(audit_floor(scene, CFG), "toilet")
    assert inst.reachable_region_cells > 0 and len(inst.region_components) == 2
    assert not inst.confirmable and inst.reason == "unreachable"


def test_footprint_regions_of_the_instances_make_up_the_goal_region():
    scene = draw([(4, 76, 4, 76)], {"chair": [(10, 16, 10, 16), (50, 56, 60, 66)]})
    labels, n = ndi.label(scene.category_mask("chair"), structure=np.ones((3, 3), bool))
    union = np.zeros(scene.shape, bool)
    for k in range(1, n + 1):
        part = footprint_region(scene, labels == k, CFG, f"chair#{k}")
        assert part.goal == f"chair#{k}"
        union |= part.region
    whole = goal_region(scene, "chair", CFG)
    assert n == 2 and whole.goal == "chair" and np.array_equal(whole.region, union)


def test_scenes_audit_cli_writes_json_and_pngs_and_audits_every_episode(tiny_dataset, tmp_path, capsys):
    out = tmp_path / "audit"
    assert (
        main(
            [
                "scenes",
                "audit",
                "--dataset",
                str(tiny_dataset),
                "--split",
                "val",
                "--frame",
                "60x80",
                "--json",
                "--out",
                str(out),
                "--all-pngs",
            ]
        )
        == 0
    )
    report = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert report == json.loads((out / "audit.json").read_text())
    assert report["counts"]["instances"] == len(report["instances"]) == 8
    assert {i["scene"] for i in report["instances"]} == {"Tiny", "Wee"}
    assert all(i["confirmable"] or i["reason"] in REASONS for i in report["instances"])
    assert len(report["episodes"]) == 8 and all(e["confirmable"] for e in report["episodes"])
    assert len(list(out.glob("*.png"))) == 8


def test_scenes_without_audit_still_lists(tiny_dataset, capsys):
    assert main(["scenes", "--dataset", str(tiny_dataset), "--split", "val"]) == 0
    assert "Tiny" in capsys.readouterr().out


@pytest.mark.parametrize(
    "extra,message",
    [
        (["audit", "--frame", "12by3"], "--frame: frame size must look like 120x160"),
        (["audit", "--frame", "240x321"], "not divisible by the mapper's downsample factor"),
        (["audit", "--scene", "Nowhere"], "unknown scene 'Nowhere'"),
        (["--json"], "--json: only for 'l3mvn scenes audit'"),
    ],
)
def test_bad_audit_input_is_one_line(tiny_dataset, extra, message, capsys):
    assert main(["scenes", *extra, "--dataset", str(tiny_dataset), "--split", "val"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and message in err and len(err.splitlines()) == 1


def test_malformed_dataset_is_one_line(tmp_path, capsys):
    (tmp_path / "val").mkdir()
    (tmp_path / "val" / "val_info.pbz2").write_bytes(b"not a pickle")
    assert main(["scenes", "audit", "--dataset", str(tmp_path), "--split", "val"]) == 2
    err = capsys.readouterr().err.strip()
    assert "corrupt or truncated" in err and len(err.splitlines()) == 1


def test_audit_config_rejects_an_empty_search():
    with pytest.raises(ValueError, match="audit needs"):
        AuditConfig(headings=0)


@pytest.mark.skipif(not (DEV / "train" / "train_info.pbz2").exists(), reason="../shared Gibson maps not present")
def test_every_dev_goal_instance_is_confirmable_or_has_a_reason():
    report = audit_split(DEV, "train", CFG, workers=2)
    insts = report.instances
    assert len(report.floors) == 25 and len(insts) > 300
    for inst in insts:
        if inst.confirmable:
            assert inst.reason is None and inst.nearest_confirmable_m <= CFG.task.success_distance_m, inst
        else:
            assert inst.reason in REASONS, inst
    # The world builder erases, buries and hides none of them: what is left lacks floor or a path.
    assert {i.reason for i in insts if not i.confirmable} <= {"no_floor", "unreachable"}

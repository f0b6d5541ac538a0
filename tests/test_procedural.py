"""Procedural houses: deterministic, furnished from real room data, connected, every goal reachable."""

from __future__ import annotations

import importlib.util
import math
from functools import cache

import numpy as np
import pytest
from scipy import ndimage as ndi

from l3mvn.core.categories import GIBSON_CATEGORIES, GOAL_CATEGORIES
from l3mvn.core.config import SimConfig
from l3mvn.core.errors import L3MVNError
from l3mvn.core.grid import disk
from l3mvn.world.scenes.procedural import (
    MAX_ROOMS,
    MIN_ROOMS,
    PROCEDURAL_CATEGORIES,
    ProceduralHouse,
    build_house,
    generate_house,
    generate_houses,
    procedural_split,
)
from l3mvn.world.scenes.room_contents import (
    ROOM_CONTENTS_PATH,
    build_room_contents,
    category_of,
    dump_room_contents,
    load_room_contents,
    room_categories,
)

SEEDS = range(30)
RADIUS_CELLS = 4  # SimConfig.agent_radius_m = 0.18 m on 5 cm cells


@cache
def house(seed: int) -> ProceduralHouse:
    return build_house(seed)


def test_same_seed_gives_bit_identical_maps():
    a, b = generate_house(7), build_house(7).scene
    assert a.name == b.name == "procedural-0007" and a.floor == 0
    assert np.array_equal(a.navigable, b.navigable) and np.array_equal(a.objects, b.objects)


def test_different_seeds_give_different_houses():
    assert house(0).scene.shape != house(1).scene.shape or not np.array_equal(
        house(0).scene.navigable, house(1).scene.navigable
    )


def test_every_house_contains_all_six_goals():
    for seed in SEEDS:
        assert house(seed).scene.present_goals() == list(GOAL_CATEGORIES), seed


def test_navmesh_is_one_connected_component():
    for seed in SEEDS:
        assert ndi.label(house(seed).scene.navigable)[1] == 1, seed


def test_navmesh_keeps_the_agent_radius_from_objects_and_walls():
    assert math.ceil(SimConfig().agent_radius_m / 0.05) == RADIUS_CELLS
    for seed in SEEDS:
        h = house(seed)
        grown = ndi.binary_dilation(h.scene.navigable, disk(RADIUS_CELLS))
        assert not (grown & h.scene.object_any).any(), seed
        assert not (grown & ~h.floor).any(), seed


def test_regrown_free_floor_never_breaches_a_wall():
    for seed in SEEDS:
        h = house(seed)
        assert not (h.scene.free & ~h.floor).any(), seed
        assert not (h.scene.traversible & ~h.floor).any(), seed


def test_doors_are_wide_and_the_navmesh_passes_through_them():
    for seed in SEEDS:
        h = house(seed)
        assert len(h.doors) >= len(h.rooms) - 1
        for door in h.doors:
            c = door.cells
            assert door.width_m >= 0.9
            assert h.scene.navigable[(c.r0 + c.r1) // 2, (c.c0 + c.c1) // 2], (seed, door)


def test_every_goal_object_has_a_navigable_cell_within_one_metre():
    for seed in SEEDS:
        scene = house(seed).scene
        dist = ndi.distance_transform_edt(~scene.navigable) * scene.resolution_m
        for goal in GOAL_CATEGORIES:
            labels, n = ndi.label(scene.category_mask(goal))
            nearest = ndi.minimum(dist, labels, index=np.arange(1, n + 1))
            assert np.all(np.asarray(nearest) <= 1.0), (seed, goal)


def test_small_items_stand_on_furniture_and_large_furniture_never_overlaps():
    index = {c: k for k, c in enumerate(PROCEDURAL_CATEGORIES)}
    small = [index[c] for c in ("book", "cup", "bottle", "vase", "clock", "laptop")]
    surfaces = [
        index[c]
        for c in (
            "counter",
            "dining-table",
            "coffee table",
            "side table",
            "desk",
            "dresser",
            "tv stand",
            "shelving unit",
        )
    ]
    large = [index[c] for c in ("bed", "couch", "toilet", "dining-table", "desk", "refrigerator", "counter")]
    for seed in SEEDS:
        scene = house(seed).scene
        under = scene.objects[surfaces].any(axis=0)
        assert not (scene.objects[small].any(axis=0) & ~under).any(), seed
        assert scene.objects[large].sum(axis=0).max() <= 1, seed


def test_houses_are_8_to_20_metres_across_with_the_requested_rooms():
    for n in range(MIN_ROOMS, MAX_ROOMS + 1):
        h = build_house(100 + n, n_rooms=n)
        kinds = [r.kind for r in h.rooms]
        assert len(kinds) == n
        assert {"living room", "kitchen", "bathroom", "bedroom"} <= set(kinds)
        assert 8.0 <= max(h.scene.shape) * h.scene.resolution_m <= 20.0


def test_bad_arguments_raise_clear_errors():
    with pytest.raises(L3MVNError, match="n_rooms must lie in 4..8"):
        generate_house(0, n_rooms=12)
    with pytest.raises(L3MVNError, match="seed must be a non-negative integer"):
        generate_house(-1)
    with pytest.raises(L3MVNError, match="number of houses"):
        generate_houses(-2)


def test_procedural_split_has_the_shape_of_a_semexp_split():
    split = procedural_split(2, seed=3)
    assert list(split) == ["procedural-0003", "procedural-0004"]
    assert all(list(floors) == [0] for floors in split.values())
    assert np.array_equal(split["procedural-0003"][0].objects, house(3).scene.objects)


def test_categories_keep_the_goals_and_gibson_spelling_in_semexp_channel_order():
    assert PROCEDURAL_CATEGORIES[: len(GIBSON_CATEGORIES)] == GIBSON_CATEGORIES
    assert set(GOAL_CATEGORIES) <= set(PROCEDURAL_CATEGORIES)
    assert set(room_categories()) == set(PROCEDURAL_CATEGORIES)
    assert len(set(PROCEDURAL_CATEGORIES)) == len(PROCEDURAL_CATEGORIES)
    assert {"bathtub", "shower", "towel", "dresser", "desk", "lamp", "microwave"} <= set(PROCEDURAL_CATEGORIES)


def test_ai2thor_types_map_to_our_categories_explicitly():
    expected = {
        "Sofa": "couch",
        "Television": "tv",
        "HousePlant": "potted plant",
        "Toilet": "toilet",
        "Bed": "bed",
        "ArmChair": "chair",
        "DiningTable": "dining-table",
        "Fridge": "refrigerator",
        "SinkBasin": "sink",
        "ShowerDoor": "shower",
        "AlarmClock": "clock",
        "Mug": "cup",
    }
    assert {t: category_of(t) for t in expected} == expected
    with pytest.raises(L3MVNError, match="has no category"):
        category_of("Painting")


def test_room_contents_reflect_real_rooms():
    rooms = load_room_contents()
    assert set(rooms) == {"bathroom", "bedroom", "kitchen", "living room"}
    assert rooms["bedroom"].frequency("bed") == 1.0 and rooms["bathroom"].frequency("toilet") == 1.0
    assert rooms["living room"].frequency("couch") == rooms["living room"].frequency("tv") == 1.0
    assert rooms["kitchen"].frequency("refrigerator") == 1.0 and rooms["kitchen"].frequency("bed") == 0.0
    assert all(room.n_rooms == 30 for room in rooms.values())
    assert ROOM_CONTENTS_PATH.stat().st_size < 50_000


def test_malformed_room_contents_file_raises(tmp_path):
    bad = tmp_path / "room_contents.json"
    bad.write_text('{"rooms": {"bedroom": {}}}')
    with pytest.raises(L3MVNError, match="malformed"):
        load_room_contents(bad)


@pytest.mark.skipif(importlib.util.find_spec("procthor") is None, reason="procthor wheel not installed")
def test_shipped_room_contents_equal_a_rebuild_from_the_procthor_wheel():
    assert dump_room_contents(build_room_contents()) == ROOM_CONTENTS_PATH.read_text()


def test_houses_whose_door_would_round_wider_than_its_wall_span_build():
    for seed in (718, 877):  # a door width rounded up to one cell more than the wall span it was cut in
        scene = generate_house(seed)
        assert scene.navigable.any() and scene.present_goals() == list(GOAL_CATEGORIES), seed

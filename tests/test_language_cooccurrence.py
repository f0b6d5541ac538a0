"""Co-occurrence statistics, entropy and the informative list."""

import json
import math
from pathlib import Path

import pytest

from l3mvn.agent.language.cooccurrence import STATS_PATH, build_stats, load_stats, stats_table
from l3mvn.agent.language.rooms import Room, load_gibson_rooms, split_of
from l3mvn.agent.language.vocabulary import GOALS
from l3mvn.core.errors import L3MVNError

SHARED = Path(__file__).resolve().parents[2] / "shared"
GIBSON = SHARED / "data" / "room_objects" / "gibson_3dsg_rooms.jsonl"


def _room(building, *objects, goals=GOALS):
    return Room("test", building, "room", frozenset(objects), goals)


def test_shipped_list_has_15_objects_ordered_by_entropy():
    stats = load_stats()
    assert len(stats.informative) == 15
    entropies = [stats.objects[o].entropy for o in stats.informative]
    assert entropies == sorted(entropies)
    outside = [
        o.entropy
        for o in stats.objects.values()
        if o.name not in stats.informative
        and o.rooms >= stats.provenance["min_rooms"]
        and o.name in stats.provenance["candidates"]
    ]
    assert min(outside) >= entropies[-1]


def test_shipped_stats_record_how_they_were_made():
    data = json.loads(STATS_PATH.read_text())
    assert data["provenance"]["command"].startswith("l3mvn language build-stats")
    assert data["provenance"]["sources"]["ai2thor"]


def test_every_object_has_a_distribution_over_the_six_goals():
    for o in load_stats().objects.values():
        assert set(o.p_goal) == set(GOALS)
        assert math.isclose(sum(o.p_goal.values()), 1.0, abs_tol=1e-4)


def test_bathroom_objects_point_to_toilet():
    stats = load_stats()
    for name in ("shower", "bathtub", "towel"):
        assert max(stats.p_goal(name), key=stats.p_goal(name).get) == "toilet"


def test_a_goal_missing_from_a_source_takes_its_rate_from_the_other_source():
    rooms = [_room("a", "sink", "toilet", goals=GOALS[:5]), _room("b", "sink", "chair", goals=GOALS[:5])]
    rooms += [_room(f"t{i}", "remote", "tv", "couch") for i in range(3)] + [_room("t9", "bed", "sink")]
    stats = build_stats(rooms, candidates=("sink", "remote"), min_rooms=1)
    assert stats.p_goal("remote")["tv"] > stats.p_goal("sink")["tv"]


def test_smoothing_keeps_a_rare_object_away_from_certainty_and_min_rooms_keeps_it_off_the_list():
    rooms = [_room("a", "bathtub", "toilet")] + [_room(f"b{i}", "sink", "bed") for i in range(5)]
    stats = build_stats(rooms, candidates=("bathtub", "sink"), min_rooms=2)
    assert stats.p_goal("bathtub")["toilet"] < 0.9
    assert stats.informative == ("sink",)


def test_informative_objects_come_in_list_order():
    stats = load_stats()
    picked = stats.informative_in(["bed", "Shower", "vase", "toilet"])
    assert picked == tuple(o for o in stats.informative if o in {"bed", "shower", "toilet"})


def test_stats_table_marks_list_members():
    text = stats_table(load_stats(), min_rooms=10)
    assert text.splitlines()[0].startswith("| object | rooms | p(chair)")
    assert "| towel |" in text and "informative list (15)" in text


def test_bad_settings_raise():
    with pytest.raises(L3MVNError, match="alpha > 0"):
        build_stats([_room("a", "sink")], alpha=0)


def test_splits_are_by_building_and_stable():
    assert split_of("Adairsville") == split_of("Adairsville")
    assert {split_of(f"b{i}") for i in range(200)} == {"train", "val", "test"}


@pytest.mark.skipif(not GIBSON.exists(), reason="shared research data not present")
def test_gibson_rooms_load_with_canonical_names_and_no_tv_label():
    rooms = load_gibson_rooms(GIBSON)
    assert len(rooms) == 2306
    assert all("tv" not in r.labelled_goals for r in rooms)
    assert any("potted plant" in r.objects for r in rooms)

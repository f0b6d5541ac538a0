"""Spelling of object categories across the Gibson maps, the room data, AI2-THOR and the queries."""

import pytest

from l3mvn.agent.language.queries import feedforward_query, zero_shot_query
from l3mvn.agent.language.vocabulary import GOALS, canonical, check_goal, query_phrase, to_coco, to_gibson
from l3mvn.core.categories import GIBSON_CATEGORIES, GOAL_CATEGORIES
from l3mvn.core.errors import L3MVNError


def test_goals_are_the_scene_goal_categories():
    assert GOALS == GOAL_CATEGORIES == ("chair", "couch", "potted plant", "bed", "toilet", "tv")


@pytest.mark.parametrize(
    "spelling, name",
    [
        ("potted_plant", "potted plant"),
        ("dining-table", "dining table"),
        ("dining_table", "dining table"),
        ("HousePlant", "potted plant"),
        ("Sofa", "couch"),
        ("sofa", "couch"),
        ("Television", "tv"),
        ("tv_monitor", "tv"),
        ("SinkBasin", "sink"),
        ("ShowerHead", "shower"),
        ("chest_of_drawers", "dresser"),
        ("TVStand", "tv stand"),
        ("ArmChair", "chair"),
        ("Fridge", "refrigerator"),
        ("  Bath_Tub ", "bathtub"),
    ],
)
def test_every_source_spelling_folds_to_one_canonical_name(spelling, name):
    assert canonical(spelling) == name


def test_unknown_categories_are_accepted_after_folding():
    assert canonical("Laundry_Basket") == "laundry basket"


def test_gibson_and_coco_spellings_round_trip():
    for name in GIBSON_CATEGORIES:
        assert to_gibson(canonical(name)) == name
        assert canonical(to_coco(name)) == canonical(name)
    assert to_gibson("dining_table") == "dining-table"
    assert to_coco("potted plant") == "potted_plant"


def test_a_category_outside_the_gibson_maps_has_no_gibson_spelling():
    with pytest.raises(L3MVNError, match="not a SemExp/Gibson map category"):
        to_gibson("bathtub")


def test_bad_names_and_goals_raise_clear_errors():
    with pytest.raises(L3MVNError, match="non-empty string"):
        canonical("  ")
    with pytest.raises(L3MVNError, match="valid goals: chair, couch"):
        check_goal("fireplace")
    assert check_goal("Sofa") == "couch"


def test_queries_follow_the_paper_templates_and_spell_tv_as_television():
    assert query_phrase("tv") == "television"
    assert zero_shot_query(("sink", "bathtub"), "toilet") == "A frontier area containing sink, bathtub, toilet."
    assert zero_shot_query((), "tv") == "A frontier area containing television."
    assert feedforward_query(("sink",)) == "This frontier contains sink."
    assert feedforward_query(("sink", "bed")) == "This frontier contains sink and bed."
    assert feedforward_query(("sink", "bed", "oven")) == "This frontier contains sink, bed, and oven."
    assert feedforward_query(()) == "This frontier contains nothing."

"""The shipped offline scorers (MiniLM embedding, room-type two-hop, feed-forward head)."""

import os

os.environ.setdefault("HF_HUB_OFFLINE", "1")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from l3mvn.agent.language import GOALS, make_scorer, scorer_names  # noqa: E402
from l3mvn.core.errors import L3MVNError  # noqa: E402

SHIPPED = ("embedding", "roomtype", "feedforward")


@pytest.fixture(scope="module")
def scorers():
    # The feed-forward scorer with the room-list head: these tests check room knowledge (the frontier
    # head is tested in test_language_frontier_policy.py).
    return {name: make_scorer(name, **({"head": "rooms"} if name == "feedforward" else {})) for name in SHIPPED}


def test_registry_names_every_scorer():
    assert scorer_names() == ("causal", "embedding", "feedforward", "llm", "mlm", "roomtype")
    with pytest.raises(L3MVNError, match="valid: causal, embedding, feedforward, llm, mlm, roomtype"):
        make_scorer("gpt5")


@pytest.mark.parametrize("name", SHIPPED)
def test_output_is_a_distribution_over_the_six_goals(scorers, name):
    out = scorers[name].score([{"sink", "bathtub"}, {"bed"}, {"oven", "refrigerator", "dining-table"}])
    for dist in out:
        assert tuple(dist) == GOALS
        assert all(p >= 0 for p in dist.values())
        assert sum(dist.values()) == pytest.approx(1.0)


@pytest.mark.parametrize("name", SHIPPED)
def test_bathroom_objects_rank_toilet_first(scorers, name):
    dist = scorers[name].score([{"sink", "bathtub", "shower"}])[0]
    assert max(dist, key=dist.get) == "toilet"


@pytest.mark.parametrize("name", ["roomtype", "feedforward"])
def test_kitchen_objects_point_away_from_toilet_and_bed(scorers, name):
    dist = scorers[name].score([{"oven", "refrigerator", "microwave"}])[0]
    assert dist["chair"] > dist["toilet"] and dist["chair"] > dist["bed"]


@pytest.mark.parametrize("name", SHIPPED)
def test_a_frontier_without_informative_objects_is_uniform(scorers, name):
    scorer = scorers[name]
    assert scorer.query_objects({"vase", "Clock"}) == ()
    np.testing.assert_allclose(scorer.score_goal([set(), {"vase"}], "tv"), [1 / 6, 1 / 6])


@pytest.mark.parametrize("name", SHIPPED)
def test_a_repeated_object_set_hits_the_cache(scorers, name):
    scorer = scorers[name]
    scorer.clear_cache()
    first = scorer.score([{"toilet", "sink"}])
    again = scorer.score([{"Sink", "toilet", "vase"}])
    info = scorer.cache_info()
    assert (info.misses, info.hits) == (6, 6)
    assert first == again


def test_feedforward_head_needs_a_matching_embedder():
    with pytest.raises(L3MVNError, match="no shipped head"):
        make_scorer("feedforward", model="roberta-large")


def test_roomtype_explains_its_choice_with_room_types(scorers):
    rooms = scorers["roomtype"].room_distribution(("bed", "desk"))
    assert max(rooms, key=rooms.get) == "bedroom"

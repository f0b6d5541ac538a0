"""The dashboard's Language folder, as pure HTML from the snapshot's records."""

import re

import numpy as np
import pytest

from l3mvn.agent.frontiers import Fusion
from l3mvn.agent.language import GOALS
from l3mvn.run.viz import category_color
from l3mvn_studio.language_panel import (
    BAR_PX,
    SHOWN_FRONTIERS,
    bar_html,
    frontier_card_html,
    fusion_html,
    language_html,
    shown_frontiers,
)
from l3mvn_studio.state import FrontierMarker, MapView

FUSION = Fusion(
    rule="paper",
    branch="fused",
    choice=2,
    ids=(0, 1, 2, 3, 4),
    s_llm=(0.16, 0.10, 0.22, 0.05, 0.02),
    explore=(0.6, 0.2, 0.4, 0.3, 0.0),
    compared=(0.24, 0.18, 0.27, 0.20, 0.15),
    bound=(0.15, 0.30),
)


def _marker(i: int, *, chosen: bool = False, metres: bool = False, objects=("sink", "towel")) -> FrontierMarker:
    scores = dict(zip(GOALS, np.roll([0.4, 0.2, 0.15, 0.1, 0.1, 0.05], i)))
    return FrontierMarker(
        id=i,
        cell=(i, i),
        size=10,
        distance_m=1.0 + i,
        s_cu=FUSION.explore[i],
        s_llm=FUSION.s_llm[i],
        fused=FUSION.compared[i],
        objects=tuple(objects),
        queries={"all goals": f"This frontier contains {objects[0]}."},
        reason="",
        chosen=chosen,
        llm_scores={g: float(p) for g, p in scores.items()},
        expected_m={g: 2.0 + k for k, g in enumerate(GOALS)} if metres else {},
    )


def _view(frontiers, fusion=FUSION, target="toilet", goal_kind="frontier") -> MapView:
    return MapView(
        image=np.zeros((4, 4, 3), np.uint8),
        origin=(0, 0),
        scale=1,
        grid_shape=(4, 4),
        resolution_m=0.05,
        source="agent map",
        agent_cell=(0, 0),
        agent_heading=0.0,
        goal_kind=goal_kind,
        frontiers=tuple(frontiers),
        target=target,
        fusion=fusion,
    )


def test_a_policy_without_a_prior_says_which_and_that_it_uses_none():
    for policy in ("cost-utility", "oracle", "frontier", "exp"):
        html = language_html(None, policy)
        assert f"<b>{policy}</b> uses no prior" in html and "l3mvn-zs" in html and "poni" in html
    assert "uses no prior" not in language_html(None, "exp+llm")  # the alias of l3mvn-ff
    assert "uses no prior" not in language_html(None, "poni")


def test_a_language_policy_before_its_first_choice_says_when_scores_appear():
    assert "first chooses a frontier" in language_html(None, "l3mvn-zs")
    assert "first chooses a frontier" in language_html(_view([_marker(0)], fusion=None), "l3mvn-ff")


def test_the_panel_shows_the_rule_line_and_a_card_per_shown_frontier_with_bars_for_every_goal():
    markers = [_marker(i, chosen=i == 2) for i in range(5)]
    html = language_html(_view(markers), "l3mvn-ff")
    assert FUSION.describe() in html and "F2 0.27 beats F0 0.24" in html
    assert html.count("&middot; S_LLM") == SHOWN_FRONTIERS  # one card per shown frontier
    assert html.index("★ F2") < html.index("<b>F3</b>")  # the chosen card first, then the best by fused
    assert "<b>F4</b>" not in html  # the lowest fused score is left out
    assert html.count("(target)</b>") == SHOWN_FRONTIERS
    rgb = "rgb" + str(category_color("toilet"))
    assert f"background:{rgb};outline:2px solid #000" in html  # the target's bar ringed in its map colour
    assert "This frontier contains sink." in html and " m</span>" not in html  # no metres without a distance head


def test_the_chosen_frontier_comes_first_then_the_rules_pick_when_commitment_kept_another():
    markers = [_marker(i, chosen=i == 0) for i in range(5)]
    order = [f.id for f in shown_frontiers(tuple(markers), FUSION)]
    assert order == [0, 2, 3, 1]
    note = fusion_html(FUSION, tuple(markers))
    assert "The rule picked F2; the agent keeps F0" in note
    assert "not a frontier (target)" in fusion_html(FUSION, tuple(_marker(i) for i in range(5)), "target")


def test_a_distance_head_shows_its_metres_beside_each_goal():
    card = frontier_card_html(_marker(1, metres=True), "bed")
    rows = card.split("display:flex")[1:]
    assert len(rows) == len(GOALS)
    for k, goal in enumerate(GOALS):
        row = next(r for r in rows if re.search(rf">(<b>)?{goal}( \(target\)</b>)?</span>", r))
        assert f"{2.0 + k:.1f} m</span>" in row
    assert card.index("bed (target)") < card.index("chair")  # the target's row first


def test_a_bar_is_as_long_as_its_probability_and_text_is_escaped():
    assert f"width:{0.5 * BAR_PX:.1f}px" in bar_html("bed", 0.5, target=False)
    assert f"width:{BAR_PX:.1f}px" in bar_html("bed", 1.7, target=False)  # clipped to the track
    card = frontier_card_html(_marker(0, objects=("<script>alert(1)</script>",)), "toilet")
    assert "<script>" not in card and "&lt;script&gt;" in card


@pytest.mark.parametrize("goal_kind", ["frontier", "target"])
def test_the_whole_panel_is_one_well_formed_block(goal_kind):
    html = language_html(
        _view([_marker(i, chosen=goal_kind == "frontier" and i == 2) for i in range(5)], goal_kind=goal_kind),
        "l3mvn-zs",
    )
    assert html.count("<div") == html.count("</div>") and html.count("<span") == html.count("</span>")

"""The dashboard's language details agree with each other (issue 34): the Frontiers table quotes the
query the Language folder shows (the target's, for a scorer that asks one per goal), and the legend
shows the episode's target from its Reset on, not only once the map shows that category.

Driven on an in-process server without a browser; the room-type scorer runs offline and asks one
query per goal, as every zero-shot scorer does."""

from __future__ import annotations

import time

import pytest
from conftest import serve_dashboard

from l3mvn.core.config import Config, SimConfig
from l3mvn_studio.language_panel import query_of
from l3mvn_studio.page_markdown import frontier_markdown
from l3mvn_studio.page_text import code

SMALL = Config(sim=SimConfig().with_frame(60, 80))
MAX_STEPS = 40  # the look-around takes 12 steps before the first frontier choice


@pytest.fixture(scope="module")
def dash():
    yield from serve_dashboard(episodes_per_house=2, cfg=SMALL, policy="l3mvn-zs")


@pytest.fixture
def ctl(dash):
    c = dash.controller
    c.set_scorer("roomtype")
    yield c
    c.pause()
    c.wait_idle()


def _reset(c, index: int):
    scene = c.scene_keys[0]
    episode = c.episodes_of(scene)[index]
    c.reset(scene, episode.episode_id)
    assert c.wait_idle(60.0)
    assert c.snapshot.error is None, c.snapshot.error
    return episode


def _step(c, steps: int = 1) -> None:
    for _ in range(steps):
        c.step()
        assert c.wait_idle(30.0)


def _legend_shows(dash, target: str, timeout: float = 5.0) -> bool:
    """Whether the page's legend names ``target`` as the target, once the draw thread catches up."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if f"<b>{target} (target)</b>" in dash.view.legend.content:
            return True
        time.sleep(0.05)
    return False


def _first_choice(c):
    """Step until the agent has scored frontiers whose objects it could name; that map view."""
    for _ in range(MAX_STEPS):
        view = c.snapshot.map
        if view is not None and any(f.queries for f in view.frontiers):
            return view
        _step(c)
    raise AssertionError("no frontier named an informative object")


def test_the_legend_shows_the_target_from_reset_on_before_the_map_shows_it(dash, ctl):
    first = _reset(ctl, 0)
    _step(ctl, 3)
    second = _reset(ctl, 1)
    assert second.goal != first.goal
    assert _legend_shows(dash, second.goal), dash.view.legend.content  # before the new map is drawn
    _step(ctl)
    view = ctl.snapshot.map
    assert view is not None and view.target == second.goal and second.goal not in dict(view.legend)
    assert _legend_shows(dash, second.goal), dash.view.legend.content  # mapped or not, the target is listed


def test_the_frontier_table_quotes_the_targets_query_as_the_language_folder_does(ctl):
    _reset(ctl, 0)
    view = _first_choice(ctl)
    asked = [f for f in view.frontiers if f.queries]
    assert all(len(f.queries) > 1 for f in asked)  # one query per goal: the first goal's is not the target's
    table = frontier_markdown(view)
    for f in asked:
        assert f"- F{f.id} {code(query_of(f, view.target))}" in table

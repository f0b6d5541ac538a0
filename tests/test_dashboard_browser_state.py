"""Issue 16 items 0 and 7 in a real browser: a first load that agrees with itself, a busy page that
says so, a Run never lost, a finished run that says finished, notices that stay, keyboard shortcuts.

Skips like tests/test_dashboard_browser.py when playwright or a chromium is missing. Set
L3MVN_SCREENSHOTS=DIR to keep the screenshots.
"""

from __future__ import annotations

import os
import re
import threading
import time
from pathlib import Path

import pytest

sync_api = pytest.importorskip("playwright.sync_api")

from conftest import free_port, serve_dashboard
from test_dashboard_browser import (  # noqa: E402  (after the skip: it needs playwright too)
    CHROMIUM,
    CHROMIUM_ARGS,
    VIEWPORT,
    _panel_text,
    _step_shown,
    _wait,
)

pytestmark = pytest.mark.skipif(
    CHROMIUM is None, reason="no chromium: `apt install chromium` or `playwright install chromium` runs these tests"
)

from l3mvn.core.config import Config  # noqa: E402
from l3mvn_studio.model_weights import scorer_problems  # noqa: E402
from l3mvn_studio.server import start_dashboard  # noqa: E402
from l3mvn_studio.tab_notices import NOTICE_SECONDS  # noqa: E402


@pytest.fixture(scope="module")
def dash():
    yield from serve_dashboard(episodes_per_house=3, policy="frontier", cfg=Config().with_frame(240, 320))


@pytest.fixture(scope="module")
def browser():
    with sync_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        yield b
        b.close()


@pytest.fixture
def page(dash, browser, tmp_path):
    page = browser.new_page(viewport=VIEWPORT)
    page.set_default_timeout(60_000)  # a starved software-WebGL page can take seconds per click
    page.shots = Path(os.environ.get("L3MVN_SCREENSHOTS", tmp_path))
    page.goto(dash.url)
    page.wait_for_selector("canvas", timeout=20_000)
    _wait(lambda: "Keys:" in _panel_text(page), what="the panel")
    yield page
    page.close()
    dash.controller.pause()
    dash.controller.wait_idle(30)


def _input_values(page) -> list[str]:
    """The values the page's visible fields show, top to bottom (Scene, Episode, Target, ...)."""
    return page.evaluate(
        "Array.from(document.querySelectorAll('input'))"
        ".filter((i) => i.type !== 'hidden' && i.offsetParent !== null).map((i) => i.value)"
    )


def _input(page, value: str):
    """The visible field showing ``value``."""
    return page.locator(f"input[value='{value}']:visible").first


def _state(page) -> str:
    """The status panel's first line's state word: running, paused or finished."""
    m = re.search(r"target \w[\w ]*, (running|paused|finished)", _panel_text(page))
    return m.group(1) if m else ""


def _blur(page) -> None:
    page.evaluate("document.activeElement && document.activeElement.blur()")


def test_the_first_load_agrees_with_itself(dash, page):
    first = dash.controller.episodes_of(dash.controller.scene_keys[0])[0]
    values = _input_values(page)
    assert f"{first.episode_id}: {first.goal}" in values
    assert values[values.index(f"{first.episode_id}: {first.goal}") + 1] == first.goal, values  # Target
    text = _panel_text(page)
    assert "keeps no map" not in text and "frontiers appear after Reset" in text
    assert "seen from afar" in text and f"{first.goal} (target)" in text  # the legend before any Reset
    assert "flat-shaded boxes" in text
    heights = page.evaluate("Array.from(document.querySelectorAll('img')).map((i) => i.getBoundingClientRect().height)")
    pair, rgb = sorted(heights)[-2:]  # depth and semantic side by side, each at half the RGB's size
    assert rgb > 200 and pair > 100, heights
    page.screenshot(path=str(page.shots / "dashboard_first_load.png"))


def test_run_before_reset_starts_the_episode_and_keys_drive_it(dash, page):
    ctl = dash.controller
    if ctl.session is not None:
        pytest.skip("needs a dashboard with no episode yet (run this module's tests in order)")
    ctl.set_speed(1)  # slow enough that the episode is still on when the keys are tried
    page.get_by_role("button", name="Run", exact=True).click()
    page.get_by_text("no episode yet: starting episode").first.wait_for(timeout=20_000)
    _wait(lambda: (_step_shown(page) or 0) >= 1 and _state(page) == "running", timeout=90, what="the run")
    # Space on the focused Run/Pause button: one toggle, not two.
    page.keyboard.press("Space")
    _wait(lambda: _state(page) == "paused", what="Space to pause")
    n = _step_shown(page)
    time.sleep(0.6)
    assert _step_shown(page) == n and not ctl.running
    _blur(page)
    page.keyboard.press("n")
    _wait(lambda: _step_shown(page) == n + 1, what="N to step once")
    page.keyboard.press("f")
    page.keyboard.press("r")
    _wait(lambda: _step_shown(page) == 0, timeout=60, what="R to reset")
    page.keyboard.press("Space")
    _wait(lambda: (_step_shown(page) or 0) >= 1 and _state(page) == "running", timeout=60, what="Space to run")
    page.keyboard.press("Space")
    _wait(lambda: _state(page) == "paused", what="Space to pause again")
    assert "failed" not in _panel_text(page)


def test_a_reset_shows_it_is_busy_holds_the_controls_and_queues_a_run(dash, page):
    ctl = dash.controller
    hold = threading.Event()
    ctl._submit("test hold", lambda: hold.wait(300), None)  # a worker as slow as a first model load
    try:
        page.get_by_role("button", name="Reset").click()
        page.get_by_text("resetting to episode").first.wait_for(timeout=20_000)
        _wait(lambda: _input(page, dash.view.scene.value).is_disabled(), what="Scene held")
        assert _input(page, dash.view.policy.value).is_disabled()
        page.screenshot(path=str(page.shots / "dashboard_busy.png"))
        page.get_by_role("button", name="Run", exact=True).click()
        page.get_by_text("Run queued").first.wait_for(timeout=20_000)
    finally:
        hold.set()
    _wait(lambda: _step_shown(page) is not None and _step_shown(page) >= 1, timeout=90, what="the queued run")
    _wait(lambda: not _input(page, dash.view.scene.value).is_disabled(), what="the controls back")
    _wait(lambda: "Working" not in _panel_text(page), what="the busy notice gone")
    page.get_by_role("button", name="Pause").click()
    _wait(lambda: _state(page) == "paused", what="pause")


def test_a_finished_run_says_finished_and_its_outcome_stays(dash, page):
    ctl = dash.controller
    scene = ctl.scene_keys[0]
    nearest = min(ctl.episodes_of(scene), key=lambda e: e.geodesic_distance_m)
    ctl.set_policy("oracle")
    dash.view.episode.value = f"{nearest.episode_id}: {nearest.goal}"
    ctl.set_speed(10)
    _blur(page)
    page.keyboard.press("r")
    _wait(
        lambda: _step_shown(page) == 0 and f"{nearest.key} (oracle)" in _panel_text(page),
        timeout=60,
        what="the nearest episode reset",
    )
    page.get_by_role("button", name="Run", exact=True).click()
    _wait(lambda: _state(page) == "finished", timeout=120, what="the end of the episode")
    text = _panel_text(page)
    assert "SUCCESS" in text and _state(page) == "finished"
    assert page.get_by_role("button", name="Run", exact=True).count() == 1  # the group offers Run again, not Pause
    time.sleep(NOTICE_SECONDS + 1.5)
    assert page.get_by_text("Episode over").count() >= 1, "the outcome notice closed by itself"
    page.screenshot(path=str(page.shots / "dashboard_finished.png"))
    ctl.set_policy("frontier")


def test_a_scorer_without_weights_is_shown_unavailable_and_refused_at_once(dash, page):
    problems = scorer_problems()
    if "mlm" not in problems:
        pytest.skip("roberta-large is on this disk: the mlm scorer can load")
    assert "Unavailable scorers" in _panel_text(page) and problems["mlm"] in _panel_text(page)
    _input(page, "policy default").click()
    started = time.monotonic()
    page.get_by_role("option", name="mlm").click()
    page.get_by_text("scorer 'mlm' is unavailable").first.wait_for(timeout=20_000)
    assert time.monotonic() - started < 15  # a refusal, not a minute of hub retries
    _wait(lambda: "policy default" in _input_values(page), what="the Scorer back to policy default")
    assert dash.controller.scorer is None


def test_target_and_step_before_an_episode_explain_themselves(dash, browser, tmp_path):
    fresh = start_dashboard(
        port=free_port(), houses=1, episodes_per_house=2, policy="frontier", cfg=Config().with_frame(120, 160)
    )
    page = browser.new_page(viewport=VIEWPORT)
    try:
        page.goto(fresh.url)
        _wait(lambda: "Keys:" in _panel_text(page), what="the panel")
        page.get_by_role("button", name="Step").click()
        page.get_by_text("no episode yet: pick one and press Reset").first.wait_for(timeout=20_000)
        page.get_by_role("button", name="Clear").click()
        page.get_by_text("no manual goal to clear").first.wait_for(timeout=20_000)
        page.get_by_role("button", name="Fit map in view").click()
        page.get_by_text("no map to fit yet").first.wait_for(timeout=20_000)
        goal = fresh.view.target.value
        _input(page, goal).click()
        other = next(o for o in fresh.view.target.options if o != goal)
        page.get_by_role("option", name=other, exact=True).click()
        page.get_by_text("Target changes the goal of a running episode").first.wait_for(timeout=20_000)
        _wait(lambda: goal in _input_values(page), what="Target back to the episode's goal")
    finally:
        page.close()
        fresh.stop()


def test_the_ground_truth_toggle_draws_the_goal_and_clears_it(dash, page):
    ctl = dash.controller
    ctl.set_policy("frontier")
    scene = ctl.scene_keys[0]
    ctl.reset(scene, ctl.episodes_of(scene)[0].episode_id)
    assert ctl.wait_idle(60)
    for _ in range(3):
        ctl.step()
        assert ctl.wait_idle(60)
    _wait(lambda: _step_shown(page) == 3, timeout=60, what="step 3 in the page")
    time.sleep(1.0)
    canvas = page.locator("canvas").first
    before = canvas.screenshot()
    page.get_by_text("Ground truth", exact=True).click()
    _wait(lambda: dash.view.map_scene.gt_plane.visible, what="the ground-truth layer")
    _wait(
        lambda: "GROUND TRUTH" in _panel_text(page) or "ground truth: goal instances" in _panel_text(page),
        what="the layer marked as ground truth",
    )
    assert "ground truth: goal instances" in _panel_text(page)  # its legend
    assert dash.view.map_scene.gt_label.text.startswith(f"GROUND TRUTH: {ctl.snapshot.event.goal}")
    time.sleep(1.0)
    shown = canvas.screenshot()
    assert shown != before, "the ground truth changed nothing on the map"
    page.screenshot(path=str(page.shots / "dashboard_ground_truth.png"))
    page.get_by_text("Ground truth", exact=True).click()
    _wait(lambda: not dash.view.map_scene.gt_plane.visible, what="the layer cleared")
    _wait(lambda: "ground truth: goal instances" not in _panel_text(page), what="its legend cleared")


def test_teleop_keys_move_the_agent_and_the_step_counter(dash, page):
    ctl = dash.controller
    events = []
    off = ctl.bus.subscribe(events.append)
    try:
        assert not page.get_by_role("button", name="Forward").is_visible()  # not the teleop policy yet
        ctl.set_policy("teleop")
        _blur(page)
        page.keyboard.press("r")  # the policy takes effect on Reset, and with it the Drive buttons
        _wait(lambda: _step_shown(page) == 0 and "(teleop)" in _panel_text(page), timeout=60, what="teleop reset")
        page.get_by_role("button", name="Forward").wait_for(timeout=20_000)
        start = events[-1].pose
        page.keyboard.press("a")
        _wait(lambda: _step_shown(page) == 1, timeout=30, what="A to turn")
        page.keyboard.press("ArrowUp")
        _wait(lambda: _step_shown(page) == 2, timeout=30, what="Up to go forward")
        assert [e.action.name for e in events[-2:]] == ["TURN_LEFT", "MOVE_FORWARD"]
        assert events[-2].pose.heading != start.heading
        assert "driven by hand" in _panel_text(page)
        page.get_by_role("button", name="Look down").click()
        _wait(lambda: _step_shown(page) == 3, timeout=30, what="the Look down button")
        page.screenshot(path=str(page.shots / "dashboard_teleop.png"))
        page.keyboard.press("x")
        _wait(lambda: _state(page) == "finished", timeout=30, what="X to stop and be scored")
        assert events[-1].done and events[-1].result["steps"] == 4
    finally:
        off()
        ctl.set_policy("frontier")

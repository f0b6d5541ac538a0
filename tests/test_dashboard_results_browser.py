"""Issue 16 item 1 in a real browser: `serve --results DIR` opens an eval of 20 procedural episodes,
filters to failures, opens one's recording and scrubs to a step, which shows that step's picture.

Skips like tests/test_dashboard_browser.py when playwright or a chromium is missing. Set
L3MVN_SCREENSHOTS=DIR to keep the screenshot.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

sync_api = pytest.importorskip("playwright.sync_api")

from conftest import free_port
from test_dashboard_browser import (
    CHROMIUM,
    CHROMIUM_ARGS,
    VIEWPORT,
    _panel_text,
    _wait,
)

pytestmark = pytest.mark.skipif(
    CHROMIUM is None, reason="no chromium: `apt install chromium` or `playwright install chromium` runs these tests"
)

from l3mvn_studio.map_image import png_rgb
from l3mvn_studio.results import load_result_file, recording_frames, recording_of
from l3mvn_studio.server import start_dashboard

HOUSES, PER_HOUSE = 4, 5


@pytest.fixture(scope="module")
def dash(tmp_path_factory):
    d = tmp_path_factory.mktemp("served")
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "TRANSFORMERS_OFFLINE": "1"}
    subprocess.run(
        [
            sys.executable,
            "-m",
            "l3mvn_studio.cli",
            "eval",
            "--policy",
            "frontier",
            "--houses",
            str(HOUSES),
            "--episodes-per-house",
            str(PER_HOUSE),
            "--frame",
            "60x80",
            "--set",
            "sim.max_steps=40",
            "--out",
            str(d / "frontier.jsonl"),
            "--record",
            "--record-dir",
            str(d / "rec"),
        ],
        check=True,
        capture_output=True,
        env=env,
        timeout=900,
    )
    (d / "notes.jsonl").write_text("these are my notes, not results\n")
    dash = start_dashboard(
        port=free_port(),
        houses=HOUSES,
        episodes_per_house=PER_HOUSE,
        policy="frontier",
        results_dir=d,
        recordings_dir=d / "rec",
    )
    yield dash
    dash.stop()


@pytest.fixture
def page(dash, tmp_path):
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        page = browser.new_page(viewport=VIEWPORT)
        page.set_default_timeout(60_000)
        page.shots = Path(os.environ.get("L3MVN_SCREENSHOTS", tmp_path))
        page.goto(dash.url)
        page.wait_for_selector("canvas", timeout=20_000)
        _open_results_tab(page)
        _wait(lambda: "Per category" in _panel_text(page), timeout=30, what="the Results panel")
        yield page
        browser.close()


def _open_results_tab(page) -> None:
    """The Results panel is a tab of its own where the page has tabs (hidden text is not read)."""
    tab = page.get_by_role("tab", name="Results", exact=True)
    _wait(lambda: tab.count() or "Per category" in _panel_text(page), timeout=30, what="the Results panel or tab")
    if tab.count():
        tab.click()


def _pick(page, current: str, option: str) -> None:
    page.locator(f"input[value='{current}']:visible").first.click()
    page.get_by_role("option", name=option, exact=True).click()


def test_filter_open_and_scrub_an_episode(dash, page):
    panel = dash.view.results
    rows = load_result_file(panel.source.results_dir / "frontier.jsonl").rows
    assert len(rows) == HOUSES * PER_HOUSE
    failed = [r for r in rows if not r.success]
    assert failed, "the eval should fail some episodes at 40 steps"
    assert f"{len(rows)} episodes" in _panel_text(page)
    _pick(page, "all", "failures")
    _wait(lambda: f"{len(failed)} episodes" in _panel_text(page), what="the failures filter")
    assert [r.label for r in panel._shown] == [r.label for r in failed]
    target = failed[0]
    _wait(lambda: page.locator(f"input[value='{target.label}']:visible").count() > 0, what="the episode list")
    page.get_by_role("button", name="Open", exact=True).click()
    page.get_by_text("opened ").first.wait_for(timeout=60_000)
    pictures, _ = recording_frames(recording_of(panel.source.recordings_dir, target))
    k = min(7, len(pictures) - 1)
    slider = page.get_by_role("slider").last
    slider.focus()
    for _ in range(k):
        slider.press("ArrowRight")
    _wait(lambda: f"step {k}:" in _panel_text(page), timeout=30, what=f"step {k} shown")
    assert np.array_equal(panel.picture.image, png_rgb(pictures[k]))
    assert pictures[k] != pictures[0]
    page.locator("img").last.scroll_into_view_if_needed()
    page.screenshot(path=str(page.shots / "dashboard_results.png"))


def test_a_file_that_is_not_results_is_a_notice(dash, page):
    _pick(page, "frontier.jsonl", "notes.jsonl")
    page.get_by_text("notes.jsonl is not an eval result file: no episode line").first.wait_for(timeout=30_000)
    assert dash.view.results._file.path.name == "frontier.jsonl"  # the last good file stays shown


def test_a_failure_opens_in_rerun_and_loads_into_the_live_session_at_a_chosen_step(dash, page):
    """Issue 34, from the page alone: a failed row opens in rerun's web viewer (a link in the panel),
    and, scrubbed to step K, loads into the live session there: the status shows that episode at K."""
    import urllib.request

    from test_dashboard_browser import _step_shown

    panel, ctl = dash.view.results, dash.controller
    if panel.filter.value != "failures":  # the dashboard is shared: an earlier test may have filtered
        _pick(page, panel.filter.value, "failures")
    target = next(r for r in panel._file.rows if not r.success)
    _wait(lambda: page.locator(f"input[value='{target.label}']:visible").count() > 0, what="the failed episode")
    link = page.get_by_role("link", name=f"Open {recording_of(panel.source.recordings_dir, target).name} in rerun")
    before = {link.nth(i).get_attribute("href") for i in range(link.count())}  # an earlier test's viewer, if any
    page.get_by_role("button", name="Open in rerun", exact=True).last.click()
    _wait(
        lambda: any(link.nth(i).get_attribute("href") not in before for i in range(link.count())),
        timeout=60,
        what="the link to the new viewer",
    )
    url = next(u for u in (link.nth(i).get_attribute("href") for i in range(link.count())) if u not in before)
    with urllib.request.urlopen(url, timeout=30) as reply:
        assert reply.status == 200
    page.get_by_role("button", name="Open", exact=True).click()
    page.get_by_text("opened ").first.wait_for(timeout=60_000)
    k = min(5, target.steps - 1)
    slider = page.get_by_role("slider").last
    slider.focus()
    for _ in range(k):
        slider.press("ArrowRight")
    _wait(lambda: panel.load_step.value == k, timeout=30, what=f"Load at step following the slider to {k}")
    page.get_by_role("button", name="Load into session", exact=True).click()
    _wait(lambda: _step_shown(page) == k and target.raw["key"] in _panel_text(page), timeout=120, what="step K")
    snap = ctl.snapshot
    assert snap.event.episode_key == target.raw["key"] and snap.event.step == k and not snap.running
    assert snap.policy == target.policy and "diverges" not in _panel_text(page)
    page.screenshot(path=str(page.shots / "dashboard_results_loaded.png"))
    page.get_by_role("button", name="Take over by hand", exact=True).click()
    _wait(lambda: ctl.snapshot.policy == "teleop" and not ctl.snapshot.busy, timeout=120, what="teleop takes over")
    assert ctl.snapshot.event.step == k and ctl.snapshot.event.episode_key == target.raw["key"]

"""Issue 16 item 2 in a real browser: the Compare folder runs two policies on the selected procedural
episode, shows both maps at the same step in one picture over the main view, and jumps to the first
step where their decisions differ.

Skips like tests/test_dashboard_browser.py when playwright or a chromium is missing. Set
L3MVN_SCREENSHOTS=DIR to keep the screenshot (docs/screenshots/dashboard_compare.png).
"""

from __future__ import annotations

import base64
import dataclasses
import os
import re
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

sync_api = pytest.importorskip("playwright.sync_api")

from conftest import free_port, serve_dashboard
from test_dashboard_browser import CHROMIUM, CHROMIUM_ARGS, VIEWPORT, _open_tab, _panel_text, _wait

pytestmark = pytest.mark.skipif(
    CHROMIUM is None, reason="no chromium: `apt install chromium` or `playwright install chromium` runs these tests"
)

from l3mvn.core.config import Config
from l3mvn_studio.compare import compare_recordings
from l3mvn_studio.results import recording_of
from l3mvn_studio.server import start_dashboard


@pytest.fixture(scope="module")
def dash(tmp_path_factory):
    cfg = Config().with_frame(240, 320)
    cfg = cfg.replace(sim=dataclasses.replace(cfg.sim, max_steps=60))
    yield from serve_dashboard(
        episodes_per_house=2, policy="frontier", cfg=cfg, record_dir=tmp_path_factory.mktemp("rec")
    )


@pytest.fixture
def page_factory(tmp_path):
    """Opens a chromium page on a dashboard (one browser per test)."""
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)

        def open_page(dashboard):
            page = browser.new_page(viewport=VIEWPORT)
            page.set_default_timeout(60_000)
            page.shots = Path(os.environ.get("L3MVN_SCREENSHOTS", tmp_path))
            page.goto(dashboard.url)
            page.wait_for_selector("canvas", timeout=20_000)
            return page

        yield open_page
        browser.close()


@pytest.fixture
def page(dash, page_factory):
    return page_factory(dash)


def _shown_picture(page) -> np.ndarray:
    """The picture the page holds over the main view, decoded from what the page received."""
    src = page.locator(".l3mvn-main-view img.l3mvn-picture").first.get_attribute("src")
    png = base64.b64decode(src.split(",", 1)[1])
    return cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)[..., ::-1]


def test_compare_two_policies_step_by_step(dash, page):
    _open_tab(page, "Compare")
    _wait(lambda: page.get_by_text("Compare", exact=True).count() >= 2, what="the Compare folder in its tab")
    page.get_by_role("button", name="Run both").wait_for()  # open at once: the tab is not empty
    assert page.locator("input[value='frontier']").count() >= 1  # A: the dashboard's policy
    assert page.locator("input[value='cost-utility']").count() >= 1  # B: the default
    page.get_by_role("button", name="Run both").click()
    _wait(lambda: "Working" in _panel_text(page), timeout=10, what="the busy line")
    assert page.get_by_role("button", name="Run both").is_disabled()
    _wait(lambda: "decisions first differ at step" in _panel_text(page), timeout=180, what="the comparison")
    c = dash.view.compare.comparison
    k = c.first_difference
    assert k is not None and k > 0
    assert re.search(rf"decisions first differ at step {k}: A <.+>; B <.+>", _panel_text(page))
    # step 0 first: both sides' step 0, composed again from the two recordings on disk
    fresh = compare_recordings(c.a.recording, c.b.recording, c.episode_key)
    _wait(lambda: page.locator(".l3mvn-main-view img").count() > 0, what="the picture over the main view")
    assert np.array_equal(_shown_picture(page), fresh.picture(0))
    # scrub to step 3 with the slider: both maps at step 3
    slider = page.get_by_role("slider").last
    slider.focus()
    for _ in range(3):
        slider.press("ArrowRight")
    _wait(
        lambda: "A: frontier, step 3:" in _panel_text(page) and "B: cost-utility, step 3:" in _panel_text(page),
        timeout=30,
        what="step 3 of both",
    )
    assert np.array_equal(_shown_picture(page), fresh.picture(3))
    # jump to the first difference
    page.get_by_role("button", name="Jump to first difference").click()
    _wait(lambda: f"A: frontier, step {k}:" in _panel_text(page), timeout=30, what=f"step {k}")
    assert f"B: cost-utility, step {k}:" in _panel_text(page)
    shown = _shown_picture(page)
    assert np.array_equal(shown, fresh.picture(k))
    a_k = fresh.a.picture(k)  # A's own step k inside the frame that flags the difference
    assert np.array_equal(shown[44 : 40 + a_k.shape[0] - 4, 4 : a_k.shape[1] - 4], a_k[4:-4, 4:-4])
    for close in page.locator("button.mantine-Notification-closeButton").all():
        close.click()
    page.wait_for_timeout(1000)  # the notices slide out
    page.get_by_role("button", name="Jump to first difference").scroll_into_view_if_needed()
    page.screenshot(path=str(page.shots / "dashboard_compare.png"))
    # the live session was never blocked: it resets and steps meanwhile
    page.get_by_role("button", name="Reset").click()
    _wait(lambda: dash.controller.snapshot.event is not None, timeout=60, what="the live reset")


def test_a_policy_that_cannot_be_compared_is_not_offered(dash):
    options = dash.view.compare.policy_a.options
    assert "teleop" not in options and "oracle" not in options and "cost-utility" in options


def test_policy_a_follows_the_dashboard_policy_until_picked_here(dash):
    panel = dash.view.compare
    start = panel.policy_a.value
    try:
        panel.follow_policy("random-sample")
        assert panel.policy_a.value == "random-sample"
        panel.follow_policy("teleop")  # not comparable: A stays
        assert panel.policy_a.value == "random-sample"
        panel.policy_a.value = "l3mvn-zs"  # the user's own pick
        panel.follow_policy("cost-utility")
        assert panel.policy_a.value == "l3mvn-zs"
    finally:
        panel.policy_a.value = panel._followed = start


@pytest.fixture(scope="module")
def results_dash(tmp_path_factory):
    d = tmp_path_factory.mktemp("results")
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "TRANSFORMERS_OFFLINE": "1"}
    for policy in ("frontier", "cost-utility"):
        subprocess.run(
            [
                sys.executable,
                "-m",
                "l3mvn_studio.cli",
                "eval",
                "--policy",
                policy,
                "--houses",
                "1",
                "--episodes-per-house",
                "2",
                "--frame",
                "120x160",
                "--set",
                "sim.max_steps=40",
                "--out",
                str(d / f"{policy}.jsonl"),
                "--record",
                "--record-dir",
                str(d / "rec"),
            ],
            check=True,
            capture_output=True,
            env=env,
            timeout=600,
        )
    dash = start_dashboard(
        port=free_port(),
        houses=1,
        episodes_per_house=2,
        policy="frontier",
        results_dir=d,
        recordings_dir=d / "rec",
        record_dir=d / "live",
    )
    yield dash
    dash.stop()


def test_compare_side_by_side_from_two_result_files(results_dash, page_factory):
    page = page_factory(results_dash)
    results, compare = results_dash.view.results, results_dash.view.compare
    _open_tab(page, "Results")
    _wait(lambda: "Per category" in _panel_text(page), timeout=30, what="the Results panel")
    page.locator("input[value='(none)']:visible").first.click()
    page.get_by_role("option", name="frontier.jsonl", exact=True).click()
    _wait(lambda: "only (" in _panel_text(page), what="the comparison of the files")
    page.get_by_role("button", name="Compare side by side").click()
    _wait(lambda: compare.comparison is not None and not compare.busy, timeout=120, what="the comparison")
    row = results._selected()
    other = next(r for r in results._other.rows if r.raw["key"] == row.raw["key"])
    c = compare.comparison
    # each line's own recording (different policies, both recorded by eval): no re-run
    assert (c.a.recording, c.b.recording) == (
        recording_of(results.source.recordings_dir, row),
        recording_of(results.source.recordings_dir, other),
    )
    assert c.a.label == f"A: {row.policy}" and c.b.label == f"B: {other.policy}"
    _wait(lambda: page.locator(".l3mvn-main-view img.l3mvn-picture").count() > 0, what="the compare picture")
    fresh = compare_recordings(c.a.recording, c.b.recording, c.episode_key)
    _wait(lambda: np.array_equal(_shown_picture(page), fresh.picture(0)), timeout=30, what="step 0 of both")
    assert page.locator(".l3mvn-main-view").first.is_visible()  # drawn over the main view, Compare tab open or not
    page.screenshot(path=str(page.shots / "dashboard_compare_from_results.png"))

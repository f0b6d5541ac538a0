"""End to end in a real browser (Debian's chromium driven by playwright): press, look, click.

Skips when playwright or a chromium is missing (Debian's ``chromium`` package, or the one
``playwright install chromium`` downloads). Set L3MVN_SCREENSHOTS=DIR to keep screenshots.
"""

from __future__ import annotations

import math
import os
import re
import shutil
import time
from pathlib import Path

import pytest

sync_api = pytest.importorskip("playwright.sync_api")


def _find_chromium() -> Path | None:
    """The system's chromium, else playwright's own download (None when neither is there)."""
    for name in ("chromium", "chromium-browser"):
        if found := shutil.which(name):
            return Path(found)
    try:
        with sync_api.sync_playwright() as p:
            bundled = Path(p.chromium.executable_path)
    except Exception:  # playwright's driver cannot start here: treat as no browser
        return None
    return bundled if bundled.exists() else None


CHROMIUM = _find_chromium()
pytestmark = pytest.mark.skipif(
    CHROMIUM is None, reason="no chromium: `apt install chromium` or `playwright install chromium` runs these tests"
)

from conftest import serve_dashboard

from l3mvn.core.config import Config  # noqa: E402
from l3mvn_studio.scene_drawing import cell_to_xy  # noqa: E402

CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]
VIEWPORT = {"width": 1400, "height": 900}


def _wait(predicate, timeout: float = 10.0, what: str = "condition") -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for {what}")


def _panel_text(page) -> str:
    return page.locator("body").inner_text()


def _open_tab(page, name: str) -> None:
    """Open the control panel's tab ``name``: only the open tab's controls are on the page."""
    page.get_by_role("tab", name=name, exact=True).click()


def _step_shown(page) -> int | None:
    m = re.search(r"Step (\d+), action", _panel_text(page))
    return int(m.group(1)) if m else None


def _screen_point(page, client, x: float, y: float) -> tuple[float, float]:
    """Pixel of scene point (x, y, 0) under the top-down camera the dashboard set (fov vertical)."""
    cam = client.camera
    box = page.locator("canvas").first.bounding_box()
    half = cam.position[2] * math.tan(cam.fov / 2)
    u = box["x"] + box["width"] / 2 + (x - cam.look_at[0]) / half * box["height"] / 2
    v = box["y"] + box["height"] / 2 - (y - cam.look_at[1]) / half * box["height"] / 2
    return u, v


@pytest.fixture(scope="module")
def dash():
    yield from serve_dashboard(episodes_per_house=2, policy="frontier", cfg=Config().with_frame(240, 320))


def test_step_and_frontier_click_in_a_real_browser(dash, tmp_path):
    shots = Path(os.environ.get("L3MVN_SCREENSHOTS", tmp_path))
    ctl = dash.controller
    events = []
    ctl.bus.subscribe(events.append)
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        try:
            page = browser.new_page(viewport=VIEWPORT)
            page.goto(dash.url)
            page.wait_for_selector("canvas", timeout=20_000)
            _wait(lambda: dash.server.get_clients(), what="the page to connect")
            client = next(iter(dash.server.get_clients().values()))

            page.get_by_role("button", name="Reset").click()
            _wait(lambda: _step_shown(page) == 0, what="step 0 in the status panel")
            page.get_by_role("button", name="Step").click()
            _wait(lambda: _step_shown(page) == 1, what="step 1 in the status panel")
            time.sleep(0.5)
            before = page.locator("canvas").first.screenshot()
            page.get_by_role("button", name="Step").click()
            _wait(lambda: _step_shown(page) == 2, what="step 2 in the status panel")
            time.sleep(0.5)
            assert page.locator("canvas").first.screenshot() != before, "the map did not change after Step"

            # Past the look-around: frontiers appear. Step in the page until then.
            for _ in range(40):
                if ctl.snapshot.map is not None and ctl.snapshot.map.frontiers and _step_shown(page) >= 14:
                    break
                n = _step_shown(page)
                page.get_by_role("button", name="Step").click()
                _wait(lambda n=n: (_step_shown(page) or 0) > n, what="the next step")
            view = ctl.snapshot.map
            assert view.frontiers, "no frontiers after the look-around"
            page.get_by_role("button", name="Fit map in view").click()
            time.sleep(1.0)
            page.screenshot(path=str(shots / "dashboard.png"))

            # A click off the map (below it, in the map's canvas) is refused with a message, and nothing changes.
            box = page.locator("canvas").first.bounding_box()
            page.mouse.click(box["x"] + box["width"] / 2, box["y"] + box["height"] - 100)
            page.get_by_text("outside the map").first.wait_for(timeout=5_000)

            target = view.frontiers[0]
            u, v = _screen_point(page, client, *cell_to_xy(target.cell, view.resolution_m))
            page.mouse.click(u, v)
            page.get_by_text("manual long-term goal set").first.wait_for(timeout=5_000)
            page.get_by_role("button", name="Step").click()
            _wait(
                lambda: events and events[-1].decision is not None and events[-1].decision.goal_kind == "manual",
                what="a manual-goal step",
            )
            decision = events[-1].decision
            assert decision.long_term_goal == target.cell
            assert decision.override == f"manual:{target.cell[0]},{target.cell[1]}"
            _wait(lambda: "Manual goal" in _panel_text(page), what="the manual goal in the status panel")
            time.sleep(0.5)
            page.screenshot(path=str(shots / "dashboard_manual_goal.png"))

            # A second tab sees the same episode at once; a reload reconnects cleanly.
            other = browser.new_page(viewport=VIEWPORT)
            other.goto(dash.url)
            _wait(lambda: _step_shown(other) == _step_shown(page), what="the second tab to catch up")
            other.reload()
            _wait(lambda: _step_shown(other) == _step_shown(page), what="the reloaded tab to catch up")
        finally:
            browser.close()

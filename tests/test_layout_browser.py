"""Issue 34 in a real browser: the map-first layout at common window sizes, notices that replace each
other instead of piling up, and keys that work after a click on a checkbox or a dropdown.

Skips like tests/test_dashboard_browser.py when playwright or a chromium is missing. Set
L3MVN_SCREENSHOTS=DIR to keep the screenshots.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

sync_api = pytest.importorskip("playwright.sync_api")

from conftest import free_port, serve_dashboard
from test_dashboard_browser import CHROMIUM, CHROMIUM_ARGS, _step_shown, _wait

pytestmark = pytest.mark.skipif(
    CHROMIUM is None, reason="no chromium: `apt install chromium` or `playwright install chromium` runs these tests"
)

from l3mvn.core.config import Config
from l3mvn_studio.server import start_dashboard
from l3mvn_studio.tab_notices import TOGETHER_SECONDS

SIZES = ((1280, 720), (1600, 1000), (1920, 1080))
STATUS_LINE = re.compile(r"Step \d+, action")


@pytest.fixture(scope="module")
def dash():
    yield from serve_dashboard(episodes_per_house=2, policy="frontier", cfg=Config().with_frame(240, 320))


@pytest.fixture(scope="module")
def browser():
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        yield browser
        browser.close()


@pytest.fixture
def page_at(browser, tmp_path):
    """Opens a page of size (width, height) on a dashboard; closed after the test."""
    pages = []

    def open_page(dashboard, size):
        page = browser.new_page(viewport={"width": size[0], "height": size[1]})
        page.set_default_timeout(30_000)
        page.shots = Path(os.environ.get("L3MVN_SCREENSHOTS", tmp_path))
        pages.append(page)
        page.goto(dashboard.url)
        page.wait_for_selector("canvas", timeout=20_000)
        _wait(lambda: "Keys:" in page.locator("body").inner_text(), what="the panel")
        return page

    yield open_page
    for page in pages:
        page.close()


def _shown_whole(page, locator, what: str) -> dict:
    """``locator``'s box, asserted to lie inside the window as loaded (nothing scrolled) and on top
    at its centre (not covered, not clipped away by the panel it is in)."""
    box = locator.bounding_box()
    assert box is not None, f"{what} is not on the page"
    size = page.viewport_size
    inside = (
        box["x"] >= 0
        and box["y"] >= 0
        and box["x"] + box["width"] <= size["width"] + 0.5
        and box["y"] + box["height"] <= size["height"] + 0.5
    )
    assert inside, f"{what} at {box} is not inside the {size['width']}x{size['height']} window"
    centre = (box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
    assert locator.evaluate("(e, [x, y]) => e.contains(document.elementFromPoint(x, y))", list(centre)), (
        f"{what} is covered at its centre"
    )
    return box


@pytest.mark.parametrize("size", SIZES, ids=lambda s: f"{s[0]}x{s[1]}")
def test_map_camera_and_status_are_all_in_view_without_scrolling(dash, page_at, size):
    page = page_at(dash, size)
    if dash.controller.snapshot.event is None:
        page.get_by_role("button", name="Reset").click()
    _wait(lambda: _step_shown(page) is not None, timeout=60, what="the status of an episode")
    page.wait_for_timeout(500)
    page.screenshot(path=str(page.shots / f"layout_{size[0]}x{size[1]}.png"))
    assert page.evaluate("[window.scrollX, window.scrollY]") == [0, 0]
    rgb = _shown_whole(page, page.get_by_text("RGB", exact=True).locator("xpath=following::img[1]"), "the RGB view")
    assert rgb["width"] >= 300, f"the RGB view is {rgb['width']:.0f} px wide: too small to read"
    status = _shown_whole(page, page.get_by_text(STATUS_LINE).first, "the status line")
    canvas = page.locator("canvas").last
    map_box = canvas.bounding_box()
    assert map_box is not None
    # The map's canvas is the window less the two panels: wide, full height, and under neither panel.
    assert map_box["x"] >= rgb["x"] + rgb["width"] and map_box["x"] + map_box["width"] <= status["x"], (
        f"the map's canvas {map_box} lies under a panel (RGB at {rgb}, status at {status})"
    )
    assert map_box["height"] >= size[1] - 1 and map_box["width"] >= 0.35 * size[0], map_box
    covered = page.evaluate(
        "([x, y]) => document.elementFromPoint(x, y).tagName", [map_box["x"] + 20, map_box["y"] + size[1] / 2]
    )
    assert covered == "CANVAS", f"the map's left edge is covered by a {covered}"


def _our_cards(page):
    return page.locator(".mantine-Notification-root").filter(has_not_text="WebGL")  # not the browser's own


def _one_card_with(page, *texts: str) -> bool:
    cards = _our_cards(page).all_inner_texts()
    return len(cards) == 1 and all(text in cards[0] for text in texts)


def test_notices_that_come_together_share_a_card_and_a_later_one_replaces_it(page_at):
    fresh = start_dashboard(
        port=free_port(), houses=1, episodes_per_house=1, policy="frontier", cfg=Config().with_frame(120, 160)
    )
    try:
        page = page_at(fresh, SIZES[0])
        page.get_by_role("button", name="Step").click()
        page.get_by_role("button", name="Fit map in view").click()
        both = (
            "no episode yet: pick one and press Reset",
            "no map to fit yet: press Reset (or Run) to start an episode",
        )
        # One card with both texts, well before a card would close by itself (NOTICE_SECONDS).
        _wait(lambda: _one_card_with(page, *both), timeout=4, what="one card with both refusals")
        page.wait_for_timeout((TOGETHER_SECONDS + 0.3) * 1000)
        page.get_by_role("button", name="Clear").click()
        _wait(lambda: _one_card_with(page, "no manual goal to clear"), timeout=4, what="a new card in its place")
        assert not any(text in _our_cards(page).first.inner_text() for text in both)
    finally:
        fresh.stop()


def test_keys_work_after_a_click_on_a_checkbox_or_a_dropdown(dash, page_at):
    page = page_at(dash, SIZES[1])
    if dash.controller.snapshot.event is None:
        page.get_by_role("button", name="Reset").click()
    _wait(lambda: _step_shown(page) is not None, timeout=60, what="an episode")
    auto_fit = page.get_by_text("Auto-fit map", exact=True).locator("xpath=following::input[@type='checkbox'][1]")
    for _ in range(2):  # ticked, then back as it was
        auto_fit.click()
        assert page.evaluate("document.activeElement.type") == "checkbox"  # the click left the focus there
        n = _step_shown(page)
        page.keyboard.press("n")
        _wait(lambda n=n: _step_shown(page) == n + 1, timeout=30, what="N to step after a checkbox click")
    head = page.locator(f"input[value='{dash.view.head.value}']:visible").first
    head.click()
    page.get_by_role("option", name=dash.view.head.value, exact=True).click()  # the same head: nothing changes
    assert page.evaluate("document.activeElement.getAttribute('role')") == "combobox"
    n = _step_shown(page)
    page.keyboard.press("n")
    _wait(lambda: _step_shown(page) == n + 1, timeout=30, what="N to step after a dropdown pick")

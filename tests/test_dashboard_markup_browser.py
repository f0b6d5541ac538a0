"""Result files and recordings from someone else are shown as text, never run (issue 30 item 1).

A folder of result files full of markup (in keys, scenes, goals, policies, error messages and the
file's own name) and a recording named with markup are opened with ``serve --results`` in a real
chromium: every panel that shows them is drawn, and afterwards no element, script, link or dialog
from them exists, while their text is on the page as typed. Skips like the other browser tests.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

sync_api = pytest.importorskip("playwright.sync_api")

from conftest import free_port
from test_dashboard_browser import CHROMIUM, CHROMIUM_ARGS, VIEWPORT, _open_tab, _panel_text, _wait

pytestmark = pytest.mark.skipif(
    CHROMIUM is None, reason="no chromium: `apt install chromium` or `playwright install chromium` runs these tests"
)

from l3mvn_studio.server import start_dashboard

# Each would leave a trace if it ran or became an element: window.__xss, an element marked data-xss,
# a javascript: link, a dialog or a changed title.
SCRIPT = "<script>window.__xss = 1</script>"
IMAGE = '<img src=x onerror="window.__xss=2" data-xss>'
FRAME = "<iframe srcdoc=\"<script>parent.document.title='XSS-'+document.domain</script>\" data-xss></iframe>"
LINK = "[press me](javascript:window.__xss=3)"
BOLD = "<b data-xss onmouseover=alert(1)>bold</b> **stars** `ticks` | cell |"
FILE_NAME = "<img src=x onerror=alert(4) data-xss>.jsonl"  # sorts first: it is the file shown on load


def _row(**changes) -> dict:
    row = {
        "key": FRAME,
        "scene": IMAGE,
        "episode_id": 0,
        "goal": SCRIPT,
        "policy": LINK,
        "config_hash": "c0ffee",
        "rule": "semexp",
        "success": 0,
        "spl": 0.0,
        "dtg": 1.5,
        "failure": "timeout",
        "steps": 3,
        "extra": {"coverage": 0.5},
    }
    return {**row, **changes}


@pytest.fixture(scope="module")
def dash(tmp_path_factory):
    d = tmp_path_factory.mktemp("markup")
    results, live = d / "results", d / "live"
    results.mkdir()
    live.mkdir()
    error = {"key": IMAGE, "policy": LINK, "config_hash": "c0ffee", "error": f"RuntimeError: {BOLD}"}
    (results / FILE_NAME).write_text("\n".join(json.dumps(r) for r in (_row(), error, {"key": SCRIPT})) + "\n")
    solved = _row(success=1, failure="success", spl=0.8)
    (results / "z-other.jsonl").write_text(json.dumps(solved) + "\n")
    (live / "<img src=x onerror=alert(5) data-xss>.rrd").write_bytes(b"")
    dash = start_dashboard(
        port=free_port(),
        houses=1,
        episodes_per_house=2,
        policy="frontier",
        results_dir=results,
        recordings_dir=d / "rec",
        record_dir=live,
    )
    yield dash
    dash.stop()


def _traces(page) -> dict:
    return page.evaluate("""() => ({
        xss: window.__xss === undefined ? null : window.__xss,
        marked: document.querySelectorAll('[data-xss]').length,
        frames: document.querySelectorAll('iframe').length,
        scripts: [...document.querySelectorAll('script')].filter(s => s.textContent.includes('__xss')).length,
        links: document.querySelectorAll('a[href^="javascript"]').length,
        title: document.title,
    })""")


def test_markup_from_result_files_and_recordings_stays_text(dash, tmp_path):
    dialogs: list[str] = []
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        page = browser.new_page(viewport=VIEWPORT)
        page.set_default_timeout(60_000)
        page.on("dialog", lambda d: (dialogs.append(d.message), d.dismiss()))
        page.goto(dash.url)
        page.wait_for_selector("canvas", timeout=20_000)
        title = page.title()
        _open_tab(page, "Results")
        _wait(lambda: "Per category" in _panel_text(page), timeout=30, what="the Results panel")
        panel = dash.view.results
        assert panel._file is not None and panel._file.path.name == FILE_NAME

        page.locator("input[value='(none)']:visible").first.click()  # Compare with: the other file
        page.get_by_role("option", name="z-other.jsonl", exact=True).click()
        _wait(lambda: "Solved by" in _panel_text(page), timeout=30, what="the comparison")
        page.get_by_role("button", name="Open", exact=True).click()  # no recording: a note naming the episode
        _wait(lambda: "no recording of" in _panel_text(page), timeout=30, what="the note of a missing recording")
        tabs = {}  # each tab's text and traces: only the open tab's content is on the page
        for tab in ("Results", "Recordings"):
            _open_tab(page, tab)
            if tab == "Recordings":
                _wait(lambda: "newest first" in _panel_text(page), timeout=30, what="the recordings list")
            page.mouse.move(700, 300)
            page.wait_for_timeout(1000)  # an onerror or a srcdoc frame would have run by now
            tabs[tab] = (_panel_text(page), _traces(page))
        page.screenshot(path=str(Path(os.environ.get("L3MVN_SCREENSHOTS", tmp_path)) / "dashboard_markup.png"))
        browser.close()

    clean = {"xss": None, "marked": 0, "frames": 0, "scripts": 0, "links": 0, "title": title}
    for tab, (_, traces) in tabs.items():
        assert traces == clean, (tab, traces)
    text = "\n".join(shown for shown, _ in tabs.values())
    assert dialogs == []
    # The same characters are on the page as text: in the file name, the table, the notes, the
    # comparison, the missing-recording note and the recordings list.
    for shown in (
        FILE_NAME,
        'onerror="window.__xss=2"',
        "window.__xss = 1",
        "(javascript:window.__xss=3)",
        "parent.document.title",
        "<b data-xss onmouseover=alert(1)>bold</b> **stars** `ticks` | cell |",
        "onerror=alert(5)",
    ):
        assert shown in text, shown

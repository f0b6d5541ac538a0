"""Issue 34 item 5 in a real browser: the page ``l3mvn report`` writes opens from a file with the
network cut off, shows its tables and charts, runs its own inlined script (its Content Security
Policy lets nothing else run) and plays an embedded episode video. Skips like
tests/test_dashboard_browser.py when playwright or a chromium is missing.
"""

from __future__ import annotations

import pytest

sync_api = pytest.importorskip("playwright.sync_api")

from test_dashboard_browser import CHROMIUM, CHROMIUM_ARGS
from test_video import _record

pytestmark = pytest.mark.skipif(
    CHROMIUM is None, reason="no chromium: `apt install chromium` or `playwright install chromium` runs these tests"
)

from l3mvn.run.eval.result_videos import export_result_video  # noqa: E402
from l3mvn.run.eval.results import encode_row  # noqa: E402
from l3mvn.run.recording.drawing import VideoOptions  # noqa: E402
from l3mvn.world.scenes.procedural import generate_house  # noqa: E402
from l3mvn_studio.report import write_report  # noqa: E402

_CANPLAY = """() => new Promise((resolve) => {
    const v = document.querySelector("video");
    const done = () => resolve({error: v.error && v.error.code, ready: v.readyState, width: v.videoWidth});
    if (v.readyState >= 3) { done(); return; }
    v.addEventListener("canplay", done, {once: true});
    v.addEventListener("error", done, {once: true});
    v.load();
})"""


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    """A page over two result files of one real recorded episode, with its exported video."""
    folder = tmp_path_factory.mktemp("report")
    recording, result = _record(folder / "recordings", generate_house(3), "frontier")
    key = f"{result.scene}/{result.floor}/{result.episode_id}"
    row = result.to_json() | {"key": key, "config_hash": "test", "config": {"sim": {"max_steps": 24}}}
    export_result_video(row, folder / "recordings", folder / "videos", VideoOptions(fps=4, height=160, title_s=1.0))
    a, b = folder / "a.jsonl", folder / "b.jsonl"
    a.write_bytes(encode_row(row))
    b.write_bytes(encode_row(row | {"policy": "other", "success": 0.0, "spl": 0.0, "failure": "timeout"}))
    return write_report([a, b], folder / "report.html", videos=folder / "videos").path


def test_the_report_opens_offline_with_its_tables_charts_script_and_a_playable_video(report):
    requested, errors = [], []
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        try:
            page = browser.new_page()
            page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
            page.on("pageerror", lambda e: errors.append(str(e)))

            def block(route):
                url = route.request.url
                if url.startswith(("file:", "data:")):
                    route.continue_()
                else:
                    requested.append(url)
                    route.abort()

            page.route("**/*", block)
            page.goto(report.as_uri())
            summary_rows = page.locator("#summary-table tbody tr").count()
            charts = page.locator("svg.chart").count()
            paired = page.locator("table.paired").count()
            header = page.locator("#summary-table th", has_text="SR")
            header.click()  # the inlined script sorts: it ran, so the policy let it
            sorted_by = header.get_attribute("aria-sort")
            outcome = page.locator("#video-grid figure").get_attribute("data-outcome")
            page.locator(f".filters button[data-show={'fail' if outcome == 'success' else 'success'}]").click()
            hidden = page.evaluate("() => document.querySelector('#video-grid figure').hidden")
            page.locator(".filters button[data-show=all]").click()
            state = page.evaluate(_CANPLAY)
        finally:
            browser.close()
    assert requested == [] and errors == [], (requested, errors)
    assert summary_rows == 2 and paired == 1
    assert charts == 4  # paired differences, failure causes, SR and SPL by length
    assert sorted_by == "ascending"
    assert hidden is True  # the other outcome's filter hides the one video
    assert state["error"] is None, f"chromium refused the embedded video: MediaError {state['error']}"
    assert state["ready"] >= 3 and state["width"] > 0

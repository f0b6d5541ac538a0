"""Issue 34 item 1 in a real browser: chromium plays the video ``l3mvn export`` writes.

OpenCV's mp4v (MPEG-4 Part 2) was refused by chromium's <video> (MediaError 4, "format not
supported"); H.264 in MP4 loads. Skips like tests/test_dashboard_browser.py when playwright or a
chromium is missing.
"""

from __future__ import annotations

import pytest

sync_api = pytest.importorskip("playwright.sync_api")

from test_dashboard_browser import CHROMIUM, CHROMIUM_ARGS
from test_video import _record

pytestmark = pytest.mark.skipif(
    CHROMIUM is None, reason="no chromium: `apt install chromium` or `playwright install chromium` runs these tests"
)

from l3mvn.run.recording.drawing import VideoOptions  # noqa: E402
from l3mvn.run.recording.video import export_video  # noqa: E402
from l3mvn.world.scenes.procedural import generate_house  # noqa: E402

_STATE = """() => {
    const v = document.querySelector("video");
    return {error: v.error && v.error.code, ready: v.readyState, width: v.videoWidth, height: v.videoHeight,
            duration: v.duration};
}"""


def test_chromium_loads_the_exported_video_without_a_media_error(tmp_path):
    recording, _ = _record(tmp_path, generate_house(3), "frontier")
    video = export_video(recording, tmp_path / "ep.mp4", VideoOptions(fps=4, height=160, title_s=1.0))
    page_file = tmp_path / "play.html"
    page_file.write_text(f'<!doctype html><video src="{video.path.name}" muted preload="auto"></video>')
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        try:
            page = browser.new_page()
            page.goto(page_file.as_uri())
            page.wait_for_function(
                "() => { const v = document.querySelector('video'); return v.error || v.readyState >= 2; }",
                timeout=20_000,
            )
            state = page.evaluate(_STATE)
        finally:
            browser.close()
    assert state["error"] is None, f"chromium refused {video.path.name}: MediaError {state['error']}"
    assert state["ready"] >= 2  # HAVE_CURRENT_DATA: a frame is decoded
    assert (state["width"], state["height"]) == (video.width, video.height)
    assert state["duration"] == pytest.approx(video.frames / video.fps, abs=0.5)

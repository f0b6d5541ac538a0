"""The Recordings folder: "Open in rerun" serves a recording in rerun's web viewer, linked in the page."""

from __future__ import annotations

import os
import subprocess
import sys
import urllib.request

import pytest
from conftest import serve_dashboard

from l3mvn.core.errors import L3MVNError
from l3mvn_studio.page_text import code


@pytest.fixture(scope="module")
def dash(tmp_path_factory):
    rec = tmp_path_factory.mktemp("rec")
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
            "1",
            "--episodes-per-house",
            "2",
            "--frame",
            "120x160",
            "--set",
            "sim.max_steps=15",
            "--out",
            str(rec / "out.jsonl"),
            "--record",
            "--record-dir",
            str(rec),
        ],
        check=True,
        capture_output=True,
        env=env,
        timeout=600,
    )
    yield from serve_dashboard(episodes_per_house=2, policy="frontier", record_dir=rec)


def _answers(url: str) -> int:
    """The viewer's HTTP status, asked once: a link is handed out only once the viewer answers."""
    with urllib.request.urlopen(url, timeout=30) as reply:
        return reply.status


def test_open_in_rerun_serves_the_recording_and_links_it(dash):
    panel = dash.view.recordings
    names = panel.pick.options
    assert len(names) == 2 and all(n.endswith(".rrd") for n in names) and not panel.pick.disabled
    first = panel.open(names[0])
    assert first.alive and _answers(first.url) == 200
    assert first.url in panel.link.content and code(names[0]) in panel.link.content
    second = panel.open(names[1])  # one viewer at a time: the first one stops
    assert not first.alive and second.alive and _answers(second.url) == 200
    dash.view.recordings.close()
    assert not second.alive


def test_a_viewer_that_exits_before_serving_is_a_one_line_error(tmp_path, monkeypatch):
    from l3mvn.run.recording import replay

    monkeypatch.setattr(replay, "viewer_executable", lambda: "/bin/false")
    monkeypatch.setattr(replay, "_check_recording", lambda path: None)
    with pytest.raises(L3MVNError, match=r"^rerun's web viewer exited \(status 1\) before serving x\.rrd$"):
        replay.start_web_viewer(tmp_path / "x.rrd")


def test_only_recordings_of_the_folder_can_be_opened(dash):
    with pytest.raises(L3MVNError, match=r"^no recording '\.\./x\.rrd' in .*; valid: .*\.rrd") as info:
        dash.view.recordings.open("../x.rrd")
    assert "\n" not in str(info.value)


def test_the_folders_the_results_panel_reads_are_listed_and_open_too(dash, tmp_path):
    """Issue 34: the eval's recordings (serve --recordings) are listed beside the live session's, each
    under its folder, and open in rerun like them; a folder two roles share is listed once."""
    import shutil

    panel = dash.view.recordings
    live = list(panel.pick.options)
    shutil.copy(panel.record_dir / live[0], tmp_path / live[0])
    before = list(panel._folders)
    try:
        panel.add_folder("eval recordings", tmp_path)
        panel.add_folder("re-runs", panel.record_dir)
        assert [label for label, _ in panel.folders()] == ["live session and re-runs", "eval recordings"]
        assert tuple(panel.pick.options) == (*live, f"eval recordings: {live[0]}")
        assert "**eval recordings**" in panel.listing.content and code(f"{tmp_path}/") in panel.listing.content
        viewer = panel.open(f"eval recordings: {live[0]}")
        assert viewer.alive and _answers(viewer.url) == 200 and viewer.url in panel.link.content
    finally:
        panel.close()
        panel._folders[:] = before
        panel.refresh()

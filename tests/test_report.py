"""``l3mvn report``: one self-contained HTML page over result files, and every bad input refused in one line."""

from __future__ import annotations

import base64
import errno
import json
import os
import re
from importlib import resources
from pathlib import Path

import pytest
from test_full_disk import full  # noqa: F401  (a fixture: a real filesystem with no byte left)

from l3mvn.run.eval.result_videos import result_video_name
from l3mvn_studio.cli import main
from l3mvn_studio.report import write_report

GOALS = ("bed", "toilet")


def _row(i: int, policy: str, success: int, *, max_steps: int = 500, goal: str | None = None, **more) -> dict:
    row = {
        "key": f"House/0/{i}",
        "scene": "House",
        "floor": 0,
        "episode_id": i,
        "goal": goal or GOALS[i % 2],
        "policy": policy,
        "success": success,
        "spl": 0.5 if success else 0.0,
        "dtg": 0.0 if success else 3.0,
        "failure": "success" if success else ("never_saw_target" if i % 3 else "false_stop"),
        "steps": 40 + i,
        "path_length_m": 5.0,
        "shortest_path_m": 1.0 + i * 0.5,
        "rule": "semexp",
        "config_hash": policy,
        "extra": {},
        "config": {"sim": {"max_steps": max_steps}, "policy": {"scorer": None}},
    }
    return row | more


def _write(path: Path, rows: list[dict]) -> Path:
    path.write_text("".join(json.dumps(r) + "\n" for r in rows))
    return path


@pytest.fixture
def two_files(tmp_path):
    """A: 40 episodes, half solved; B: the same episodes but two, all solved, under another max_steps."""
    a = _write(tmp_path / "a.jsonl", [_row(i, "frontier", i % 2) for i in range(40)])
    b = _write(tmp_path / "b.jsonl", [_row(i, "l3mvn-zs", 1, max_steps=200) for i in range(2, 40)])
    return a, b


def _report(tmp_path, *args: str) -> str:
    out = tmp_path / "report.html"
    assert main(["report", *args, "--out", str(out)]) == 0
    return out.read_text(encoding="utf-8")


def test_two_files_make_one_page_with_intervals_per_category_and_the_paired_differences(two_files, tmp_path):
    page = _report(tmp_path, *map(str, two_files))

    summary = page[page.index('id="summary-table"') :]
    assert re.search(
        r"a\.jsonl \(frontier\)</td><td>40</td><td[^>]*>0\.500<span class=\"ci\">\[0\.3\d\d, 0\.6\d\d\]", summary
    )
    assert re.search(
        r"b\.jsonl \(l3mvn-zs\)</td><td>38</td><td[^>]*>1\.000<span class=\"ci\">\[1\.000, 1\.000\]", summary
    )
    # A solved every toilet (odd episodes) and no bed; B solved all
    sr = page[page.index("<h3>SR per goal category") : page.index("<h3>SPL per goal category")]
    ci = '<span class="ci">'
    assert f'<td class="name">bed</td><td>20</td><td data-value="0.000000">0.000{ci}[0.000, 0.000]</span>' in sr
    assert f'<td class="name">toilet</td><td>20</td><td data-value="1.000000">1.000{ci}[1.000, 1.000]</span>' in sr
    for goal in GOALS:
        assert page.count(f'<td class="name">{goal}</td>') == 3 + 2  # SR, SPL, DTG tables; SR, SPL paired
    paired = page[page.index('id="paired"') :]
    # the 38 shared episodes: A solved 19 of them, B all; so B - A in SR is +0.5 with wins only
    assert re.search(
        r"<td class=\"name\">all</td><td>38</td><td class=\"name\">SR</td><td>0\.500</td><td>1\.000</td>", paired
    )
    assert "19 / 0" in paired
    assert "38 episodes shared and paired; left out: 2 only in the first file, 0 only in this one." in page
    assert page.count('<svg class="chart"') == 4  # paired differences, failure causes, SR and SPL by length
    assert "geodesic start distance (m)" in page


def test_the_settings_that_differ_come_first_and_max_steps_is_named_a_trap(two_files, tmp_path):
    page = _report(tmp_path, *map(str, two_files))
    settings = page.index('id="settings"')
    assert settings < page.index('id="summary"') < page.index('id="paired"')
    assert "sim.max_steps: 500 -&gt; 200" in page[settings:]
    assert 'class="trap">sim.max_steps differs: SR and SPL are not comparable' in page


def test_the_page_inlines_its_shipped_css_and_js_and_loads_nothing(two_files, tmp_path):
    page = _report(tmp_path, *map(str, two_files))
    static = resources.files("l3mvn_studio.static")
    assert static.joinpath("report.css").read_text() in page
    assert static.joinpath("report.js").read_text() in page
    assert not re.search(r"""(src|href)=["']?(https?:|//)|@import|url\(""", page)
    assert "default-src 'none'" in page  # and the page's own policy forbids any load but data:


def test_every_string_from_a_result_file_is_escaped(tmp_path):
    evil = '<script>alert("x")</script><img src=x onerror=alert(1)>'
    rows = [_row(i, evil, i % 2, goal=evil, scene=evil, key=f"{evil}/0/{i}") for i in range(4)]
    a = _write(tmp_path / "a.jsonl", rows)
    videos = tmp_path / "videos"
    videos.mkdir()
    for row in rows:
        (videos / result_video_name(row)).write_bytes(b"video")
    page = _report(tmp_path, str(a), "--videos", str(videos), "--title", evil)
    assert page.count("<script") == 1 and "<img" not in page
    assert "&lt;script&gt;alert(&quot;x&quot;)&lt;/script&gt;" in page


def test_videos_are_embedded_failures_first_and_capped(tmp_path):
    rows = [_row(i, "frontier", i % 2) for i in range(6)]
    a = _write(tmp_path / "a.jsonl", rows)
    videos = tmp_path / "videos"
    videos.mkdir()
    for row in rows[:5]:  # the last episode has no video
        (videos / result_video_name(row)).write_bytes(f"video of {row['key']}".encode())
    webm = videos / result_video_name(rows[0]).replace(".mp4", ".webm")  # the exporter's fallback codec
    (videos / result_video_name(rows[0])).rename(webm)

    page = _report(tmp_path, str(a), "--videos", str(videos), "--max-videos", "3")

    embedded = re.findall(
        r'<figure data-outcome="(\w+)"><video controls preload="auto" src="data:(video/\w+);base64,([^"]+)"', page
    )
    assert [outcome for outcome, _, _ in embedded] == ["fail", "fail", "fail"]  # episodes 0, 2, 4 failed
    assert [base64.b64decode(data).decode() for _, _, data in embedded] == [
        "video of House/0/0",  # false_stop: scored before never_saw_target
        "video of House/0/2",
        "video of House/0/4",
    ]
    assert embedded[0][1] == "video/webm" and embedded[1][1] == "video/mp4"
    size = sum(len(f"video of House/0/{i}") for i in (0, 2, 4)) / (1 << 20)
    assert f"3 of the 5 videos found in <code>{videos}</code> embedded ({size:.1f} MiB), failures first." in page
    assert "2 left out (--max-videos 3)." in page and "1 episodes have no video in the folder." in page


def test_without_videos_the_page_says_none_were_given(two_files, tmp_path):
    page = _report(tmp_path, *map(str, two_files))
    assert "No videos were given" in page and "<video" not in page


def test_a_file_of_two_policies_is_two_runs_and_is_not_paired(tmp_path):
    rows = [_row(i, "frontier", 1) for i in range(4)] + [_row(i, "random", 0) for i in range(4)]
    a = _write(tmp_path / "a.jsonl", rows)
    b = _write(tmp_path / "b.jsonl", [_row(i, "frontier", 1) for i in range(4)])
    written = write_report([a, b], tmp_path / "r.html")
    assert written.runs == 3
    page = written.path.read_text()
    assert "a.jsonl (frontier)" in page and "a.jsonl (random)" in page
    assert "a.jsonl holds 2 policies (frontier, random): paired differences need one policy per file" in page


def _refused(capsys, tmp_path, out: Path, *args: str) -> str:
    before = set(tmp_path.rglob("*"))
    assert main(["report", *args, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1, err
    assert set(tmp_path.rglob("*")) == before  # no page, no partial file
    return err


@pytest.mark.parametrize(
    ("content", "expected"),
    [
        (None, "results file {path} not found"),
        ("", "is not an eval result file: no episode row (it is empty)"),
        ("this is not JSON\n", "line 1: not JSON"),
        ('{"accuracy": 0.9}\n', "line 1: no 'key'"),
        ("\x89PNG\r\n\x1a\n\x00\x00", "not UTF-8 text"),
    ],
    ids=["missing", "empty", "malformed", "not-a-result-file", "binary"],
)
def test_a_bad_result_file_is_one_line_and_no_page(tmp_path, capsys, content, expected):
    path = tmp_path / "bad.jsonl"
    if content is not None:
        path.write_bytes(content.encode("latin-1"))
    err = _refused(capsys, tmp_path, tmp_path / "report.html", str(path))
    assert expected.format(path=path) in err


def test_mixed_success_rules_and_a_repeated_file_are_refused(two_files, tmp_path, capsys):
    a, _ = two_files
    mixed = _write(tmp_path / "mixed.jsonl", [_row(0, "p", 1), _row(1, "p", 1, rule="hm3d")])
    assert "mixes success rules (hm3d, semexp)" in _refused(capsys, tmp_path, tmp_path / "r.html", str(mixed))
    assert "is given twice" in _refused(capsys, tmp_path, tmp_path / "r.html", str(a), str(a))


def test_an_out_that_cannot_be_written_leaves_nothing(two_files, tmp_path, capsys):
    a, b = two_files
    blocker = tmp_path / "file"
    blocker.write_text("x")
    err = _refused(capsys, tmp_path, blocker / "report.html", str(a))
    assert f"cannot write report {blocker / 'report.html'}" in err
    assert "is one of the result files" in _refused(capsys, tmp_path, a, str(a), str(b))
    assert a.read_text().count("\n") == 40  # the result file is untouched
    err = _refused(capsys, tmp_path, tmp_path / "r.html", str(a), "--videos", str(tmp_path / "none"))
    assert "videos folder" in err and "not found" in err


def test_a_disk_that_fills_on_sync_leaves_no_partial_page(two_files, tmp_path, capsys, monkeypatch):
    def no_space(fd):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "fsync", no_space)
    err = _refused(capsys, tmp_path, tmp_path / "report.html", *map(str, two_files))
    assert "No space left on device; nothing was written there" in err


def test_a_real_full_disk_leaves_no_partial_page(two_files, full, capsys):  # noqa: F811
    assert main(["report", *map(str, two_files), "--out", str(full / "report.html")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: cannot write report {full / 'report.html'}: No space left on device")
    assert sorted(p.name for p in full.iterdir()) == ["filler"]


def test_dev_full_is_refused_in_one_line(two_files, tmp_path, capsys):
    if not Path("/dev/full").exists():
        pytest.skip("no /dev/full here")
    assert main(["report", str(two_files[0]), "--out", "/dev/full"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: cannot write report /dev/full") and err.count("\n") == 1


def test_a_negative_max_videos_is_a_usage_error(two_files, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["report", str(two_files[0]), "--max-videos", "-1"])
    assert exc.value.code == 2 and "expected 0 or more, got -1" in capsys.readouterr().err

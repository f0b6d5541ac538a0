"""The results browser's data (app/results.py): reading eval result files, filters, summaries, the
comparison of two files, and the re-run of a result line (same seed, same result)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from conftest import free_port

from l3mvn.core.errors import L3MVNError
from l3mvn.run.recording import read_recording
from l3mvn_studio.compare import EpisodeSource
from l3mvn_studio.map_image import png_rgb
from l3mvn_studio.page_text import md
from l3mvn_studio.results import (
    FAILURES,
    filter_choices,
    list_result_files,
    load_result_file,
    recording_frames,
    recording_of,
    rerun,
    select,
    solved_by_one,
    summaries,
)

HOUSES, PER_HOUSE, SEED = 1, 3, 0
SOURCE = EpisodeSource(None, "val", HOUSES, PER_HOUSE, SEED)  # the episode set the evals here ran
EVAL = [
    "--houses",
    str(HOUSES),
    "--episodes-per-house",
    str(PER_HOUSE),
    "--seed",
    str(SEED),
    "--frame",
    "60x80",
    "--set",
    "sim.max_steps=40",
]


def _eval(out: Path, policy: str, *extra: str) -> None:
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "TRANSFORMERS_OFFLINE": "1"}
    subprocess.run(
        [sys.executable, "-m", "l3mvn_studio.cli", "eval", "--policy", policy, *EVAL, "--out", str(out), *extra],
        check=True,
        capture_output=True,
        env=env,
        timeout=600,
    )


@pytest.fixture(scope="module")
def evaluated(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("results")
    _eval(d / "frontier.jsonl", "frontier", "--record", "--record-dir", str(d / "rec"))
    _eval(d / "cost-utility.jsonl", "cost-utility")
    return d


def test_a_result_file_reads_filters_sorts_and_sums(evaluated):
    assert [p.name for p in list_result_files(evaluated)] == ["cost-utility.jsonl", "frontier.jsonl"]
    f = load_result_file(evaluated / "frontier.jsonl")
    assert len(f.rows) == HOUSES * PER_HOUSE and f.problems == ()
    choices = filter_choices(f.rows)
    assert choices[:3] == ("all", "failures", "successes")
    failed = select(f.rows, FAILURES)
    assert all(not r.success for r in failed) and len(failed) == sum(not r.success for r in f.rows)
    for cause in (c for c in choices if c.startswith("cause: ")):
        assert {r.failure for r in select(f.rows, cause)} == {cause[7:]}
    by_steps = select(f.rows, "all", "steps", descending=True)
    assert [r.steps for r in by_steps] == sorted((r.steps for r in f.rows), reverse=True)
    per_goal, causes = summaries(list(f.rows))
    assert sum(n for n, _, _ in per_goal.values()) == len(f.rows) == sum(causes.values())
    with pytest.raises(L3MVNError, match="unknown filter 'nope'; choose one of all, failures"):
        select(f.rows, "nope")


def test_bad_files_and_lines_are_one_line_problems(evaluated, tmp_path):
    good = (evaluated / "frontier.jsonl").read_text().splitlines()
    mixed = tmp_path / "mixed.jsonl"
    mixed.write_text(
        "\n".join(
            [
                good[0],
                "{not json",
                json.dumps({"key": "x", "error": "boom\nmore"}),
                json.dumps({**json.loads(good[1]), "spl": "high"}),
            ]
        )
        + "\n"
    )
    f = load_result_file(mixed)
    assert len(f.rows) == 1
    assert f.problems[0].startswith("line 2: not JSON (") and "failed to run: boom" in f.problems[1]
    assert f.problems[2].startswith("line 4: ") and "spl" in f.problems[2]
    assert all("\n" not in p for p in f.problems)
    notes = tmp_path / "notes.jsonl"
    notes.write_text("hello\n")
    with pytest.raises(
        L3MVNError,
        match=r"^notes.jsonl is not an eval result file: no episode line "
        r"\(line 1: not JSON \(Expecting value at column 1\)\)$",
    ):
        load_result_file(notes)


def test_two_files_list_the_episodes_only_one_solved(evaluated):
    a = load_result_file(evaluated / "frontier.jsonl").rows
    b = load_result_file(evaluated / "cost-utility.jsonl").rows
    only_a, only_b = solved_by_one(a, b)
    solved_b = {r.raw["key"] for r in b if r.success}
    assert {r.raw["key"] for r in only_a} == {r.raw["key"] for r in a if r.success} - solved_b
    assert {r.raw["key"] for r in only_b} == solved_b - {r.raw["key"] for r in a if r.success}


def test_a_recording_reads_back_one_picture_per_step(evaluated):
    row = load_result_file(evaluated / "frontier.jsonl").rows[0]
    path = recording_of(evaluated / "rec", row)
    assert path is not None
    pictures, decisions = recording_frames(path)
    assert len(pictures) == len(decisions) == row.steps + 1  # the reset, then one per action
    assert decisions[3].startswith("step 3: ") and png_rgb(pictures[0]).ndim == 3


def test_rerun_with_the_stored_config_and_seed_gives_the_stored_result(evaluated, tmp_path):
    made = []
    for row in load_result_file(evaluated / "frontier.jsonl").rows:
        done = rerun(
            row.raw,
            SOURCE,
            record_dir=tmp_path,
        )
        assert done.same_config and done.reproduced, done.summary
        for field in ("success", "spl", "dtg", "steps", "failure", "path_length_m"):
            assert done.row[field] == row.raw[field], field
        assert done.recording.parent == tmp_path and read_recording(done.recording).steps[-1] == row.steps
        made.append(done.recording)
    edited = {**row.raw, "config": {**row.raw["config"], "sim": {**row.raw["config"]["sim"], "max_steps": 5}}}
    other = rerun(edited, SOURCE, record_dir=tmp_path)
    made.append(other.recording)
    assert sorted(tmp_path.glob("*.rrd")) == sorted(made) and len(set(made)) == len(made)  # one new file each
    assert not other.same_config and not other.reproduced and other.row["steps"] <= 5
    assert "DIFFERENT result from stored" in other.summary and "config hash differs" in other.summary
    with pytest.raises(L3MVNError, match="is not in this dashboard's episode set"):
        rerun(
            {**row.raw, "key": "procedural-0099/0/0"},
            SOURCE,
            record_dir=tmp_path,
        )
    with pytest.raises(L3MVNError, match="stores no config"):
        rerun(
            {k: v for k, v in row.raw.items() if k != "config"},
            SOURCE,
            record_dir=tmp_path,
        )


def test_three_tabs_rerunning_one_episode_leave_every_recording_readable(evaluated, tmp_path):
    """Re-runs record beside the eval's recordings (reruns/), each in a file of its own; the eval's
    recordings stay byte for byte as they were, even with three re-runs of one line at once."""
    from l3mvn_studio.server import start_dashboard

    shutil.copytree(evaluated / "rec", tmp_path / "rec")
    before = {p.name: p.read_bytes() for p in (tmp_path / "rec").iterdir()}
    dash = start_dashboard(
        port=free_port(),
        houses=HOUSES,
        episodes_per_house=PER_HOUSE,
        results_dir=evaluated,
        recordings_dir=tmp_path / "rec",
    )
    try:
        panel = dash.view.results
        panel._load("frontier.jsonl")
        row = panel._shown[0]
        assert recording_of(tmp_path / "rec", row) is not None  # the eval recorded this very episode
        failures: list[BaseException] = []

        def press() -> None:
            try:
                panel._rerun(row, None)
            except BaseException as exc:  # noqa: BLE001 - reported below
                failures.append(exc)

        tabs = [threading.Thread(target=press) for _ in range(3)]
        for t in tabs:
            t.start()
        for t in tabs:
            t.join(timeout=300)
        assert not failures, failures
    finally:
        dash.stop()
    assert {p.name: p.read_bytes() for p in (tmp_path / "rec").iterdir()} == before
    reruns = sorted((tmp_path / "reruns").glob("*.rrd"))
    assert len(reruns) == 3
    for path in reruns:
        assert read_recording(path).steps[-1] == row.steps
    with pytest.raises(
        L3MVNError,
        match=r"re-runs would be recorded among the eval's own recordings in .*rec: give "
        r"--record-dir another folder",
    ):
        start_dashboard(
            port=free_port(),
            houses=HOUSES,
            episodes_per_house=PER_HOUSE,
            results_dir=evaluated,
            recordings_dir=tmp_path / "rec",
            record_dir=tmp_path / "rec",
        )


def test_the_panel_starts_on_a_folder_whose_first_file_is_not_results(evaluated, tmp_path):
    from l3mvn_studio.server import start_dashboard

    (tmp_path / "a_notes.jsonl").write_text("not results\n")
    (tmp_path / "b.jsonl").write_text((evaluated / "frontier.jsonl").read_text())
    dash = start_dashboard(
        port=free_port(),
        houses=HOUSES,
        episodes_per_house=PER_HOUSE,
        results_dir=tmp_path,
        recordings_dir=evaluated / "rec",
    )
    try:
        panel = dash.view.results
        assert panel._file is None and md("a_notes.jsonl is not an eval result file") in panel.notes.content
        panel._load("b.jsonl")
        panel.episode.value = panel._shown[0].label
        panel._open(panel._selected(), None)
        assert panel.step.max == panel._shown[0].steps and panel.decision.content.startswith("step 0: ")
    finally:
        dash.stop()
    with pytest.raises(L3MVNError, match="--results .* is not a folder"):
        start_dashboard(port=free_port(), results_dir=tmp_path / "absent")


def test_hostile_files_in_the_results_folder_neither_crash_nor_hang_the_dashboard(evaluated, tmp_path):
    """A FIFO named like a result file is not offered (reading it would block forever); a file whose
    lines hold bad episode ids, NaN, a line nested 200,000 deep and one longer than the line limit
    opens with each of those lines named as a problem."""
    from l3mvn.run.eval.results import MAX_LINE_BYTES
    from l3mvn_studio.server import start_dashboard

    os.mkfifo(tmp_path / "a.jsonl")
    good = (evaluated / "frontier.jsonl").read_text().splitlines()
    row = json.loads(good[0])
    hostile = [json.dumps({**row, "episode_id": v}) for v in ("abc", [1])]
    hostile += [
        good[0].replace('"dtg": ', '"dtg": NaN, "was": '),
        "[" * 200_000 + "]" * 200_000,
        '"' + "x" * (MAX_LINE_BYTES + 10) + '"',
        good[1],
    ]
    (tmp_path / "b.jsonl").write_text("\n".join(hostile) + "\n")
    dash = start_dashboard(
        port=free_port(),
        houses=HOUSES,
        episodes_per_house=PER_HOUSE,
        results_dir=tmp_path,
        recordings_dir=evaluated / "rec",
    )
    try:
        panel = dash.view.results
        assert tuple(panel.file.options) == ("b.jsonl",)
        assert [r.index for r in panel._file.rows] == [6]
        problems = panel._file.problems
        assert [p.split(":")[0] for p in problems] == [f"line {n}" for n in range(1, 6)]
        assert "'episode_id' is \"abc\"" in problems[0] and "NaN" in problems[2]
        assert "nested deeper" in problems[3] and "longer than" in problems[4]
    finally:
        dash.stop()


def test_several_files_compare_with_their_config_differences_first(evaluated, tmp_path):
    """Issue 34: a file run with another max_steps is said to differ before any number; episodes not in
    every file are counted and left out of the pairing; the page escapes what the files hold."""
    from l3mvn_studio.results_comparison import compare_files
    from l3mvn_studio.results_view import comparison_html

    lines = [json.loads(x) for x in (evaluated / "frontier.jsonl").read_text().splitlines()]
    longer = [{**r, "config": {**r["config"], "sim": {**r["config"]["sim"], "max_steps": 250}}} for r in lines[1:]]
    longer[0]["policy"] = "<b>frontier</b>"
    (tmp_path / "longer.jsonl").write_text("".join(json.dumps(r) + "\n" for r in longer))
    files = [load_result_file(p) for p in (evaluated / "frontier.jsonl", tmp_path / "longer.jsonl")]
    files.append(load_result_file(evaluated / "cost-utility.jsonl"))
    c = compare_files(files, resamples=200)
    assert c.config_notes[0] == "longer.jsonl: sim.max_steps: 40 -> 250"
    assert c.shared == len(lines) - 1 and [s.left_out for s in c.summaries] == [1, 0, 1]
    assert [p.b for p in c.pairings] == ["longer.jsonl", "cost-utility.jsonl"]
    assert all(d.n == c.shared for p in c.pairings for d in p.rows["all"])
    sr = c.summaries[0].measures["SR"]
    assert sr.low <= sr.mean <= sr.high and set(c.summaries[0].measures) == {"SR", "SPL", "DTG"}
    page = comparison_html(c)
    assert page.index("Configs differ") < page.index("Paired differences") < page.index("Solved by")
    assert "max_steps: 40 -&gt; 250" in page and "<b>frontier</b>" not in page
    with pytest.raises(L3MVNError, match="at least two result files"):
        compare_files(files[:1])


def test_the_results_table_shows_every_column_in_full(evaluated):
    from l3mvn_studio.results_view import _table_html

    rows = load_result_file(evaluated / "frontier.jsonl").rows
    table = _table_html(list(rows))
    assert "nowrap" not in table and "overflow-wrap:break-word" in table and "overflow:auto" in table
    assert ">cause</th>" in table and ">cov</th>" in table
    for r in rows:
        assert f">{r.failure.replace('_', '_<wbr>')}</td>" in table and f">{r.coverage:.2f}</td>" in table


def test_a_result_line_becomes_an_episode_start_with_its_recorded_poses(evaluated):
    from l3mvn_studio.results import episode_start, recorded_poses

    row = load_result_file(evaluated / "frontier.jsonl").rows[0]
    path = recording_of(evaluated / "rec", row)
    poses = recorded_poses(path)
    assert sorted(poses) == list(range(row.steps + 1))
    start = episode_start(row.raw, SOURCE, recording=path)
    assert start.episode.key == row.raw["key"] and start.policy == row.policy and start.recorded == poses
    assert start.config.sim.max_steps == 40 and start.stored_hash == row.raw["config_hash"]
    with pytest.raises(L3MVNError, match="is not in this dashboard's episode set"):
        episode_start(
            {**row.raw, "key": "procedural-0099/0/0"},
            SOURCE,
        )
    broken = evaluated / "broken.rrd"
    broken.write_bytes(b"not a recording")
    try:
        with pytest.raises(L3MVNError, match="broken.rrd"):
            recorded_poses(broken)
    finally:
        broken.unlink()

"""The ``--out`` file as a user's disk treats it: a torn tail is set aside before anything is appended,
unusable rows are reported and run again (never fatal), one eval at a time holds the file, and every
bad path is one line on stderr with status 2."""

from __future__ import annotations

import json
import math
import os
import resource
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from l3mvn.run.cli import main
from l3mvn.run.eval.results import parse_line, row_problem

REPO = Path(__file__).resolve().parents[1]
METRICS = ("key", "success", "spl", "dtg", "steps", "failure")


def eval_args(dataset: Path, out: Path | str, *extra: str) -> list[str]:
    return [
        "eval",
        "--dataset",
        str(dataset),
        "--split",
        "val",
        "--policy",
        "oracle",
        "--frame",
        "60x80",
        "--out",
        str(out),
        "--json",
        *extra,
    ]


def lines_of(out: Path) -> list[bytes]:
    return out.read_bytes().splitlines(keepends=True)


def usable_keys(out: Path) -> list[str]:
    """Keys of the rows a summary may count, one entry per such row (so duplicates show)."""
    keys = []
    for line in lines_of(out):
        row, problem = parse_line(line)
        if problem is None and row_problem(row) is None:
            keys.append(row["key"])
    return keys


def last_json(text: str) -> dict:
    return json.loads(text.strip().splitlines()[-1])


def error_line(err: str) -> str:
    """The one ``error:`` line of a failed run, which must also be the last line on stderr."""
    lines = err.strip().splitlines()
    errors = [line for line in lines if line.startswith("error: ")]
    assert len(errors) == 1 and lines[-1] == errors[0], err
    return errors[0]


@pytest.fixture
def finished(tiny_dataset, tmp_path, capsys) -> Path:
    """A results file holding all 8 episodes of the tiny dataset."""
    out = tmp_path / "results.jsonl"
    assert main(eval_args(tiny_dataset, out)) == 0
    capsys.readouterr()
    assert len(lines_of(out)) == 8
    return out


# --- torn tail -----------------------------------------------------------------------------------


def test_a_torn_tail_is_set_aside_and_resume_keeps_every_episode_exactly_once(tiny_dataset, finished, capsys):
    *whole, last = lines_of(finished)
    torn = last[: len(last) // 2]
    finished.write_bytes(b"".join(whole) + torn)
    assert main(eval_args(tiny_dataset, finished, "--resume")) == 0
    captured = capsys.readouterr()
    assert "ended in a torn line" in captured.err and "1 to run" in captured.err
    [kept] = finished.parent.glob("results.jsonl.torn-*")
    assert kept.read_bytes() == torn  # not a byte lost
    assert lines_of(finished)[:-1] == whole
    rerun, original = json.loads(lines_of(finished)[-1]), json.loads(last)
    assert [rerun[k] for k in METRICS] == [original[k] for k in METRICS]  # the torn row's episode, run again
    assert sorted(usable_keys(finished)) == sorted(set(usable_keys(finished))) and len(usable_keys(finished)) == 8
    assert last_json(captured.out)["episodes"] == 8


def test_a_whole_last_row_without_its_newline_is_kept_not_set_aside(tiny_dataset, finished, capsys):
    before = finished.read_bytes()
    finished.write_bytes(before[:-1])  # an editor that strips the final newline
    assert main(eval_args(tiny_dataset, finished, "--resume")) == 0
    captured = capsys.readouterr()
    assert "no newline (the row is whole); added one" in captured.err and "0 to run" in captured.err
    assert finished.read_bytes() == before
    assert not list(finished.parent.glob("*.torn-*"))
    assert last_json(captured.out)["episodes"] == 8


def test_a_fresh_run_never_glues_its_first_row_to_a_torn_tail(tiny_dataset, finished, capsys):
    *whole, last = lines_of(finished)
    finished.write_bytes(b"".join(whole) + last[:40])
    assert main(eval_args(tiny_dataset, finished, "--episodes", "1")) == 0
    assert "ended in a torn line" in capsys.readouterr().err
    assert all(row_problem(json.loads(line)) is None for line in lines_of(finished))
    assert len(lines_of(finished)) == 8


# --- unusable rows -------------------------------------------------------------------------------


def test_unusable_rows_are_reported_in_one_line_and_run_again(tiny_dataset, finished, capsys):
    lines = lines_of(finished)
    rows = [json.loads(line) for line in lines]
    broken = [rows[i]["key"] for i in range(6)]
    no_metrics = {k: rows[0][k] for k in ("key", "policy", "config_hash")}
    damaged = [
        no_metrics,
        {**rows[1], "success": "1"},
        {**rows[2], "spl": "high"},
        {**rows[3], "steps": 2.5},
    ]
    glued = lines[4][: len(lines[4]) // 2].rstrip(b"\n") + lines[5]  # an older version's torn line + the next
    foreign = {"key": "Tiny/0/0", "policy": "frontier", "config_hash": "elsewhere", "note": "not ours"}
    text = b"".join(json.dumps(r).encode() + b"\n" for r in damaged) + glued + b"".join(lines[6:])
    finished.write_bytes(text + b"garbage\n[1, 2]\n" + json.dumps(foreign).encode() + b"\n")

    assert main(eval_args(tiny_dataset, finished, "--resume")) == 0
    captured = capsys.readouterr()
    reports = [line for line in captured.err.splitlines() if "cannot be used" in line]
    assert len(reports) == 1 and "7 lines cannot be used, their episodes run again" in reports[0]
    assert f"line 1 ({broken[0]}): no 'rule'" in reports[0]
    assert "6 to run" in captured.err
    assert sorted(usable_keys(finished)) == sorted(r["key"] for r in rows)  # each exactly once
    assert sorted(json.loads(line)["key"] for line in lines_of(finished)[-6:]) == sorted(broken)
    summary = last_json(captured.out)
    assert summary["episodes"] == 8 and summary["success"] == 1.0


def valid_row() -> dict:
    return {
        "key": "Tiny/0/1",
        "policy": "oracle",
        "config_hash": "abc",
        "rule": "semexp",
        "goal": "bed",
        "success": 1.0,
        "spl": 0.8,
        "dtg": 0.0,
        "failure": "success",
        "steps": 30,
        "scene": "Tiny",
        "episode_id": 1,
    }


@pytest.mark.parametrize(
    "change,problem",
    [
        ({}, None),
        ({"spl": None, "dtg": None}, None),
        ({"success": 0, "failure": "timeout", "spl": 0.0}, None),
        ({"success": "1"}, "'success' is \"1\", not 0 or 1"),
        ({"success": True}, "'success' is true, not 0 or 1"),
        ({"success": 0.5}, "'success' is 0.5, not 0 or 1"),
        ({"spl": math.nan}, "'spl' is NaN"),
        ({"spl": 1.5}, "'spl' is 1.5"),
        ({"dtg": -1}, "'dtg' is -1"),
        ({"steps": "30"}, "'steps' is \"30\""),
        ({"failure": "bored"}, "'failure' is \"bored\""),
        ({"failure": "timeout"}, "'success' is 1.0 but 'failure' is \"timeout\""),
        ({"rule": "geodesic"}, "but this config's rule is 'semexp'"),
        ({"goal": {"name": "bed"}}, '\'goal\' is {"name": "bed"}'),
        ({"key": None}, "'key' is null"),
        ({"episode_id": "abc"}, "'episode_id' is \"abc\", not a whole number >= 0"),
        ({"episode_id": math.inf}, "'episode_id' is Infinity"),
        ({"episode_id": [1]}, "'episode_id' is [1]"),
        ({"episode_id": 1.0}, "'episode_id' is 1.0"),
        ({"scene": ""}, "'scene' is \"\", not a scene name"),
    ],
)
def test_row_problem_names_the_first_field_the_summary_cannot_use(change, problem):
    found = row_problem({**valid_row(), **change}, "semexp")
    assert found == problem if problem is None else problem in found


@pytest.mark.parametrize(
    "row,problem",
    [
        ([1, 2], "not a JSON object but [1, 2]"),
        ({"key": "Tiny/0/1", "policy": "oracle", "config_hash": "abc"}, "no 'rule'"),
    ],
)
def test_row_problem_of_rows_without_metrics(row, problem):
    assert row_problem(row) == problem


def test_hostile_lines_are_reported_and_their_episodes_run_again(tiny_dataset, finished, capsys):
    """Values JSON allows but no row holds, NaN, a line nested 200,000 deep and one of 5 MB: each is
    one unusable line, never a traceback, and each of their episodes runs again exactly once."""
    lines = lines_of(finished)
    rows = [json.loads(line) for line in lines]
    hostile = [
        json.dumps({**rows[0], "episode_id": "abc"}).encode(),
        json.dumps({**rows[1], "episode_id": [1]}).encode(),
        json.dumps({**rows[2], "spl": 0.5}).encode().replace(b'"spl": 0.5', b'"spl": 1e400'),
        json.dumps({**rows[3], "dtg": 1.0}).encode().replace(b'"dtg": 1.0', b'"dtg": NaN'),
        b'{"key": "' + rows[4]["key"].encode() + b'", "x": ' + b"[" * 200_000 + b"]" * 200_000 + b"}",
        b'{"key": "' + rows[5]["key"].encode() + b'", "x": "' + b"y" * (5 << 20) + b'"}',
    ]
    finished.write_bytes(b"\n".join(hostile) + b"\n" + b"".join(lines[6:]))
    assert main(eval_args(tiny_dataset, finished, "--resume")) == 0
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err
    assert "6 lines cannot be used, their episodes run again" in captured.err and "6 to run" in captured.err
    assert sorted(usable_keys(finished)) == sorted(r["key"] for r in rows)


# --- one writer at a time --------------------------------------------------------------------------


def test_a_second_eval_on_a_running_evals_out_is_refused_and_writes_nothing(
    tiny_dataset, tmp_path, capsys, monkeypatch
):
    import l3mvn.run.eval.backends as backends

    real = backends.run_local
    out = tmp_path / "results.jsonl"
    second = {}

    def second_eval_after_the_first_row(job, keys, workers):
        rows = real(job, keys, workers)
        yield next(rows)
        before = out.read_bytes()
        second["code"] = main(eval_args(tiny_dataset, out, "--resume"))
        second["unchanged"] = out.read_bytes() == before
        yield from rows

    monkeypatch.setattr(backends, "run_local", second_eval_after_the_first_row)
    assert main(eval_args(tiny_dataset, out)) == 0
    captured = capsys.readouterr()
    assert second == {"code": 2, "unchanged": True}
    refusal = (
        f"error: {out} is being written by another l3mvn eval (pid {os.getpid()}); wait for it to "
        "finish or choose another --out\n"
    )
    assert captured.err.count("error: ") == 1 and refusal in captured.err  # amid the first run's progress bar
    assert sorted(usable_keys(out)) == sorted(set(usable_keys(out))) and len(usable_keys(out)) == 8
    assert last_json(captured.out)["episodes"] == 8


HOLD = (
    "import fcntl, os, sys, time; fd = os.open(sys.argv[1], os.O_RDWR); fcntl.flock(fd, fcntl.LOCK_EX); "
    "print('held', flush=True); time.sleep(600)"
)


def test_the_lock_goes_with_its_holder_even_when_it_is_killed(tiny_dataset, finished, capsys):
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(finished)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline() == "held\n"
        before = finished.read_bytes()
        assert main(eval_args(tiny_dataset, finished, "--resume")) == 2
        assert f"is being written by another l3mvn eval (pid {holder.pid})" in error_line(capsys.readouterr().err)
        assert finished.read_bytes() == before
    finally:
        holder.kill()
        holder.wait(timeout=30)
    assert main(eval_args(tiny_dataset, finished, "--resume")) == 0  # the kernel dropped the lock
    assert "0 to run" in capsys.readouterr().err


# --- bad paths and full disks ------------------------------------------------------------------------


def _directory(tmp: Path) -> str:
    return str(tmp)


def _under_a_file(tmp: Path) -> str:
    (tmp / "notes.txt").write_text("x\n")
    return str(tmp / "notes.txt" / "deeper" / "results.jsonl")


def _long_name(tmp: Path) -> str:
    return str(tmp / ("r" * 300 + ".jsonl"))


def _long_folder(tmp: Path) -> str:
    return str(tmp / ("d" * 300) / "results.jsonl")


def _not_results(tmp: Path) -> str:
    (tmp / "paper.tex").write_text("\\documentclass{article}\n")
    return str(tmp / "paper.tex")


@pytest.mark.parametrize(
    "make,message",
    [
        (_directory, "is a directory; give a file such as"),
        (_under_a_file, "notes.txt is a file, not a folder"),
        (_long_name, "File name too long"),
        (_long_folder, "File name too long"),
        (_not_results, "is not an l3mvn results file"),
    ],
)
def test_a_bad_out_path_is_one_line_and_status_2(make, message, tiny_dataset, tmp_path, capsys):
    where = tmp_path / "where"
    where.mkdir()
    out = make(where)
    before = {p: p.read_bytes() for p in where.rglob("*") if p.is_file()}
    assert main(eval_args(tiny_dataset, out)) == 2
    line = error_line(capsys.readouterr().err)
    assert message in line and len(line) < 300
    assert {p: p.read_bytes() for p in where.rglob("*") if p.is_file()} == before


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into a read-only folder")
def test_an_out_in_a_read_only_folder_is_one_line_and_status_2(tiny_dataset, tmp_path, capsys):
    folder = tmp_path / "ro"
    folder.mkdir(mode=0o500)
    assert main(eval_args(tiny_dataset, folder / "sub" / "results.jsonl")) == 2
    assert "Permission denied" in error_line(capsys.readouterr().err)


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="no /dev/full")
def test_a_full_device_stops_the_run_with_one_line(tiny_dataset, capsys):
    assert main(eval_args(tiny_dataset, "/dev/full")) == 2
    assert error_line(capsys.readouterr().err) == (
        "error: cannot write to /dev/full: No space left on device; the rows written before are kept "
        "(--resume runs the rest)"
    )


@pytest.mark.parametrize("device", ["/dev/null", "/dev/full"])
def test_resume_from_a_device_is_one_line(device, tiny_dataset, capsys):
    if not Path(device).exists():
        pytest.skip(f"no {device}")
    assert main(eval_args(tiny_dataset, device, "--resume")) == 2
    assert "is not a regular file" in error_line(capsys.readouterr().err)


def _file_size_limit(limit: int):
    def apply() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # the write fails with EFBIG instead of killing
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    return apply


def test_a_disk_that_fills_mid_row_keeps_the_rows_before_and_no_partial_line(tiny_dataset, tmp_path, capsys):
    """The file may grow only 1000 bytes more: the third row is written in part, then refused. The
    part is cut back off, the run stops with one line, and --resume finishes each episode once."""
    out = tmp_path / "results.jsonl"
    assert main(eval_args(tiny_dataset, out, "--episodes", "2")) == 0
    capsys.readouterr()
    before = out.read_bytes()
    cmd = [sys.executable, "-m", "l3mvn.run.cli", *eval_args(tiny_dataset, out, "--resume")]
    full = subprocess.run(
        cmd, cwd=REPO, capture_output=True, text=True, timeout=300, preexec_fn=_file_size_limit(len(before) + 1000)
    )
    assert full.returncode == 2 and "Traceback" not in full.stderr
    assert error_line(full.stderr) == (
        f"error: cannot write to {out}: File too large; the rows written before are kept (--resume runs the rest)"
    )
    assert out.read_bytes() == before
    assert main(eval_args(tiny_dataset, out, "--resume")) == 0
    assert sorted(usable_keys(out)) == sorted(set(usable_keys(out))) and len(usable_keys(out)) == 8

"""Local worker processes: the worker count never changes a metric, a broken episode or a dead worker
costs one row, and an interrupted ``l3mvn eval --workers 2`` resumes to exactly one line per episode."""

from __future__ import annotations

import gzip
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import draw_two_room_house

from l3mvn.core.config import Config
from l3mvn.run.eval.backends import run_local
from l3mvn.run.eval.job import EvalJob, is_error_row
from l3mvn.world.episodes import episode_file, generate_episodes, write_episode_file
from l3mvn.world.scenes.semexp import save_split

REPO = Path(__file__).resolve().parents[1]
METRICS = ("success", "spl", "dtg", "steps", "failure")


def metrics_by_key(rows: list[dict]) -> dict[str, tuple]:
    return {r["key"]: tuple(r[m] for m in METRICS) for r in rows}


def small_job(dataset: Path, policy: str) -> EvalJob:
    return EvalJob.create(dataset, "val", config=Config().with_frame(60, 80), policy=policy)


def write_dataset(root: Path, per_house: int) -> Path:
    scenes = [draw_two_room_house("Tiny"), draw_two_room_house("Wee", height=130, width=210)]
    save_split(root, "val", scenes)
    for s in scenes:
        eps = generate_episodes(s, per_house, seed=1, goals=("toilet", "bed", "chair", "tv"))
        write_episode_file(episode_file(root, "val", s.name), eps, {0: s})
    return root


def set_goal(dataset: Path, scene: str, index: int, goal: str) -> str:
    """Rewrite one episode's target in place; returns the episode's key."""
    path = episode_file(dataset, "val", scene)
    with gzip.open(path, "rt") as fh:
        data = json.load(fh)
    rec = data["episodes"][index]
    rec["object_category"] = goal
    with gzip.open(path, "wt") as fh:
        json.dump(data, fh)
    return f"{scene}/{rec['floor_id']}/{rec['episode_id']}"


@pytest.mark.parametrize("policy", ["oracle", "random-walk"])
def test_two_workers_give_every_episode_the_same_metrics_as_one(tiny_dataset, policy):
    job = small_job(tiny_dataset, policy)
    one = list(run_local(job, job.keys(), workers=1))
    two = list(run_local(job, job.keys(), workers=2))
    assert len(one) == len(two) == 8
    assert not any(is_error_row(r) for r in one + two)
    assert metrics_by_key(two) == metrics_by_key(one)
    assert len({r["worker"] for r in two}) == 2
    assert all(r["config_hash"] == job.config_hash and r["config"]["sim"]["frame_width"] == 80 for r in two)


def test_an_episode_that_raises_becomes_an_error_row_and_the_others_finish(tiny_dataset):
    broken = set_goal(tiny_dataset, "Tiny", 1, "couch")  # valid category, absent from the house
    job = small_job(tiny_dataset, "oracle")
    rows = list(run_local(job, job.keys(), workers=2))
    errors = [r for r in rows if is_error_row(r)]
    assert sorted(r["key"] for r in rows) == sorted(job.keys())
    assert [r["key"] for r in errors] == [broken]
    assert "couch" in errors[0]["error"] and errors[0]["policy"] == "oracle"
    assert all(r["success"] == 1.0 for r in rows if not is_error_row(r))


def test_a_worker_killed_mid_run_costs_a_retry_not_an_episode(tiny_dataset):
    job = EvalJob.create(tiny_dataset, "val", config=Config().with_frame(240, 320), policy="oracle")
    rows = []
    for row in run_local(job, job.keys(), workers=2):
        if not rows:
            os.kill(int(row["worker"].rsplit(":", 1)[1]), signal.SIGKILL)  # it already holds its next episode
        rows.append(row)
    assert sorted(r["key"] for r in rows) == sorted(job.keys())
    assert not any(is_error_row(r) for r in rows)
    assert len({r["worker"] for r in rows}) == 3  # the replacement ran the lost episode


def eval_cmd(dataset: Path, out: Path, *extra: str) -> list[str]:
    return [
        sys.executable,
        "-m",
        "l3mvn.run.cli",
        "eval",
        "--dataset",
        str(dataset),
        "--policy",
        "oracle",
        "--frame",
        "240x320",
        "--workers",
        "2",
        "--out",
        str(out),
        *extra,
    ]


def complete_rows(out: Path) -> list[dict]:
    text = out.read_text()
    assert text == "" or text.endswith("\n"), "a partial line was written"
    return [json.loads(line) for line in text.splitlines()]


def interrupt_after_new_line(cmd: list[str], out: Path, sig: int) -> subprocess.CompletedProcess:
    """Start the CLI, send ``sig`` once it has written a line, and check that it stopped mid-run."""
    before = len(complete_rows(out)) if out.exists() else 0
    proc = subprocess.Popen(
        cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=default_sigint
    )
    deadline = time.monotonic() + 30
    while (not out.exists() or len(complete_rows(out)) == before) and time.monotonic() < deadline:
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.05)
    proc.send_signal(sig)
    stdout, stderr = proc.communicate(timeout=30)
    return subprocess.CompletedProcess(cmd, proc.returncode, stdout, stderr)


def default_sigint() -> None:
    """A shell's background jobs start with SIGINT ignored; the CLI must see Ctrl-C as a terminal would."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def assert_gone(pids: set[int], timeout_s: float = 5.0) -> None:
    deadline = time.monotonic() + timeout_s
    alive = set(pids)
    while alive and time.monotonic() < deadline:
        for pid in list(alive):
            try:
                os.kill(pid, 0)
            except ProcessLookupError:
                alive.discard(pid)
        time.sleep(0.05)
    assert not alive, f"worker processes outlived the run: {sorted(alive)}"


def test_an_interrupted_parallel_cli_run_resumes_to_exactly_one_line_per_episode(tmp_path):
    dataset = write_dataset(tmp_path / "data", per_house=15)
    out = tmp_path / "results.jsonl"
    for sig, extra in ((signal.SIGINT, ()), (signal.SIGTERM, ("--resume",))):
        run = interrupt_after_new_line(eval_cmd(dataset, out, *extra), out, sig)
        assert run.returncode == 130, run.stderr
        assert "Traceback" not in run.stderr and "interrupted" in run.stderr
        rows = complete_rows(out)
        assert len({r["key"] for r in rows}) < 30, "the run finished before it was interrupted"
        assert_gone({int(r["worker"].rsplit(":", 1)[1]) for r in rows})
    done = subprocess.run(eval_cmd(dataset, out, "--resume"), cwd=REPO, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    keys = [r["key"] for r in complete_rows(out) if not is_error_row(r)]
    assert len(keys) == len(set(keys)) == 30

"""A disk that fills up is an error, never a success (issue 30 item 5).

Each writer runs as the CLI on a real filesystem that is full: a 256 KB tmpfs (mounted for the test,
so it needs root; skipped elsewhere) filled to its last pages. Every command must end with one
``error:`` line and status 2, leave no partial file behind, and keep what was computed before.
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SMALL = ["--frame", "60x80", "--set", "sim.max_steps=20"]


def _mount(where: Path) -> bool:
    if os.geteuid() != 0 or shutil.which("mount") is None:
        return False
    where.mkdir(parents=True, exist_ok=True)
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=256k", "tmpfs", str(where)], capture_output=True)
    return done.returncode == 0


@pytest.fixture
def full(tmp_path):
    """A folder on a filesystem with no byte left (a folder entry may still fit)."""
    disk = tmp_path / "disk"
    if not _mount(disk):
        pytest.skip("mounting a small tmpfs needs root and mount(8)")
    try:
        with open(disk / "filler", "wb", buffering=0) as fh:
            try:
                while fh.write(b"\0" * 4096):
                    pass
            except OSError:
                pass
        yield disk
    finally:
        subprocess.run(["umount", "-l", str(disk)], capture_output=True)


def _cli(*argv: str, cwd: Path = REPO) -> subprocess.CompletedProcess:
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "TRANSFORMERS_OFFLINE": "1"}
    return subprocess.run(
        [sys.executable, "-m", "l3mvn_studio.cli", *argv], cwd=cwd, capture_output=True, text=True, env=env, timeout=600
    )


def _one_error_line(done: subprocess.CompletedProcess) -> str:
    assert done.returncode == 2, (done.returncode, done.stdout, done.stderr)
    assert "Traceback" not in done.stderr, done.stderr
    errors = [line for line in done.stderr.splitlines() if line.startswith("error: ")]
    assert len(errors) == 1 and done.stderr.strip().splitlines()[-1] == errors[0], done.stderr
    return errors[0]


def _left(disk: Path) -> list[str]:
    return sorted(str(p.relative_to(disk)) for p in disk.rglob("*") if p.name != "filler" and p.is_file())


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> tuple[Path, Path]:
    """One recorded episode: (its results file, its recordings folder)."""
    d = tmp_path_factory.mktemp("recorded")
    done = _cli(
        "eval",
        "--policy",
        "frontier",
        "--houses",
        "1",
        "--episodes-per-house",
        "1",
        *SMALL,
        "--out",
        str(d / "r.jsonl"),
        "--record",
        "--record-dir",
        str(d / "rec"),
    )
    assert done.returncode == 0, done.stderr
    return d / "r.jsonl", d / "rec"


def test_render_to_a_full_disk_leaves_no_empty_picture(full):
    line = _one_error_line(_cli("render", "--out", str(full / "frame.png"), "--houses", "1"))
    assert "cannot write --out" in line and "No space left on device" in line
    assert _left(full) == []


def test_export_to_a_full_disk_is_an_error_and_leaves_no_partial_video(full, recorded):
    _, rec = recorded
    [recording] = rec.glob("*.rrd")
    line = _one_error_line(_cli("export", str(full / "v.mp4"), "--recording", str(recording), "--height", "160"))
    assert "cannot write video" in line and str(full / "v.mp4") in line and "No space left on device" in line
    assert _left(full) == []


def _eval_recorded(out: Path, record_dir: Path, **popen) -> subprocess.CompletedProcess:
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "TRANSFORMERS_OFFLINE": "1"}
    return subprocess.run(
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
            *SMALL,
            "--out",
            str(out),
            "--record",
            "--record-dir",
            str(record_dir),
        ],
        cwd=REPO,
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
        **popen,
    )


def _results_kept(out: Path, done: subprocess.CompletedProcess) -> None:
    assert "recordings or videos were not written whole, the results are kept" in _one_error_line(done)
    rows = [json.loads(text) for text in out.read_text().splitlines()]
    assert len(rows) == 2 and all("success" in r and "recording_error" in r for r in rows)


def test_eval_recording_to_a_full_disk_keeps_the_results_and_exits_2(full, tmp_path):
    """No recording can start on the full disk: every episode still runs and keeps its result."""
    out = tmp_path / "r.jsonl"
    done = _eval_recorded(out, full / "rec")
    _results_kept(out, done)
    assert "KiB free on its disk" in done.stderr
    assert _left(full) == []  # no empty recording left to be listed


def test_a_recording_cut_short_by_the_disk_is_named_and_the_run_exits_2(tmp_path):
    """Each file may grow to 256 KB: the recordings start, then their writes fail in rerun's
    background writer, which raises nothing; reading the file back finds each one cut."""

    def limited() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails with EFBIG
        resource.setrlimit(resource.RLIMIT_FSIZE, (256 << 10, 256 << 10))

    out = tmp_path / "r.jsonl"
    done = _eval_recorded(out, tmp_path / "rec", preexec_fn=limited)
    _results_kept(out, done)
    assert "(is the disk full?); kept as " in done.stderr
    assert list((tmp_path / "rec").glob("*.rrd")) == []  # nothing cut is offered as a recording
    assert len(list((tmp_path / "rec").glob("*.rrd.partial"))) == 2


def test_eval_video_to_a_full_disk_exits_2(full, tmp_path):
    done = _cli(
        "eval",
        "--policy",
        "frontier",
        "--houses",
        "1",
        "--episodes-per-house",
        "1",
        *SMALL,
        "--out",
        str(tmp_path / "r.jsonl"),
        "--record-dir",
        str(tmp_path / "rec"),
        "--video",
        str(full / "videos"),
    )
    assert "were not written whole" in _one_error_line(done)
    assert _left(full) == []
    devices = _cli(
        "eval",
        "--policy",
        "frontier",
        "--houses",
        "1",
        "--episodes-per-house",
        "1",
        *SMALL,
        "--record-dir",
        str(tmp_path / "rec"),
        "--video",
        "/dev/full",
    )
    assert "--video /dev/full is a file, not a folder" in _one_error_line(devices)


def test_dataset_writers_on_a_full_disk_end_in_one_line(full):
    for argv, what in (
        (["episodes", "generate", "--out", str(full / "ds"), "--houses", "1"], "map file"),
        (["export-hm3d", "--out", str(full / "hm3d"), "--houses", "1"], ""),
    ):
        line = _one_error_line(_cli(*argv))
        assert "No space left on device" in line and what in line
        assert all(".partial-" not in name for name in _left(full))


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="no /dev/full")
def test_an_audit_out_that_is_a_file_is_one_line(tmp_path):
    line = _one_error_line(_cli("scenes", "audit", "--houses", "1", "--out", "/dev/full"))
    assert line == "error: --out /dev/full is a file, not a folder"

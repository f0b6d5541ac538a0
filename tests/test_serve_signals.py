"""`l3mvn serve` and `l3mvn replay --web` run as a user runs them: stopped by signals, refused bad addresses.

Each command runs as a real process (the installed script's entry point, ``l3mvn_studio.cli.main``). What
is checked is what a user or a service manager would see: after SIGTERM (or SIGHUP, or the parent
killed outright) nothing the command started is still running or listening; a bad or busy address
is one line on stderr and status 2, before anything is served.
"""

from __future__ import annotations

import dataclasses
import os
import queue
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import psutil
import pytest
from conftest import draw_two_room_house, free_port

from l3mvn.core.config import Config, SimConfig
from l3mvn.core.errors import L3MVNError
from l3mvn.run.events import EventBus
from l3mvn.run.recording import (
    Recorder,
    add_replay_arguments,
    read_recording,
    run_replay,
    viewer_executable,
)
from l3mvn.run.recording.catalogue import RecordingCut
from l3mvn.run.runner import Runner
from l3mvn.world.episodes import generate_episodes

ROOT = Path(__file__).resolve().parents[1]
ENTRY = "import sys; from l3mvn_studio.cli import main; sys.exit(main())"  # what the installed `l3mvn` runs
START_S = 120.0  # generous: the suite may share two slow cores with other jobs
STOP_S = 20.0  # the dashboard's threads each get 5 s to finish; the viewer 5 s before SIGKILL
SERVE = ["serve", "--houses", "1", "--episodes-per-house", "1"]


class Cli:
    """One ``l3mvn`` command in its own process (and session, so a failed test can kill all it left)."""

    def __init__(self, *argv: str) -> None:
        env = {**os.environ, "HF_HUB_OFFLINE": "1", "TRANSFORMERS_OFFLINE": "1", "PYTHONUNBUFFERED": "1"}
        self.proc = subprocess.Popen(
            [sys.executable, "-c", ENTRY, *argv],
            cwd=ROOT,
            env=env,
            text=True,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            start_new_session=True,
        )
        self.seen: list[psutil.Process] = []
        self.stdout: list[str] = []
        self.stderr: list[str] = []
        self._lines: queue.Queue[str] = queue.Queue()
        self._readers = [
            threading.Thread(target=self._drain, args=(self.proc.stdout, self.stdout, True), daemon=True),
            threading.Thread(target=self._drain, args=(self.proc.stderr, self.stderr, False), daemon=True),
        ]
        for reader in self._readers:
            reader.start()

    def _drain(self, stream, into: list[str], announce: bool) -> None:
        """Read a pipe to its end (the viewer's logs are copious; an unread pipe would block it)."""
        for line in stream:
            into.append(line.rstrip("\n"))
            if announce:
                self._lines.put(line)

    def wait_for(self, pattern: str, timeout: float = START_S) -> re.Match:
        """The first stdout line matching ``pattern``; fails with the command's stderr if it exits first."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                match = re.search(pattern, self._lines.get(timeout=0.2))
            except queue.Empty:
                if self.proc.poll() is not None and self._lines.empty():
                    break
                continue
            if match:
                return match
        raise AssertionError(f"no line matching {pattern!r}; exit {self.proc.poll()}; stderr: {self.stderr_text()}")

    def finish(self, timeout: float = START_S) -> int:
        """Its exit status, after it ends by itself within ``timeout``, with every output line read."""
        code = self.proc.wait(timeout)
        for reader in self._readers:
            reader.join(timeout)
        return code

    def stderr_text(self) -> str:
        return "\n".join(self.stderr[-20:])

    def descendants(self) -> list[psutil.Process]:
        """What it runs now; remembered, so cleanup finds them even once they are orphans."""
        found = psutil.Process(self.proc.pid).children(recursive=True)
        self.seen += found
        return found

    def kill_all(self) -> None:
        """Clean up after a failed test: all it started (the viewer has a group of its own), then its session."""
        if self.proc.poll() is None:
            self.descendants()
        for process in self.seen:
            try:
                process.kill()
            except psutil.NoSuchProcess:
                pass
        try:
            os.killpg(self.proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        self.proc.wait(STOP_S)


@pytest.fixture
def cli():
    started: list[Cli] = []

    def start(*argv: str) -> Cli:
        started.append(Cli(*argv))
        return started[-1]

    yield start
    for c in started:
        c.kill_all()


def _accepts(port: int) -> bool:
    """Something listens on 127.0.0.1:``port``."""
    with socket.socket() as s:
        s.settimeout(1.0)
        return s.connect_ex(("127.0.0.1", port)) == 0


def _bindable(port: int) -> bool:
    """A server could listen on ``port`` now (binds as servers do, SO_REUSEADDR)."""
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def _poll(predicate, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.1)
    return predicate()


def _gone(process: psutil.Process) -> bool:
    """Not running: exited, or a zombie waiting for a parent (pid 1 in a container may never reap it)."""
    try:
        return not process.is_running() or process.status() == psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return True


def _one_error_line(c: Cli) -> str:
    assert c.finish() == 2, c.stderr_text()
    assert len(c.stderr) == 1 and c.stderr[0].startswith("error: "), c.stderr
    assert not any("dashboard:" in line or "serving" in line for line in c.stdout), c.stdout
    return c.stderr[0]


# --- l3mvn serve -------------------------------------------------------------------------------


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_serve_stops_cleanly_on_sigterm_and_sighup_and_frees_its_port(cli, sig):
    port = free_port()
    c = cli(*SERVE, "--port", str(port))
    c.wait_for(rf"L3MVN Studio dashboard: http://127\.0\.0\.1:{port}\b")
    assert _accepts(port)
    started = c.descendants()
    c.proc.send_signal(sig)

    assert c.finish(STOP_S) == 0, c.stderr_text()
    assert "stopping" in c.stderr
    assert all(_gone(p) for p in started)
    assert not _accepts(port) and _poll(lambda: _bindable(port), STOP_S)


def test_serve_on_a_busy_port_refuses_naming_it_instead_of_taking_the_next(cli):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        line = _one_error_line(cli(*SERVE, "--port", str(port)))
    assert f"port {port} is in use on 127.0.0.1" in line and "--port N" in line
    free = re.search(r"--port (\d+) is free", line)
    assert free is None or int(free.group(1)) > port


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--port", "99999"], "--port must lie in 1..65535, got 99999"),
        (["--port", "-1"], "--port must lie in 1..65535, got -1"),
        (["--host", "no.such.host.invalid"], "--host no.such.host.invalid: cannot resolve it"),
    ],
)
def test_serve_with_a_bad_port_or_host_is_one_line_and_status_2(cli, argv, message):
    line = _one_error_line(cli(*SERVE, *argv, *([] if "--port" in argv else ["--port", str(free_port())])))
    assert message in line


@pytest.mark.timeout(60)  # unhandled, viser waits forever for a server thread that died: fail, not hang
@pytest.mark.parametrize("port, message", [(None, "is in use on 127.0.0.1"), (99999, "--port must lie in 1..65535")])
def test_a_port_lost_after_the_check_is_reported_not_moved_to_the_next_and_leaves_no_thread(port, message):
    """The race the up-front check cannot close: viser's own bind fails (viser would take the next port)."""
    from l3mvn_studio.viser_hooks import start_checked_server

    before = set(threading.enumerate())
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = port or taken.getsockname()[1]
        with pytest.raises(L3MVNError, match=re.escape(message)):
            start_checked_server(lambda *request: None, host="127.0.0.1", port=port, verbose=False)
    assert _poll(lambda: not set(threading.enumerate()) - before, STOP_S)


# --- l3mvn replay --web --------------------------------------------------------------------------


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    """An oracle episode of up to 30 steps recorded by the real loop (as tests/test_recording.py does):
    long enough that the layout, sent first, is a small share of the file (random walk stopped after 3)."""
    scene = draw_two_room_house()
    episode = generate_episodes(scene, 1, seed=3, goals=("toilet",))[0]
    cfg = Config(sim=dataclasses.replace(SimConfig().with_frame(60, 80), max_steps=30))
    bus = EventBus()
    recorder = Recorder.for_episode(tmp_path_factory.mktemp("recordings"), "tiny", episode, "oracle").attach(bus)
    assert Runner(cfg).run(scene, episode, "oracle", bus).steps >= 10
    assert recorder.closed and recorder.errors == 0
    return recorder.path


def _serving_viewer(cli, recording: Path) -> tuple[Cli, int, int, list[psutil.Process]]:
    """``l3mvn replay --web`` with both its ports accepting; skips when rerun's viewer cannot run here."""
    try:
        viewer_executable()
    except L3MVNError as exc:
        pytest.skip(f"the rerun web viewer cannot run here: {exc}")
    c = cli("replay", str(recording), "--web", "--port", str(free_port()))
    ports = c.wait_for(r"HTTP port (\d+), data port (\d+)")
    web, data = int(ports.group(1)), int(ports.group(2))
    if (
        not _poll(lambda: c.proc.poll() is not None or (_accepts(web) and _accepts(data)), START_S)
        or c.proc.poll() is not None
    ):
        pytest.skip(f"the rerun web viewer cannot run here (exit {c.proc.poll()}): {c.stderr_text()}")
    viewers = c.descendants()
    assert viewers, "the viewer should be a child process"
    return c, web, data, viewers


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_replay_web_stops_its_viewer_on_sigterm_and_sighup(cli, recording, sig):
    c, web, data, viewers = _serving_viewer(cli, recording)
    c.proc.send_signal(sig)

    assert c.finish(STOP_S) == 0, c.stderr_text()
    assert "stopping the viewer" in c.stderr
    assert all(_gone(v) for v in viewers)
    assert not _accepts(web) and not _accepts(data)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the viewer dies with its parent on Linux only")
def test_the_viewer_dies_with_replay_when_replay_is_killed_outright(cli, recording):
    c, web, data, viewers = _serving_viewer(cli, recording)
    c.proc.kill()

    assert c.finish(STOP_S) == -signal.SIGKILL
    assert _poll(lambda: all(_gone(v) for v in viewers), STOP_S)
    assert _poll(lambda: not _accepts(web) and not _accepts(data), STOP_S)


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--port", "99999"], "--port must lie in 1..65535, got 99999"),
        (["--host", "no.such.host.invalid"], "--host no.such.host.invalid: cannot resolve it"),
    ],
)
def test_replay_web_with_a_bad_port_or_host_is_one_line_and_status_2(cli, recording, argv, message):
    line = _one_error_line(cli("replay", str(recording), "--web", *argv))
    assert message in line


# --- a recording cut off mid-write ---------------------------------------------------------------


def _replay_args(*argv: str):
    import argparse

    parser = argparse.ArgumentParser()
    add_replay_arguments(parser)
    return parser.parse_args(list(argv))


@pytest.mark.parametrize("fraction", [0.3, 0.6, 0.95])
def test_a_cut_recording_reads_back_the_steps_before_the_cut_and_says_what_was_lost(recording, tmp_path, fraction):
    whole = read_recording(recording)
    data = recording.read_bytes()
    cut = tmp_path / "cut.rrd"
    cut.write_bytes(data[: int(len(data) * fraction)])

    with pytest.raises(RecordingCut, match="cut.rrd ends inside a message"):
        read_recording(cut)
    part = read_recording(cut, cut_ok=True)
    assert part.path == cut and 0 < part.lost_bytes < len(data)
    assert part.steps == whole.steps[: len(part.steps)]  # a prefix of the episode, nothing invented
    assert part.recording_id == whole.recording_id


def test_a_cut_recording_with_nothing_whole_before_the_cut_is_refused(recording, tmp_path):
    cut = tmp_path / "stub.rrd"
    cut.write_bytes(recording.read_bytes()[:100])
    with pytest.raises(L3MVNError, match="stub.rrd ends inside a message.*hold no readable recording"):
        read_recording(cut, cut_ok=True)


def test_replay_of_a_cut_recording_warns_what_it_shows_instead_of_refusing_it(recording, tmp_path, capsys):
    data = recording.read_bytes()
    cut = tmp_path / "cut.rrd"
    cut.write_bytes(data[: len(data) // 2])
    with socket.socket() as taken:  # a busy port stops replay after the recording check, before any viewer
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with pytest.raises(L3MVNError, match=f"port {port} is in use"):
            run_replay(_replay_args(str(cut), "--web", "--port", str(port)))
    warning = capsys.readouterr().err
    assert re.search(
        r"warning: .*cut\.rrd ends inside a message .* the viewer shows what precedes the cut "
        r"\(steps 0\.\.\d+\)",
        warning,
    ), warning

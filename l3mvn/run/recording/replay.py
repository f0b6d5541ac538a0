"""``l3mvn replay``: open a recording in the rerun viewer, native or on the web.

The viewer is a child process. However ``replay`` is asked to stop (Ctrl-C, SIGTERM from a service
manager or ``kill``, SIGHUP from a closed terminal) it stops the viewer and waits for it; on Linux
the viewer also dies with ``replay`` when that is killed outright (stop signals and the address check
come from ``l3mvn.run.serving``, shared with ``l3mvn serve``).
"""

from __future__ import annotations

import argparse
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from contextlib import suppress
from dataclasses import dataclass
from pathlib import Path

from l3mvn.core.errors import L3MVNError
from l3mvn.run.recording.catalogue import RecordingCut, open_recording, read_recording
from l3mvn.run.serving import check_listen_address, interrupt_on_stop_signals

DEFAULT_WEB_PORT = 9090
STOP_GRACE_S = 5.0  # rerun exits at once on SIGTERM; one that has not by then is killed
# A web viewer's link is handed out only once its HTTP port answers (a link followed at once would
# otherwise meet a refused connection); it starts in well under a second, this long on a loaded machine.
READY_TIMEOUT_S = 30.0
_PR_SET_PDEATHSIG = 1  # linux/prctl.h


def add_replay_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``l3mvn replay FILE.rrd [--web] [--port N]``."""
    parser.add_argument("file", help="a .rrd recording (see recordings/)")
    parser.add_argument(
        "--web",
        action="store_true",
        help="serve rerun's web viewer over HTTP and print its URL instead of opening a window",
    )
    parser.add_argument(
        "--port",
        type=int,
        default=DEFAULT_WEB_PORT,
        help=f"HTTP port of the web viewer with --web (default {DEFAULT_WEB_PORT}); its data "
        "port is picked free and printed too",
    )
    parser.add_argument(
        "--host",
        default="127.0.0.1",
        help="interface the web viewer binds with --web (default 127.0.0.1, this machine only)",
    )


def run_replay(args: argparse.Namespace) -> int:
    """Open ``args.file`` in rerun's viewer (native, or web with ``--web``); returns its exit status.

    Stopping ``replay`` (Ctrl-C, SIGTERM, SIGHUP) stops the viewer and returns 0.
    """
    path = Path(args.file)
    _check_recording(path)
    exe = viewer_executable()
    with interrupt_on_stop_signals():
        cmd = _web_command(exe, path, args.host, args.port) if args.web else _native_command(exe, path)
        return run_viewer(cmd)


@dataclass
class WebViewer:
    """rerun's web viewer serving one recording, a child of this process (``stop()`` ends it; it also
    dies with this process)."""

    path: Path
    url: str
    proc: subprocess.Popen

    @property
    def alive(self) -> bool:
        return self.proc.poll() is None

    def stop(self) -> None:
        _stop(self.proc)


def start_web_viewer(path: str | Path, host: str = "127.0.0.1") -> WebViewer:
    """Serve ``path`` in rerun's web viewer on free ports of ``host`` (for the dashboard's "Open in
    rerun": no terminal needed), returned once its page answers; one-line L3MVNError for a file the
    viewer cannot show, or a viewer that exits or does not answer within READY_TIMEOUT_S."""
    path = Path(path)
    _check_recording(path)
    exe = viewer_executable()
    port = _free_port(host)
    cmd = _web_command(exe, path, host, port)
    url = web_viewer_url(port, int(cmd[cmd.index("--port") + 1]), _url_host(host))
    proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, **_child_options())
    viewer = WebViewer(path, url, proc)
    _wait_answering(viewer, host, port)
    return viewer


def _wait_answering(viewer: WebViewer, host: str, port: int, timeout_s: float = READY_TIMEOUT_S) -> None:
    """Return once ``host:port`` accepts a connection; stop the viewer and raise if it exits or times out."""
    deadline = time.monotonic() + timeout_s
    while True:
        if not viewer.alive:
            status = viewer.proc.returncode
            raise L3MVNError(f"rerun's web viewer exited (status {status}) before serving {viewer.path.name}")
        try:
            with socket.create_connection((host, port), timeout=1.0):
                return
        except OSError:
            if time.monotonic() > deadline:
                viewer.stop()
                raise L3MVNError(
                    f"rerun's web viewer did not answer on {host}:{port} within {timeout_s:g} s; it was stopped"
                ) from None
            time.sleep(0.05)


def _check_recording(path: Path) -> None:
    """Refuse a file the viewer cannot show; for one cut off mid-write, say what it will show.

    rerun's viewer reads a cut file up to the cut, so that is shown rather than refused whole.
    """
    try:
        open_recording(path)
    except RecordingCut as cut:
        steps = read_recording(path, cut_ok=True).steps
        shown = f"steps {steps[0]}..{steps[-1]}" if steps else "no steps"
        print(f"warning: {cut}; the viewer shows what precedes the cut ({shown})", file=sys.stderr)


def _web_command(exe: str, path: Path, host: str, port: int) -> list[str]:
    """The viewer serving ``path`` on ``host:port`` (HTTP) and a free data port; prints the URL.

    ``--serve-web``, not ``--web-viewer``: the latter also launches a browser as the viewer's own
    child, which stopping the viewer would take down with it.
    """
    check_listen_address(host, port)
    data_port = _free_port(host)
    if host not in ("127.0.0.1", "localhost", "::1"):
        print(f"warning: serving on {host}: anyone who can reach it can read the recording", file=sys.stderr)
    print(
        f"serving {path} at {web_viewer_url(port, data_port, _url_host(host))} (HTTP port {port}, data port "
        f"{data_port}; Ctrl-C to stop)",
        flush=True,
    )
    return [exe, "--serve-web", "--web-viewer-port", str(port), "--port", str(data_port), "--bind", host, str(path)]


def _native_command(exe: str, path: Path) -> list[str]:
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise L3MVNError("no display for the native viewer (DISPLAY is unset); use --web to serve it in a browser")
    return [exe, str(path)]


def run_viewer(cmd: list[str]) -> int:
    """Run ``cmd`` until it exits (its status) or this process is interrupted (stops it, returns 0).

    The viewer gets a session, so a process group, of its own: stopping it reaches anything it
    starts, and Ctrl-C in the terminal reaches only ``replay``, which then stops the viewer the one
    orderly way.
    """
    proc = None
    try:
        proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, **_child_options())
        return proc.wait()
    except KeyboardInterrupt:
        print("stopping the viewer", file=sys.stderr)
        if proc is not None:
            _stop(proc)
        return 0


def _child_options() -> dict:
    if os.name != "posix":
        return {}
    return {"start_new_session": True, "preexec_fn": _die_with_parent() if sys.platform.startswith("linux") else None}


def _die_with_parent() -> Callable[[], None]:
    """For ``preexec_fn``: the kernel SIGKILLs the viewer when its parent dies (PR_SET_PDEATHSIG).

    Covers what no handler can: ``replay`` killed with SIGKILL, or crashing. ``prctl`` is looked up
    here, before the fork, so the child runs no more than the call. A parent that died before the
    call would never signal, so the child checks and exits.
    """
    import ctypes

    prctl = ctypes.CDLL(None, use_errno=True).prctl
    parent = os.getpid()

    def die_with_parent() -> None:
        prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
        if os.getppid() != parent:
            os._exit(1)

    return die_with_parent


def _stop(proc: subprocess.Popen) -> None:
    """SIGTERM the viewer's process group and wait; SIGKILL it after STOP_GRACE_S, or at a second interrupt."""
    try:
        _signal_group(proc, force=False)
        proc.wait(STOP_GRACE_S)
    except (subprocess.TimeoutExpired, KeyboardInterrupt):
        _signal_group(proc, force=True)
        proc.wait()


def _signal_group(proc: subprocess.Popen, *, force: bool) -> None:
    if proc.returncode is not None:  # reaped: its group id may belong to someone else by now
        return
    if os.name != "posix":
        (proc.kill if force else proc.terminate)()
        return
    with suppress(ProcessLookupError):
        os.killpg(proc.pid, signal.SIGKILL if force else signal.SIGTERM)


def viewer_executable() -> str:
    """The ``rerun`` viewer binary shipped with rerun-sdk (``rerun_cli``), else one on PATH."""
    try:
        import rerun_cli

        bundled = Path(rerun_cli.__file__).parent / ("rerun.exe" if sys.platform.startswith("win") else "rerun")
        if bundled.is_file():
            return str(bundled)
    except ImportError:
        pass
    import shutil

    found = shutil.which("rerun")
    if not found:
        raise L3MVNError("the rerun viewer binary was not found; reinstall rerun-sdk (pip install rerun-sdk)")
    return found


def web_viewer_url(web_port: int, grpc_port: int, host: str = "127.0.0.1") -> str:
    from urllib.parse import quote

    return f"http://{host}:{web_port}/?url={quote(f'rerun+http://{host}:{grpc_port}/proxy', safe='')}"


def _url_host(host: str) -> str:
    """``host`` as a browser should be given it: a wildcard bind is reached on loopback; IPv6 in brackets."""
    if host in ("0.0.0.0", "::"):
        return "127.0.0.1"
    return f"[{host}]" if ":" in host else host


def _free_port(host: str) -> int:
    """A port free on ``host`` now (for the viewer's data port, which nobody types)."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return s.getsockname()[1]

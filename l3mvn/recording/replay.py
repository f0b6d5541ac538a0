"""``l3mvn replay``: open a recording in the rerun viewer, native or on the web."""

from __future__ import annotations

import argparse
import os
import socket
import subprocess
import sys
from pathlib import Path

from l3mvn.errors import L3MVNError
from l3mvn.recording.catalogue import open_recording

DEFAULT_WEB_PORT = 9090


def add_replay_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``l3mvn replay FILE.rrd [--web] [--port N]``."""
    parser.add_argument("file", help="a .rrd recording (see recordings/)")
    parser.add_argument("--web", action="store_true",
                        help="serve rerun's web viewer over HTTP and print its URL instead of opening a window")
    parser.add_argument("--port", type=int, default=DEFAULT_WEB_PORT,
                        help=f"HTTP port of the web viewer with --web (default {DEFAULT_WEB_PORT}); its data "
                             "port is picked free and printed too")
    parser.add_argument("--host", default="127.0.0.1",
                        help="interface the web viewer binds with --web (default 127.0.0.1, this machine only)")


def run_replay(args: argparse.Namespace) -> int:
    """Open ``args.file`` in rerun's viewer (native, or web with ``--web``); returns its exit status."""
    path = Path(args.file)
    open_recording(path)
    exe = viewer_executable()
    if args.web:
        if not 0 < args.port < 65536:
            raise L3MVNError(f"--port must lie in 1..65535, got {args.port}")
        if not _port_free(args.port):
            raise L3MVNError(f"port {args.port} is in use; pick another with --port")
        grpc = _free_port()
        cmd = [exe, "--web-viewer", "--web-viewer-port", str(args.port), "--port", str(grpc),
               "--bind", args.host, str(path)]
        if args.host not in ("127.0.0.1", "localhost", "::1"):
            print(f"warning: serving on {args.host}: anyone who can reach it can read the recording", file=sys.stderr)
        print(f"serving {path} at {web_viewer_url(args.port, grpc)} (HTTP port {args.port}, data port {grpc}; "
              "Ctrl-C to stop)", flush=True)
    else:
        if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
            raise L3MVNError("no display for the native viewer (DISPLAY is unset); use --web to serve it in a browser")
        cmd = [exe, str(path)]
    try:
        return subprocess.call(cmd)
    except KeyboardInterrupt:
        return 0


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


def _port_free(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        try:
            s.bind(("0.0.0.0", port))
        except OSError:
            return False
    return True


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]

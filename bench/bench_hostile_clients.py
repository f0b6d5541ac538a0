"""The dashboard under hostile websocket clients: does it stay up, quiet and flat in memory?

    .venv/bin/python bench/bench_hostile_clients.py --clients 10 --seconds 300

Starts ``l3mvn serve`` (procedural houses) in a subprocess, lets it run an episode, then opens
``--clients`` connections from the dashboard's own origin that send frames which do not decode
(bad msgpack, unknown types, updates without fields, text frames) as fast as they can, reconnecting
when dropped, for ``--seconds``. Prints the server's RSS after the first minute and at the end, the
log lines about dropped frames, tracebacks in its log, and whether a fresh tab still works. Only
127.0.0.1 is contacted, and every loop is bounded in count and time.
"""

from __future__ import annotations

import argparse
import os
import re
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import msgspec
import viser
from websockets.sync.client import connect

REPO = Path(__file__).resolve().parents[1]
GARBAGE = (
    b"\xc1 not msgpack",
    msgspec.msgpack.encode({"type": "NoSuchMessage"}),
    msgspec.msgpack.encode({"type": "GuiUpdateMessage"}),
    msgspec.msgpack.encode([1, 2, 3]),
    msgspec.msgpack.encode(
        {
            "type": "ScenePointerMessage",
            "event_type": "click",
            "ray_origin": [1e308, 0, 5],
            "ray_direction": [0, 0, -1],
            "screen_pos": [[0.5, 0.5]],
            "modifier": None,
        }
    ),
)


def _port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def _hostile(url: str, stop: float, sent: list[int]) -> None:
    protocol = f"viser-v{viser.__version__}"
    while time.monotonic() < stop:
        try:
            with connect(
                url,
                origin=url.replace("ws", "http", 1),
                subprotocols=[protocol],
                max_size=None,
                open_timeout=10,
                ping_interval=None,
            ) as ws:  # a hostile client answers nothing
                while time.monotonic() < stop:
                    for frame in GARBAGE:
                        ws.send(frame)
                    ws.send("text")
                    sent[0] += len(GARBAGE) + 1
                    time.sleep(0.001)
        except Exception:  # noqa: BLE001 - dropped by the server: connect again until the time is up
            time.sleep(0.1)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--clients", type=int, default=10)
    ap.add_argument("--seconds", type=float, default=300.0)
    args = ap.parse_args()
    port = _port()
    log = Path(f"/tmp/l3mvn-hostile-{port}.log")
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "TRANSFORMERS_OFFLINE": "1"}
    server = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "l3mvn_studio.cli",
            "serve",
            "--port",
            str(port),
            "--policy",
            "frontier",
            "--houses",
            "1",
            "--episodes-per-house",
            "2",
            "--speed",
            "20",
        ],
        cwd=REPO,
        env=env,
        stdout=log.open("w"),
        stderr=subprocess.STDOUT,
    )
    try:
        url = f"ws://127.0.0.1:{port}"
        deadline = time.monotonic() + 120
        while "127.0.0.1" not in log.read_text() and time.monotonic() < deadline:
            time.sleep(0.5)
        stop = time.monotonic() + args.seconds
        sent = [0]
        threads = [threading.Thread(target=_hostile, args=(url, stop, sent), daemon=True) for _ in range(args.clients)]
        for t in threads:
            t.start()
        time.sleep(min(60.0, args.seconds / 2))
        first = _rss_mb(server.pid)
        for t in threads:
            t.join(timeout=args.seconds + 30)
        last = _rss_mb(server.pid)
        text = log.read_text(errors="replace")
        alive = server.poll() is None
        with connect(
            url,
            origin=f"http://127.0.0.1:{port}",
            subprotocols=[f"viser-v{viser.__version__}"],
            max_size=None,
            open_timeout=10,
        ) as ws:
            fresh = bool(ws.recv(timeout=10))
        dropped = len(re.findall("dropped a frame a page sent", text))
        print(f"clients {args.clients}, {args.seconds:.0f} s, frames sent {sent[0]}")
        print(f"server alive {alive}, a fresh tab gets the page {fresh}")
        print(
            f"RSS after {min(60.0, args.seconds / 2):.0f} s {first:.0f} MB, at the end {last:.0f} MB "
            f"({(last / first - 1) * 100:+.1f}%)"
        )
        print(
            f"log lines for dropped frames {dropped} ({dropped / args.seconds:.1f}/s), tracebacks "
            f"{text.count('Traceback')}"
        )
    finally:
        server.terminate()
        server.wait(timeout=30)
    return 0


if __name__ == "__main__":
    sys.exit(main())

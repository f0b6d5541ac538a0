"""Serving from the command line: is an address listenable, and SIGTERM/SIGHUP as Ctrl-C.

Shared by ``l3mvn replay --web`` (the rerun viewer) and ``l3mvn serve`` (the dashboard): both must
refuse a bad or busy address with one line before anything starts, and stop everything they started
when the terminal or a supervisor ends them.
"""

from __future__ import annotations

import errno
import signal
import socket
import threading
from collections.abc import Iterator
from contextlib import contextmanager

from l3mvn.core.errors import L3MVNError, first_line

STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGTERM", "SIGHUP") if hasattr(signal, name))
_PORT_HINTS = 20  # ports above a busy one tried for the "--port N is free" hint


@contextmanager
def interrupt_on_stop_signals() -> Iterator[None]:
    """Within the block, SIGTERM and SIGHUP raise KeyboardInterrupt in the main thread, as Ctrl-C does.

    By default either kills Python on the spot, leaving a child (the rerun viewer) serving and a
    recording unfinished; as KeyboardInterrupt they take the Ctrl-C path that stops everything.
    The previous handlers come back after. Only the main thread may set handlers; elsewhere (a
    test calling a command on a thread) this changes nothing.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {sig: signal.signal(sig, _raise_interrupt) for sig in STOP_SIGNALS}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, signal.SIG_DFL if handler is None else handler)


def _raise_interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt(signal.Signals(signum).name)


def check_listen_address(host: str, port: int) -> None:
    """Raise L3MVNError, one line saying what to pass instead, unless a server can listen on ``host:port``.

    Binds, without listening, every address ``host`` resolves to, as asyncio and rerun will: a port
    out of range, a name that does not resolve, another machine's address and a port in use are
    refused here, before anything starts, instead of surfacing from a server thread (or, as viser
    does, moving to the next port).
    """
    if not 0 < port < 65536:
        raise L3MVNError(f"--port must lie in 1..65535, got {port}")
    failure = _cannot_bind(host, port)
    if failure is not None:
        raise L3MVNError(bind_failure(host, port, failure))


def bind_failure(host: str, port: int, exc: BaseException) -> str:
    """Why ``host:port`` cannot be served, in one line, with the flag to change."""
    if isinstance(exc, (socket.gaierror, UnicodeError)):
        return f"--host {host}: cannot resolve it ({getattr(exc, 'strerror', None) or first_line(exc)})"
    if isinstance(exc, OverflowError):
        return f"--port must lie in 1..65535, got {port}"
    code = getattr(exc, "errno", None)
    if code == errno.EADDRINUSE:
        free = next((p for p in range(port + 1, min(port + 1 + _PORT_HINTS, 65536)) if not _cannot_bind(host, p)), None)
        return f"port {port} is in use on {host}; pick another with --port N" + (
            f" (--port {free} is free)" if free else ""
        )
    if code == errno.EADDRNOTAVAIL:
        return f"--host {host} is not an address of this machine; give one of its own, or 0.0.0.0 for all"
    if code == errno.EACCES:
        return f"port {port} on {host} needs privileges; pick one above 1023 with --port N"
    return f"cannot listen on {host} port {port}: {first_line(exc)}"


def _cannot_bind(host: str, port: int) -> BaseException | None:
    """Why binding ``port`` on every address of ``host`` fails now (socket options as asyncio's), or None."""
    try:
        addresses = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    except (OSError, UnicodeError) as exc:
        return exc
    for family, kind, proto, _, address in dict.fromkeys(addresses):
        try:
            sock = socket.socket(family, kind, proto)
        except OSError:  # a family this machine lacks (IPv6 off): servers skip it too
            continue
        with sock:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            if family == socket.AF_INET6:
                sock.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_V6ONLY, 1)
            try:
                sock.bind(address)
            except OSError as exc:
                return exc
    return None

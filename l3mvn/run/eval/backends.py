"""Run an evaluation's episodes on local worker processes, streaming result rows as they finish.

Workers are forked from a forkserver that has already imported ``l3mvn`` (a fresh interpreter per
worker would pay seconds of imports each), load the episode set once and reuse environments across
episodes (see ``EvalJob``). The parent hands out one key at a time, so it always knows which episode
each worker holds: an interrupted run loses at most those, and a worker that dies (segfault, OOM
kill) costs only its own episode, which is retried on a fresh worker and then reported as an error
row. Workers ignore Ctrl-C (the parent owns the run and stops them) and die with the parent even
when it is killed outright.
"""

from __future__ import annotations

import ctypes
import multiprocessing as mp
import os
import signal
import sys
import threading
import time
from collections import Counter, deque
from collections.abc import Generator, Iterable
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait

from l3mvn.core.errors import L3MVNError
from l3mvn.run.eval.job import EvalJob, error_row

_PR_SET_PDEATHSIG = 1
_STOP_GRACE_S = 5.0


def run_local(job: EvalJob, keys: Iterable[str], workers: int, *, max_retries: int = 1) -> Generator[dict, None, None]:
    """One result row per key, in completion order; ``workers=1`` runs in this process. Arguments are
    checked now, workers start on the first ``next()``.

    A key whose worker process dies is retried up to ``max_retries`` times on a fresh worker, then
    yielded as an error row. Close the iterator (or let it be collected) to stop the workers.
    """
    if workers < 1:
        raise L3MVNError(f"--workers must be >= 1, got {workers}")
    keys = list(keys)
    if workers == 1 or len(keys) <= 1:
        return (job.run_one(key) for key in keys)
    return _Pool(job, min(workers, len(keys)), max_retries).run(keys)


# --- the pool ----------------------------------------------------------------------------------


@dataclass
class _Worker:
    process: mp.process.BaseProcess
    conn: Connection
    key: str | None = None


class _Pool:
    def __init__(self, job: EvalJob, size: int, max_retries: int) -> None:
        self.job, self.size, self.max_retries = job, size, max_retries
        self.ctx = _context()

    def run(self, keys: list[str]) -> Generator[dict, None, None]:
        self.pending = deque(keys)
        self.strikes: Counter[str] = Counter()
        self.workers: list[_Worker] = []
        with interrupt_on_sigterm():
            try:
                self.workers = [self._start() for _ in range(self.size)]
                for w in self.workers:
                    _feed(w, self.pending)
                while busy := [w for w in self.workers if w.key is not None]:
                    ready = set(wait([w.conn for w in busy] + [w.process.sentinel for w in busy]))
                    for w in busy:
                        row = _receive(w) if w.conn in ready else None
                        if row is not None:
                            w.key = None
                            _feed(w, self.pending)  # keep it busy while the caller handles the row
                        elif w.process.sentinel in ready or not w.process.is_alive():
                            row = self._bury(w)
                        if row is not None:
                            yield row
            finally:
                _stop(self.workers)

    def _bury(self, w: _Worker) -> dict | None:
        """Replace a dead worker; its episode is queued again, or an error row once out of retries."""
        key = w.key
        assert key is not None
        self.workers.remove(w)
        w.process.join(timeout=1)
        w.conn.close()
        fresh = self._start()
        self.workers.append(fresh)
        self.strikes[key] += 1
        if self.strikes[key] <= self.max_retries:
            self.pending.appendleft(key)
        _feed(fresh, self.pending)
        if self.strikes[key] <= self.max_retries:
            return None
        return error_row(
            self.job,
            key,
            f"worker process died {self.strikes[key]} times running this episode (last exit code {w.process.exitcode})",
        )

    def _start(self) -> _Worker:
        parent, child = self.ctx.Pipe()
        process = self.ctx.Process(
            target=_worker_main, args=(self.job, child, os.getpid()), daemon=True, name="l3mvn-eval-worker"
        )
        with _children_ignore_sigint():
            process.start()
        child.close()
        return _Worker(process, parent)


def _context() -> mp.context.SpawnContext | mp.context.ForkServerContext:
    if "forkserver" not in mp.get_all_start_methods():
        return mp.get_context("spawn")
    ctx = mp.get_context("forkserver")
    ctx.set_forkserver_preload(["l3mvn.run.eval.job"])
    return ctx


def _feed(w: _Worker, pending: deque[str]) -> None:
    if pending:
        w.key = pending.popleft()
        with suppress(OSError):  # a worker that just died: its sentinel reports it and the key is retried
            w.conn.send(w.key)


def _receive(w: _Worker) -> dict | None:
    try:
        return w.conn.recv()
    except (EOFError, OSError):
        return None


def _stop(workers: list[_Worker]) -> None:
    """Idle workers are told to exit; busy ones (an interrupted run) are terminated at once."""
    for w in workers:
        if w.key is None and w.process.is_alive():
            with suppress(OSError):
                w.conn.send(None)
        else:
            w.process.terminate()
    deadline = time.monotonic() + _STOP_GRACE_S
    for w in workers:
        w.process.join(max(0.0, deadline - time.monotonic()))
        if w.process.is_alive():
            w.process.kill()
            w.process.join()
        w.conn.close()


# --- signals -----------------------------------------------------------------------------------


def _in_main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


@contextmanager
def interrupt_on_sigterm():
    """SIGTERM ends the run like Ctrl-C: the caller's cleanup runs and workers are stopped."""
    if not _in_main_thread():
        yield
        return

    def interrupt(signum, frame):
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


@contextmanager
def _children_ignore_sigint():
    """A process started while SIGINT is ignored keeps ignoring it (Python installs no handler), so a
    Ctrl-C in the terminal reaches only the parent, even before a worker runs its first line."""
    if not _in_main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _die_with_parent(owner_pid: int) -> None:
    """Exit when the process that owns the run is gone, however it ended. The direct parent is the
    forkserver, which exits with the owner: the kernel signal covers that chain on Linux, the
    watch thread covers the owner elsewhere."""
    if sys.platform.startswith("linux"):
        with suppress(OSError, AttributeError):
            ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)

    def alive() -> bool:
        try:
            os.kill(owner_pid, 0)
        except ProcessLookupError:
            return False
        except PermissionError:
            return True
        return True

    if not alive():
        os._exit(1)

    def watch() -> None:
        while alive():
            time.sleep(1.0)
        os._exit(1)

    threading.Thread(target=watch, daemon=True, name="l3mvn-parent-watch").start()


def _worker_main(job: EvalJob, conn: Connection, owner_pid: int) -> None:
    _die_with_parent(owner_pid)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    with suppress(Exception):
        job.load()  # a load error is reported by run_one, once per episode, as an error row
    while True:
        try:
            key = conn.recv()
        except (EOFError, OSError):
            return
        if key is None:
            return
        conn.send(job.run_one(key))

"""A thread that draws the newest snapshot: a fast agent makes the page drop frames, never queue them.

Snapshots are offered from the worker's thread and the GUI handlers' threads; the loop keeps only
the latest and hands it to ``draw`` on a thread of its own. A redraw request (a display setting
changed) makes the next draw a full one, whichever snapshot it draws.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

from l3mvn_studio.state import Snapshot

log = logging.getLogger(__name__)

Draw = Callable[[Snapshot, bool], None]  # (snapshot, full): full when the drawing must not skip what it drew already


class DrawLoop:
    """Calls ``draw`` with the latest snapshot offered, on its own daemon thread, until ``close()``."""

    def __init__(self, draw: Draw, *, name: str) -> None:
        self._draw = draw
        self._wake = threading.Condition()
        self._latest: Snapshot | None = None
        self._full = False
        self._closed = False
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def offer(self, snap: Snapshot) -> None:
        """Draw ``snap`` next, in place of any snapshot not drawn yet."""
        with self._wake:
            self._latest = snap
            self._wake.notify()

    def redraw(self, snap: Snapshot) -> None:
        """Draw ``snap`` next, in full (nothing skipped as drawn already)."""
        with self._wake:
            self._latest, self._full = snap, True
            self._wake.notify()

    def close(self, timeout: float = 5.0) -> None:
        with self._wake:
            self._closed = True
            self._wake.notify()
        self._thread.join(timeout=timeout)

    def _run(self) -> None:
        while True:
            with self._wake:
                while self._latest is None and not self._closed:
                    self._wake.wait()
                if self._closed:
                    return
                snap, full, self._latest, self._full = self._latest, self._full, None, False
            try:
                self._draw(snap, full)
            except Exception:  # a drawing bug must not stop later updates
                log.exception("dashboard: drawing snapshot %d failed", snap.seq)

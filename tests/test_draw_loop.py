"""The draw loop draws the newest snapshot only, and a redraw request makes the next draw a full one."""

from __future__ import annotations

import threading

from l3mvn_studio.draw_loop import DrawLoop
from l3mvn_studio.state import Metrics, Snapshot

TIMEOUT_S = 10.0


def _snap(seq: int) -> Snapshot:
    return Snapshot(seq=seq, policy="oracle", running=False, steps_per_second=4.0, metrics=Metrics())


def test_snapshots_offered_while_one_draws_collapse_into_the_newest():
    drawing, release = threading.Event(), threading.Event()
    drawn: list[tuple[int, bool]] = []

    def draw(snap: Snapshot, full: bool) -> None:
        drawn.append((snap.seq, full))
        drawing.set()
        release.wait(TIMEOUT_S)

    loop = DrawLoop(draw, name="test-draw-loop")
    try:
        loop.offer(_snap(0))
        assert drawing.wait(TIMEOUT_S)
        drawing.clear()
        loop.redraw(_snap(1))
        loop.offer(_snap(2))  # replaces 1, and is drawn in full as 1 would have been
        loop.offer(_snap(3))
        release.set()
        assert drawing.wait(TIMEOUT_S)
    finally:
        release.set()
        loop.close()
    assert drawn == [(0, False), (3, True)]


def test_a_draw_that_raises_does_not_stop_later_draws(caplog):
    failed, drawn = threading.Event(), threading.Event()

    def draw(snap: Snapshot, full: bool) -> None:
        if snap.seq == 0:
            failed.set()
            raise RuntimeError("a drawing bug")
        drawn.set()

    loop = DrawLoop(draw, name="test-draw-loop")
    try:
        loop.offer(_snap(0))
        assert failed.wait(TIMEOUT_S)
        loop.offer(_snap(1))
        assert drawn.wait(TIMEOUT_S)
    finally:
        loop.close()
    assert "drawing snapshot 0 failed" in caplog.text and "a drawing bug" in caplog.text

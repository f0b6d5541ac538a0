"""The map's picture and the patch of cells drawn over it: how a step's change reaches the page at once.

A page decodes every picture it is sent before it can draw it, which kept the map a few frames
behind the status text of the same step. So the picture is re-sent only now and then, and the cells
that changed since (a few hundred a step) go as points drawn over it, which the page draws in the
frame they arrive in. A new picture is sent when the patch grows past ``max_points`` or the map's
crop changes; for ``hold_s`` after that the patch also covers what changed since the picture before
it, which the page may still show while it decodes the new one.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from l3mvn_studio.state import Cell


@dataclass(frozen=True, eq=False)
class CellPicture:
    """The map's colour per cell (rows, cols, 3) over grid cells ``origin ..``, at ``resolution_m``."""

    cells: np.ndarray
    origin: Cell
    resolution_m: float

    def same_grid(self, other: CellPicture) -> bool:
        return (
            self.origin == other.origin
            and self.resolution_m == other.resolution_m
            and self.cells.shape == other.cells.shape
        )


@dataclass(frozen=True, eq=False)
class Patch:
    """What to send for one draw: a new picture or not, and the cells (absolute (row, col)) and
    colours to draw over the picture."""

    send_picture: bool
    cells: np.ndarray
    colours: np.ndarray


class PicturePatches:
    """Decides, draw by draw, when the picture is re-sent and which cells are drawn over it."""

    def __init__(self, *, max_points: int = 3000, hold_s: float = 1.0, clock: Callable[[], float] = time.monotonic):
        self._max_points = max_points
        self._hold_s = hold_s
        self._clock = clock
        self._base: CellPicture | None = None  # the picture sent last
        self._previous: tuple[CellPicture, float] | None = None  # the one before, and until when the page may show it

    def update(self, now: CellPicture) -> Patch:
        t = self._clock()
        if self._previous is not None and t >= self._previous[1]:
            self._previous = None
        base = self._base
        send = base is None or not now.same_grid(base) or int(_changed(now, base).sum()) > self._max_points
        if send:
            if base is not None and base.resolution_m == now.resolution_m:
                self._previous = (base, t + self._hold_s)
            base = self._base = now
        shown = [base] + ([self._previous[0]] if self._previous is not None else [])
        changed = np.zeros(now.cells.shape[:2], bool)
        for picture in shown:
            changed |= _changed(now, picture)
        rows, cols = np.nonzero(changed)
        cells = np.stack([rows + now.origin[0], cols + now.origin[1]], axis=1)
        return Patch(send, cells, now.cells[rows, cols])


def _changed(now: CellPicture, shown: CellPicture) -> np.ndarray:
    """Cells of ``now`` the page would draw otherwise with ``shown``: those of another colour there,
    and all those outside it."""
    out = np.ones(now.cells.shape[:2], bool)
    r0, c0 = shown.origin[0] - now.origin[0], shown.origin[1] - now.origin[1]
    rows, cols = shown.cells.shape[0], shown.cells.shape[1]
    a0, b0 = max(r0, 0), max(c0, 0)
    a1, b1 = min(r0 + rows, out.shape[0]), min(c0 + cols, out.shape[1])
    if a0 < a1 and b0 < b1:
        mine = now.cells[a0:a1, b0:b1]
        theirs = shown.cells[a0 - r0 : a1 - r0, b0 - c0 : b1 - c0]
        out[a0:a1, b0:b1] = (mine != theirs).any(axis=2)
    return out

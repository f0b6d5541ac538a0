"""A camera frame whose arrays are made when first read.

A backend that renders on the CPU pays per pixel, and most readers read few of them: the agent maps
the centre pixel of every 4 x 4 block of a 480x640 frame (SemExp's downsampling), the task's view
record reads the same pixels, the task's visibility count reads the pixels of one category, and only
a recording or the dashboard reads the whole frame. So a frame makes what it is asked for:
``strided(k)`` only the centre pixels of every k x k block and ``count(label)`` only the pixels that
category could cover (a renderer makes them alone, value for value as in the whole frame), the whole
depth and semantic images on first read, the colour image on its own first read.

Frames that arrive as arrays (habitat-sim, a robot, a test) are ``CameraFrame.of(rgb, depth,
semantic)``; a renderer subclasses ``CameraFrame`` and fills in the ``_make_*`` methods.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TypeVar

import numpy as np

from l3mvn.core.errors import L3MVNError

T = TypeVar("T")


def centre_pixels(image: np.ndarray, step: int) -> np.ndarray:
    """The centre pixel of every ``step`` x ``step`` block (a view, not a copy)."""
    start = step // 2
    return image[start::step, start::step]


class CameraFrame:
    """rgb uint8 (H, W, 3); depth float32 metres (H, W), 0 where invalid; semantic int32 (H, W), ids
    into the observation's categories shifted by one (0 = background)."""

    def __init__(self, shape: tuple[int, int]) -> None:
        self.shape = (int(shape[0]), int(shape[1]))
        self._rgb: np.ndarray | None = None
        self._depth: np.ndarray | None = None
        self._semantic: np.ndarray | None = None
        self._strided: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._render_s = 0.0  # seconds spent making arrays, not yet claimed by ``take_render_seconds``

    @classmethod
    def of(cls, rgb: np.ndarray, depth: np.ndarray, semantic: np.ndarray) -> CameraFrame:
        """A frame of arrays already made."""
        if depth.ndim != 2 or semantic.shape != depth.shape or rgb.shape[:2] != depth.shape:
            raise L3MVNError(
                f"frame arrays disagree in size: rgb {rgb.shape}, depth {depth.shape}, semantic {semantic.shape}"
            )
        frame = cls(depth.shape)
        frame._rgb, frame._depth, frame._semantic = rgb, depth, semantic
        return frame

    @property
    def rgb(self) -> np.ndarray:
        if self._rgb is None:
            self._rgb = self._timed(self._make_rgb)
        return self._rgb

    @property
    def depth(self) -> np.ndarray:
        self._ensure_full()
        assert self._depth is not None
        return self._depth

    @property
    def semantic(self) -> np.ndarray:
        self._ensure_full()
        assert self._semantic is not None
        return self._semantic

    def strided(self, step: int) -> tuple[np.ndarray, np.ndarray]:
        """(depth, semantic) at the centre pixel of every ``step`` x ``step`` block."""
        if step < 1:
            raise L3MVNError(f"stride must be >= 1, got {step}")
        if step == 1:
            return self.depth, self.semantic
        if self._depth is not None and self._semantic is not None:
            return centre_pixels(self._depth, step), centre_pixels(self._semantic, step)
        if step not in self._strided:
            made = self._timed(lambda: self._make_strided(step))
            if made is None:
                return centre_pixels(self.depth, step), centre_pixels(self.semantic, step)
            self._strided[step] = made
        return self._strided[step]

    def count(self, label: int) -> int:
        """Pixels of the whole frame that show ``label`` with valid depth (a renderer counts them
        without making the rest of the frame)."""
        if self._depth is None or self._semantic is None:
            made = self._timed(lambda: self._make_count(label))
            if made is not None:
                return made
        return int(np.count_nonzero((self.semantic == label) & (self.depth > 0)))

    def take_render_seconds(self) -> float:
        """Seconds spent making this frame's arrays since the last call (a step's timing claims
        them for the simulator, whoever read the frame first)."""
        seconds, self._render_s = self._render_s, 0.0
        return seconds

    # --- what a rendering backend fills in ---------------------------------------------------
    def _make_full(self) -> tuple[np.ndarray, np.ndarray]:
        raise L3MVNError("this frame has no depth and semantic images")

    def _make_rgb(self) -> np.ndarray:
        raise L3MVNError("this frame has no colour image")

    def _make_strided(self, step: int) -> tuple[np.ndarray, np.ndarray] | None:
        """The strided pixels made alone, or None to cut them from the whole frame."""
        return None

    def _make_count(self, label: int) -> int | None:
        """``count`` without the whole frame, or None to count in it."""
        return None

    # -------------------------------------------------------------------------------------------
    def _ensure_full(self) -> None:
        if self._depth is None or self._semantic is None:
            self._depth, self._semantic = self._timed(self._make_full)

    def _timed(self, make: Callable[[], T]) -> T:
        t0 = time.perf_counter()
        try:
            return make()
        finally:
            self._render_s += time.perf_counter() - t0

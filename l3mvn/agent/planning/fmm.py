"""Geodesic distance fields by Fast Marching (scikit-fmm's values, compiled: ``marcher``), computed on
a window of the map.

FMM costs about 0.1-0.2 us per marched cell on one core (more as the front grows), so a whole
720x720 map (~90 ms) is far over the planner's few-millisecond budget. Two ways to march less,
both exact where they claim a value: a ``Window`` (only a rectangle of the map is marched) and
``limit_m`` (marching stops at that distance, a narrow band). ``GeodesicField`` keeps the values
together with the window they belong to, so callers index it in map cells and never juggle offsets.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import overload

import numpy as np

from l3mvn.agent.planning.marcher import march
from l3mvn.core.errors import L3MVNError


@dataclass(frozen=True)
class Window:
    """Half-open rectangle ``[r0, r1) x [c0, c1)`` of map cells."""

    r0: int
    c0: int
    r1: int
    c1: int

    def __post_init__(self) -> None:
        if not (self.r0 < self.r1 and self.c0 < self.c1):
            raise L3MVNError(f"empty window rows [{self.r0}, {self.r1}) cols [{self.c0}, {self.c1})")

    @staticmethod
    def full(shape: tuple[int, int]) -> Window:
        return Window(0, 0, int(shape[0]), int(shape[1]))

    @staticmethod
    def bounding(rows: np.ndarray, cols: np.ndarray, margin: int, shape: tuple[int, int]) -> Window:
        """Bounding box of the given cells grown by ``margin`` cells, clipped to the map."""
        rows, cols = np.asarray(rows), np.asarray(cols)
        if rows.size == 0:
            raise L3MVNError("cannot bound an empty set of cells")
        return Window(
            max(int(rows.min()) - margin, 0),
            max(int(cols.min()) - margin, 0),
            min(int(rows.max()) + margin + 1, int(shape[0])),
            min(int(cols.max()) + margin + 1, int(shape[1])),
        )

    @property
    def slices(self) -> tuple[slice, slice]:
        return slice(self.r0, self.r1), slice(self.c0, self.c1)

    @property
    def shape(self) -> tuple[int, int]:
        return self.r1 - self.r0, self.c1 - self.c0

    def grown(self, margin: int, shape: tuple[int, int]) -> Window:
        return Window(
            max(self.r0 - margin, 0),
            max(self.c0 - margin, 0),
            min(self.r1 + margin, int(shape[0])),
            min(self.c1 + margin, int(shape[1])),
        )

    def union(self, other: Window) -> Window:
        return Window(min(self.r0, other.r0), min(self.c0, other.c0), max(self.r1, other.r1), max(self.c1, other.c1))

    def contains(self, other: Window) -> bool:
        return self.r0 <= other.r0 and self.c0 <= other.c0 and other.r1 <= self.r1 and other.c1 <= self.c1

    @overload
    def inside(self, rows: int, cols: int) -> bool: ...

    @overload
    def inside(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray: ...

    def inside(self, rows: np.ndarray | int, cols: np.ndarray | int) -> np.ndarray | bool:
        """Which of the given map cells lie in the window."""
        return (rows >= self.r0) & (rows < self.r1) & (cols >= self.c0) & (cols < self.c1)


@dataclass(frozen=True)
class GeodesicField:
    """Geodesic distances (metres) over a window of the map.

    values: float32 (h, w) for the cells of ``window``; ``inf`` where a cell is unreachable or
    farther than ``limit_m`` (the march stopped there). Cells outside the window read as ``inf``.
    """

    values: np.ndarray
    window: Window
    map_shape: tuple[int, int]
    limit_m: float = float("inf")

    def at(self, rows: np.ndarray | int, cols: np.ndarray | int) -> np.ndarray:
        """Distances at map cells (arrays or scalars); ``inf`` outside the window."""
        rows = np.asarray(rows, dtype=np.int64)
        cols = np.asarray(cols, dtype=np.int64)
        out = np.full(np.broadcast(rows, cols).shape, np.inf, dtype=np.float32)
        ok = self.window.inside(rows, cols)
        out[ok] = self.values[rows[ok] - self.window.r0, cols[ok] - self.window.c0]
        return out

    def full(self) -> np.ndarray:
        """The field as a whole (M, M) map (for display; allocates)."""
        out = np.full(self.map_shape, np.inf, dtype=np.float32)
        out[self.window.slices] = self.values
        return out


def distance_field(
    traversible: np.ndarray,
    sources: np.ndarray,
    *,
    resolution_m: float,
    limit_m: float | None = None,
) -> np.ndarray:
    """FMM distance in metres from ``sources`` to every cell, moving only through ``traversible``.

    traversible: (h, w) bool. sources: (h, w) bool mask or (N, 2) int array of (row, col) cells;
    sources that are not traversible are ignored (a goal inside a wall is reached from its free
    surroundings, which the caller expresses by dilating the goal). limit_m: stop marching at this
    distance (a narrow band); farther cells read ``inf``. Returns float32 (h, w), ``inf``
    where unreachable.
    """
    traversible = np.asarray(traversible)
    if traversible.ndim != 2 or traversible.dtype != bool:
        raise L3MVNError(f"traversible must be a 2D bool array, got {traversible.dtype} {traversible.shape}")
    if resolution_m <= 0:
        raise L3MVNError(f"resolution_m must be positive, got {resolution_m}")
    if limit_m is not None and limit_m <= 0:
        raise L3MVNError(f"limit_m must be positive or None, got {limit_m}")
    source_mask = _as_mask(sources, traversible.shape) & traversible
    narrow = float(limit_m) if limit_m is not None and np.isfinite(limit_m) else 0.0
    out: np.ndarray = march(traversible, source_mask, float(resolution_m), narrow).astype(np.float32)
    if narrow:
        out[out > narrow] = np.inf  # a value within the band may round past it in float32
    return out


def _as_mask(sources: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    sources = np.asarray(sources)
    if sources.dtype == bool:
        if sources.shape != shape:
            raise L3MVNError(f"sources mask has shape {sources.shape}, expected {shape}")
        return sources
    if sources.ndim != 2 or sources.shape[1] != 2 or not np.issubdtype(sources.dtype, np.integer):
        raise L3MVNError(f"sources must be a bool mask or an (N, 2) int array of cells, got {sources.shape}")
    rows, cols = sources[:, 0], sources[:, 1]
    if ((rows < 0) | (rows >= shape[0]) | (cols < 0) | (cols >= shape[1])).any():
        raise L3MVNError(f"source cells must lie inside the {shape[0]}x{shape[1]} array")
    mask = np.zeros(shape, dtype=bool)
    mask[rows, cols] = True
    return mask


__all__ = ["Window", "GeodesicField", "distance_field"]

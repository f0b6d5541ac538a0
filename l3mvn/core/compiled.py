"""Small numba functions that more than one compiled pass needs, defined once."""

from __future__ import annotations

import math

import numba as nb
import numpy as np


@nb.njit(cache=True)
def hypot32(dx: np.float32, dy: np.float32) -> np.float32:
    """float32 ``hypot`` as numpy's float32 ``np.hypot`` rounds it (libm's ``hypotf``): the length
    in double precision, rounded once, so a compiled pass compares lengths as the array code did."""
    length: np.float32 = np.float32(math.sqrt(np.float64(dx) * np.float64(dx) + np.float64(dy) * np.float64(dy)))
    return length


@nb.njit(cache=True)
def bool_extent(mask: np.ndarray) -> tuple[int, int, int, int]:
    """(first row, last row, first column, last column) holding a True cell of a 2D bool array,
    or (-1, -1, -1, -1) when none does. Each row is scanned from both ends only as far as the
    columns found so far, so a map whose True cells sit in one part of it costs a fraction of a
    whole-array reduction."""
    h, w = mask.shape
    rmin = -1
    for r in range(h):
        for c in range(w):
            if mask[r, c]:
                rmin = r
                break
        if rmin >= 0:
            break
    if rmin < 0:
        return -1, -1, -1, -1
    rmax = rmin
    for r in range(h - 1, rmin, -1):
        for c in range(w):
            if mask[r, c]:
                rmax = r
                break
        if rmax > rmin:
            break
    cmin, cmax = w, -1
    for r in range(rmin, rmax + 1):
        for c in range(cmin):
            if mask[r, c]:
                cmin = c
                break
        for c in range(w - 1, cmax, -1):
            if mask[r, c]:
                cmax = c
                break
    return rmin, rmax, cmin, cmax

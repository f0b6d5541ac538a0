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

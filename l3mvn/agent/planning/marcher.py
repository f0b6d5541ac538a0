"""Fast Marching from source cells over a 2D grid, compiled: the values of scikit-fmm's
second-order distance marcher, to the bit, for the one case the planner asks.

Why not skfmm itself: its generic N-dimensional code, behind masked arrays, takes ~1.7x this
march's time on the planner's marches, the largest part of an episode. Why the same values:
every plan and every decision to keep a cached field reads them, so a march that differs in the
last bit can change an episode.

What fixes skfmm's values, and is kept here operation for operation: its second-order stencil
(including a quirk: a second neighbour found on one side is kept when the first neighbour is then
taken from the other side), the first-order fallback where the quadratic has no root, the
arithmetic in the same order, an estimate of zero never replacing a value, every cell of the least
value frozen before any neighbour is updated, and marching stopped at the first value beyond the
narrow band. What does not: the order in which equal values leave the heap. An update reads only
frozen cells, and a whole group of equal values is frozen before any of them updates a neighbour,
so every update in a group sees the same frozen set and the group's order changes no value. That
frees the heap (an indexed binary heap here, its keys kept in heap order) and the indexing (a
two-cell masked border instead of bounds checks: skfmm treats cells off the grid as it treats
masked ones).

Left out, as the planner never asks them: distances from a zero contour between cells (all its
sources are cells at distance zero), signed distances, periodic borders, other dimensions.
``tests/test_marcher.py`` checks the values against skfmm's.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

_FAR, _NARROW, _FROZEN, _MASK = 0, 1, 2, 3
_MAX_DOUBLE = float(np.finfo(np.float64).max)
_AA = 9.0 / 4.0
_ONE_THIRD = 1.0 / 3.0
_BORDER = 2  # the stencil reaches two cells out


@nb.njit(cache=True)
def march(traversible: np.ndarray, sources: np.ndarray, dx: float, narrow: float) -> np.ndarray:
    """Distances (float64, inf where not reached) from the ``sources`` cells (bool) through the
    ``traversible`` ones (bool, same shape; a source that is not traversible is ignored), ``dx``
    metres a cell. ``narrow`` > 0 stops the march at that distance (cells beyond read inf)."""
    h, w = traversible.shape
    stride = w + 2 * _BORDER
    size = (h + 2 * _BORDER) * stride
    flag = np.full(size, _MASK, np.int8)
    distance = np.zeros(size)
    frozen = 0
    for r in range(h):
        for c in range(w):
            if traversible[r, c]:
                i = (r + _BORDER) * stride + c + _BORDER
                if sources[r, c]:
                    flag[i] = _FROZEN
                    frozen += 1
                else:
                    flag[i] = _FAR
    out = np.full((h, w), np.inf)
    if frozen == 0:
        return out
    idx2 = 1.0 / dx / dx
    heap = np.empty(size, np.int64)  # cells in heap order
    where = np.empty(size, np.int64)  # each cell's place in ``heap``
    key = np.empty(size)  # the values of the cells in ``heap``, in heap order
    n = 0
    for r in range(h):
        for c in range(w):
            i = (r + _BORDER) * stride + c + _BORDER
            if flag[i] != _FAR:
                continue
            if (
                flag[i - stride] == _FROZEN
                or flag[i + stride] == _FROZEN
                or flag[i - 1] == _FROZEN
                or flag[i + 1] == _FROZEN
            ):
                flag[i] = _NARROW
                d = _estimate(distance, flag, i, stride, idx2)
                distance[i] = d
                n = _insert(heap, where, key, n, i, abs(d))
    group = np.empty(size, np.int64)
    offsets = (-stride, stride, -1, 1)
    while n > 0:
        value = key[0]
        if narrow != 0.0 and value > narrow:
            break
        count = 0
        while n > 0 and key[0] == value:
            group[count] = heap[0]
            flag[heap[0]] = _FROZEN
            count += 1
            n = _remove_top(heap, where, key, n)
        for k in range(count):
            cell = group[k]
            for step in offsets:
                near = cell + step
                state = flag[near]
                if state == _NARROW:
                    d = _estimate(distance, flag, near, stride, idx2)
                    if d != 0.0:
                        distance[near] = d
                        _rekey(heap, where, key, n, near, abs(d))
                elif state == _FAR:
                    d = _estimate(distance, flag, near, stride, idx2)
                    if d != 0.0:
                        distance[near] = d
                        flag[near] = _NARROW
                        n = _insert(heap, where, key, n, near, abs(d))
                elif state == _FROZEN:
                    # The second-order stencil reaches past a frozen neighbour to a narrow cell.
                    beyond = near + step
                    if flag[beyond] == _NARROW:
                        d = _estimate(distance, flag, beyond, stride, idx2)
                        if d != 0.0:
                            distance[beyond] = d
                            _rekey(heap, where, key, n, beyond, abs(d))
    for r in range(h):
        for c in range(w):
            i = (r + _BORDER) * stride + c + _BORDER
            if flag[i] == _FROZEN:
                out[r, c] = distance[i]
    return out


@nb.njit(cache=True, inline="always")
def _estimate(distance: np.ndarray, flag: np.ndarray, i: int, stride: int, idx2: float) -> float:
    """Second-order estimate at cell ``i`` from its frozen neighbours; first order where that
    quadratic has no root; the first-order quadratic's minimum where neither has."""
    a = b = c = 0.0
    for dim in range(2):
        step = stride if dim == 0 else 1
        value1 = _MAX_DOUBLE
        value2 = _MAX_DOUBLE
        for j in (-1, 1):
            n = i + j * step
            if flag[n] == _FROZEN and abs(distance[n]) < abs(value1):
                value1 = distance[n]
                n2 = n + j * step
                if flag[n2] == _FROZEN and (
                    (distance[n2] <= value1 and value1 >= 0) or (distance[n2] >= value1 and value1 <= 0)
                ):
                    value2 = distance[n2]
        if value2 < _MAX_DOUBLE:
            tp = _ONE_THIRD * (4 * value1 - value2)
            a += idx2 * _AA
            b -= idx2 * 2 * _AA * tp
            c += idx2 * _AA * (tp * tp)
        elif value1 < _MAX_DOUBLE:
            a += idx2
            b -= idx2 * 2 * value1
            c += idx2 * (value1 * value1)
    c -= 1
    det = b * b - 4 * a * c
    if det >= 0:
        return (-b + math.sqrt(det)) / 2.0 / a
    a = b = c = 0.0
    for dim in range(2):
        step = stride if dim == 0 else 1
        value = _MAX_DOUBLE
        for j in (-1, 1):
            n = i + j * step
            if flag[n] == _FROZEN and abs(distance[n]) < abs(value):
                value = distance[n]
        if value < _MAX_DOUBLE:
            a += idx2
            b -= idx2 * 2 * value
            c += idx2 * (value * value)
    c -= 1
    det = b * b - 4 * a * c
    if det >= 0:
        return (-b + math.sqrt(det)) / 2.0 / a
    return -b / (2.0 * a)


# -- the indexed binary heap of narrow cells, least key first: each key is kept beside its cell
# in heap order, so a comparison reads the heap's own memory instead of a cell's far-away slot.


@nb.njit(cache=True, inline="always")
def _insert(heap: np.ndarray, where: np.ndarray, key: np.ndarray, n: int, cell: int, value: float) -> int:
    _towards_root(heap, where, key, n, cell, value)
    return n + 1


@nb.njit(cache=True, inline="always")
def _remove_top(heap: np.ndarray, where: np.ndarray, key: np.ndarray, n: int) -> int:
    n -= 1
    if n > 0:
        _towards_leaves(heap, where, key, n, 0, heap[n], key[n])
    return n


@nb.njit(cache=True, inline="always")
def _rekey(heap: np.ndarray, where: np.ndarray, key: np.ndarray, n: int, cell: int, value: float) -> None:
    pos = where[cell]
    old = key[pos]
    if value < old:
        _towards_root(heap, where, key, pos, cell, value)
    elif value > old:
        _towards_leaves(heap, where, key, n, pos, cell, value)


@nb.njit(cache=True, inline="always")
def _towards_root(heap: np.ndarray, where: np.ndarray, key: np.ndarray, pos: int, cell: int, value: float) -> None:
    """Place ``cell`` with ``value`` at ``pos`` or above it (``pos`` is free to overwrite)."""
    while pos > 0:
        parent = (pos - 1) >> 1
        if not value < key[parent]:
            break
        heap[pos] = heap[parent]
        key[pos] = key[parent]
        where[heap[pos]] = pos
        pos = parent
    heap[pos] = cell
    key[pos] = value
    where[cell] = pos


@nb.njit(cache=True, inline="always")
def _towards_leaves(
    heap: np.ndarray, where: np.ndarray, key: np.ndarray, n: int, pos: int, cell: int, value: float
) -> None:
    """Place ``cell`` with ``value`` at ``pos`` or below it, among the first ``n`` places."""
    child = 2 * pos + 1
    while child < n:
        if child + 1 < n and key[child + 1] < key[child]:
            child += 1
        if not key[child] < value:
            break
        heap[pos] = heap[child]
        key[pos] = key[child]
        where[heap[pos]] = pos
        pos = child
        child = 2 * pos + 1
    heap[pos] = cell
    key[pos] = value
    where[cell] = pos

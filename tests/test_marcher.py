"""The compiled Fast Marching gives scikit-fmm's distances to the bit: every plan and every decision
to keep a cached field reads them, so episodes stay what they were."""

from __future__ import annotations

import numpy as np
import numpy.ma as ma
import pytest
import skfmm

from l3mvn.agent.planning.marcher import march


def skfmm_distances(traversible: np.ndarray, sources: np.ndarray, dx: float, narrow: float) -> np.ndarray:
    """The reference: skfmm's second-order march on the masked grid, inf where it left no value."""
    phi = ma.MaskedArray(np.ones(traversible.shape), mask=~traversible)
    phi[sources & traversible] = 0.0
    found = skfmm.distance(phi, dx=dx, narrow=narrow)
    out = np.full(traversible.shape, np.inf)
    reached = ~ma.getmaskarray(found)
    out[reached] = ma.getdata(found)[reached]
    return out


def random_grids(seed: int, count: int):
    rng = np.random.default_rng(seed)
    for _ in range(count):
        h, w = (int(v) for v in rng.integers(1, 48, 2))
        traversible = rng.random((h, w)) >= rng.choice([0.0, 0.05, 0.25, 0.45])
        sources = np.zeros((h, w), bool)
        for _ in range(int(rng.integers(1, 6))):
            sources[rng.integers(h), rng.integers(w)] = True
        if rng.random() < 0.3:  # a goal region, as the planner's dilated goals are
            r, c = rng.integers(h), rng.integers(w)
            sources[max(r - 2, 0) : r + 3, max(c - 2, 0) : c + 3] = True
        sources &= traversible
        if sources.any():
            yield traversible, sources, float(rng.choice([0.0, 0.2, 0.6, 1.5]))


@pytest.mark.parametrize("seed", range(4))
def test_distances_equal_skfmms_to_the_bit_on_random_grids(seed):
    for traversible, sources, narrow in random_grids(seed, 150):
        expected = skfmm_distances(traversible, sources, 0.05, narrow)
        found = march(traversible, sources, 0.05, narrow)
        assert np.array_equal(found, expected), (traversible.shape, narrow)


def test_open_floors_with_many_equal_values_and_rooms_behind_walls():
    """An open floor from one or two cells makes every distance come in equal groups (symmetry); a
    wall with a door makes the second-order stencil meet masked cells and the border."""
    open_floor = np.ones((61, 61), bool)
    one, two = np.zeros_like(open_floor), np.zeros_like(open_floor)
    one[30, 30] = True
    two[30, 10] = two[30, 50] = True
    rooms = open_floor.copy()
    rooms[:, 30] = False
    rooms[28:33, 30] = True
    for traversible, sources in ((open_floor, one), (open_floor, two), (rooms, two), (rooms, one)):
        for dx, narrow in ((0.05, 0.0), (0.05, 0.75), (1.0, 0.0), (0.1, 2.0)):
            expected = skfmm_distances(traversible, sources, dx, narrow)
            assert np.array_equal(march(traversible, sources, dx, narrow), expected)


def test_house_sized_grids_whose_fronts_fill_a_deep_heap():
    """Fronts of thousands of cells move keys up and down many levels of the heap."""
    rng = np.random.default_rng(7)
    for density in (0.0, 0.1, 0.3):
        traversible = rng.random((240, 260)) >= density
        sources = np.zeros_like(traversible)
        sources[rng.integers(240, size=3), rng.integers(260, size=3)] = True
        sources &= traversible
        for narrow in (0.0, 4.0):
            expected = skfmm_distances(traversible, sources, 0.05, narrow)
            assert np.array_equal(march(traversible, sources, 0.05, narrow), expected), (density, narrow)


def test_no_source_or_no_free_cell_reaches_nothing():
    free = np.ones((4, 5), bool)
    assert np.isinf(march(free, np.zeros_like(free), 0.05, 0.0)).all()
    walled = np.zeros((4, 5), bool)
    assert np.isinf(march(walled, free, 0.05, 0.0)).all()
    single = np.ones((1, 1), bool)
    assert march(single, single, 0.05, 0.0)[0, 0] == 0.0

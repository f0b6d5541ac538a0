"""Shapes on the map grid shared by every layer that dilates cells: the world builder, the mapper's
footprint, the planner's obstacle growth and the policies that judge where the agent fits."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt


def disk(radius_cells: int) -> npt.NDArray[np.bool_]:
    """The (2r+1, 2r+1) bool disk of cells within ``radius_cells`` of the centre: one shape, so the
    planner and the policies agree on which gaps the agent fits through."""
    r = int(radius_cells)
    yy, xx = np.ogrid[-r : r + 1, -r : r + 1]
    inside: npt.NDArray[np.bool_] = (xx * xx + yy * yy) <= r * r  # np.ogrid is typed Any
    return inside

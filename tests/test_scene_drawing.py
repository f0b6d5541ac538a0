"""Where a click on the 3D view lands: scene coordinates back to map cells, checked without a server."""

from __future__ import annotations

import numpy as np
import pytest

from l3mvn.core.errors import L3MVNError
from l3mvn_studio.scene_drawing import MARKER_RADIUS_M, cell_to_xy, clicked_cell, ray_to_cell
from l3mvn_studio.state import FrontierMarker, MapView

RES = 0.05
DOWN = (0.0, 0.0, -1.0)


def _view(*frontier_cells: tuple[int, int]) -> MapView:
    """A 40 x 60 cell map whose crop starts at cell (100, 200)."""
    frontiers = tuple(
        FrontierMarker(
            id=i,
            cell=c,
            size=10,
            distance_m=1.0,
            s_cu=0.5,
            s_llm=None,
            fused=None,
            objects=(),
            queries={},
            reason="",
            chosen=False,
        )
        for i, c in enumerate(frontier_cells)
    )
    return MapView(
        image=np.zeros((40, 60, 3), np.uint8),
        origin=(100, 200),
        scale=1,
        grid_shape=(480, 480),
        resolution_m=RES,
        source="agent map",
        agent_cell=(120, 230),
        agent_heading=0.0,
        frontiers=frontiers,
    )


def _above(cell: tuple[int, int]) -> tuple[float, float, float]:
    x, y = cell_to_xy(cell, RES)
    return x, y, 10.0


def test_a_click_ray_lands_on_the_map_cell_below_it():
    x, y = cell_to_xy((40, 25), 0.05)
    assert ray_to_cell((x, y, 10.0), (0.0, 0.0, -1.0), 0.05) == (40, 25)
    assert ray_to_cell((x, y, 10.0), (0.0, 0.0, 1.0), 0.05) is None  # looking away from the map
    assert ray_to_cell((x, y, 1e308), (1e308, 0.0, -1e-300), 0.05) is None  # meets the plane at infinity


def test_a_click_near_a_frontier_marker_picks_that_frontier_and_elsewhere_the_cell_below():
    near = int(MARKER_RADIUS_M / RES)  # cells from the marker's centre still on the sphere
    view = _view((110, 210), (130, 250))
    assert clicked_cell(view, _above((110 + near, 210)), DOWN) == (110, 210)
    assert clicked_cell(view, _above((125, 230)), DOWN) == (125, 230)


@pytest.mark.parametrize("cell", [(99, 230), (140, 230), (120, 199), (120, 260)])
def test_a_click_beside_the_map_is_refused(cell):
    with pytest.raises(L3MVNError, match="outside the map"):
        clicked_cell(_view(), _above(cell), DOWN)

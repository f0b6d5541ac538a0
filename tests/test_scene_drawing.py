"""Where a click on the 3D view lands: scene coordinates back to map cells, checked without a server."""

from __future__ import annotations

import numpy as np
import pytest

from l3mvn.core.errors import L3MVNError
from l3mvn.run.viz import SCORE_ANCHORS
from l3mvn_studio.label_placement import Box
from l3mvn_studio.map_image import frontier_colors
from l3mvn_studio.page_markdown import legend_html
from l3mvn_studio.scene_drawing import (
    MARKER_RADIUS_M,
    cell_to_xy,
    clicked_cell,
    fitted_em_m,
    map_labels,
    marker_radii,
    ray_to_cell,
)
from l3mvn_studio.state import FrontierMarker, MapView

RES = 0.05
DOWN = (0.0, 0.0, -1.0)


def _view(*frontier_cells: tuple[int, int], fused: tuple[float, ...] = ()) -> MapView:
    """A 40 x 60 cell map whose crop starts at cell (100, 200); frontier 0 is the chosen one when scored."""
    frontiers = tuple(
        FrontierMarker(
            id=i,
            cell=c,
            size=10,
            distance_m=1.0,
            s_cu=0.5,
            s_llm=None,
            fused=fused[i] if fused else None,
            objects=(),
            queries={},
            reason="",
            chosen=bool(fused) and i == 0,
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


# Frontiers a few cells apart (at 5 cm cells), beside the agent, the chosen one under the long-term goal:
# where the old fixed-offset labels printed on top of each other.
CROWD = ((110, 230), (110, 234), (113, 231), (116, 229), (112, 238), (121, 231))
CROWD_FUSED = (0.30, 0.284, 0.274, 0.209, 0.167, 0.15)


def _overlap(a: Box, b: Box) -> bool:
    return a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1


def test_labels_of_crowded_frontiers_overlap_no_label_sphere_goal_or_agent():
    view = _view(*CROWD, fused=CROWD_FUSED)
    goal_xy = cell_to_xy(CROWD[0], RES)
    layout = map_labels(view, ("long-term goal (frontier)", goal_xy), fitted_em_m(view, 1000))
    placed = [p for p in layout.placed if p is not None]
    assert layout.placed[0] is not None and layout.placed[0].text == "long-term goal (frontier)"
    assert len(placed) == len(CROWD) + 1  # every frontier found a spot
    assert any(p.text.startswith("★F0 0.30") for p in placed)
    for i, a in enumerate(placed):
        for b in placed[i + 1 :]:
            assert not _overlap(a.box, b.box), (a.text, b.text)
    spheres = [Box.around(*cell_to_xy(f.cell, RES), r) for f, r in zip(view.frontiers, layout.radii)]
    agent = Box.around(*cell_to_xy(view.agent_cell, RES), 0.25)
    for p in placed:
        assert not any(_overlap(p.box, s) for s in [*spheres, agent]), p.text


def test_spheres_of_close_frontiers_do_not_touch_and_a_click_picks_the_nearer():
    xy = [cell_to_xy(c, RES) for c in CROWD]
    radii = marker_radii(xy)
    for i in range(len(xy)):
        for j in range(i + 1, len(xy)):
            assert radii[i] + radii[j] < np.hypot(xy[i][0] - xy[j][0], xy[i][1] - xy[j][1])
    assert marker_radii([xy[0]]) == [MARKER_RADIUS_M]  # a lone frontier keeps its full size
    view = _view(*CROWD)
    assert clicked_cell(view, _above((110, 233)), DOWN) == (110, 234)
    assert clicked_cell(view, _above((110, 231)), DOWN) == (110, 230)


def test_the_score_colours_span_the_colormap_over_the_scores_present_and_the_legend_says_so():
    view = _view(*CROWD, fused=CROWD_FUSED)
    colours = frontier_colors(view.frontiers)
    assert colours[0] == tuple(int(v) for v in SCORE_ANCHORS[-1])  # the best fused score, 0.30: top of the scale
    assert colours[-1] == tuple(int(v) for v in SCORE_ANCHORS[0])  # the lowest, 0.15: bottom
    assert len(set(colours)) == len(colours)
    legend = legend_html((), frontiers=view.frontiers)
    assert "0.15" in legend and "0.30" in legend and "min-max" in legend


def test_a_steps_changed_cells_go_as_a_patch_over_the_picture_until_a_new_picture_is_due():
    from l3mvn_studio.map_patches import CellPicture, PicturePatches

    now = [0.0]
    patches = PicturePatches(max_points=5, hold_s=1.0, clock=lambda: now[0])
    cells = np.zeros((10, 12, 3), np.uint8)
    first = patches.update(CellPicture(cells, (100, 200), RES))
    assert first.send_picture and not len(first.cells)
    cells = cells.copy()
    cells[2, 3] = cells[4, 5] = 200
    step = patches.update(CellPicture(cells, (100, 200), RES))
    assert not step.send_picture
    assert sorted(map(tuple, step.cells)) == [(102, 203), (104, 205)] and (step.colours == 200).all()
    cells = cells.copy()
    cells[7, :] = 90  # twelve more cells: past max_points, a new picture is due
    due = patches.update(CellPicture(cells, (100, 200), RES))
    assert due.send_picture and len(due.cells) == 14  # the page may still show the old picture meanwhile
    now[0] = 2.0
    assert not len(patches.update(CellPicture(cells, (100, 200), RES)).cells)  # the new picture has landed
    grown = np.zeros((11, 12, 3), np.uint8)
    grown[1:] = cells
    moved = patches.update(CellPicture(grown, (99, 200), RES))
    assert moved.send_picture and {tuple(c) for c in moved.cells} >= {(99, c) for c in range(200, 212)}

"""The rerun viewer layout that travels with every recording (a blueprint): the map first.

The map view takes most of the window and is fitted to what the agent mapped (the recorder re-sends
the blueprint as the mapped area grows and once at the end), the camera frames sit in a narrow
column at their own aspect ratio, and the time series (each frontier's score, the chosen
frontier's LLM / CU / fused scores, ground truth, timings) share a tab strip under the map.
"""

from __future__ import annotations

from dataclasses import dataclass

import rerun.blueprint as rrb

from l3mvn.run.recording.entities import (
    CAMERA_DEPTH,
    CAMERA_RGB,
    CAMERA_SEMANTIC,
    EPISODE,
    LANGUAGE_CHOSEN,
    LOG,
    MAP,
    METRICS_CHOSEN_FRONTIER,
    METRICS_FRONTIER_SCORES,
    METRICS_FRONTIERS,
    METRICS_GROUND_TRUTH,
    METRICS_TIMINGS_MS,
    WORLD,
)

LABELLED_FRONTIERS = 3  # only the best frontiers (and the chosen one) carry a label: more would overlap
MIN_VIEW_M = 6.0  # a fitted map view is never narrower: the first steps map a thin cone
VIEW_MARGIN = 0.1  # of the mapped extent, on every side


@dataclass(frozen=True)
class MapBounds:
    """The map view's visible range in map pixels (x = column, y = row)."""

    x0: float
    x1: float
    y0: float
    y1: float


def map_view_bounds(box: tuple[int, int, int, int], resolution_m: float, *, final: bool = False) -> MapBounds:
    """The view around the mapped box (rows r0..r1, cols c0..c1, end exclusive): the box plus a margin
    on each axis, at least ``MIN_VIEW_M`` on a side, and while the episode runs 1.5 times as large, so
    the view is re-sent a few times per episode rather than at every step. Not squared: the viewer
    keeps the aspect ratio, so a wide house fills a wide view."""
    r0, r1, c0, c1 = box
    grow = (1 + 2 * VIEW_MARGIN) * (1 if final else 1.5)
    least = MIN_VIEW_M / resolution_m
    w, h = max((c1 - c0) * grow, least), max((r1 - r0) * grow, least)
    cx, cy = (c0 + c1) / 2, (r0 + r1) / 2
    return MapBounds(cx - w / 2, cx + w / 2, cy - h / 2, cy + h / 2)


def default_blueprint(view: MapBounds | None = None) -> rrb.Blueprint:
    """Map (fitted to ``view`` when given) and its time series on the left, about two thirds of the
    width; RGB, then depth and semantic side by side, then the logs on the right."""
    bounds = None if view is None else rrb.VisualBounds2D(x_range=[view.x0, view.x1], y_range=[view.y0, view.y1])
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial2DView(name="Map", origin=MAP, visual_bounds=bounds),
                rrb.Tabs(
                    rrb.TimeSeriesView(name="Frontier scores", origin=METRICS_FRONTIER_SCORES),
                    rrb.TimeSeriesView(name="Chosen frontier", origin=METRICS_CHOSEN_FRONTIER),
                    rrb.TimeSeriesView(name="Language (chosen)", origin=LANGUAGE_CHOSEN),
                    rrb.TimeSeriesView(name="Ground truth", origin=METRICS_GROUND_TRUTH),
                    rrb.TimeSeriesView(name="Frontiers", origin=METRICS_FRONTIERS),
                    rrb.TimeSeriesView(name="Timings (ms)", origin=METRICS_TIMINGS_MS),
                ),
                row_shares=[3, 1],
            ),
            rrb.Vertical(
                rrb.Spatial2DView(name="RGB", origin=CAMERA_RGB),
                rrb.Horizontal(
                    rrb.Spatial2DView(name="Depth", origin=CAMERA_DEPTH),
                    rrb.Spatial2DView(name="Semantic", origin=CAMERA_SEMANTIC),
                ),
                rrb.Tabs(
                    rrb.TextLogView(name="Decisions", origin=LOG),
                    rrb.TextDocumentView(name="Episode", origin=EPISODE),
                    rrb.Spatial3DView(name="World", origin=WORLD),
                ),
                row_shares=[4, 2, 3],
            ),
            column_shares=[2, 1],
        ),
        collapse_panels=True,
    )

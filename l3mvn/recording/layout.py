"""The rerun viewer layout that travels with every recording (a blueprint)."""

from __future__ import annotations

import rerun.blueprint as rrb


def default_blueprint() -> rrb.Blueprint:
    """Cameras and metrics on the left, the map (and 3D world) on the right, logs below."""
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Horizontal(
                    rrb.Spatial2DView(name="RGB", origin="camera/rgb"),
                    rrb.Spatial2DView(name="Depth", origin="camera/depth"),
                    rrb.Spatial2DView(name="Semantic", origin="camera/semantic"),
                ),
                rrb.Horizontal(
                    rrb.TimeSeriesView(name="Ground truth", origin="metrics/ground_truth"),
                    rrb.TimeSeriesView(name="Timings (ms)", origin="metrics/timings_ms"),
                    rrb.TimeSeriesView(name="Frontiers", origin="metrics/frontiers"),
                ),
                rrb.Tabs(
                    rrb.TextLogView(name="Decisions", origin="log"),
                    rrb.TextDocumentView(name="Episode", origin="episode"),
                ),
                row_shares=[2, 1, 1],
            ),
            rrb.Tabs(
                rrb.Spatial2DView(name="Map", origin="map"),
                rrb.Spatial3DView(name="World", origin="world"),
            ),
            column_shares=[3, 2],
        ),
        collapse_panels=True,
    )

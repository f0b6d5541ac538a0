"""Map -> picture, fast (a few ms for a 720x720 map): crop to what was seen, colour, upscale.

Two sources: the agent's own SemanticMap (what it knows), or, for policies that keep no map, the
scene's ground-truth grid (marked as such). Either way the result is a ``MapView`` in that grid's cells.
"""

from __future__ import annotations

import math

import numpy as np

from app.state import Cell, FrontierMarker, MapView
from l3mvn.events import Decision
from l3mvn.scenes.scene import SceneMap
from l3mvn.types import Pose
from l3mvn.viz import category_palette, legend

UNEXPLORED = (28, 30, 36)
FREE = (226, 226, 220)
GLIMPSED = (170, 170, 160)  # explored only from afar (SemanticMap.looked): what the agent may go look at
OBSTACLE = (112, 112, 124)
TRAJECTORY = (10, 10, 10)
MARGIN_CELLS = 24
TARGET_PIXELS = 640


def agent_map_view(decision: Decision) -> MapView:
    """The agent's SemanticMap, cropped to the explored bounding box plus a margin."""
    m = decision.map
    frontiers = tuple(_marker(f, i == decision.chosen_frontier) for i, f in enumerate(decision.frontiers))
    extra = [m.agent_cell, decision.long_term_goal, decision.short_term_goal, *(f.cell for f in frontiers)]
    r0, r1, c0, c1 = _bbox(m.explored, [c for c in extra if c is not None], m.size, m.size)
    rows, cols = slice(r0, r1), slice(c0, c1)
    img = np.empty((r1 - r0, c1 - c0, 3), np.uint8)
    img[:] = UNEXPLORED
    img[m.explored[rows, cols]] = FREE
    img[m.explored[rows, cols] & ~m.looked[rows, cols]] = GLIMPSED
    img[m.obstacle[rows, cols]] = OBSTACLE
    _paint_categories(img, m.categories[:, rows, cols], m.category_names)
    img[m.visited[rows, cols]] = TRAJECTORY
    scale = _scale(img.shape)
    return MapView(
        image=_upscale(img, scale), origin=(r0, c0), scale=scale, grid_shape=(m.size, m.size),
        resolution_m=m.resolution_m, source="agent map", agent_cell=tuple(m.agent_cell),
        agent_heading=m.agent_heading, long_term_goal=_cell(decision.long_term_goal),
        short_term_goal=_cell(decision.short_term_goal), goal_kind=decision.goal_kind,
        override=decision.override, frontiers=frontiers, legend=tuple(legend(m.category_names)),
    )


def ground_truth_view(scene: SceneMap, trajectory: list[Pose], decision: Decision | None = None) -> MapView:
    """The scene's ground-truth floor plan with the walked path: for policies without a map."""
    h, w = scene.shape
    img = np.empty((h, w, 3), np.uint8)
    img[:] = UNEXPLORED
    img[scene.free] = FREE
    _paint_categories(img, scene.objects, scene.categories)
    cells = np.array([scene.cell_of(p.x, p.y) for p in trajectory], dtype=np.int64).reshape(-1, 2)
    inside = (cells[:, 0] >= 0) & (cells[:, 0] < h) & (cells[:, 1] >= 0) & (cells[:, 1] < w)
    img[cells[inside, 0], cells[inside, 1]] = TRAJECTORY
    pose = trajectory[-1]
    scale = _scale(img.shape)
    return MapView(
        image=_upscale(img, scale), origin=(0, 0), scale=scale, grid_shape=(h, w),
        resolution_m=scene.resolution_m, source="ground truth", agent_cell=scene.cell_of(pose.x, pose.y),
        agent_heading=pose.heading, goal_kind=decision.goal_kind if decision else "",
        override=decision.override if decision else None, legend=tuple(legend(scene.categories)),
    )


def score_color(score: float | None) -> tuple[int, int, int]:
    """Low score dark purple -> high score yellow (viridis anchors); unscored grey."""
    if score is None or not math.isfinite(score):
        return (150, 150, 150)
    s = min(max(score, 0.0), 1.0) * (len(_VIRIDIS) - 1)
    i = min(int(s), len(_VIRIDIS) - 2)
    t = s - i
    return tuple(int(round(a * (1 - t) + b * t)) for a, b in zip(_VIRIDIS[i], _VIRIDIS[i + 1]))  # type: ignore[return-value]


_VIRIDIS = ((68, 1, 84), (59, 82, 139), (33, 145, 140), (94, 201, 98), (253, 231, 37))


def _marker(f, chosen: bool) -> FrontierMarker:
    """``Decision.chosen_frontier`` is an index into ``Decision.frontiers``."""
    return FrontierMarker(
        id=int(f.id), cell=(int(f.center[0]), int(f.center[1])), size=int(f.size),
        distance_m=float(f.distance_m), s_cu=float(f.s_cu),
        s_llm=None if f.s_llm is None else float(f.s_llm), fused=None if f.fused is None else float(f.fused),
        objects=tuple(f.objects), queries=dict(f.queries), reason=f.reason, chosen=chosen,
    )


def _cell(cell) -> Cell | None:
    return None if cell is None else (int(cell[0]), int(cell[1]))


def _bbox(explored: np.ndarray, extra: list, height: int, width: int) -> tuple[int, int, int, int]:
    rows, cols = np.flatnonzero(explored.any(axis=1)), np.flatnonzero(explored.any(axis=0))
    rs = [int(c[0]) for c in extra] + ([int(rows[0]), int(rows[-1])] if rows.size else [])
    cs = [int(c[1]) for c in extra] + ([int(cols[0]), int(cols[-1])] if cols.size else [])
    r0, r1 = max(min(rs) - MARGIN_CELLS, 0), min(max(rs) + MARGIN_CELLS + 1, height)
    c0, c1 = max(min(cs) - MARGIN_CELLS, 0), min(max(cs) + MARGIN_CELLS + 1, width)
    return r0, r1, c0, c1


def _paint_categories(img: np.ndarray, cats: np.ndarray, names: tuple[str, ...]) -> None:
    """Last category wins where several overlap; goal categories come first in both our grids."""
    palette = category_palette(names)
    for k in np.flatnonzero(cats.reshape(len(names), -1).any(axis=1)):
        img[cats[k]] = palette[k + 1]


def _scale(shape: tuple[int, ...]) -> int:
    return int(min(max(TARGET_PIXELS // max(shape[0], shape[1]), 1), 8))


def _upscale(img: np.ndarray, scale: int) -> np.ndarray:
    """Nearest-neighbour upscale so the browser's texture filter does not blur cell edges."""
    if scale == 1:
        return img
    return np.repeat(np.repeat(img, scale, axis=0), scale, axis=1)

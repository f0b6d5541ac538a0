"""Map -> picture, fast (a few ms for a 720x720 map): crop to what was seen, colour, upscale.

Two sources: the agent's own SemanticMap (what it knows), or, for policies that keep no map, the
scene's ground-truth grid (marked as such). Either way the result is a ``MapView`` in that grid's cells.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from l3mvn.agent.decision import Decision
from l3mvn.agent.frontiers.types import prior_score_name
from l3mvn.core.types import Pose
from l3mvn.run.viz import (
    COLLISION_RGB,
    FREE_RGB,
    GLIMPSED_RGB,
    GUESSED_RGB,
    OBSTACLE_RGB,
    TRAJECTORY_RGB,
    UNEXPLORED_RGB,
    category_palette,
    legend,
    score_colors,
)
from l3mvn.world.scenes.scene import SceneMap
from l3mvn_studio.frontier_ranking import frontier_score
from l3mvn_studio.state import Cell, FrontierMarker, MapView

# The map's colours are the one scheme of l3mvn.run.viz, under the names the live map's callers use.
UNEXPLORED, FREE, GLIMPSED = UNEXPLORED_RGB, FREE_RGB, GLIMPSED_RGB
OBSTACLE, GUESSED, TRAJECTORY = OBSTACLE_RGB, GUESSED_RGB, TRAJECTORY_RGB
# The target's cells get a white ring inside a black one: one of them shows on any background.
TARGET_RINGS = ((255, 255, 255), (0, 0, 0))
# Ground truth drawn over the map on demand (RGBA): what the agent does not know.
GT_FLOOR = (60, 140, 255, 90)
GT_REGION = (0, 210, 90, 150)
GT_GOAL = (0, 255, 255, 255)  # not the long-term goal's magenta: the agent does not know these
MARGIN_CELLS = 24
TARGET_PIXELS = 640


def agent_map_view(decision: Decision, target: str = "") -> MapView:
    """The agent's SemanticMap, cropped to the explored bounding box plus a margin; ``target``'s
    cells ringed."""
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
    if m.inferred is not None:
        img[m.inferred[rows, cols]] = GUESSED
    if decision.collision_marks is not None and len(decision.collision_marks):
        marks = decision.collision_marks - (r0, c0)
        inside = ((marks >= 0) & (marks < (r1 - r0, c1 - c0))).all(axis=1)
        img[marks[inside, 0], marks[inside, 1]] = COLLISION_RGB
    shown = _paint_categories(img, m.categories[:, rows, cols], m.category_names, target)
    img[m.visited[rows, cols]] = TRAJECTORY
    scale = _scale(img.shape)
    half = m.size // 2
    return MapView(
        image=_upscale(img, scale),
        origin=(r0, c0),
        scale=scale,
        grid_shape=(m.size, m.size),
        world_origin=(m.start_xy[0] + (0.5 - half) * m.resolution_m, m.start_xy[1] + (0.5 - half) * m.resolution_m),
        resolution_m=m.resolution_m,
        source="agent map",
        agent_cell=tuple(m.agent_cell),
        agent_heading=m.agent_heading,
        long_term_goal=_cell(decision.long_term_goal),
        short_term_goal=_cell(decision.short_term_goal),
        goal_kind=decision.goal_kind,
        override=decision.override,
        frontiers=frontiers,
        legend=tuple(legend(shown)),
        target=target,
        fusion=decision.frontiers[0].fusion if decision.frontiers else None,
    )


def ground_truth_view(
    scene: SceneMap, trajectory: list[Pose], decision: Decision | None = None, target: str = ""
) -> MapView:
    """The scene's ground-truth floor plan with the walked path: for policies without a map."""
    h, w = scene.shape
    img = np.empty((h, w, 3), np.uint8)
    img[:] = UNEXPLORED
    img[scene.free] = FREE
    shown = _paint_categories(img, scene.objects, scene.categories, target)
    cells = np.array([scene.cell_of(p.x, p.y) for p in trajectory], dtype=np.int64).reshape(-1, 2)
    inside = (cells[:, 0] >= 0) & (cells[:, 0] < h) & (cells[:, 1] >= 0) & (cells[:, 1] < w)
    img[cells[inside, 0], cells[inside, 1]] = TRAJECTORY
    pose = trajectory[-1]
    scale = _scale(img.shape)
    return MapView(
        image=_upscale(img, scale),
        origin=(0, 0),
        scale=scale,
        grid_shape=(h, w),
        world_origin=(0.5 * scene.resolution_m, 0.5 * scene.resolution_m),
        resolution_m=scene.resolution_m,
        source="ground truth",
        agent_cell=scene.cell_of(pose.x, pose.y),
        agent_heading=pose.heading,
        goal_kind=decision.goal_kind if decision else "",
        override=decision.override if decision else None,
        legend=tuple(legend(shown)),
        target=target,
    )


@dataclass(frozen=True, eq=False)
class GroundTruthLayer:
    """The scene's truth in ``view``'s cells: RGBA ``image`` over cells ``origin .. origin + cells``."""

    image: np.ndarray
    origin: Cell
    cells: Cell
    goal_cell: Cell | None  # a cell of the nearest true goal instance, for its label


def ground_truth_layer(view: MapView, scene: SceneMap, success_region: np.ndarray, target: str) -> GroundTruthLayer:
    """The whole floor plan, the success region and the true instances of ``target``, resampled
    into the grid ``view`` is drawn in (the agent's map is offset from the scene's grid by its start)."""
    res = view.resolution_m
    h, w = scene.shape
    x0, y0 = view.world_origin
    # The scene's extent in view cells, then each view cell's centre back in scene cells.
    r0, c0 = math.floor((0.0 - y0) / res), math.floor((0.0 - x0) / res)
    r1, c1 = math.ceil((h * scene.resolution_m - y0) / res), math.ceil((w * scene.resolution_m - x0) / res)
    rows, cols = np.arange(r0, r1), np.arange(c0, c1)
    sr = np.floor((y0 + rows * res) / scene.resolution_m).astype(np.int64)
    sc = np.floor((x0 + cols * res) / scene.resolution_m).astype(np.int64)
    ok_r, ok_c = (sr >= 0) & (sr < h), (sc >= 0) & (sc < w)

    def sample(mask: np.ndarray) -> np.ndarray:
        out = np.zeros((len(rows), len(cols)), bool)
        out[np.ix_(ok_r, ok_c)] = mask[np.ix_(sr[ok_r], sc[ok_c])]
        return out

    goal = sample(scene.category_mask(target)) if target in scene.categories else np.zeros((len(rows), len(cols)), bool)
    img = np.zeros((len(rows), len(cols), 4), np.uint8)
    img[sample(scene.free)] = GT_FLOOR
    img[sample(success_region)] = GT_REGION
    img[goal] = GT_GOAL
    goal_cells = np.argwhere(goal)
    goal_cell = None
    if goal_cells.size:
        agent = np.array(view.agent_cell) - (r0, c0)
        r, c = goal_cells[int(np.argmin(((goal_cells - agent) ** 2).sum(axis=1)))]
        goal_cell = (int(r) + r0, int(c) + c0)
    return GroundTruthLayer(_upscale(img, view.scale), (r0, c0), (len(rows), len(cols)), goal_cell)


def png_bytes(rgb: np.ndarray) -> bytes:
    """Lossless PNG of an RGB picture (the page receives exactly these pixels); fast compression, as
    pictures are made per step."""
    return cv2.imencode(".png", np.ascontiguousarray(rgb[..., ::-1]), (cv2.IMWRITE_PNG_COMPRESSION, 1))[1].tobytes()


def png_rgb(png: bytes) -> np.ndarray:
    """The RGB picture back from ``png_bytes``."""
    return cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)[..., ::-1]


def frontier_colors(frontiers: tuple[FrontierMarker, ...]) -> list[tuple[int, int, int]]:
    """Each frontier's colour: its score on the scale fitted to the scores of ``frontiers``
    (``l3mvn.run.viz.fitted_scores``: min-max), so a narrow band of scores spans the whole colormap."""
    rgb = score_colors([frontier_score(f) for f in frontiers])
    return [(int(r), int(g), int(b)) for r, g, b in rgb]


def score_range(frontiers: tuple[FrontierMarker, ...]) -> tuple[float, float] | None:
    """The lowest and highest finite score of ``frontiers`` (the fitted scale's ends), or None."""
    scores = [s for s in (frontier_score(f) for f in frontiers) if math.isfinite(s)]
    return (min(scores), max(scores)) if scores else None


def _marker(f, chosen: bool) -> FrontierMarker:
    """``Decision.chosen_frontier`` is an index into ``Decision.frontiers``."""
    return FrontierMarker(
        id=int(f.id),
        cell=(int(f.center[0]), int(f.center[1])),
        size=int(f.size),
        distance_m=float(f.distance_m),
        s_cu=float(f.s_cu),
        s_llm=None if f.s_llm is None else float(f.s_llm),
        fused=None if f.fused is None else float(f.fused),
        objects=tuple(f.objects),
        queries=dict(f.queries),
        reason=f.reason,
        chosen=chosen,
        llm_scores=dict(f.llm_scores),
        expected_m=dict(f.expected_m),
        score_name=prior_score_name(f.fusion),
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


def _paint_categories(img: np.ndarray, cats: np.ndarray, names: tuple[str, ...], target: str = "") -> tuple[str, ...]:
    """Paint every category present and ring ``target``'s cells; returns the names painted (the
    legend lists only what the map shows). Last category wins where several overlap; goal
    categories come first in both our grids."""
    palette = category_palette(names)
    present = np.flatnonzero(cats.reshape(len(names), -1).any(axis=1))
    for k in present:
        img[cats[k]] = palette[k + 1]
    if target in names and cats[names.index(target)].any():
        mask = cats[names.index(target)].astype(np.uint8)
        inner = cv2.dilate(mask, np.ones((3, 3), np.uint8)).astype(bool)
        outer = cv2.dilate(mask, np.ones((5, 5), np.uint8)).astype(bool)
        img[outer & ~inner] = TARGET_RINGS[1]
        img[inner & ~mask.astype(bool)] = TARGET_RINGS[0]
    return tuple(names[k] for k in present)


def _scale(shape: tuple[int, ...]) -> int:
    return int(min(max(TARGET_PIXELS // max(shape[0], shape[1]), 1), 8))


def _upscale(img: np.ndarray, scale: int) -> np.ndarray:
    """Nearest-neighbour upscale so the browser's texture filter does not blur cell edges."""
    if scale == 1:
        return img
    return np.repeat(np.repeat(img, scale, axis=0), scale, axis=1)

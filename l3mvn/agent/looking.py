"""Where to look: the geometry behind "reaching a place is not seeing it".

The agent's exploration ends a goal only once it has faced the unknown beyond it, sends it to floor
it has only seen from afar when frontiers run out, looks at a glimpsed target from other sides, and
walks towards a target seen beyond the depth range. These are the pure map computations behind
those decisions (``MapAgent`` keeps the state); cells are (row, col) of the agent's map.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from l3mvn.agent.mapping import SemanticMap
from l3mvn.agent.planning import LocalPlanner
from l3mvn.agent.planning.goal_field import mask_cells
from l3mvn.core.types import Action, wrap_angle

Cell = tuple[int, int]


def turn_towards(sem_map: SemanticMap, cell: Cell, tolerance_rad: float) -> Action | None:
    """The turn that brings ``cell`` nearer the view's centre, or None once it lies within
    ``tolerance_rad`` of it."""
    r, c = sem_map.agent_cell
    if (r, c) == tuple(cell):
        return None
    off = wrap_angle(math.atan2(cell[0] - r, cell[1] - c) - sem_map.agent_heading)
    if abs(off) <= tolerance_rad:
        return None
    return Action.TURN_LEFT if off > 0 else Action.TURN_RIGHT


def unknown_near(sem_map: SemanticMap, cell: Cell, radius_cells: float) -> Cell | None:
    """Centroid of the unexplored cells within ``radius_cells`` of ``cell``, or None."""
    r, c, k = int(cell[0]), int(cell[1]), int(math.ceil(radius_cells))
    r0, c0 = max(r - k, 0), max(c - k, 0)
    win = ~sem_map.explored[r0 : r + k + 1, c0 : c + k + 1]
    rows, cols = np.nonzero(win)
    near = (rows + r0 - r) ** 2 + (cols + c0 - c) ** 2 <= radius_cells**2
    if not near.any():
        return None
    return int(round(rows[near].mean())) + r0, int(round(cols[near].mean())) + c0


def pick_viewpoint(
    sem_map: SemanticMap,
    target: np.ndarray,
    planner: LocalPlanner,
    views: list[float],
    min_cells: float,
    max_cells: float,
) -> tuple[Cell, float] | None:
    """A reachable explored cell ``min_cells``-``max_cells`` from the glimpsed ``target``, on the
    bearing (from the target) most unlike ``views`` and the agent's own, nearest first among equals:
    a slit or a depth gap rarely repeats from there. Returns it with the agent's bearing, or None."""
    centre = np.array(mask_centre(target))
    d = distance_to(target, max_cells + 1)
    ring = (d >= min_cells) & (d <= max_cells) & sem_map.explored
    if not ring.any():
        return None
    field = planner.distance_from_agent(sem_map.obstacle, sem_map.agent_cell, targets=ring).full()
    cells = np.argwhere(ring & np.isfinite(field))
    if len(cells) == 0:
        return None
    here = math.atan2(*(np.array(sem_map.agent_cell) - centre))  # as atan2(dr, dc), like the bearings
    bearings = np.arctan2(cells[:, 0] - centre[0], cells[:, 1] - centre[1])
    seen = np.array([*views, here])
    gap = np.abs(wrap_angle(bearings[:, None] - seen[None, :])).min(axis=1)
    best = np.lexsort((field[cells[:, 0], cells[:, 1]], -np.round(gap, 1)))[0]
    return (int(cells[best, 0]), int(cells[best, 1])), here


def look_goal(
    sem_map: SemanticMap, planner: LocalPlanner, done: list[Cell], done_radius_cells: float, min_area_m2: float
) -> Cell | None:
    """The nearest reachable cell of the areas explored but not looked at (each at least
    ``min_area_m2``, away from the ``done`` goals), or None."""
    glimpsed = sem_map.explored & ~sem_map.looked & ~sem_map.obstacle
    rows, cols = np.flatnonzero(glimpsed.any(axis=1)), np.flatnonzero(glimpsed.any(axis=0))
    if len(rows) == 0:
        return None
    r0, r1, c0, c1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
    _, labels, stats, _ = cv2.connectedComponentsWithStats(glimpsed[r0:r1, c0:c1].astype(np.uint8), connectivity=8)
    big = np.flatnonzero(stats[:, cv2.CC_STAT_AREA] * sem_map.resolution_m**2 >= min_area_m2)
    big = big[big > 0]
    if len(big) == 0:
        return None
    areas = np.zeros_like(glimpsed)
    areas[r0:r1, c0:c1] = np.isin(labels, big)
    if done:
        mask = np.zeros(areas.shape, np.uint8)
        for br, bc in done:
            cv2.circle(mask, (int(bc), int(br)), int(done_radius_cells), 1, -1)
        areas &= mask == 0
        if not areas.any():
            return None
    field = planner.distance_from_agent(sem_map.obstacle, sem_map.agent_cell, targets=areas).full()
    field = np.where(areas, field, np.inf)
    best = int(np.argmin(field))
    if not np.isfinite(field.flat[best]):
        return None
    r, c = np.unravel_index(best, field.shape)
    return int(r), int(c)


def far_sighting(
    sem_map: SemanticMap,
    depth: np.ndarray,
    semantic: np.ndarray,
    goal_id: int,
    focal_px: float,
    reach_cells: float,
    fractions: tuple[float, float],
    done: list[Cell],
    done_radius_cells: float,
) -> Cell | None:
    """The map cell ``reach_cells`` out along the bearing of ``goal_id`` pixels without depth (seen
    beyond the depth range), when they fill a share of the frame within ``fractions`` (more is too
    near to have depth) and do not point within ``done_radius_cells`` of a ``done`` goal; else None."""
    far = (semantic == goal_id) & (depth <= 0)
    share = np.count_nonzero(far) / far.size
    if not fractions[0] <= share <= fractions[1]:
        return None
    width = far.shape[1]
    column = float(np.nonzero(far)[1].mean()) + 0.5
    bearing = sem_map.agent_heading - math.atan((column - width / 2.0) / focal_px)  # right is clockwise
    r = int(round(sem_map.agent_cell[0] + reach_cells * math.sin(bearing)))
    c = int(round(sem_map.agent_cell[1] + reach_cells * math.cos(bearing)))
    r, c = min(max(r, 0), sem_map.size - 1), min(max(c, 0), sem_map.size - 1)
    if any(math.hypot(r - br, c - bc) <= done_radius_cells for br, bc in done):
        return None
    return r, c


def distance_to(mask: np.ndarray, limit_cells: float) -> np.ndarray:
    """Straight-line distance (cells) to the nearest cell of ``mask``, inf beyond ``limit_cells``."""
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    pad = int(math.ceil(limit_cells)) + 1
    r0, c0 = max(rows[0] - pad, 0), max(cols[0] - pad, 0)
    r1, c1 = min(rows[-1] + pad + 1, mask.shape[0]), min(cols[-1] + pad + 1, mask.shape[1])
    out = np.full(mask.shape, np.inf, dtype=np.float32)
    out[r0:r1, c0:c1] = cv2.distanceTransform((~mask[r0:r1, c0:c1]).view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    return out


def mask_centre(mask: np.ndarray) -> Cell:
    rows, cols = mask_cells(mask)  # within its bounding box: a whole-map nonzero costs ~0.2 ms
    return int(np.median(rows)), int(np.median(cols))

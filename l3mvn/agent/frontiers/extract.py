"""Frontier extraction and cost-utility scoring on plain map arrays (paper, after PONI).

1. Explored edge: the outer contour of the explored map (``cv2.findContours``). ``edge="largest"``
   (the paper) keeps the largest blob only. It loses the frontiers of disconnected explored blobs (far
   sparse depth, a room glimpsed through a gap): usually noise, or space the agent reaches through the
   main blob's own frontier anyway; ``edge="all"`` keeps them and lets the geodesic filter drop the
   unreachable ones. Holes inside the explored blob are not frontiers: they are mostly depth gaps, not
   unexplored rooms. Cells on the outermost frame of the array are not frontiers either: the map
   cannot record what lies beyond it (the authors' code clears the frame too).
2. Frontier = explored edge minus obstacles dilated by a square of ``obstacle_dilation_cells``.
3. 8-connected clusters; drop those under ``min_cluster_cells``, unreachable, nearer than
   ``min_distance_m`` or farther than ``max_distance_m``. The far limit only applies while some
   frontier lies within it: otherwise an agent in a big open area would have nowhere to go, so every
   far frontier is kept. Every cluster counts, including the first (the code skipped it).
4. Candidate = the cluster cell nearest the cluster's centroid (the centroid of a curved frontier can
   lie off the frontier, in a wall or in unknown space; the code used it anyway).
5. S_CU = U - lambda * C (Julia et al. 2012), U = cluster size in cells, C = geodesic distance in
   metres, or the code's U = size + 8 within 3 m with no cost term; clusters sorted by S_CU, the best
   ``top_k`` kept, S_CU min-max normalised to [0, 1] over them.

Distances: frontier cells border unknown space, so the planner's field may mark them unreachable
(inflated obstacles, unknown treated as blocked). A cell's distance is therefore the smallest finite
distance in its 3x3 neighbourhood (NaN counts as unreachable), and a cluster's distance is its
centre's, or the smallest over the whole cluster when the centre has no reachable neighbour. A
cluster with no reachable cell next to it is dropped.

Only the bounding box of explored space (plus a margin) is processed, so the cost follows the
explored area, not the map size.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import cast

import cv2
import numpy as np
import numpy.typing as npt

from l3mvn.agent.frontiers.types import Frontier
from l3mvn.core.config import FrontierConfig
from l3mvn.core.errors import L3MVNError
from l3mvn.core.types import wrap_angle

_NEIGHBOURS = np.array([(dr, dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1)], dtype=np.int64)


def extract_frontiers(
    explored: np.ndarray,
    obstacle: np.ndarray,
    agent_cell: tuple[int, int],
    distance_m: np.ndarray,
    category_maps: np.ndarray,
    category_names: tuple[str, ...],
    cfg: FrontierConfig = FrontierConfig(),
    *,
    resolution_m: float,
    blocked: np.ndarray | None = None,
    blocked_radius_cells: float | np.ndarray = 0.0,
    blocked_frontiers: Sequence[np.ndarray | None] | None = None,
    blocked_gap_cells: float = 0.0,
    agent_heading: float | None = None,
) -> list[Frontier]:
    """Frontiers of an (H, W) map, best S_CU first, ids 0..n-1 in that order.

    explored, obstacle: bool (H, W); agent_cell: (row, col); distance_m: float (H, W) geodesic
    distance from the agent, inf where unreachable; category_maps: bool (K, H, W) named by
    ``category_names``; resolution_m: the map's cell size (the objects window is in metres).
    blocked: (N, 2) cells the caller is done with (reached or unreachable goals); a cluster whose
    candidate lies within ``blocked_radius_cells`` of one (a radius, or one per blocked cell) is
    dropped before the far limit, so frontiers beyond it stay eligible once the near ones are used up.
    blocked_frontiers: per blocked cell, the (M, 2) cells of the frontier it was (None: not a frontier);
    such a cell drops only the clusters within its radius that come within ``blocked_gap_cells`` of
    those cells: the same frontier, as much of it as is left, and not other unknown space beside it.
    agent_heading (radians): with ``cfg.turn_cost_m_per_rad`` > 0, a frontier's cost C is its
    geodesic distance plus the turning needed to face it, so a frontier straight ahead beats an
    equally near one behind (turns spend the step budget as forward moves do).
    """
    _validate(explored, obstacle, agent_cell, distance_m, category_maps, category_names, cfg)
    radius = np.asarray(blocked_radius_cells, dtype=np.float64)
    if (radius < 0).any():
        raise L3MVNError(f"blocked_radius_cells must be >= 0, got {blocked_radius_cells}")
    if blocked is not None:
        blocked = np.asarray(blocked)
        if blocked.size == 0:
            blocked = None
        elif blocked.ndim != 2 or blocked.shape[1] != 2:
            raise L3MVNError(f"blocked must be an (N, 2) array of (row, col) cells, got shape {blocked.shape}")
    box = _crop_box(explored, margin=max(1, cfg.obstacle_dilation_cells))
    if box is None:
        return []
    r0, r1, c0, c1 = box
    frontier = _explored_edge(explored[r0:r1, c0:c1], cfg.edge)
    if cfg.obstacle_dilation_cells > 0:
        size = 2 * cfg.obstacle_dilation_cells + 1
        kernel = np.ones((size, size), np.uint8)
        frontier &= cv2.dilate(obstacle[r0:r1, c0:c1].view(np.uint8), kernel) == 0
    else:
        frontier &= ~obstacle[r0:r1, c0:c1]
    height, width = explored.shape
    _clear_map_frame(frontier, box, height, width)

    cells, bounds = _clusters(frontier, cfg.min_cluster_cells, offset=(r0, c0))
    if len(bounds) < 2:
        return []
    sizes = np.diff(bounds).astype(np.float64)
    centers = _centers(cells, bounds)
    distances = _cluster_distances(cells, bounds, centers, distance_m)
    if blocked is not None:
        gap = np.hypot(centers[:, None, 0] - blocked[None, :, 0], centers[:, None, 1] - blocked[None, :, 1])
        if radius.ndim and radius.shape != (len(blocked),):
            raise L3MVNError(
                f"blocked_radius_cells: one radius per blocked cell, got {radius.shape[0]} for {len(blocked)}"
            )
        near = gap <= radius
        if blocked_frontiers is not None:
            _same_frontier_only(near, cells, bounds, blocked_frontiers, blocked_gap_cells)
        distances = np.where(near.any(axis=1), np.inf, distances)
    keep = _distance_filter(distances, cfg)
    if keep.size == 0:
        return []
    costs = distances + _turn_costs(centers, agent_cell, agent_heading, cfg)
    utility, score = _cost_utility(sizes[keep], costs[keep], cfg)
    # Best score first; ties go to the cheaper cluster, then to raster order (the label order).
    ranked = np.lexsort((keep, costs[keep], -score))[: cfg.top_k]
    order = keep[ranked]
    s_cu = _normalise(score[ranked])
    objects = _window_objects(centers[order], category_maps, category_names, cfg.window_cells(resolution_m))
    return [
        Frontier(
            id=rank,
            cells=cells[bounds[i] : bounds[i + 1]],
            center=(int(centers[i, 0]), int(centers[i, 1])),
            size=int(sizes[i]),
            distance_m=float(distances[i]),
            utility=float(utility[ranked[rank]]),
            cost=float(costs[i]),
            s_cu=float(s_cu[rank]),
            objects=objects[rank],
        )
        for rank, i in enumerate(order)
    ]


def _same_frontier_only(
    near: np.ndarray,
    cells: np.ndarray,
    bounds: np.ndarray,
    blocked_frontiers: Sequence[np.ndarray | None],
    gap_cells: float,
) -> None:
    """Clear ``near[i, j]`` (cluster i lies within blocked cell j's radius) where j was a frontier
    and no cell of cluster i comes within ``gap_cells`` of that frontier's cells."""
    if len(blocked_frontiers) != near.shape[1]:
        raise L3MVNError(
            f"blocked_frontiers: one entry per blocked cell, got {len(blocked_frontiers)} for {near.shape[1]}"
        )
    for j, own in enumerate(blocked_frontiers):
        if own is None or len(own) == 0 or not near[:, j].any():
            continue
        own = np.asarray(own, dtype=np.float64).reshape(-1, 2)
        for i in np.flatnonzero(near[:, j]):
            mine = cells[bounds[i] : bounds[i + 1]].astype(np.float64)
            d2 = ((mine[:, None, :] - own[None, :, :]) ** 2).sum(axis=2)
            near[i, j] = float(d2.min()) <= gap_cells * gap_cells


def _validate(
    explored: np.ndarray,
    obstacle: np.ndarray,
    agent_cell: tuple[int, int],
    distance_m: np.ndarray,
    category_maps: np.ndarray,
    category_names: tuple[str, ...],
    cfg: FrontierConfig,
) -> None:
    if not isinstance(cfg, FrontierConfig):
        raise L3MVNError(f"cfg must be a FrontierConfig, got {type(cfg).__name__}")
    for name, arr in (("explored", explored), ("obstacle", obstacle)):
        if not isinstance(arr, np.ndarray) or arr.ndim != 2 or arr.dtype != bool:
            raise L3MVNError(f"{name} must be a 2-D bool array, got {_describe(arr)}")
    shape = explored.shape
    if obstacle.shape != shape:
        raise L3MVNError(f"obstacle map {obstacle.shape} does not match explored map {shape}")
    if (
        not isinstance(distance_m, np.ndarray)
        or distance_m.shape != shape
        or not np.issubdtype(distance_m.dtype, np.floating)
    ):
        raise L3MVNError(f"distance_m must be a float array of shape {shape}, got {_describe(distance_m)}")
    if (
        not isinstance(category_maps, np.ndarray)
        or category_maps.ndim != 3
        or category_maps.shape[1:] != shape
        or category_maps.dtype != bool
    ):
        raise L3MVNError(
            f"category_maps must be a bool (K, {shape[0]}, {shape[1]}) array, got {_describe(category_maps)}"
        )
    if len(category_names) != category_maps.shape[0]:
        raise L3MVNError(f"{len(category_names)} category names for {category_maps.shape[0]} category maps")
    row, col = agent_cell
    if not (0 <= row < shape[0] and 0 <= col < shape[1]):
        raise L3MVNError(f"agent cell {tuple(agent_cell)} lies outside the {shape[0]}x{shape[1]} map")
    at_agent = float(distance_m[row, col])
    if np.isfinite(at_agent) and at_agent > cfg.min_distance_m:
        raise L3MVNError(
            f"distance_m is {at_agent:.2f} m at the agent cell {tuple(agent_cell)}; it must be the "
            "geodesic distance from the agent (0 there)"
        )


def _describe(arr: object) -> str:
    if isinstance(arr, np.ndarray):
        return f"{arr.dtype} array of shape {arr.shape}"
    return type(arr).__name__


def _crop_box(explored: np.ndarray, margin: int) -> tuple[int, int, int, int] | None:
    """Bounding box of explored space grown by ``margin`` cells, clipped to the map."""
    rows = np.flatnonzero(explored.any(axis=1))
    if rows.size == 0:
        return None
    cols = np.flatnonzero(explored[rows[0] : rows[-1] + 1].any(axis=0))
    height, width = explored.shape
    return (
        max(0, rows[0] - margin),
        min(height, rows[-1] + 1 + margin),
        max(0, cols[0] - margin),
        min(width, cols[-1] + 1 + margin),
    )


def _explored_edge(explored: np.ndarray, mode: str) -> np.ndarray:
    """Cells on the outer contour(s) of the explored blobs."""
    padded = cv2.copyMakeBorder(explored.view(np.uint8), 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=0)
    contours, _ = cv2.findContours(padded, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    edge = np.zeros(explored.shape, dtype=bool)
    if not contours:
        return edge
    if mode == "largest":
        contours = [max(contours, key=cv2.contourArea)]
    points = np.concatenate([c.reshape(-1, 2) for c in contours])
    edge[points[:, 1] - 1, points[:, 0] - 1] = True
    return edge


def _clear_map_frame(frontier: np.ndarray, box: tuple[int, int, int, int], height: int, width: int) -> None:
    r0, r1, c0, c1 = box
    if r0 == 0:
        frontier[0, :] = False
    if r1 == height:
        frontier[-1, :] = False
    if c0 == 0:
        frontier[:, 0] = False
    if c1 == width:
        frontier[:, -1] = False


def _clusters(frontier: np.ndarray, min_cells: int, offset: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """8-connected clusters of at least ``min_cells`` cells, in label (raster) order.

    Returns (N, 2) int32 map cells grouped by cluster and the (n + 1,) bounds of each group.
    """
    count, labels = cv2.connectedComponents(frontier.view(np.uint8), connectivity=8, ltype=cv2.CV_32S)
    rows, cols = _nonzero(frontier)
    lab = labels[rows, cols]
    kept = np.bincount(lab, minlength=count) >= min_cells
    kept[0] = False
    mask = kept[lab]
    order = np.argsort(lab[mask], kind="stable")
    cells = np.stack((rows[mask][order] + offset[0], cols[mask][order] + offset[1]), axis=1).astype(np.int32)
    sizes = np.bincount(lab[mask], minlength=count)[kept]
    return cells, np.concatenate(([0], np.cumsum(sizes)))


def _nonzero(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.nonzero`` of a 2-D mask via ``flatnonzero``: an order of magnitude faster, on a hot path."""
    rows, cols = np.divmod(np.flatnonzero(mask), mask.shape[1])
    return rows, cols


def _centers(cells: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """Per cluster, the cell nearest its centroid (first in raster order on ties)."""
    sizes = np.diff(bounds)
    member = np.repeat(np.arange(len(sizes)), sizes)
    centroid = np.add.reduceat(cells.astype(np.float64), bounds[:-1], axis=0) / sizes[:, None]
    offsets = cells - centroid[member]
    d2 = (offsets * offsets).sum(axis=1)
    nearest = np.flatnonzero(d2 == np.minimum.reduceat(d2, bounds[:-1])[member])
    _, first = np.unique(member[nearest], return_index=True)
    return cells[nearest[first]].astype(np.int64)


def _cluster_distances(
    cells: np.ndarray, bounds: np.ndarray, centers: np.ndarray, distance_m: np.ndarray
) -> np.ndarray:
    """Geodesic distance of each cluster (see the module docstring for unreachable cells)."""
    near = _near_distance(np.concatenate((centers, cells)), distance_m)
    out = near[: len(centers)]
    fallback = np.minimum.reduceat(near[len(centers) :], bounds[:-1])
    return np.where(np.isfinite(out), out, fallback)


def _near_distance(cells: np.ndarray, distance_m: np.ndarray) -> npt.NDArray[np.float64]:
    """Smallest finite distance in each cell's 3x3 neighbourhood (inf if none; NaN is unreachable)."""
    height, width = distance_m.shape
    rows = np.clip(cells[:, 0, None] + _NEIGHBOURS[None, :, 0], 0, height - 1)
    cols = np.clip(cells[:, 1, None] + _NEIGHBOURS[None, :, 1], 0, width - 1)
    values = distance_m[rows, cols].astype(np.float64)
    values[np.isnan(values)] = np.inf
    nearest: npt.NDArray[np.float64] = values.min(axis=1)  # numpy types the reduction as Any
    return nearest


def _distance_filter(distances: np.ndarray, cfg: FrontierConfig) -> np.ndarray:
    """Indices kept: reachable, not too near, and within the far limit unless none is."""
    usable = np.isfinite(distances) & (distances >= cfg.min_distance_m)
    within = usable & (distances <= cfg.max_distance_m)
    return np.flatnonzero(within if within.any() else usable)


def _turn_costs(
    centers: npt.NDArray[np.int64], agent_cell: tuple[int, int], heading: float | None, cfg: FrontierConfig
) -> npt.NDArray[np.float64]:
    """Metres charged for turning toward each centre (0 without a heading or a turn cost)."""
    if heading is None or cfg.turn_cost_m_per_rad == 0.0:
        return np.zeros(len(centers))
    bearing = np.arctan2(centers[:, 0] - agent_cell[0], centers[:, 1] - agent_cell[1])
    error = np.abs(wrap_angle(bearing - heading))
    costs: npt.NDArray[np.float64] = cfg.turn_cost_m_per_rad * error  # numpy types the product as Any
    return costs


def _cost_utility(sizes: np.ndarray, distances: np.ndarray, cfg: FrontierConfig) -> tuple[np.ndarray, np.ndarray]:
    """(utility, S_CU) per cluster for the configured mode."""
    if cfg.utility == "official_code":
        utility = sizes + np.where(distances < cfg.near_bonus_m, cfg.near_bonus, 0.0)
        return utility, utility
    return sizes, sizes - cfg.cu_lambda * distances


def _normalise(score: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Min-max to [0, 1]; all-equal scores (one frontier included) all get 1."""
    span = score.max() - score.min()
    if span <= 0:
        return np.ones_like(score)
    normalised: npt.NDArray[np.float64] = (score - score.min()) / span  # numpy types the division as Any
    return normalised


def _window_objects(
    centers: np.ndarray, category_maps: np.ndarray, names: tuple[str, ...], half: int
) -> list[tuple[str, ...]]:
    """Sorted distinct names of the categories with a cell within ``half`` cells (Chebyshev) of each
    centre, i.e. inside the square window around it."""
    if category_maps.shape[0] == 0:
        return [() for _ in centers]
    height, width = category_maps.shape[1:]
    r0 = max(0, int(centers[:, 0].min()) - half)
    r1 = min(height, int(centers[:, 0].max()) + half + 1)
    c0 = max(0, int(centers[:, 1].min()) - half)
    c1 = min(width, int(centers[:, 1].max()) + half + 1)
    window = category_maps[:, r0:r1, c0:c1]
    # numpy types a reduction over an axis as maybe a scalar; over axis 0 of a 3-D array it is 2-D.
    rows, cols = _nonzero(cast(npt.NDArray[np.bool_], window.any(axis=0)))
    if rows.size == 0:
        return [() for _ in centers]
    member = window[:, rows, cols]
    inside = (np.abs(rows[None, :] + r0 - centers[:, :1]) <= half) & (
        np.abs(cols[None, :] + c0 - centers[:, 1:]) <= half
    )
    # A loop over categories, not a matmul: BLAS threads stall when the CPU is shared.
    hits = np.zeros((len(centers), len(names)), dtype=bool)
    for k in np.flatnonzero(member.any(axis=1)):
        hits[:, k] = inside[:, member[k]].any(axis=1)
    return [tuple(sorted({names[k] for k in np.flatnonzero(row)})) for row in hits]

"""Local policy: Fast Marching toward a goal on the agent's own map, one discrete action per step.

Map frame: (row, col) cells; world ``x = col * res``, ``y = row * res``; heading counter-clockwise
from ``+x``, so heading ``h`` points along ``(drow, dcol) = (sin h, cos h)`` and ``TURN_LEFT`` adds to
it. Unknown cells count as free (optimistic planning, as SemExp); obstacles are dilated by the
agent radius; cells where a forward step failed are blocked in a collision map.

Collision marks and the stuck signal live in ``collisions.py``.

Speed: a fresh FMM costs 5-40 ms on a house-sized window, so the field to the goal is kept across
steps while it provably still gives the agent's shortest path and short-term goal: same goal, no
cell freed, and no newly blocked cell on either path (see ``_reusable``); about one step in ten
replans while a house is being mapped. The window is only as large as the agent, the goal and a
margin; a path that leaves it is longer than the reflection bound ``_exit_bound_m``, and the window
grows until the agent's distance is safely below it (or holds every obstacle: then it is exact).
The planner never stops by itself: whether the goal is the target object is the agent's call.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from l3mvn.config import PlannerConfig
from l3mvn.errors import L3MVNError
from l3mvn.planning.collisions import CollisionTracker
from l3mvn.planning.fmm import GeodesicField, Window, distance_field
from l3mvn.types import Action

# FMM is a first/second-order scheme: its distances differ from the true geodesic by a few
# percent, so every comparison between an FMM value and a straight-line bound gets this slack.
_SLACK_M = 0.10
_SLACK_REL = 0.03
# Directions of the rays that look for the short-term goal (5 degrees apart), sampled every half
# cell so a ray cannot slip between two diagonal blocked cells.
_RAY_DIRECTIONS = 72
_RAY_STEP_CELLS = 0.5
# Ties between equal distances (every cell inside the dilated goal reads 0; reachable cells
# equally near an unreachable goal) go to the cell nearest the goal, resp. the agent; the weight is
# far below one cell so it never overrides a real difference in distance.
_TIE_WEIGHT = 1e-3


@dataclass(frozen=True)
class Plan:
    """One step of the local policy.

    distance_to_goal_m: geodesic estimate to the goal: FMM distance to the goal dilated by
    ``goal_dilation_m`` plus that dilation, or the straight-line distance once inside it; ``inf``
    when unreachable (then ``short_term_goal`` leads to the reachable cell nearest the goal).
    field: the distance field the step followed (to the goal, or to that fallback cell).
    replanned: whether this step ran FMM (False when the previous field was still valid).
    """

    action: Action
    short_term_goal: tuple[int, int]
    distance_to_goal_m: float
    reachable: bool
    reached: bool
    collided: bool
    stuck: bool
    replanned: bool
    field: GeodesicField


@dataclass
class _GoalField:
    goal_key: tuple[bytes, bytes]
    traversible: np.ndarray
    sources: np.ndarray
    field: GeodesicField


class LocalPlanner:
    """Fast Marching local policy with a collision map and stuck detection; one per episode.

    Call ``plan`` once per step (collisions and stuck detection count calls as steps) and
    ``reset`` between episodes. ``fmm_runs`` counts the marches so far (for speed reports).
    """

    def __init__(self, cfg: PlannerConfig, resolution_m: float) -> None:
        """``resolution_m``: the cell size of the maps it will plan on (the agent's map)."""
        if not (math.isfinite(resolution_m) and resolution_m > 0):
            raise L3MVNError(f"resolution_m must be positive, got {resolution_m}")
        self.cfg, self.resolution_m = cfg, resolution_m
        self.goal_dilation_cells = int(round(cfg.goal_dilation_m / resolution_m))
        self.lookahead_cells = max(1, int(round(cfg.stg_lookahead_m / resolution_m)))
        self._obstacle_kernel = _disk(cfg.obstacle_dilation_cells)
        self._goal_kernels = {self.goal_dilation_cells: _disk(self.goal_dilation_cells)}
        escape = cfg.obstacle_dilation_cells + 1
        self._escape_offsets = np.argwhere(_disk(escape) > 0) - escape
        self._ray_rows, self._ray_cols = _rays(self.lookahead_cells)
        self.reset()

    def reset(self) -> None:
        """Forget the collision map, the cached field and the stuck history (new episode)."""
        self._collisions = CollisionTracker(self.cfg, self.resolution_m)
        self._cache: _GoalField | None = None
        self.fmm_runs = 0

    def clear_collisions(self) -> None:
        """Forget the collision marks and the stuck history (an agent escaping a trap it marked)."""
        self._collisions.clear()
        self._cache = None

    @property
    def collision_map(self) -> np.ndarray | None:
        """(M, M) bool cells blocked by failed forward steps (None before the first plan)."""
        return self._collisions.map

    def plan(
        self,
        obstacle: np.ndarray,
        agent_cell: tuple[int, int],
        heading: float,
        goal: np.ndarray | tuple[int, int],
        *,
        last_move_m: float | None = None,
        goal_reached_radius_m: float = 0.5,
        goal_dilation_m: float | None = None,
    ) -> Plan:
        """Choose the next action toward ``goal``.

        obstacle: (M, M) bool obstacle map (undilated). agent_cell: (row, col). heading: radians.
        goal: a (row, col) cell, an (N, 2) int array of cells, or an (M, M) bool mask.
        last_move_m: distance actually moved by the previous action if it was MOVE_FORWARD, else
        None; below ``collision_threshold_m`` it counts as a collision. reached: the goal
        distance estimate is within ``goal_reached_radius_m`` and the goal is reachable.
        goal_dilation_m: overrides the config's for this call. The 0.5 m disk suits an object
        (approached from any free side), but it reaches through walls: an exploration goal needs
        a small one, or a frontier behind a wall reads as reached from the wrong room.
        """
        obstacle = self._check_map(obstacle)
        agent = _check_cell(agent_cell, obstacle.shape)
        if not math.isfinite(heading):
            raise L3MVNError(f"heading must be finite radians, got {heading}")
        if goal_reached_radius_m < 0:
            raise L3MVNError(f"goal_reached_radius_m must be >= 0, got {goal_reached_radius_m}")
        goal_rows, goal_cols = _goal_cells(goal, obstacle.shape)
        dilation = self._dilation_cells(goal_dilation_m)
        collided = self._collisions.record(agent, heading, last_move_m)

        key = (goal_rows.tobytes(), goal_cols.tobytes(), dilation)
        nearest_goal = _nearest(agent, goal_rows, goal_cols)
        reused = self._reusable(obstacle, agent, key, nearest_goal)
        replanned = reused is None
        if reused is not None:
            field, trav, stg = reused
        else:
            escape = not self._base_free(obstacle, agent)
            field, trav, sources = self._goal_field(
                obstacle, agent, goal_rows, goal_cols, nearest_goal, escape, dilation
            )
            if not escape:
                self._cache = _GoalField(key, trav, sources, field)
            stg = None
        d_agent = float(field.at(*agent))
        reachable = math.isfinite(d_agent)
        if not reachable:
            distance = math.inf
            field, trav = self._fallback_field(obstacle, agent, goal_rows, goal_cols)
        elif d_agent > 0:
            distance = d_agent + dilation * self.resolution_m
        else:
            distance = math.dist(nearest_goal, agent) * self.resolution_m
        if stg is None:
            stg = self._short_term_goal(field, trav, agent, nearest_goal)
        action = self._action(agent, heading, stg if stg != agent else nearest_goal)
        return Plan(
            action=action,
            short_term_goal=stg,
            distance_to_goal_m=distance,
            reachable=reachable,
            reached=reachable and distance <= goal_reached_radius_m,
            collided=collided,
            stuck=self._collisions.stuck(agent),
            replanned=replanned,
            field=field,
        )

    def distance_from_agent(
        self,
        obstacle: np.ndarray,
        agent_cell: tuple[int, int],
        *,
        targets: np.ndarray | None = None,
        max_distance_m: float | None = None,
    ) -> GeodesicField:
        """Geodesic distance from the agent over the planner's traversible map (frontier costs).

        With ``max_distance_m`` only cells within that distance are computed (a path that long
        stays inside a square of that half-size, which is all that is marched; ~3 ms). Without
        it the window covers the obstacles, the collision marks and ``targets`` (an (N, 2) int
        array of cells, or a bool (M, M) mask such as the explored map), and the free space
        beyond them cannot shorten a path, so every cell of the window is exact (~20-40 ms for
        a house). Cells outside the window read ``inf``.
        """
        obstacle = self._check_map(obstacle)
        agent = _check_cell(agent_cell, obstacle.shape)
        rows, cols = np.array([agent[0]]), np.array([agent[1]])
        if max_distance_m is not None:
            if max_distance_m <= 0:
                raise L3MVNError(f"max_distance_m must be positive or None, got {max_distance_m}")
            margin = int(math.ceil(max_distance_m / self.resolution_m)) + 1
            window = Window.bounding(rows, cols, margin, obstacle.shape)
        else:
            if targets is not None:
                target_rows, target_cols = _target_extent(targets, obstacle.shape)
                rows, cols = np.append(rows, target_rows), np.append(cols, target_cols)
            window = self._whole_window(obstacle, rows, cols)
        trav = self._with_escape(self._traversible(obstacle, window), obstacle, window, agent)
        local = np.array([[agent[0] - window.r0, agent[1] - window.c0]])
        values = distance_field(trav, local, resolution_m=self.resolution_m, limit_m=max_distance_m)
        self.fmm_runs += 1
        limit = math.inf if max_distance_m is None else float(max_distance_m)
        return GeodesicField(values, window, obstacle.shape, limit)

    def _dilation_cells(self, goal_dilation_m: float | None) -> int:
        if goal_dilation_m is None:
            return self.goal_dilation_cells
        if not (math.isfinite(goal_dilation_m) and 0 <= goal_dilation_m <= self.cfg.goal_dilation_m):
            raise L3MVNError(
                f"goal_dilation_m must lie in [0, {self.cfg.goal_dilation_m}] (the config's), got {goal_dilation_m}"
            )
        return int(round(goal_dilation_m / self.resolution_m))

    # -- map preparation ------------------------------------------------------------------------

    def _check_map(self, obstacle: np.ndarray) -> np.ndarray:
        obstacle = np.asarray(obstacle)
        if obstacle.ndim != 2 or obstacle.dtype != bool:
            raise L3MVNError(f"obstacle map must be a 2D bool array, got {obstacle.dtype} {obstacle.shape}")
        self._collisions.start(obstacle.shape)
        return obstacle

    def _traversible(self, obstacle: np.ndarray, window: Window) -> np.ndarray:
        """Not (dilated obstacle) and not collision, over ``window`` (obstacles just outside count)."""
        pad = window.grown(self.cfg.obstacle_dilation_cells, obstacle.shape)
        crop = obstacle[pad.slices].view(np.uint8)
        dilated = cv2.dilate(crop, self._obstacle_kernel) if self._obstacle_kernel.size > 1 else crop
        inner = dilated[window.r0 - pad.r0 : window.r1 - pad.r0, window.c0 - pad.c0 : window.c1 - pad.c0]
        return (inner == 0) & ~self._collisions.map[window.slices]

    def _with_escape(
        self, trav: np.ndarray, obstacle: np.ndarray, window: Window, agent: tuple[int, int]
    ) -> np.ndarray:
        """Open the undilated free cells around the agent, so dilation cannot trap it in place."""
        rows = self._escape_offsets[:, 0] + agent[0]
        cols = self._escape_offsets[:, 1] + agent[1]
        ok = window.inside(rows, cols)
        rows, cols = rows[ok], cols[ok]
        free = ~obstacle[rows, cols] & ~self._collisions.map[rows, cols]
        out = trav.copy()
        out[rows[free] - window.r0, cols[free] - window.c0] = True
        out[agent[0] - window.r0, agent[1] - window.c0] = True
        return out

    def _base_free(self, obstacle: np.ndarray, agent: tuple[int, int]) -> bool:
        return bool(self._traversible(obstacle, Window(agent[0], agent[1], agent[0] + 1, agent[1] + 1))[0, 0])

    def _exact(self, window: Window, obstacle: np.ndarray) -> bool:
        """Whether every obstacle (dilated) and collision mark lies strictly inside the window.

        Then the outside is free, and clamping any path to the window never lengthens it.
        """
        grow = self.cfg.obstacle_dilation_cells + 1
        for extent in (_extent(obstacle), _extent(self._collisions.map)):
            if extent is None:
                continue
            rmin, rmax, cmin, cmax = extent
            bound = Window(rmin, cmin, rmax + 1, cmax + 1).grown(grow, obstacle.shape)
            if not window.contains(bound):
                return False
        return True

    # -- distance fields ------------------------------------------------------------------------

    def _goal_field(
        self,
        obstacle: np.ndarray,
        agent: tuple[int, int],
        goal_rows: np.ndarray,
        goal_cols: np.ndarray,
        nearest_goal: tuple[int, int],
        escape: bool,
        dilation: int,
    ) -> tuple[GeodesicField, np.ndarray, np.ndarray]:
        """FMM to the dilated goal on the smallest window whose answer around the agent is exact.

        A window is exact around the agent once its exit bound exceeds the agent's distance plus
        the lookahead; the first margin is the one a straight path needs and a failure widens it
        to what the found distance needs. A window holding every obstacle is exact everywhere: it
        is used as soon as it is the smaller one, or when the agent was not reached at all (the
        goal may be unreachable, which only that window can tell).
        """
        cfg = self.cfg
        res = self.resolution_m
        rows = np.append(goal_rows, agent[0])
        cols = np.append(goal_cols, agent[1])
        lookahead = self.lookahead_cells * res
        straight = math.dist(agent, nearest_goal) * res
        margin = max(cfg.window_margin_m, _margin_for(straight + lookahead + _slack(straight), straight))
        pad = dilation + 1
        kernel = self._goal_kernels.setdefault(dilation, _disk(dilation))
        whole = self._whole_window(obstacle, rows, cols)
        while True:
            window = whole
            if math.isfinite(margin):
                grown = Window.bounding(rows, cols, pad + int(math.ceil(margin / res)), obstacle.shape)
                window = grown if _area(grown) < _area(whole) else whole
            trav = self._traversible(obstacle, window)
            if escape:
                trav = self._with_escape(trav, obstacle, window, agent)
            goal_mask = np.zeros(window.shape, dtype=np.uint8)
            goal_mask[goal_rows - window.r0, goal_cols - window.c0] = 1
            sources = (cv2.dilate(goal_mask, kernel) > 0) & trav
            exact = window == whole or self._exact(window, obstacle)
            bound = math.inf if exact else self._exit_bound_m(agent, window, sources, obstacle.shape)
            values = distance_field(trav, sources, resolution_m=res, limit_m=None if exact else bound)
            self.fmm_runs += 1
            d_agent = float(values[agent[0] - window.r0, agent[1] - window.c0])
            needed = d_agent + lookahead + _slack(d_agent)
            if exact or needed <= bound:
                field = GeodesicField(values, window, obstacle.shape, bound)
                return field, trav, np.argwhere(sources) + (window.r0, window.c0)
            margin = max(2 * margin, _margin_for(needed, straight))

    def _whole_window(self, obstacle: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> Window:
        """The window around the given cells and every obstacle and collision mark: exact."""
        rows, cols = [rows], [cols]
        for extent in (_extent(obstacle), _extent(self._collisions.map)):
            if extent is not None:
                rows.append(np.array(extent[:2]))
                cols.append(np.array(extent[2:]))
        margin = max(self.cfg.obstacle_dilation_cells, self.goal_dilation_cells) + 2
        return Window.bounding(np.concatenate(rows), np.concatenate(cols), margin, obstacle.shape)

    def _reusable(
        self,
        obstacle: np.ndarray,
        agent: tuple[int, int],
        goal_key: tuple[bytes, bytes],
        nearest_goal: tuple[int, int],
    ) -> tuple[GeodesicField, np.ndarray, tuple[int, int]] | None:
        """The cached goal field, the current traversible and the short-term goal, if still valid.

        Cells only ever get blocked between replans (a freed cell forces one), and blocking only
        lengthens paths, so a cached distance is exact unless its path crosses a newly blocked
        cell ``b``, which needs ``|x - b| + d(b) <= d(x)``: checked for the agent and for the
        chosen short-term goal (other candidates could only be under-estimated, and still lose).
        """
        cache = self._cache
        if cache is None or cache.goal_key != goal_key:
            return None
        field = cache.field
        window = field.window
        if not window.inside(agent[0], agent[1]):
            return None
        trav = self._traversible(obstacle, window)
        local = (agent[0] - window.r0, agent[1] - window.c0)
        if not trav[local] or (trav & ~cache.traversible).any():
            return None
        d_agent = float(field.values[local])
        if not math.isfinite(d_agent):
            return None
        res = self.resolution_m
        if not self._exact(window, obstacle):
            bound = min(field.limit_m, self._exit_bound_m(agent, window, cache.sources, obstacle.shape))
            if d_agent + self.lookahead_cells * res + _slack(d_agent) > bound:
                return None
        stg = self._short_term_goal(field, trav, agent, nearest_goal)
        br, bc = _cells(cache.traversible & ~trav)
        if br.size:
            via = field.values[br, bc]
            for cell in {agent, stg}:
                d_cell = float(field.at(*cell))
                detour = np.hypot(br + window.r0 - cell[0], bc + window.c0 - cell[1]) * res + via
                if (detour <= d_cell + _slack(d_cell)).any():
                    return None
        return field, trav, stg

    def _exit_bound_m(
        self, agent: tuple[int, int], window: Window, sources: np.ndarray, shape: tuple[int, int]
    ) -> float:
        """Lower bound on any path from the agent to a source that leaves the window.

        Such a path touches a window side that is not the map border; going via a line is at least
        the straight distance from the agent to the source mirrored in that line.
        """
        if sources.dtype == bool:
            sr, sc = np.nonzero(sources)
            sr, sc = sr + window.r0, sc + window.c0
        else:
            sr, sc = sources[:, 0], sources[:, 1]
        if sr.size == 0:
            return math.inf
        best = math.inf
        sides = (
            (window.r0 > 0, 2 * window.r0 - sr, sc),
            (window.r1 < shape[0], 2 * (window.r1 - 1) - sr, sc),
            (window.c0 > 0, sr, 2 * window.c0 - sc),
            (window.c1 < shape[1], sr, 2 * (window.c1 - 1) - sc),
        )
        for open_side, mr, mc in sides:
            if open_side:
                best = min(best, float(np.hypot(mr - agent[0], mc - agent[1]).min()))
        return best * self.resolution_m

    def _fallback_field(
        self, obstacle: np.ndarray, agent: tuple[int, int], goal_rows: np.ndarray, goal_cols: np.ndarray
    ) -> tuple[GeodesicField, np.ndarray]:
        """Goal unreachable: a field to the reachable cell nearest (straight-line) to the goal."""
        res = self.resolution_m
        reach = self.distance_from_agent(obstacle, agent, targets=np.stack([goal_rows, goal_cols], axis=1))
        window = reach.window
        trav = self._with_escape(self._traversible(obstacle, window), obstacle, window, agent)
        not_goal = np.ones(window.shape, dtype=np.uint8)
        not_goal[goal_rows - window.r0, goal_cols - window.c0] = 0
        to_goal = cv2.distanceTransform(not_goal, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
        score = np.where(np.isfinite(reach.values), to_goal + _TIE_WEIGHT * reach.values / res, np.inf)
        target = np.array([np.unravel_index(int(np.argmin(score)), score.shape)])
        values = distance_field(trav, target, resolution_m=res)
        self.fmm_runs += 1
        return GeodesicField(values, window, obstacle.shape), trav

    # -- decisions ------------------------------------------------------------------------------

    def _short_term_goal(
        self, field: GeodesicField, trav: np.ndarray, agent: tuple[int, int], nearest_goal: tuple[int, int]
    ) -> tuple[int, int]:
        """The cell nearest the goal among those seen from the agent along free straight rays.

        Only cells that score strictly better than the agent's own count; with none (boxed in, or
        as near the goal as the free space allows) the short-term goal is the agent's cell.
        """
        window = field.window
        local = (agent[0] - window.r0, agent[1] - window.c0)
        rows = self._ray_rows + local[0]
        cols = self._ray_cols + local[1]
        inside = (rows >= 0) & (rows < window.shape[0]) & (cols >= 0) & (cols < window.shape[1])
        rows, cols = np.where(inside, rows, 0), np.where(inside, cols, 0)
        visible = np.logical_and.accumulate(inside & trav[rows, cols], axis=1)
        tie = _TIE_WEIGHT * self.resolution_m
        score = field.values[rows, cols] + tie * np.hypot(
            rows + window.r0 - nearest_goal[0], cols + window.c0 - nearest_goal[1]
        )
        own = field.values[local] + tie * math.hypot(agent[0] - nearest_goal[0], agent[1] - nearest_goal[1])
        score = np.where(visible & (score < own), score, np.inf)
        best = int(np.argmin(score))
        if not math.isfinite(score.flat[best]):
            return agent
        return int(rows.flat[best]) + window.r0, int(cols.flat[best]) + window.c0

    def _action(self, agent: tuple[int, int], heading: float, target: tuple[int, int]) -> Action:
        if target == agent:  # standing on the goal cell itself: any turn is harmless
            return Action.TURN_LEFT
        desired = math.atan2(target[0] - agent[0], target[1] - agent[1])
        error = (desired - heading + math.pi) % (2 * math.pi) - math.pi
        threshold = math.radians(self.cfg.turn_threshold_deg)
        if error > threshold:
            return Action.TURN_LEFT
        if error < -threshold:
            return Action.TURN_RIGHT
        return Action.MOVE_FORWARD

def _slack(distance_m: float) -> float:
    return _SLACK_M + _SLACK_REL * distance_m


def _margin_for(path_m: float, straight_m: float) -> float:
    """Window margin whose exit bound admits a path this long between points this far apart.

    Mirroring the goal in a side at margin ``m`` from the agent-goal segment puts it at
    ``sqrt(straight^2 + (2m)^2)`` in the worst (axis-aligned) case.
    """
    return math.sqrt(max(path_m**2 - straight_m**2, 0.0)) / 2


def _area(window: Window) -> int:
    return window.shape[0] * window.shape[1]


def _disk(radius: int) -> np.ndarray:
    r = np.arange(-radius, radius + 1)
    return (r[:, None] ** 2 + r[None, :] ** 2 <= radius * radius).astype(np.uint8)


def _rays(length_cells: int) -> tuple[np.ndarray, np.ndarray]:
    """(directions, samples) cell offsets along straight rays from the agent, origin excluded."""
    angles = np.linspace(0.0, 2 * np.pi, _RAY_DIRECTIONS, endpoint=False)
    steps = np.arange(_RAY_STEP_CELLS, length_cells + 1e-9, _RAY_STEP_CELLS)
    rows = np.rint(np.sin(angles)[:, None] * steps[None, :]).astype(np.int64)
    cols = np.rint(np.cos(angles)[:, None] * steps[None, :]).astype(np.int64)
    at_origin = (rows == 0) & (cols == 0)
    # A sample that rounds back onto the agent's cell is not a goal; push it one step out.
    rows = np.where(at_origin, np.rint(np.sin(angles)[:, None] * 1.0).astype(np.int64), rows)
    cols = np.where(at_origin, np.rint(np.cos(angles)[:, None] * 1.0).astype(np.int64), cols)
    return rows, cols


def _extent(mask: np.ndarray | None) -> tuple[int, int, int, int] | None:
    """(rmin, rmax, cmin, cmax) of the True cells, or None (row/col reductions: no full nonzero)."""
    if mask is None:
        return None
    rows = np.flatnonzero(mask.any(axis=1))
    if rows.size == 0:
        return None
    cols = np.flatnonzero(mask.any(axis=0))
    return int(rows[0]), int(rows[-1]), int(cols[0]), int(cols[-1])


def _target_extent(targets: np.ndarray, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Rows and cols spanning the targets: the cells themselves, or a mask's bounding corners."""
    targets = np.asarray(targets)
    if targets.dtype == bool:
        if targets.shape != shape:
            raise L3MVNError(f"targets mask has shape {targets.shape}, expected the map shape {shape}")
        extent = _extent(targets)
        if extent is None:
            return np.empty(0, np.int64), np.empty(0, np.int64)
        return np.array(extent[:2]), np.array(extent[2:])
    if targets.ndim != 2 or targets.shape[1] != 2 or not np.issubdtype(targets.dtype, np.integer):
        raise L3MVNError(
            f"targets must be an (N, 2) int array of cells or a bool map mask, got {targets.shape}"
        )
    return targets[:, 0], targets[:, 1]


def _cells(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """np.nonzero restricted to the mask's bounding box (nonzero over a whole map costs ~2 ms)."""
    extent = _extent(mask)
    if extent is None:
        return np.empty(0, np.int64), np.empty(0, np.int64)
    rmin, rmax, cmin, cmax = extent
    rows, cols = np.nonzero(mask[rmin : rmax + 1, cmin : cmax + 1])
    return rows + rmin, cols + cmin


def _check_cell(cell: tuple[int, int], shape: tuple[int, int]) -> tuple[int, int]:
    try:
        r, c = (int(v) for v in cell)
    except (TypeError, ValueError):
        raise L3MVNError(f"a cell must be a (row, col) pair of ints, got {cell!r}") from None
    if not (0 <= r < shape[0] and 0 <= c < shape[1]):
        raise L3MVNError(f"cell ({r}, {c}) lies outside the {shape[0]}x{shape[1]} map")
    return r, c


def _goal_cells(goal: np.ndarray | tuple[int, int], shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    arr = np.asarray(goal)
    if arr.dtype == bool:
        if arr.shape != shape:
            raise L3MVNError(f"goal mask has shape {arr.shape}, expected the map shape {shape}")
        rows, cols = _cells(arr)
        if rows.size == 0:
            raise L3MVNError("goal mask is empty")
        return rows, cols
    if arr.shape == (2,):
        r, c = _check_cell(tuple(arr.tolist()), shape)
        return np.array([r]), np.array([c])
    if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] == 0 or not np.issubdtype(arr.dtype, np.integer):
        raise L3MVNError(
            "goal must be a (row, col) cell, an (N, 2) int array of cells or a bool map mask; "
            f"got {arr.shape}"
        )
    rows, cols = arr[:, 0].astype(np.int64), arr[:, 1].astype(np.int64)
    if ((rows < 0) | (rows >= shape[0]) | (cols < 0) | (cols >= shape[1])).any():
        raise L3MVNError(f"goal cells must lie inside the {shape[0]}x{shape[1]} map")
    return rows, cols


def _nearest(agent: tuple[int, int], rows: np.ndarray, cols: np.ndarray) -> tuple[int, int]:
    i = int(np.argmin((rows - agent[0]) ** 2 + (cols - agent[1]) ** 2))
    return int(rows[i]), int(cols[i])


__all__ = ["PlannerConfig", "Plan", "LocalPlanner"]

"""Distance fields of the local policy: Fast Marching to the goal on the smallest exact window, kept
across steps while it provably still holds.

Speed: a fresh FMM costs 5-40 ms on a house-sized window, so the field to the goal is kept across
steps while it provably still gives the agent's shortest path and short-term goal: same goal, no
cell freed, and no newly blocked cell on either path (see ``_reusable``); about one step in ten
replans while a house is being mapped. The window is only as large as the agent, the goal and a
margin; a path that leaves it is longer than the reflection bound ``_exit_bound_m``, and the window
grows until the agent's distance is safely below it (or holds every obstacle: then it is exact).
Unknown cells count as free (optimistic planning, as SemExp); obstacles are dilated by
``obstacle_dilation_cells``, and the way to a goal first by ``clearance_cells`` more (``field_to``);
cells where a forward step failed (``CollisionTracker``) are blocked.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from l3mvn.agent.planning.collisions import CollisionTracker
from l3mvn.agent.planning.fmm import GeodesicField, Window, distance_field
from l3mvn.agent.planning.steering import TIE_WEIGHT, Steering
from l3mvn.core.config import PlannerConfig
from l3mvn.core.errors import L3MVNError
from l3mvn.core.grid import disk

# FMM is a first/second-order scheme: its distances differ from the true geodesic by a few
# percent, so every comparison between an FMM value and a straight-line bound gets this slack.
_SLACK_M = 0.10
_SLACK_REL = 0.03

# A goal as the cache knows it: its cells (rows, cols as bytes), the dilation and the obstacle growth.
_GoalKey = tuple[bytes, bytes, int, bool]


@dataclass
class _GoalField:
    goal_key: _GoalKey
    traversible: np.ndarray
    sources: np.ndarray
    field: GeodesicField


# What ``GoalFields.saved`` hands out: the cached fields and the goal the way keeps the narrow margin to.
_Saved = tuple[dict[bool, _GoalField], tuple[bytes, bytes, int] | None]


class GoalFields:
    """The field to the current goal (cached) and the agent's own distance fields, over the
    traversible map of one episode. ``fmm_runs`` counts the marches (for speed reports)."""

    def __init__(
        self, cfg: PlannerConfig, resolution_m: float, steering: Steering, collisions: CollisionTracker
    ) -> None:
        self.cfg, self.resolution_m = cfg, resolution_m
        self.steering = steering
        self.lookahead_cells = steering.lookahead_cells
        self.goal_dilation_cells = int(round(cfg.goal_dilation_m / resolution_m))
        # Obstacle growth in cells: ``False`` the body's (frontier costs, fallbacks), ``True`` the
        # body's plus the clearance the way to a goal keeps where the floor allows.
        self._growth = {False: cfg.obstacle_dilation_cells, True: cfg.obstacle_dilation_cells + cfg.clearance_cells}
        self._obstacle_kernels = {wide: _kernel(r) for wide, r in self._growth.items()}
        self._goal_kernels = {self.goal_dilation_cells: _kernel(self.goal_dilation_cells)}
        self._escape_offsets = {wide: np.argwhere(disk(r + 1)) - (r + 1) for wide, r in self._growth.items()}
        self.reset(collisions)

    def reset(self, collisions: CollisionTracker) -> None:
        """A new episode: its collision marks, no cached field, no marches counted."""
        self._collisions = collisions
        self._cache: dict[bool, _GoalField] = {}
        self._narrow_goal: tuple[bytes, bytes, int] | None = None
        self.fmm_runs = 0

    def forget(self) -> None:
        """Drop the cached goal fields (the collision marks they were built on were cleared)."""
        self._cache = {}
        self._narrow_goal = None

    def saved(self) -> _Saved:
        """The cached fields and the clearance choice, for ``restore`` after a trial plan."""
        return dict(self._cache), self._narrow_goal

    def restore(self, saved: _Saved) -> None:
        """Back to the state ``saved`` returned: a trial plan on other marks leaves nothing behind."""
        cache, self._narrow_goal = saved
        self._cache = dict(cache)

    def field_to(
        self,
        obstacle: np.ndarray,
        agent: tuple[int, int],
        goal_rows: np.ndarray,
        goal_cols: np.ndarray,
        nearest_goal: tuple[int, int],
        dilation: int,
        marks: bool = True,
    ) -> tuple[GeodesicField, np.ndarray, tuple[int, int] | None, bool]:
        """(field, traversible, short-term goal if the cached field gave it, replanned) for the goal
        dilated by ``dilation`` cells. Without ``marks``: as if no collision mark had been laid
        (never cached; asked only while marks stand between the agent and its target).

        The way keeps ``clearance_cells`` more from obstacles (a path along the body's own margin
        grazes walls at every heading error) unless that closes it or lengthens it by more than
        ``clearance_detour_m``: then the body's margin alone is used until the goal changes or the
        marks are cleared. The comparison is made whenever the wide field is replanned; the narrow
        field is marched for it only while the straight line to the goal leaves it room to win."""
        goal = (goal_rows.tobytes(), goal_cols.tobytes(), dilation)
        args = (obstacle, agent, goal_rows, goal_cols, nearest_goal, dilation, marks)
        if self.cfg.clearance_cells == 0 or goal == self._narrow_goal:
            return self._field_to(*args, False)
        wide = self._field_to(*args, True)
        if not wide[3]:
            return wide
        d_wide = float(wide[0].at(*agent))
        # No way, however narrow, is shorter than the straight line to the dilated goal: when the wide
        # way is within the detour of it, the narrow field could not win and is not marched.
        straight = max(float(np.hypot(goal_rows - agent[0], goal_cols - agent[1]).min()) - dilation, 0.0)
        straight *= self.resolution_m
        if math.isfinite(d_wide) and not straight - _slack(straight) + self.cfg.clearance_detour_m < d_wide:
            return wide
        narrow = self._field_to(*args, False)
        d_narrow = float(narrow[0].at(*agent))
        if math.isfinite(d_wide) and not d_narrow + self.cfg.clearance_detour_m < d_wide:
            return wide
        if marks:
            self._narrow_goal = goal
        return narrow[0], narrow[1], narrow[2], True

    def _field_to(
        self,
        obstacle: np.ndarray,
        agent: tuple[int, int],
        goal_rows: np.ndarray,
        goal_cols: np.ndarray,
        nearest_goal: tuple[int, int],
        dilation: int,
        marks: bool,
        wide: bool,
    ) -> tuple[GeodesicField, np.ndarray, tuple[int, int] | None, bool]:
        """``field_to`` at one obstacle growth (``wide``: with the clearance); each growth keeps its
        own cached field, so comparing the two does not replan both every step."""
        key = (goal_rows.tobytes(), goal_cols.tobytes(), dilation, wide)
        reused = self._reusable(obstacle, agent, key, nearest_goal, wide) if marks else None
        if reused is not None:
            field, trav, stg = reused
            return field, trav, stg, False
        escape = not self._base_free(obstacle, agent, marks, wide)
        field, trav, sources = self._goal_field(
            obstacle, agent, goal_rows, goal_cols, nearest_goal, escape, dilation, marks, wide
        )
        if marks and not escape:
            self._cache[wide] = _GoalField(key, trav, sources, field)
        return field, trav, None, True

    def distance_from_agent(
        self,
        obstacle: np.ndarray,
        agent: tuple[int, int],
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

    def _traversible(
        self, obstacle: np.ndarray, window: Window, marks: bool = True, wide: bool = False
    ) -> npt.NDArray[np.bool_]:
        """Not (dilated obstacle) and, with ``marks``, not collision, over ``window`` (obstacles just
        outside count); ``wide``: grown by the clearance too."""
        pad = window.grown(self._growth[wide], obstacle.shape)
        crop = obstacle[pad.slices].view(np.uint8)
        kernel = self._obstacle_kernels[wide]
        dilated = cv2.dilate(crop, kernel) if kernel.size > 1 else crop
        inner = dilated[window.r0 - pad.r0 : window.r1 - pad.r0, window.c0 - pad.c0 : window.c1 - pad.c0]
        clear: npt.NDArray[np.bool_] = inner == 0  # cv2's result is typed as any number array
        if not marks:
            return clear
        assert self._collisions.map is not None  # the planner starts the tracker before any field
        return clear & ~self._collisions.map[window.slices]

    def _with_escape(
        self, trav: np.ndarray, obstacle: np.ndarray, window: Window, agent: tuple[int, int], wide: bool = False
    ) -> npt.NDArray[np.bool_]:
        """Open the undilated free cells around the agent, so dilation cannot trap it in place."""
        rows = self._escape_offsets[wide][:, 0] + agent[0]
        cols = self._escape_offsets[wide][:, 1] + agent[1]
        ok = window.inside(rows, cols)
        rows, cols = rows[ok], cols[ok]
        assert self._collisions.map is not None  # the planner starts the tracker before any field
        free = ~obstacle[rows, cols] & ~self._collisions.map[rows, cols]
        out: npt.NDArray[np.bool_] = trav.copy()
        out[rows[free] - window.r0, cols[free] - window.c0] = True
        out[agent[0] - window.r0, agent[1] - window.c0] = True
        return out

    def _base_free(self, obstacle: np.ndarray, agent: tuple[int, int], marks: bool = True, wide: bool = False) -> bool:
        cell = Window(agent[0], agent[1], agent[0] + 1, agent[1] + 1)
        return bool(self._traversible(obstacle, cell, marks, wide)[0, 0])

    def _exact(self, window: Window, obstacle: np.ndarray, wide: bool = False) -> bool:
        """Whether every obstacle (dilated) and collision mark lies strictly inside the window.

        Then the outside is free, and clamping any path to the window never lengthens it.
        """
        grow = self._growth[wide] + 1
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
        marks: bool = True,
        wide: bool = False,
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
        kernel = self._goal_kernels.setdefault(dilation, _kernel(dilation))
        whole = self._whole_window(obstacle, rows, cols)
        while True:
            window = whole
            if math.isfinite(margin):
                grown = Window.bounding(rows, cols, pad + int(math.ceil(margin / res)), obstacle.shape)
                window = grown if _area(grown) < _area(whole) else whole
            trav = self._traversible(obstacle, window, marks, wide)
            if escape:
                trav = self._with_escape(trav, obstacle, window, agent, wide)
            goal_mask = np.zeros(window.shape, dtype=np.uint8)
            goal_mask[goal_rows - window.r0, goal_cols - window.c0] = 1
            sources = (cv2.dilate(goal_mask, kernel) > 0) & trav
            exact = window == whole or self._exact(window, obstacle, wide)
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
        all_rows, all_cols = [rows], [cols]
        for extent in (_extent(obstacle), _extent(self._collisions.map)):
            if extent is not None:
                all_rows.append(np.array(extent[:2]))
                all_cols.append(np.array(extent[2:]))
        margin = max(self._growth[True], self.goal_dilation_cells) + 2
        return Window.bounding(np.concatenate(all_rows), np.concatenate(all_cols), margin, obstacle.shape)

    def _reusable(
        self,
        obstacle: np.ndarray,
        agent: tuple[int, int],
        goal_key: _GoalKey,
        nearest_goal: tuple[int, int],
        wide: bool = False,
    ) -> tuple[GeodesicField, np.ndarray, tuple[int, int]] | None:
        """The cached goal field, the current traversible and the short-term goal, if still valid.

        Cells only ever get blocked between replans (a freed cell forces one), and blocking only
        lengthens paths, so a cached distance is exact unless its path crosses a newly blocked
        cell ``b``, which needs ``|x - b| + d(b) <= d(x)``: checked for the agent and for the
        chosen short-term goal (other candidates could only be under-estimated, and still lose).
        """
        cache = self._cache.get(wide)
        if cache is None or cache.goal_key != goal_key:
            return None
        field = cache.field
        window = field.window
        if not window.inside(agent[0], agent[1]):
            return None
        trav = self._traversible(obstacle, window, wide=wide)
        local = (agent[0] - window.r0, agent[1] - window.c0)
        if not trav[local] or (trav & ~cache.traversible).any():
            return None
        d_agent = float(field.values[local])
        if not math.isfinite(d_agent):
            return None
        res = self.resolution_m
        if not self._exact(window, obstacle, wide):
            bound = min(field.limit_m, self._exit_bound_m(agent, window, cache.sources, obstacle.shape))
            if d_agent + self.lookahead_cells * res + _slack(d_agent) > bound:
                return None
        stg = self.steering.short_term_goal(field, trav, agent, nearest_goal)
        br, bc = mask_cells(cache.traversible & ~trav)
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

    def fallback_field(
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
        score = np.where(np.isfinite(reach.values), to_goal + TIE_WEIGHT * reach.values / res, np.inf)
        target = np.array([np.unravel_index(int(np.argmin(score)), score.shape)])
        values = distance_field(trav, target, resolution_m=res)
        self.fmm_runs += 1
        return GeodesicField(values, window, obstacle.shape), trav

    # -- decisions ------------------------------------------------------------------------------


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


def _kernel(radius: int) -> np.ndarray:
    """``disk`` as the uint8 kernel cv2 dilates with."""
    return disk(radius).astype(np.uint8)


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
        raise L3MVNError(f"targets must be an (N, 2) int array of cells or a bool map mask, got {targets.shape}")
    return targets[:, 0], targets[:, 1]


def mask_cells(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """np.nonzero restricted to the mask's bounding box (nonzero over a whole map costs ~2 ms)."""
    extent = _extent(mask)
    if extent is None:
        return np.empty(0, np.int64), np.empty(0, np.int64)
    rmin, rmax, cmin, cmax = extent
    rows, cols = np.nonzero(mask[rmin : rmax + 1, cmin : cmax + 1])
    return rows + rmin, cols + cmin

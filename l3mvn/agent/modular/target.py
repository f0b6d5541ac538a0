"""The target search: what on the map may be the goal object, and how sure the agent is of it.

A goal category's cells are a confirmed target once their largest blob has ``target_min_cells``;
fewer cells are a candidate worth a closer look, from up to ``candidate_views`` other poses, before
they are set aside as mapping noise; a sighting beyond the depth range (no mapped cell at all) is a
glimpse to walk towards. This module keeps that state per episode; ``MapAgent`` decides when each
applies, ``looking`` holds the geometry.
"""

from __future__ import annotations

import cv2
import numpy as np

from l3mvn.agent.looking import far_sighting, pick_viewpoint
from l3mvn.agent.mapping import SemanticMap
from l3mvn.agent.planning import LocalPlanner
from l3mvn.core.config import AgentConfig

Cell = tuple[int, int]


class TargetSearch:
    """Per-episode state of the search for the goal object on the agent's own map."""

    def __init__(self, cfg: AgentConfig) -> None:
        self.cfg = cfg
        self.reset()

    def reset(self) -> None:
        self.rejected: np.ndarray | None = None  # goal cells set aside (unreachable or never confirmed)
        self.viewpoint: Cell | None = None  # the other pose a candidate is being looked at from
        self.views: list[float] = []  # bearings (from the candidate) it was looked at from
        self.glimpse: Cell | None = None  # where a sighting beyond the depth range points
        self.escapes = 0  # escapes spent on a confirmed target the planner cannot reach

    def mask(self, sem_map: SemanticMap, goal: str) -> tuple[np.ndarray | None, bool]:
        """The largest connected blob of the goal channel (rejected cells aside) and whether it has
        enough cells to stop at; a smaller one is worth a closer look (a far plant maps to 1-2 cells)."""
        if goal not in sem_map.category_names:
            return None, False
        channel = sem_map.category(goal)
        if self.rejected is None or self.rejected.shape != channel.shape:
            self.rejected = np.zeros_like(channel)
        channel = channel & ~self.rejected
        rows, cols = np.nonzero(channel.any(axis=1))[0], np.nonzero(channel.any(axis=0))[0]
        if len(rows) == 0:
            return None, False
        r0, r1, c0, c1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
        crop = channel[r0:r1, c0:c1].astype(np.uint8)
        n, labels, stats, _ = cv2.connectedComponentsWithStats(crop, connectivity=8)
        if n <= 1:
            return None, False
        best = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
        found = np.zeros_like(channel)
        found[r0:r1, c0:c1] = labels == best
        return found, bool(stats[best, cv2.CC_STAT_AREA] >= self.cfg.target_min_cells)

    def observe(self, target: np.ndarray | None, confirmed: bool, sighting: Cell | None) -> None:
        """Update after this step's map: other views end once the target is confirmed or gone; a
        glimpse is kept until a new one replaces it or goal cells appear on the map."""
        if target is None or confirmed:
            self.viewpoint, self.views = None, []
        if target is None:
            self.glimpse = sighting or self.glimpse
        else:
            self.glimpse = None

    def set_aside(self, cells: np.ndarray) -> None:
        """Never treat these goal cells as the target again this episode."""
        self.rejected |= cells
        self.viewpoint, self.views = None, []

    def pick_viewpoint(self, sem_map: SemanticMap, target: np.ndarray, planner: LocalPlanner) -> Cell | None:
        """Another pose to look at a candidate from (``looking.pick_viewpoint``); the view from here is
        remembered so the next one differs from it too."""
        res = sem_map.resolution_m
        found = pick_viewpoint(
            sem_map, target, planner, self.views, self.cfg.viewpoint_min_m / res, self.cfg.viewpoint_max_m / res
        )
        if found is None:
            return None
        self.views.append(found[1])
        self.viewpoint = found[0]
        return found[0]

    def far_sighting(
        self,
        sem_map: SemanticMap,
        depth: np.ndarray,
        semantic: np.ndarray,
        goal_id: int,
        focal_px: float,
        max_depth_m: float,
        done: list[Cell],
    ) -> Cell | None:
        """Where a sighting of the goal (semantic id ``goal_id``) beyond the depth range points, away
        from the ``done`` goals; None when there is none."""
        res = sem_map.resolution_m
        return far_sighting(
            sem_map,
            depth,
            semantic,
            goal_id,
            focal_px,
            max_depth_m / res,
            (self.cfg.glimpse_min_fraction, self.cfg.glimpse_max_fraction),
            done,
            self.cfg.blocked_radius_m / res,
        )

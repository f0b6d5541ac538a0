"""The ObjectNav task on one scene floor: the judge beside the simulator (habitat-lab's EmbodiedTask).

The simulator moves the agent and renders; the task answers what only ground truth can: where each
goal's success region lies under the configured rule, how far the agent is from it, and the
shortest path an episode allows. Evaluation, the oracle baselines and the dashboard's ground-truth
panel read it; agents never do.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage as ndi

from l3mvn.core.config import Config
from l3mvn.core.config.task import VIEW_POINT_RULES
from l3mvn.core.types import Pose
from l3mvn.world.episode import Episode
from l3mvn.world.scenes.scene import SceneMap
from l3mvn.world.task.regions import GoalRegion, goal_region


class ObjectNavTask:
    """Success regions and distances for episodes on ``scene`` under ``cfg.task``'s success rule."""

    def __init__(self, scene: SceneMap, cfg: Config) -> None:
        self.scene, self.cfg = scene, cfg
        self._regions: dict[str, GoalRegion] = {}
        self._walk_labels: np.ndarray | None = None

    @property
    def rule(self) -> str:
        return self.cfg.task.success_rule

    def region(self, goal: str) -> GoalRegion:
        """The goal's success region (built once per goal); a goal absent from the scene is an error
        naming the goals present."""
        if goal not in self._regions:
            self._regions[goal] = goal_region(self.scene, goal, self.cfg)
        return self._regions[goal]

    def distance_to_goal(self, pose: Pose, goal: str) -> float:
        """Geodesic metres from ``pose`` to the goal's success region (inf: no path)."""
        return self.region(goal).distance_at(pose.x, pose.y)

    def in_success_region(self, pose: Pose, goal: str) -> bool:
        return self.region(goal).contains(pose.x, pose.y)

    def shortest_path_length(self, episode: Episode, goal: str | None = None) -> float:
        """The ``l`` of SPL from the episode's start (to ``goal``, default the episode's own).

        Under habitat's view-point rules it is the episode file's ``geodesic_distance`` (habitat's
        navmesh measured it; ``datasets.geodesic_agreement`` checks it against ours), as long as our
        grid has a path at all: an episode we cannot walk stays ``no_path``."""
        start = episode.start
        ours = self.region(goal or episode.goal).shortest_path_length(start.x, start.y)
        if (
            self.rule in VIEW_POINT_RULES
            and goal in (None, episode.goal)
            and math.isfinite(ours)
            and math.isfinite(episode.geodesic_distance_m)
        ):
            return episode.geodesic_distance_m
        return ours

    def reachable_cells(self, start: Pose) -> tuple[np.ndarray, np.ndarray]:
        """(rows, cols) of the walkable cells connected to ``start``: the floor an episode can cover."""
        if self._walk_labels is None:
            self._walk_labels, _ = ndi.label(self.scene.walkable, structure=np.ones((3, 3), dtype=bool))
        r, c = self.scene.cell_of(start.x, start.y)
        if not self.scene.in_bounds(r, c) or self._walk_labels[r, c] == 0:
            return np.empty(0, np.int64), np.empty(0, np.int64)
        rows, cols = np.nonzero(self._walk_labels == self._walk_labels[r, c])
        return rows, cols

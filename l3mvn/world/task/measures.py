"""Per-step measures of one episode, kept by the task while the session steps it.

They record what the failure causes need (whether the target was ever in view or confirmed, whether
the agent ever stood in the success region, how often its forward moves collided) and turn the end
state into an ``EpisodeOutcome`` for scoring.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from l3mvn.world.task.objectnav import ObjectNavTask
from l3mvn.world.task.scoring import EpisodeOutcome
from l3mvn.core.types import Action, Observation
from l3mvn.world.episode import Episode


def target_visible(obs: Observation, seen_fraction: float) -> bool:
    """Whether at least ``seen_fraction`` of the frame shows the goal with valid depth."""
    visible = np.count_nonzero((obs.semantic == obs.goal_id) & (obs.depth > 0))
    return visible >= seen_fraction * obs.semantic.size


class EpisodeMeasures:
    """Accumulates one episode's measures; ``retarget`` starts them over for a new goal."""

    def __init__(self, task: ObjectNavTask, episode: Episode, obs: Observation) -> None:
        self.task, self.episode, self.cfg = task, episode, task.cfg.task
        self._forwards: deque[bool] = deque(maxlen=self.cfg.collision_window)
        self.retarget(episode, obs)

    def retarget(self, episode: Episode, obs: Observation) -> None:
        self.episode = episode
        self.saw_target = target_visible(obs, self.cfg.seen_fraction)
        self.confirmed = False
        self.entered_region = self.task.in_success_region(obs.pose, episode.goal)

    def update(self, obs: Observation, action: Action, target_confirmed: bool) -> None:
        if action == Action.MOVE_FORWARD:
            self._forwards.append(obs.collided)
        self.saw_target = self.saw_target or target_visible(obs, self.cfg.seen_fraction)
        self.confirmed = self.confirmed or target_confirmed
        self.entered_region = self.entered_region or self.task.in_success_region(obs.pose, self.episode.goal)

    @property
    def recent_collision_rate(self) -> float:
        f = self._forwards
        return (sum(f) / len(f)) if len(f) >= 10 else 0.0

    def coverage(self, sem_map) -> float | None:
        """The share of the floor reachable from the start that the agent's own map marks explored
        (None when the policy keeps no map)."""
        if sem_map is None:
            return None
        rows, cols = self.task.reachable_cells(self.episode.start)
        if not len(rows):
            return None
        xs, ys = self.task.scene.cell_center(rows, cols)
        return float(sem_map.explored_at(xs, ys).mean())

    def outcome(self, env, *, agent_reported_stuck: bool, sem_map) -> EpisodeOutcome:
        """The end state of the episode in ``env`` as scoring reads it."""
        goal = self.episode.goal
        return EpisodeOutcome(
            stopped=env.stopped, in_success_region=self.task.in_success_region(env.pose, goal), steps=env.steps,
            path_length_m=env.path_length_m, shortest_path_m=self.task.shortest_path_length(self.episode),
            final_distance_m=self.task.distance_to_goal(env.pose, goal), saw_target=self.saw_target,
            entered_region=self.entered_region, recent_collision_rate=self.recent_collision_rate,
            agent_reported_stuck=agent_reported_stuck, coverage=self.coverage(sem_map),
        )

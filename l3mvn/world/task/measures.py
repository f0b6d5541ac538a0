"""Per-step measures of one episode, kept by the task while the session steps it.

They read the simulator and the task only, never the agent: whether the goal was ever in view or
confirmed in view (``views``: from the rendered frames at the true poses), whether the agent ever
stood in the success region, how much of the reachable floor it had seen, how often its forward moves
collided. So two policies' failure causes come from the same measures. The end state becomes an
``EpisodeOutcome`` for scoring.
"""

from __future__ import annotations

from collections import deque

from l3mvn.core.types import Action, Observation
from l3mvn.world.episode import Episode
from l3mvn.world.sim.base import Environment
from l3mvn.world.task.objectnav import ObjectNavTask
from l3mvn.world.task.scoring import EpisodeOutcome
from l3mvn.world.task.views import ViewRecord


def target_visible(obs: Observation, seen_fraction: float) -> bool:
    """Whether at least ``seen_fraction`` of the frame shows the goal with valid depth."""
    h, w = obs.frame.shape
    return obs.frame.count(obs.goal_id) >= seen_fraction * h * w


class EpisodeMeasures:
    """Accumulates one episode's measures; ``retarget`` starts the goal's over for a new goal."""

    def __init__(self, task: ObjectNavTask, env: Environment, episode: Episode, obs: Observation) -> None:
        self.task, self.env, self.episode, self.cfg = task, env, episode, task.cfg.task
        self._forwards: deque[bool] = deque(maxlen=self.cfg.collision_window)
        self.views = ViewRecord(task.scene, task.cfg)
        self.retarget(episode, obs)

    def retarget(self, episode: Episode, obs: Observation) -> None:
        self.episode = episode
        self.views.retarget()
        self.saw_target = False
        self.entered_region = self.task.in_success_region(self.env.pose, episode.goal)
        self._look(obs)

    def update(self, obs: Observation, action: Action) -> None:
        if action == Action.MOVE_FORWARD:
            self._forwards.append(obs.collided)
        self._look(obs)
        self.entered_region = self.entered_region or self.task.in_success_region(self.env.pose, self.episode.goal)

    def _look(self, obs: Observation) -> None:
        # The views first: where they read the whole frame, the count is taken from it, not rendered.
        self.views.add(obs, self.env.pose)
        self.saw_target = self.saw_target or target_visible(obs, self.cfg.seen_fraction)

    @property
    def confirmed(self) -> bool:
        """Whether the goal was ever in view well enough to confirm (``ViewRecord.confirmed``)."""
        return self.views.confirmed

    @property
    def recent_collision_rate(self) -> float:
        f = self._forwards
        return (sum(f) / len(f)) if len(f) >= 10 else 0.0

    def coverage(self) -> float:
        """The share of the floor reachable from the start whose floor the frames have shown."""
        return self.views.coverage(*self.task.reachable_cells(self.episode.start))

    def outcome(self) -> EpisodeOutcome:
        """The end state of the episode as scoring reads it."""
        env, goal = self.env, self.episode.goal
        return EpisodeOutcome(
            stopped=env.stopped,
            in_success_region=self.task.in_success_region(env.pose, goal),
            steps=env.steps,
            path_length_m=env.path_length_m,
            shortest_path_m=self.task.shortest_path_length(self.episode),
            final_distance_m=self.task.distance_to_goal(env.pose, goal),
            saw_target=self.saw_target,
            entered_region=self.entered_region,
            recent_collision_rate=self.recent_collision_rate,
            coverage=self.coverage(),
        )

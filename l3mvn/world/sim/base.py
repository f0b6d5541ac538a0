"""The environment contract every backend satisfies (built-in simulator, habitat-sim, a real robot).

Everything above the simulator (session, agent, runner, dashboard) depends on this protocol, not on
a backend. It moves the agent and renders; what counts as success is the task's business
(``l3mvn.world.task``), which reads the ground truth of the scene, never the agent.
"""

from __future__ import annotations

import dataclasses
from typing import Protocol, runtime_checkable

from l3mvn.core.config import SimConfig
from l3mvn.core.errors import L3MVNError
from l3mvn.core.types import Action, Observation, Pose
from l3mvn.world.episode import Episode
from l3mvn.world.scenes.scene import SceneMap


@runtime_checkable
class Environment(Protocol):
    categories: tuple[str, ...]
    cfg: SimConfig

    def reset(self, episode: Episode) -> Observation:
        """Place the agent at the episode start and return the first observation."""

    def step(self, action: Action) -> Observation:
        """Apply one action; a blocked forward move stays put and sets ``Observation.collided``."""

    def set_goal(self, goal: str) -> None:
        """Retarget the running episode: later observations name the new goal."""

    @property
    def done(self) -> bool:
        """True after STOP or when the step budget is spent."""

    @property
    def stopped(self) -> bool:
        """True once the agent called STOP."""

    @property
    def pose(self) -> Pose:
        """The agent's pose in scene coordinates (metres, heading CCW from +x)."""

    @property
    def steps(self) -> int:
        """Actions taken since reset."""

    @property
    def path_length_m(self) -> float:
        """Distance actually walked since reset (the ``p`` of SPL)."""


@runtime_checkable
class MotionModel(Protocol):
    """An environment that can say where a forward move would end without making it: planners that
    look ahead on the true dynamics (the oracle) need it. Both our simulator and the habitat bridge
    (on its floor's grid) have it."""

    scene: SceneMap
    cfg: SimConfig

    def forward_result(self, pose: Pose) -> tuple[Pose, float]:
        """The pose a forward move from ``pose`` ends at, and the metres it moves."""


class EpisodeState:
    """The per-episode bookkeeping every backend keeps the same way (steps, path, stop, pose, goal),
    so the contract's properties mean the same on each. A backend sets the underscored fields in
    ``reset`` and ``step``; it has ``cfg``, ``categories`` and ``scene``."""

    scene: SceneMap
    cfg: SimConfig
    categories: tuple[str, ...]
    _episode: Episode | None = None
    _pose: Pose | None = None
    _steps = 0
    _path = 0.0
    _stopped = False

    def set_goal(self, goal: str) -> None:
        """Retarget the running episode (the dashboard's mid-episode target change)."""
        self._check_goal(goal)
        self._episode = dataclasses.replace(self.episode, goal=goal)

    @property
    def done(self) -> bool:
        return self._stopped or self._steps >= self.cfg.max_steps

    @property
    def stopped(self) -> bool:
        return self._stopped

    @property
    def pose(self) -> Pose:
        if self._pose is None:
            raise L3MVNError("no episode: call reset() first")
        return self._pose

    @property
    def steps(self) -> int:
        return self._steps

    @property
    def path_length_m(self) -> float:
        return self._path

    @property
    def episode(self) -> Episode:
        if self._episode is None:
            raise L3MVNError("no episode: call reset() first")
        return self._episode

    def _check_goal(self, goal: str) -> None:
        """Observations label the goal by its category id: the goal must be one of the scene's
        categories (whether it is present, and where, is the task's business)."""
        if goal not in self.categories:
            raise L3MVNError(f"unknown goal {goal!r} for {self.scene.key}; categories: {', '.join(self.categories)}")

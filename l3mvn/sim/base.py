"""The environment contract every backend satisfies (built-in simulator, habitat-sim, a real robot).

Everything above the simulator (session, agent, runner, dashboard) depends on this protocol, not on
a backend. It moves the agent and renders; what counts as success is the task's business
(``l3mvn.task``), which reads the ground truth of the scene, never the agent.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

from l3mvn.config import SimConfig
from l3mvn.types import Action, Episode, Observation, Pose


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

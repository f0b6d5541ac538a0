"""The environment contract every backend satisfies (built-in simulator, habitat-sim, a real robot).

Agents only see ``reset``/``step`` and Observations. The ground-truth queries exist for the evaluator
and the oracle baseline; a real robot may leave them unimplemented (raise ``NotImplementedError``).
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

from l3mvn.sim.types import Action, Episode, Observation


@runtime_checkable
class Environment(Protocol):
    categories: tuple[str, ...]

    def reset(self, episode: Episode) -> Observation:
        """Place the agent at the episode start and return the first observation."""

    def step(self, action: Action) -> Observation:
        """Apply one action; a blocked forward move stays put and sets ``Observation.collided``."""

    @property
    def done(self) -> bool:
        """True after STOP or when the step budget is spent."""

    @property
    def path_length_m(self) -> float:
        """Distance actually walked since reset (the ``p`` of SPL)."""

    def distance_to_goal(self) -> float:
        """Ground truth: geodesic metres from the agent to the goal's success region."""

    def in_success_region(self) -> bool:
        """Ground truth: whether STOP here would succeed."""

    def shortest_path_length(self) -> float:
        """Ground truth: the ``l`` of SPL for the current episode."""

"""Driving by hand: the map-based agent with a person choosing every action.

The agent still maps, finds frontiers and scores them each step, so the dashboard keeps showing
what it would do; the action taken is the one given with ``drive`` (the dashboard's keys and
buttons), and the episode is scored like any other (STOP ends it). Handy to reproduce a failure or
to show a colleague what the map looks like from a given spot. It lives beside ``MapAgent`` (not in
``l3mvn.agent.policies``, which sits below the agent) because it is one.
"""

from __future__ import annotations

from dataclasses import replace

from l3mvn.agent.decision import Decision
from l3mvn.agent.modular.map_agent import MapAgent
from l3mvn.agent.policies.global_policies import GlobalPolicy
from l3mvn.core.config import Config
from l3mvn.core.errors import L3MVNError
from l3mvn.core.types import Action, Observation


class TeleopAgent(MapAgent):
    """``MapAgent`` whose next action is the one last given to ``drive``; it never acts on its own."""

    def __init__(self, global_policy: GlobalPolicy, categories: tuple[str, ...], config: Config, seed: int = 0) -> None:
        super().__init__(global_policy, categories, config, seed)
        self._driven: Action | None = None

    def drive(self, action: Action | int | str) -> None:
        """The action of the next step (replaces one given before that step ran)."""
        self._driven = Action.parse(action)

    def act(self, obs: Observation) -> Decision:
        if self._driven is None:
            raise L3MVNError(
                "policy 'teleop' acts only when driven: use the Drive keys or buttons of `l3mvn serve --policy teleop`"
            )
        action, self._driven = self._driven, None
        decision = super().act(obs)
        self._prev_action = action  # what moved the agent: the next step's collision check compares with it
        return replace(
            decision,
            action=action,
            reason=f"driven by hand: {action.name.lower()} (the agent would {decision.action.name.lower()}: "
            f"{decision.reason})",
        )

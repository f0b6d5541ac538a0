"""What a map-based agent decided at one step, and why: the record the dashboard and the recorder show.

``GoalKind`` names what the long-term goal is; ``Decision`` carries the action with the map, the
frontiers and the reason behind it. A policy may return a plain ``Action`` instead.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from l3mvn.core.types import Action

if TYPE_CHECKING:
    from l3mvn.agent.frontiers import Frontier


class GoalKind(str, enum.Enum):
    """What the agent's long-term goal is; a ``str`` so event consumers can compare with plain names,
    printed as its value (``enum.StrEnum``'s behaviour, which Python 3.10 lacks)."""

    NONE = ""
    TARGET = "target"  # the target, confirmed on the map: walk to it and stop
    CANDIDATE = "candidate"  # goal cells too few to confirm: approach and look again
    VIEWPOINT = "viewpoint"  # another pose to look at a candidate from
    GLIMPSE = "glimpse"  # the target seen beyond the depth range: walk towards it
    FRONTIER = "frontier"  # a frontier chosen by the global policy
    RANDOM = "random"  # a free cell the global policy sampled
    EXPLORE = "explore"  # no frontier left: a random free cell
    LOOK = "look"  # an area only seen from afar: go and look
    MANUAL = "manual"  # a cell picked in the dashboard
    ESCAPE = "escape"  # stuck: collision marks cleared, a random turn then forward
    LOOK_AROUND = "look-around"  # the initial turn in place

    def __str__(self) -> str:
        return str(self.value)

    def __format__(self, spec: str) -> str:
        return format(str(self.value), spec)


# Goals that explore rather than approach what was seen.
EXPLORING = frozenset({GoalKind.FRONTIER, GoalKind.RANDOM, GoalKind.EXPLORE, GoalKind.LOOK})


@dataclass
class Decision:
    """What an agent decided this step and why (map-based agents fill the map fields)."""

    action: Action
    reason: str = ""
    map: Any = None  # l3mvn.agent.mapping.SemanticMap (live view: copy to keep)
    frontiers: list[Frontier] = field(default_factory=list)
    long_term_goal: tuple[int, int] | None = None
    goal_kind: GoalKind = GoalKind.NONE
    chosen_frontier: int | None = None
    short_term_goal: tuple[int, int] | None = None
    override: str | None = None
    target_seen: bool = False
    stuck: bool = False
    timings_ms: dict[str, float] = field(default_factory=dict)
    # (N, 2) int32 map cells the agent's failed forward steps blocked: walls to the planner, though
    # the map may show free floor there (so they can close a way the map shows open).
    collision_marks: np.ndarray | None = None

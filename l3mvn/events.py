"""What one step of the navigation loop tells the outside world.

The loop publishes a ``StepEvent`` after every step; the dashboard and the recorder subscribe to an
``EventBus`` and never reach into the agent. A subscriber that raises is reported and dropped from
that event, never allowed to break the episode.
"""

from __future__ import annotations

import enum

import logging
import threading
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from l3mvn.types import Action, Observation, Pose

log = logging.getLogger(__name__)


class GoalKind(enum.StrEnum):
    """What the agent's long-term goal is; a ``str`` so event consumers can compare with plain names."""

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


# Goals that explore rather than approach what was seen.
EXPLORING = frozenset({GoalKind.FRONTIER, GoalKind.RANDOM, GoalKind.EXPLORE, GoalKind.LOOK})


@dataclass
class Decision:
    """What an agent decided this step and why (map-based agents fill the map fields)."""

    action: Action
    reason: str = ""
    map: Any = None  # l3mvn.mapping.SemanticMap (live view: copy to keep)
    frontiers: list = field(default_factory=list)  # list[l3mvn.frontiers.Frontier]
    long_term_goal: tuple[int, int] | None = None
    goal_kind: GoalKind = GoalKind.NONE
    chosen_frontier: int | None = None
    short_term_goal: tuple[int, int] | None = None
    override: str | None = None
    target_seen: bool = False
    stuck: bool = False
    timings_ms: dict[str, float] = field(default_factory=dict)
    # (N, 2) int32 map cells the agent's failed forward steps blocked: walls to the planner, though
    # the map may show free floor there (what closed Forkland/0/6's way to its toilet).
    collision_marks: np.ndarray | None = None


@dataclass
class StepEvent:
    """One step: the observation that led to the decision, the decision, and ground-truth metrics.

    ``action`` is the action taken at this step (None for the event emitted at reset).
    ``ground_truth`` holds evaluator-only values (geodesic distance to goal, path length, ...), kept
    apart so nobody mistakes them for what the agent knows.
    """

    episode_key: str
    segment: int
    step: int
    goal: str
    pose: Pose
    observation: Observation
    decision: Decision | None
    action: Action | None
    ground_truth: dict[str, float] = field(default_factory=dict)
    done: bool = False
    result: dict | None = None  # the episode's result line once done


Subscriber = Callable[[StepEvent], None]


class EventBus:
    """Thread-safe fan-out of step events to subscribers."""

    def __init__(self) -> None:
        self._subs: list[Subscriber] = []
        self._lock = threading.Lock()

    def subscribe(self, fn: Subscriber) -> Callable[[], None]:
        with self._lock:
            self._subs.append(fn)

        def unsubscribe() -> None:
            with self._lock:
                if fn in self._subs:
                    self._subs.remove(fn)

        return unsubscribe

    def publish(self, event: StepEvent) -> None:
        with self._lock:
            subs = list(self._subs)
        for fn in subs:
            try:
                fn(event)
            except Exception:  # a broken viewer must not end an episode
                log.exception("step-event subscriber %r failed", fn)

    def __len__(self) -> int:
        return len(self._subs)

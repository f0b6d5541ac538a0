"""What one step of the navigation loop tells the outside world.

The loop publishes a ``StepEvent`` after every step; the dashboard and the recorder subscribe to an
``EventBus`` and never reach into the agent. A subscriber that raises is reported and dropped from
that event, never allowed to break the episode.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass, field

from l3mvn.agent.decision import Decision
from l3mvn.core.types import Action, Observation, Pose

log = logging.getLogger(__name__)


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

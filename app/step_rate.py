"""The rate a Run actually achieves, beside the rate it was asked for.

A Run waits ``1 / speed`` between steps, but a step (agent, simulator, drawing) may take longer than
that wait: then the run goes slower than asked, and the page should say so rather than let the
slider promise a speed no one gets. The rate is measured over the last few steps of the current run
only: a pause, a Reset or a single Step starts the count again.
"""

from __future__ import annotations

from collections import deque

WINDOW = 10  # steps the achieved rate is averaged over: steady within a second at a few steps per second


class StepRate:
    """Steps per second over the last ``WINDOW`` steps of an uninterrupted run."""

    def __init__(self, window: int = WINDOW) -> None:
        self._times: deque[float] = deque(maxlen=window + 1)

    def add(self, t: float) -> None:
        """A run step arrived at time ``t`` (seconds, any monotonic clock)."""
        self._times.append(t)

    def clear(self) -> None:
        """The run stopped (a pause, a Reset, a single Step): the next run measures afresh."""
        self._times.clear()

    @property
    def per_second(self) -> float | None:
        """None until two steps of this run arrived."""
        if len(self._times) < 2 or self._times[-1] <= self._times[0]:
            return None
        return (len(self._times) - 1) / (self._times[-1] - self._times[0])

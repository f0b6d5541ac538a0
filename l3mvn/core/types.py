"""Typed records that cross the simulator boundary: actions, poses, observations, episode briefs.

World frame (shared by every backend): metres on the floor plane, ``x`` along map columns, ``y`` along
map rows, ``z`` up; the map cell of a point is ``(row, col) = (floor(y / res), floor(x / res))``.
Heading is in radians, counter-clockwise about ``z`` from ``+x``, so ``turn_left`` adds to it.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import Any, overload

import numpy as np
import numpy.typing as npt

from l3mvn.core.errors import L3MVNError
from l3mvn.core.frames import CameraFrame


class Action(enum.IntEnum):
    """Habitat ObjectNav action ids (stop is 0, as in SemExp)."""

    STOP = 0
    MOVE_FORWARD = 1
    TURN_LEFT = 2
    TURN_RIGHT = 3
    LOOK_UP = 4
    LOOK_DOWN = 5

    @classmethod
    def parse(cls, value: Action | int | str) -> Action:
        if isinstance(value, Action):
            return value
        if isinstance(value, str):
            key = value.strip().upper().replace("-", "_")
            if key in cls.__members__:
                return cls[key]
            names = ", ".join(a.name.lower() for a in cls)
            raise L3MVNError(f"unknown action {value!r}; valid actions: {names}")
        try:
            return cls(int(value))
        except ValueError:
            raise L3MVNError(f"unknown action id {value!r}; valid ids: 0-{len(cls) - 1}") from None


@dataclass(frozen=True)
class Pose:
    """Agent pose on the floor plane: metres and radians (see module docstring for the frame)."""

    x: float
    y: float
    heading: float

    def __post_init__(self) -> None:
        if not all(math.isfinite(v) for v in (self.x, self.y, self.heading)):
            raise L3MVNError(f"non-finite pose ({self.x}, {self.y}, {self.heading})")

    def cell(self, resolution_m: float) -> tuple[int, int]:
        return int(math.floor(self.y / resolution_m)), int(math.floor(self.x / resolution_m))

    def as_array(self) -> np.ndarray:
        return np.array([self.x, self.y, self.heading], dtype=np.float64)


@dataclass(frozen=True)
class Observation:
    """What an agent receives each step, from any backend (ours, habitat-sim, a robot).

    frame: the camera frame (``CameraFrame``: rgb uint8 (H, W, 3); depth float32 metres (H, W), 0
    where invalid (nearer than the sensor's minimum range, or at or beyond its maximum: every backend
    reports both as 0); semantic int32 (H, W) ids into ``categories`` shifted by one (0 =
    background)), made as far as it is read; pose: the agent's odometry pose; tilt: camera pitch in
    radians (positive looks up).
    """

    frame: CameraFrame
    pose: Pose
    tilt: float
    goal: str
    step: int
    collided: bool
    categories: tuple[str, ...]

    @property
    def rgb(self) -> np.ndarray:
        return self.frame.rgb

    @property
    def depth(self) -> np.ndarray:
        return self.frame.depth

    @property
    def semantic(self) -> np.ndarray:
        return self.frame.semantic

    @property
    def goal_id(self) -> int:
        """Semantic id of the goal category (1-based, matching ``semantic``)."""
        return self.categories.index(self.goal) + 1


@dataclass(frozen=True)
class EpisodeBrief:
    """What an agent is told when an episode starts: which episode (it seeds itself by the key), the
    goal category and the start pose (the origin of its odometry). Nothing the task judges by: no
    goal position, no shortest path (those stay in the world's ``Episode``)."""

    episode_id: int
    scene: str
    floor: int
    start: Pose
    goal: str

    @property
    def key(self) -> str:
        """Globally unique id used for resuming runs and naming recordings."""
        return f"{self.scene}/{self.floor}/{self.episode_id}"


@overload
def wrap_angle(angle: float) -> float: ...


@overload
def wrap_angle(angle: npt.NDArray[np.floating[Any]]) -> npt.NDArray[np.floating[Any]]: ...


def wrap_angle(angle: float | npt.NDArray[np.floating[Any]]) -> float | npt.NDArray[np.floating[Any]]:
    """``angle`` (radians; a float or a numpy array) wrapped into [-pi, pi)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi

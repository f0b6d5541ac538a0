"""The built-in simulator: a SceneMap extruded to 3D, ray-cast on the CPU, Habitat's action space.

Collisions: SemExp's channel 0 is the navmesh, i.e. where the agent's centre may stand once the
agent radius has been eroded from the free floor. A forward move is swept in sub-steps of at most one
cell; a blocked sub-step slides along the wall or stops, so a move never passes through a wall, and
``Observation.collided`` reports any move shorter than the full step.
"""

from __future__ import annotations

import math
from functools import cached_property

import numpy as np

from l3mvn.core.config import SimConfig
from l3mvn.core.errors import L3MVNError
from l3mvn.core.types import Action, Observation, Pose, wrap_angle
from l3mvn.world.episode import Episode
from l3mvn.world.scenes.scene import SceneMap
from l3mvn.world.sim.base import EpisodeState
from l3mvn.world.sim.render import Renderer
from l3mvn.world.sim.world import build_world


class BuiltinSimulator(EpisodeState):
    """One scene floor; episodes on it are reset in turn. Satisfies ``sim.base.Environment``."""

    def __init__(self, scene: SceneMap, cfg: SimConfig | None = None) -> None:
        self.scene = scene
        self.cfg = cfg or SimConfig()
        self.categories = scene.categories
        self._episode: Episode | None = None
        self._pose: Pose | None = None
        self._tilt = 0.0
        self._steps = 0
        self._path = 0.0
        self._stopped = False

    @cached_property
    def renderer(self) -> Renderer:
        return Renderer(build_world(self.scene, self.cfg), self.cfg)

    # --- contract ----------------------------------------------------------------------------
    def reset(self, episode: Episode) -> Observation:
        if (episode.scene, episode.floor) != (self.scene.name, self.scene.floor):
            raise L3MVNError(f"episode {episode.key} belongs to {episode.scene}/{episode.floor}, not {self.scene.key}")
        self._check_goal(episode.goal)
        start = episode.start
        if not self.is_walkable(start.x, start.y):
            raise L3MVNError(f"episode {episode.key}: start ({start.x:.2f}, {start.y:.2f}) m is off the navigable area")
        self._episode, self._pose = episode, start
        self._tilt, self._steps, self._path, self._stopped = 0.0, 0, 0.0, False
        return self._observe(collided=False)

    def step(self, action: Action | int | str) -> Observation:
        if self._episode is None or self._pose is None:
            raise L3MVNError("step() before reset(): start an episode first")
        if self.done:
            raise L3MVNError(f"episode {self._episode.key} is over (stopped or {self.cfg.max_steps} steps)")
        action = Action.parse(action)
        self._steps += 1
        collided = False
        pose = self._pose
        if action == Action.STOP:
            self._stopped = True
        elif action == Action.MOVE_FORWARD:
            pose, moved = self._move_forward(pose)
            self._path += moved
            collided = moved < self.cfg.forward_step_m - 1e-6
        elif action in (Action.TURN_LEFT, Action.TURN_RIGHT):
            sign = 1.0 if action == Action.TURN_LEFT else -1.0
            heading = wrap_angle(pose.heading + sign * self.cfg.turn_angle_rad)
            pose = Pose(pose.x, pose.y, heading)
        else:
            sign = 1.0 if action == Action.LOOK_UP else -1.0
            tilt = math.degrees(self._tilt) + sign * self.cfg.tilt_angle_deg
            tilt = min(max(tilt, self.cfg.min_tilt_deg), self.cfg.max_tilt_deg)
            self._tilt = math.radians(tilt)
        self._pose = pose
        return self._observe(collided)

    # --- mechanics ---------------------------------------------------------------------------
    def is_walkable(self, x: float, y: float) -> bool:
        r, c = self.scene.cell_of(x, y)
        return self.scene.in_bounds(r, c) and bool(self.scene.walkable[r, c])

    def forward_result(self, pose: Pose) -> tuple[Pose, float]:
        """Where a forward move from ``pose`` ends and how far it travels, without moving.

        Swept in sub-steps of at most one cell. A blocked sub-step slides along the wall (the
        axis-aligned component of the motion that stays walkable), as Habitat's navmesh does; a move
        that makes less than the full step counts as a collision.
        """
        step = self.cfg.forward_step_m
        n = max(1, math.ceil(step / self.scene.resolution_m))
        sub = step / n
        dx, dy = math.cos(pose.heading) * sub, math.sin(pose.heading) * sub
        x, y, moved = pose.x, pose.y, 0.0
        for _ in range(n):
            for mx, my in ((dx, dy), (dx, 0.0), (0.0, dy)) if abs(dx) >= abs(dy) else ((dx, dy), (0.0, dy), (dx, 0.0)):
                if (mx or my) and self.is_walkable(x + mx, y + my):
                    x, y = x + mx, y + my
                    moved += math.hypot(mx, my)
                    break
            else:
                break
        return Pose(x, y, pose.heading), moved

    def _move_forward(self, pose: Pose) -> tuple[Pose, float]:
        return self.forward_result(pose)

    def _observe(self, collided: bool) -> Observation:
        assert self._pose is not None and self._episode is not None
        return Observation(
            frame=self.renderer.frame(self._pose, self._tilt),
            pose=self._pose,
            tilt=self._tilt,
            goal=self._episode.goal,
            step=self._steps,
            collided=collided,
            categories=self.categories,
        )


def random_walkable_pose(scene: SceneMap, rng: np.random.Generator) -> Pose:
    cells = np.argwhere(scene.navigable)
    r, c = cells[rng.integers(len(cells))]
    x, y = scene.cell_center(int(r), int(c))
    return Pose(x, y, float(rng.uniform(-math.pi, math.pi)))

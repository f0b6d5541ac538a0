"""The simulated robot and its sensors, as the paper's Habitat setup (Gibson ObjectNav)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from l3mvn.core.errors import L3MVNError

BACKENDS = ("builtin", "habitat")


@dataclass(frozen=True)
class SimConfig:
    """Camera, depth range, actions, step budget and body of the agent the simulator moves."""

    frame_height: int = 480
    frame_width: int = 640
    hfov_deg: float = 79.0
    camera_height_m: float = 0.88
    min_depth_m: float = 0.5
    max_depth_m: float = 5.0
    forward_step_m: float = 0.25
    turn_angle_deg: float = 30.0
    tilt_angle_deg: float = 30.0
    min_tilt_deg: float = -60.0
    max_tilt_deg: float = 30.0
    max_steps: int = 500
    agent_radius_m: float = 0.18
    wall_height_m: float = 2.5
    # The highest step the agent walks up (habitat's navmesh agentMaxClimb): the floor of a scan is
    # the standing room within this of a floor's height, and its obstacles start above it.
    max_climb_m: float = 0.2
    # A scan's rendered mesh merges vertices closer than this (0: keeps every triangle): frames cost
    # time per triangle, and detail below ~2 cm is under a pixel of the agent's 120x160 frames.
    scan_vertex_merge_m: float = 0.02
    # A simulator in another process (the habitat bridge) that answers no request within this long
    # is stopped and reported: loading a large scan on a CPU renderer takes tens of seconds.
    server_timeout_s: float = 300.0
    # Who moves and renders: our simulator, or habitat-sim in the interpreter ``habitat_python``
    # (a Python that has habitat_sim; the bridge starts a server there). Both are hashed: results
    # depend on the simulator.
    backend: str = "builtin"
    habitat_python: str = ""

    def __post_init__(self) -> None:
        for name in ("frame_height", "frame_width", "max_steps"):
            if getattr(self, name) <= 0:
                raise L3MVNError(f"{name} must be positive, got {getattr(self, name)}")
        for name in (
            "camera_height_m",
            "forward_step_m",
            "turn_angle_deg",
            "tilt_angle_deg",
            "agent_radius_m",
            "wall_height_m",
            "server_timeout_s",
            "max_climb_m",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise L3MVNError(f"{name} must be a positive finite number, got {value}")
        if not 0 < self.hfov_deg < 180:
            raise L3MVNError(f"hfov_deg must lie in (0, 180), got {self.hfov_deg}")
        if not (0 < self.min_depth_m < self.max_depth_m and math.isfinite(self.max_depth_m)):
            raise L3MVNError("depth range must satisfy 0 < min_depth_m < max_depth_m < inf")
        if not (-90 < self.min_tilt_deg <= 0 <= self.max_tilt_deg < 90):
            raise L3MVNError("tilt range must satisfy -90 < min_tilt_deg <= 0 <= max_tilt_deg < 90")
        if self.turn_angle_deg >= 180:
            raise L3MVNError(f"turn_angle_deg must be below 180, got {self.turn_angle_deg}")
        if not (math.isfinite(self.scan_vertex_merge_m) and 0 <= self.scan_vertex_merge_m <= 0.1):
            raise L3MVNError(f"scan_vertex_merge_m must lie in [0, 0.1] metres, got {self.scan_vertex_merge_m}")
        if self.max_climb_m >= self.camera_height_m:
            raise L3MVNError("max_climb_m must be below camera_height_m (a step taller than the body is a wall)")
        if self.backend not in BACKENDS:
            raise L3MVNError(f"unknown simulator backend {self.backend!r}; valid: {', '.join(BACKENDS)}")
        if self.backend == "habitat" and not self.habitat_python:
            raise L3MVNError(
                "the habitat backend needs habitat_python: the python of the environment that has "
                "habitat-sim (--habitat-python PATH)"
            )
        if self.camera_height_m >= self.wall_height_m:
            raise L3MVNError("camera_height_m must be below wall_height_m (the camera would see over every wall)")

    @property
    def turn_angle_rad(self) -> float:
        return math.radians(self.turn_angle_deg)

    def with_frame(self, height: int, width: int) -> SimConfig:
        return dataclasses.replace(self, frame_height=height, frame_width=width)

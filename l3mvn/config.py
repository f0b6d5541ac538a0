"""Every constant of the task and simulator in one typed place.

Defaults follow the paper and ``l3mvn_spec.md``; each field can be overridden from the CLI and is
hashed into every result line so a number can always be traced to the settings that made it.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from dataclasses import dataclass
from typing import Any

from l3mvn.errors import L3MVNError

SUCCESS_RULES = ("semexp", "geodesic")


@dataclass(frozen=True)
class SimConfig:
    """The ObjectNav task as the paper runs it (Habitat, Gibson)."""

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
    map_resolution_m: float = 0.05
    # Channel 0 of SemExp maps is the navmesh, already eroded by the agent radius; dilating it by
    # this many cells recovers the free floor without breaching thin walls (3 does, in Lakeville).
    free_recovery_cells: int = 2
    # SemExp's ground-truth traversible map is channel 0 dilated by a disk of this radius.
    traversible_dilation_cells: int = 2
    wall_height_m: float = 2.5
    success_distance_m: float = 1.0
    success_rule: str = "semexp"

    def __post_init__(self) -> None:
        if self.success_rule not in SUCCESS_RULES:
            raise L3MVNError(
                f"unknown success rule {self.success_rule!r}; choose one of {', '.join(SUCCESS_RULES)}"
            )
        for name in ("frame_height", "frame_width", "max_steps"):
            if getattr(self, name) <= 0:
                raise L3MVNError(f"{name} must be positive, got {getattr(self, name)}")
        if not 0 < self.hfov_deg < 180:
            raise L3MVNError(f"hfov_deg must lie in (0, 180), got {self.hfov_deg}")
        if not 0 < self.min_depth_m < self.max_depth_m:
            raise L3MVNError("depth range must satisfy 0 < min_depth_m < max_depth_m")

    @property
    def turn_angle_rad(self) -> float:
        return math.radians(self.turn_angle_deg)

    def with_frame(self, height: int, width: int) -> "SimConfig":
        return dataclasses.replace(self, frame_height=height, frame_width=width)


def config_hash(*configs: Any, extra: dict | None = None) -> str:
    """A short stable hash of dataclass configs (and extra settings) for result lines."""
    payload: dict[str, Any] = {}
    for cfg in configs:
        payload[type(cfg).__name__] = dataclasses.asdict(cfg)
    if extra:
        payload["extra"] = extra
    blob = json.dumps(payload, sort_keys=True, default=str).encode()
    return hashlib.sha1(blob).hexdigest()[:12]


def config_dict(*configs: Any) -> dict[str, Any]:
    return {type(cfg).__name__: dataclasses.asdict(cfg) for cfg in configs}


def override(cfg: Any, assignments: list[str]) -> Any:
    """Apply ``name=value`` strings (from ``--set``) to a frozen dataclass, typed by its fields."""
    fields = {f.name: f for f in dataclasses.fields(cfg)}
    changes: dict[str, Any] = {}
    for item in assignments:
        name, sep, raw = item.partition("=")
        if not sep:
            raise L3MVNError(f"--set expects name=value, got {item!r}")
        if name not in fields:
            raise L3MVNError(
                f"unknown setting {name!r} for {type(cfg).__name__}; valid: {', '.join(sorted(fields))}"
            )
        current = getattr(cfg, name)
        try:
            if current is None:
                value: Any = None if raw.lower() == "none" else _number_or_text(raw)
            elif isinstance(current, bool):
                if raw.lower() not in ("true", "false", "1", "0"):
                    raise ValueError(raw)
                value = raw.lower() in ("true", "1")
            else:
                value = type(current)(raw)
        except ValueError:
            raise L3MVNError(f"setting {name} expects a {type(current).__name__}, got {raw!r}") from None
        changes[name] = value
    return dataclasses.replace(cfg, **changes)


def _number_or_text(raw: str) -> Any:
    for kind in (int, float):
        try:
            return kind(raw)
        except ValueError:
            pass
    return raw


__all__ = ["SimConfig", "SUCCESS_RULES", "config_hash", "config_dict", "override"]

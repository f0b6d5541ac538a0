"""The typed config tree: every setting of a run, each defined once, hashed beside every result.

Sections: ``sim`` (robot and sensors), ``task`` (success and failure measures), ``map``,
``frontiers``, ``planner``, ``agent`` (the map-based agent's own constants) and ``policy`` (options of
the named policy). Any field is set from the CLI as ``--set section.field=value`` (a field name that
only one section has may go without its section); the whole tree is hashed into every result line
and written beside it, so a number can always be traced to the settings that made it.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import typing
from dataclasses import dataclass, field
from typing import Any

from l3mvn.core.config.agent import AgentConfig
from l3mvn.core.config.frontiers import EDGE_MODES, UTILITY_MODES, FrontierConfig
from l3mvn.core.config.mapping import MapConfig
from l3mvn.core.config.planner import PlannerConfig
from l3mvn.core.config.policy import SELECTIONS, PolicyConfig
from l3mvn.core.config.potentials import PotentialConfig
from l3mvn.core.config.sim import SimConfig
from l3mvn.core.config.task import SUCCESS_RULES, TaskConfig
from l3mvn.core.errors import L3MVNError


@dataclass(frozen=True)
class Config:
    sim: SimConfig = field(default_factory=SimConfig)
    task: TaskConfig = field(default_factory=TaskConfig)
    map: MapConfig = field(default_factory=MapConfig)
    frontiers: FrontierConfig = field(default_factory=FrontierConfig)
    planner: PlannerConfig = field(default_factory=PlannerConfig)
    agent: AgentConfig = field(default_factory=AgentConfig)
    policy: PolicyConfig = field(default_factory=PolicyConfig)
    poni: PotentialConfig = field(default_factory=PotentialConfig)

    def __post_init__(self) -> None:
        """Checks that span sections (each section checks its own fields)."""
        agent = self.agent
        if agent.frontier_reached_m < self.frontiers.min_distance_m:
            raise L3MVNError("agent.frontier_reached_m must be >= frontiers.min_distance_m (else a dead zone)")
        if agent.blocked_stop_distance_m >= self.task.success_distance_m:
            raise L3MVNError(
                f"agent.blocked_stop_distance_m ({agent.blocked_stop_distance_m} m) must be below "
                f"task.success_distance_m ({self.task.success_distance_m} m): a stop there never succeeds"
            )
        if agent.look_tolerance_deg < self.sim.turn_angle_deg / 2:
            raise L3MVNError(
                f"agent.look_tolerance_deg ({agent.look_tolerance_deg}) must be >= half of "
                f"sim.turn_angle_deg ({self.sim.turn_angle_deg / 2}): else the agent turns past its "
                "goal and back forever"
            )
        if self.sim.agent_radius_m < self.map.resolution_m / 2:
            raise L3MVNError("sim.agent_radius_m must be at least half a map cell (map.resolution_m / 2)")
        cells = self.map.map_cells
        for section in (self.planner, self.frontiers, self.agent):
            for f in dataclasses.fields(section):
                if f.name.endswith("_cells") and getattr(section, f.name) > cells:
                    name = f"{type(section).__name__.removesuffix('Config').lower()}.{f.name}"
                    raise L3MVNError(
                        f"{name} is {getattr(section, f.name)} cells, more than the whole "
                        f"{cells}-cell map (map.map_size_m / map.resolution_m)"
                    )
        _check_memory(self)

    def replace(self, **sections: Any) -> Config:
        return dataclasses.replace(self, **sections)

    def with_frame(self, height: int, width: int) -> Config:
        return self.replace(sim=self.sim.with_frame(height, width))


SECTIONS = tuple(f.name for f in dataclasses.fields(Config))

# Upper bounds of what one episode holds per map cell (the map's layers, the planner's distance
# fields in float64 and their masks) and per camera pixel (RGB, depth, labels and their points).
MAP_BYTES_PER_CELL = 200
FRAME_BYTES_PER_PIXEL = 64


def machine_memory_bytes() -> int:
    """This machine's physical memory (a large stand-in where the OS does not say)."""
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return 1 << 50


def _check_memory(cfg: Config) -> None:
    """Refuse a tree whose map or frames could not fit in this machine's memory: it would fail every
    episode, after the run started, with a MemoryError asking for terabytes."""
    cells, have = cfg.map.map_cells, machine_memory_bytes()
    need_map = cells * cells * MAP_BYTES_PER_CELL
    need_frame = cfg.sim.frame_height * cfg.sim.frame_width * FRAME_BYTES_PER_PIXEL
    if need_map > have:
        raise L3MVNError(
            f"map.map_size_m {cfg.map.map_size_m:g} at map.resolution_m {cfg.map.resolution_m:g} is a "
            f"{cells}x{cells}-cell map, about {_size(need_map)} per episode; this machine has "
            f"{_size(have)}: choose a coarser resolution_m or a smaller map_size_m"
        )
    if need_frame > have:
        raise L3MVNError(
            f"a {cfg.sim.frame_height}x{cfg.sim.frame_width} frame needs about {_size(need_frame)}; "
            f"this machine has {_size(have)}: choose a smaller sim.frame_height / frame_width"
        )


def _size(nbytes: float) -> str:
    for unit, scale in (("TiB", 1 << 40), ("GiB", 1 << 30), ("MiB", 1 << 20)):
        if nbytes >= scale:
            return f"{nbytes / scale:.1f} {unit}"
    return f"{nbytes / 1024:.0f} KiB"


def config_dict(cfg: Config) -> dict[str, Any]:
    """The whole tree as plain data (written beside every result)."""
    return dataclasses.asdict(cfg)


def config_hash(cfg: Config, policy: str | None = None, seed: int | None = None) -> str:
    """A short stable hash of the tree, and of a run's policy name and seed when given: the one
    recipe behind every result line's ``config_hash`` (eval, the dashboard, re-runs)."""
    payload: dict[str, Any] = {"config": config_dict(cfg)}
    if policy is not None or seed is not None:
        payload["extra"] = {"policy": policy, "seed": seed}
    blob = json.dumps(payload, sort_keys=True, default=str).encode()
    return hashlib.sha1(blob).hexdigest()[:12]


def override(cfg: Config, assignments: list[str]) -> Config:
    """Apply ``section.field=value`` strings (from ``--set``), typed by the fields they name; every
    mistake is one line naming the valid choices, and the sections re-check their ranges."""
    changes: dict[str, dict[str, Any]] = {}
    for item in assignments:
        name, sep, raw = item.partition("=")
        if not sep:
            raise L3MVNError(f"--set expects section.field=value, got {item!r}")
        section, key = _resolve(cfg, name.strip())
        changes.setdefault(section, {})[key] = _parse(getattr(cfg, section), key, raw.strip(), f"{section}.{key}")
    try:
        return dataclasses.replace(cfg, **{s: dataclasses.replace(getattr(cfg, s), **kv) for s, kv in changes.items()})
    except TypeError as exc:  # a field that is not an __init__ argument
        raise L3MVNError(f"--set: {exc}") from None


def settings(cfg: Config) -> list[str]:
    """Every settable ``section.field`` of the tree."""
    return [f"{s}.{f.name}" for s in SECTIONS for f in dataclasses.fields(getattr(cfg, s)) if f.init]


def _resolve(cfg: Config, name: str) -> tuple[str, str]:
    section, dot, key = name.partition(".")
    if dot:
        if section not in SECTIONS:
            raise L3MVNError(f"unknown config section {section!r} in --set {name!r}; sections: {', '.join(SECTIONS)}")
        fields = [f.name for f in dataclasses.fields(getattr(cfg, section)) if f.init]
        if key not in fields:
            raise L3MVNError(f"unknown setting {key!r} in section {section}; valid: {', '.join(sorted(fields))}")
        return section, key
    owners = [s for s in SECTIONS if any(f.name == name and f.init for f in dataclasses.fields(getattr(cfg, s)))]
    if len(owners) == 1:
        return owners[0], name
    if owners:
        raise L3MVNError(f"setting {name!r} is in several sections: write {' or '.join(f'{s}.{name}' for s in owners)}")
    raise L3MVNError(
        f"unknown setting {name!r}; write section.field with a section of {', '.join(SECTIONS)} "
        "(`l3mvn config` lists every field)"
    )


def _parse(section_cfg: Any, key: str, raw: str, where: str) -> Any:
    kind = typing.get_type_hints(type(section_cfg))[key]
    options = [a for a in typing.get_args(kind) if a is not type(None)] or [kind]
    if raw.lower() == "none":
        if type(None) in typing.get_args(kind):
            return None
        raise L3MVNError(f"setting {where} cannot be none")
    base = options[0]
    if base in (int, float):
        return number(raw, base, f"setting {where}")
    try:
        if base is bool:
            if raw.lower() not in ("true", "false", "1", "0"):
                raise ValueError(raw)
            return raw.lower() in ("true", "1")
        return base(raw)
    except (TypeError, ValueError):
        raise L3MVNError(f"setting {where} expects a {base.__name__}, got {raw!r}") from None


def number(raw: str, kind: type, where: str) -> int | float:
    """``raw`` as a finite ``kind`` (int or float) written in ASCII (Python also reads other scripts'
    digits, which a user who typed them cannot have meant for a config), else a one-line L3MVNError
    starting with ``where``."""
    article = "an" if kind is int else "a"
    if not raw.isascii():
        raise L3MVNError(f"{where} expects {article} {kind.__name__} in ASCII digits, got {raw!r}")
    try:
        value: int | float = kind(raw)
    except (TypeError, ValueError, OverflowError):
        raise L3MVNError(f"{where} expects {article} {kind.__name__}, got {raw!r}") from None
    if isinstance(value, float) and not math.isfinite(value):
        raise L3MVNError(f"{where} expects a finite number, got {raw!r}")
    return value


__all__ = [
    "EDGE_MODES",
    "SECTIONS",
    "SELECTIONS",
    "SUCCESS_RULES",
    "UTILITY_MODES",
    "AgentConfig",
    "Config",
    "FrontierConfig",
    "MapConfig",
    "PlannerConfig",
    "PolicyConfig",
    "PotentialConfig",
    "SimConfig",
    "TaskConfig",
    "config_dict",
    "config_hash",
    "override",
    "settings",
]

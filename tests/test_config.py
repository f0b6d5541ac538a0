"""The config tree: one place per setting, typed ``--set``, a hash that sees every field."""

import dataclasses

import pytest

from l3mvn.core.config import (
    SECTIONS,
    AgentConfig,
    Config,
    SimConfig,
    TaskConfig,
    config_dict,
    config_hash,
    override,
    settings,
)
from l3mvn.core.errors import L3MVNError


def test_every_field_of_every_section_changes_the_hash():
    base = Config()
    for name in settings(base):
        section, key = name.split(".")
        value = getattr(getattr(base, section), key)
        assignment = {
            bool: lambda v: str(not v),
            int: lambda v: str(v + 1),
            float: lambda v: repr(v * 1.01 + 0.001),
            str: lambda v: v,
        }.get(type(value))
        if assignment is None or isinstance(value, str):
            continue  # None-able and enumerated fields: checked below with valid values
        try:
            changed = override(base, [f"{name}={assignment(value)}"])
        except L3MVNError:
            continue  # a neighbouring value out of range (e.g. a probability at 1.0)
        assert config_hash(changed) != config_hash(base), name
    assert config_hash(override(base, ["policy.scorer=roomtype"])) != config_hash(base)
    assert config_hash(override(base, ["task.success_rule=geodesic"])) != config_hash(base)


def test_set_is_typed_and_a_unique_field_needs_no_section():
    cfg = override(Config(), ["sim.max_steps=300", "replan_every=5", "frontiers.top_k=4", "policy.scorer=none"])
    assert cfg.sim.max_steps == 300 and cfg.agent.replan_every == 5 and cfg.frontiers.top_k == 4
    assert cfg.policy.scorer is None and isinstance(cfg.sim.max_steps, int)
    assert override(cfg, ["frontiers.top_k=none"]).frontiers.top_k is None


@pytest.mark.parametrize(
    "assignment, message",
    [
        ("nope=1", "unknown setting 'nope'; write section.field with a section of sim, task, map"),
        ("agent.nope=1", "unknown setting 'nope' in section agent; valid: .*replan_every"),
        ("zzz.a=1", "unknown config section 'zzz'.*sections: sim, task, map, frontiers, planner, agent, policy"),
        (
            "obstacle_dilation_cells=2",
            "in several sections: write frontiers.obstacle_dilation_cells or planner.obstacle_dilation_cells",
        ),
        ("sim.max_steps=ten", "sim.max_steps expects an int, got 'ten'"),
        ("sim.max_steps=٣٠", "sim.max_steps expects an int in ASCII digits, got '٣٠'"),
        ("map.resolution_m=0.0005", "is a 96000x96000-cell map, about 1.7 TiB per episode; this machine has"),
        (
            "planner.clearance_cells=1000000",
            "planner.clearance_cells is 1000000 cells, more than the whole 960-cell map",
        ),
        ("task.success_distance_m=nan", "expects a finite number"),
        ("sim.max_depth_m=inf", "expects a finite number"),
        ("map.resolution_m=0", "resolution_m must be positive"),
        ("sim.forward_step_m=-1", "forward_step_m must be a positive finite number"),
        ("sim.agent_radius_m=-5", "agent_radius_m must be a positive finite number"),
        ("sim.max_steps=none", "sim.max_steps cannot be none"),
        ("max_steps", "expects section.field=value"),
        ("agent.look_tolerance_deg=10", "must be >= half of sim.turn_angle_deg"),
        ("agent.blocked_stop_distance_m=1.0", "must be below task.success_distance_m"),
    ],
)
def test_every_bad_setting_is_one_line_naming_the_choices(assignment, message):
    with pytest.raises(L3MVNError, match=message) as err:
        override(Config(), [assignment])
    assert "\n" not in str(err.value)


def test_cross_section_rules_see_both_sections():
    with pytest.raises(L3MVNError, match="blocked_stop_distance_m"):
        Config(task=TaskConfig(success_distance_m=0.9))
    Config(
        task=TaskConfig(success_distance_m=0.9), agent=AgentConfig(stop_distance_m=0.8, blocked_stop_distance_m=0.85)
    )


def test_the_tree_is_plain_data_in_section_order():
    tree = config_dict(Config())
    assert tuple(tree) == SECTIONS == ("sim", "task", "map", "frontiers", "planner", "agent", "policy", "poni")
    assert tree["sim"]["max_steps"] == 500 and tree["task"]["success_rule"] == "semexp"
    assert "map_resolution_m" not in tree["sim"] and "resolution_m" not in tree["planner"]


def test_each_constant_is_defined_once():
    """A field name in two sections must mean two different things (both listed here)."""
    seen: dict[str, list[str]] = {}
    for name in settings(Config()):
        section, key = name.split(".")
        seen.setdefault(key, []).append(section)
    shared = {k: v for k, v in seen.items() if len(v) > 1}
    # frontiers grow obstacles to find frontier edges, the planner to plan paths: two settings.
    assert shared == {"obstacle_dilation_cells": ["frontiers", "planner"]}


def test_with_frame_changes_only_the_frame():
    small = Config().with_frame(120, 160)
    assert (small.sim.frame_height, small.sim.frame_width) == (120, 160)
    assert dataclasses.replace(small.sim, frame_height=480, frame_width=640) == SimConfig()


@pytest.mark.parametrize(
    "setting",
    [
        "map.free_space_bins=-1",
        "agent.blocked_radius_m=0",
        "agent.candidate_reached_m=-1",
        "agent.look_around_steps=-1",
        "agent.escape_after_unreachable=0",
        "agent.max_reselect=-2",
        "agent.target_escapes=-1",
        "agent.commitment_margin=-0.1",
        "agent.explore_goal_dilation_m=-0.1",
        "agent.blocked_frontier_gap_m=-0.1",
        "agent.goal_progress_area_m2=-1",
    ],
)
def test_counts_and_distances_out_of_range_are_one_line_errors_naming_the_field(setting):
    with pytest.raises(L3MVNError) as err:
        override(Config(), [setting])
    assert setting.split(".")[1].split("=")[0] in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--speed", "-1"], "error: --speed must be a number of steps per second from 0.5 to 60, got -1.0"),
        (["--speed", "nan"], "argument --speed: expects a finite number, got 'nan'"),
        (["--speed", "٣"], "argument --speed: expects a float in ASCII digits, got '٣'"),
        (["--port", "٨٠٨٠"], "argument --port: expects an int in ASCII digits, got '٨٠٨٠'"),
        (["--set", "sim.max_steps=٣٠"], "error: setting sim.max_steps expects an int in ASCII digits"),
    ],
)
def test_serve_flags_follow_the_rules_of_set(argv, message, capsys):
    """Refused before anything is served: one line, status 2, never a clamped or misread value."""
    from l3mvn_studio.cli import main as serve_cli

    try:
        code = serve_cli(["serve", *argv])
    except SystemExit as stop:  # argparse's own refusal
        code = stop.code
    err = capsys.readouterr().err
    assert code == 2 and message in err, err

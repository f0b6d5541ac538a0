"""Recordings of a language policy: per-goal scores over time and the fusion line, read back with
rerun's own reader and checked against the decisions the recorder was sent."""

import dataclasses
import math

import pytest
from rerun.chunk import RrdReader

from l3mvn.agent.language import GOALS
from l3mvn.core.config import AgentConfig, Config, SimConfig
from l3mvn.core.types import Pose
from l3mvn.run.events import EventBus
from l3mvn.run.recording import Recorder
from l3mvn.run.recording.entities import (
    LANGUAGE_CHOSEN,
    LANGUAGE_CHOSEN_METRES,
    LOG_FUSION,
    METRICS_LANGUAGE,
    TEXT_LOG,
    language_by_goal,
    reader_path,
)
from l3mvn.run.runner import Runner
from l3mvn.world.episode import Episode

CONFIG = Config(
    sim=dataclasses.replace(SimConfig().with_frame(60, 80), max_steps=40), agent=AgentConfig(look_around_steps=2)
)


pytestmark = pytest.mark.usefixtures("strict_rerun")  # a bad log call fails the test (conftest)


def _by_step(path, entity, column) -> dict[int, list]:
    out = {}
    for chunk in RrdReader(path).stream():
        batch = chunk.to_record_batch()
        if chunk.entity_path == reader_path(entity) and column in batch.schema.names and "step" in batch.schema.names:
            for step, value in zip(batch.column("step").to_pylist(), batch.column(column).to_pylist()):
                if value is not None:
                    out[step] = value
    return out


def _static(path, entity, column) -> list:
    return [
        v
        for chunk in RrdReader(path).stream()
        if chunk.entity_path == reader_path(entity)
        for v in (
            chunk.to_record_batch().column(column).to_pylist() if column in chunk.to_record_batch().schema.names else []
        )
        if v is not None
    ]


def _record(tiny_scene, tmp_path, policy: str, config: Config = CONFIG):
    episode = Episode(episode_id=0, scene="Tiny", floor=0, start=Pose(2.5, 2.0, 0.0), goal="toilet")
    bus, events = EventBus(), []
    bus.subscribe(events.append)
    recorder = Recorder.for_episode(tmp_path, "tiny", episode, policy).attach(bus)
    Runner(config).run(tiny_scene, episode, policy, bus)
    assert recorder.errors == 0
    return recorder.path, events


def test_the_chosen_frontiers_per_goal_scores_and_the_fusion_line_are_recorded_per_step(tiny_scene, tmp_path):
    path, events = _record(tiny_scene, tmp_path, "l3mvn-zs")
    chosen = {
        ev.step: ev.decision.frontiers[ev.decision.chosen_frontier]
        for ev in events
        if ev.decision is not None and ev.decision.chosen_frontier is not None and ev.decision.frontiers
    }
    assert chosen, "the agent never chose a frontier"

    assert _static(path, LANGUAGE_CHOSEN, "SeriesLines:names")[-1] == list(GOALS)
    rows = _by_step(path, LANGUAGE_CHOSEN, "Scalars:scalars")
    for step, frontier in chosen.items():
        assert rows[step] == pytest.approx([frontier.llm_scores[g] for g in GOALS])
    gaps = [step for step, row in rows.items() if step not in chosen]  # a goal that is not a frontier: a gap
    assert all(all(math.isnan(v) for v in rows[s]) for s in gaps)

    toilet = _by_step(path, language_by_goal("toilet"), "Scalars:scalars")
    names = _static(path, language_by_goal("toilet"), "SeriesLines:names")[-1]
    step, frontier = next(iter(chosen.items()))
    assert toilet[step][names.index(f"F{frontier.id}")] == pytest.approx(frontier.llm_scores["toilet"])
    assert reader_path(language_by_goal("potted plant")) in {c.entity_path for c in RrdReader(path).stream()}

    lines = {step: text for step, (text,) in _by_step(path, LOG_FUSION, TEXT_LOG).items()}
    first = min(chosen)
    assert lines[first] == events[first].decision.frontiers[0].fusion.describe()
    assert lines[first].startswith("bound B = [0.15, 0.30]; max S_LLM")
    # Once no frontier is the goal (here: the toilet seen), a line says no rule is in force, so a
    # replayed or exported step never shows the last choice's rule behind a walk to the target.
    after = next(ev for ev in events if ev.step > max(chosen) and ev.decision is not None)
    assert after.decision.goal_kind != "frontier"
    assert (
        lines[after.step]
        == f"no frontier choice in force: the goal is {str(after.decision.goal_kind)!r}, not a frontier"
    )
    assert max(lines) == after.step  # and nothing more while no frontier is chosen again
    assert not _static(path, LANGUAGE_CHOSEN_METRES, "SeriesLines:names")  # the room scorer gives no metres


def test_a_distance_head_records_the_chosen_frontiers_expected_metres_to_each_goal(tiny_scene, tmp_path):
    config = CONFIG.replace(policy=dataclasses.replace(CONFIG.policy, head="frontiers", selection="expected"))
    path, events = _record(tiny_scene, tmp_path, "l3mvn-ff", config)
    chosen = {
        ev.step: ev.decision.frontiers[ev.decision.chosen_frontier]
        for ev in events
        if ev.decision is not None and ev.decision.chosen_frontier is not None and ev.decision.frontiers
    }
    assert chosen
    assert _static(path, LANGUAGE_CHOSEN_METRES, "SeriesLines:names")[-1] == list(GOALS)
    rows = _by_step(path, LANGUAGE_CHOSEN_METRES, "Scalars:scalars")
    for step, frontier in chosen.items():
        assert rows[step] == pytest.approx([frontier.expected_m[g] for g in GOALS])
    assert _by_step(path, LOG_FUSION, TEXT_LOG)[min(chosen)][0].startswith("expected: least metres")


def test_a_policy_without_language_records_no_language_series(tiny_scene, tmp_path):
    path, _ = _record(tiny_scene, tmp_path, "cost-utility")
    entities = {c.entity_path for c in RrdReader(path).stream()}
    assert not any(e.startswith(reader_path(METRICS_LANGUAGE)) or e == reader_path(LOG_FUSION) for e in entities)

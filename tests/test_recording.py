"""Rerun recordings: the real loop writes an .rrd that rerun's own reader reads back."""

from __future__ import annotations

import argparse
import dataclasses
import os
import re
import time

import numpy as np
import pytest
from rerun.chunk import RrdReader

from l3mvn.core.config import AgentConfig, Config, SimConfig
from l3mvn.core.errors import L3MVNError
from l3mvn.core.frames import CameraFrame
from l3mvn.core.types import Action
from l3mvn.run.events import EventBus
from l3mvn.run.recording import (
    Recorder,
    add_replay_arguments,
    list_recordings,
    open_recording,
    parse_recording_name,
    read_recording,
    recording_path,
    run_replay,
)
from l3mvn.run.recording.catalogue import unique_tag
from l3mvn.run.recording.entities import (
    CAMERA,
    CAMERA_DEPTH,
    CAMERA_RGB,
    CAMERA_SEMANTIC,
    EPISODE,
    LOG_DECISIONS,
    LOG_EPISODE,
    MAP,
    MAP_AGENT,
    MAP_COLLISION_MARKS,
    MAP_FRONTIER_CELLS,
    MAP_FRONTIERS,
    MAP_GOAL,
    MAP_SEMANTIC,
    MAP_TARGET,
    MAP_TRAJECTORY,
    METRICS_CHOSEN_FRONTIER,
    METRICS_FRONTIER_SCORES,
    METRICS_FRONTIERS,
    METRICS_GROUND_TRUTH,
    METRICS_TIMINGS_MS,
    POINTS_LABELS,
    POINTS_POSITIONS,
    TEXT_LOG,
    WORLD_AGENT,
    WORLD_GOAL,
    WORLD_TRAJECTORY,
    reader_path,
)
from l3mvn.run.recording.layout import LABELLED_FRONTIERS
from l3mvn.run.runner import Runner
from l3mvn.world.episodes import generate_episodes

MAX_STEPS = 15
ALWAYS = {
    reader_path(e)
    for e in (
        CAMERA,
        CAMERA_RGB,
        CAMERA_DEPTH,
        CAMERA_SEMANTIC,
        WORLD_AGENT,
        WORLD_TRAJECTORY,
        METRICS_GROUND_TRUTH,
        METRICS_TIMINGS_MS,
        LOG_DECISIONS,
        LOG_EPISODE,
        EPISODE,
    )
}
MAPPED = {
    reader_path(e)
    for e in (
        MAP,
        MAP_SEMANTIC,
        MAP_TRAJECTORY,
        MAP_AGENT,
        MAP_GOAL,
        MAP_FRONTIERS,
        MAP_FRONTIER_CELLS,
        METRICS_FRONTIERS,
        WORLD_GOAL,
    )
}


pytestmark = pytest.mark.usefixtures("strict_rerun")  # a bad log call fails the test (conftest)


CONFIG = Config(sim=dataclasses.replace(SimConfig().with_frame(60, 80), max_steps=MAX_STEPS))


@pytest.fixture
def runner():
    return Runner(CONFIG, config_hash="test")


def _episode(scene, goal="toilet"):
    return generate_episodes(scene, 1, seed=3, goals=(goal,))[0]


def _record(runner, scene, policy_name, tmp_path):
    episode = _episode(scene)
    bus = EventBus()
    recorder = Recorder.for_episode(tmp_path, "tiny_ds", episode, policy_name).attach(bus)
    result = runner.run(scene, episode, policy_name, bus)
    return recorder, result, bus


def _values(path, entity, column):
    """Every value of one component column of one entity, read with rerun's own reader."""
    out = []
    for chunk in RrdReader(path).stream():
        if chunk.entity_path == reader_path(entity) and column in chunk.to_record_batch().schema.names:
            out += [v for row in chunk.to_record_batch().column(column).to_pylist() for v in (row or [])]
    return out


def test_oracle_episode_records_camera_world_metrics_and_one_row_per_step_without_map(runner, tiny_scene, tmp_path):
    recorder, result, bus = _record(runner, tiny_scene, "oracle", tmp_path)

    assert recorder.closed and recorder.errors == 0 and len(bus) == 0  # closed on done, unsubscribed
    summary = read_recording(recorder.path)
    assert summary.application_id == "l3mvn"
    assert ALWAYS <= set(summary.entity_paths)
    assert not any(p.startswith(reader_path(MAP)) for p in summary.entity_paths)  # no map: no map entities
    assert result.steps == MAX_STEPS
    assert summary.steps == tuple(range(MAX_STEPS + 1))  # the reset event is step 0
    decisions = _values(recorder.path, LOG_DECISIONS, TEXT_LOG)
    assert len(decisions) == MAX_STEPS
    assert all(d.split()[0] in {a.name.lower() for a in Action} for d in decisions)


def test_map_agent_episode_records_map_frontiers_goal_and_trajectory(tiny_scene, tmp_path):
    runner = Runner(CONFIG.replace(agent=AgentConfig(look_around_steps=2)))
    recorder, result, _ = _record(runner, tiny_scene, "frontier", tmp_path)

    assert recorder.errors == 0
    summary = read_recording(recorder.path)
    assert ALWAYS | MAPPED <= set(summary.entity_paths)
    assert summary.steps == tuple(range(result.steps + 1))
    assert open_recording(recorder.path).blueprints()  # the default layout travels with the file
    assert recorder.path == tmp_path / "tiny-ds_Tiny_0_frontier.rrd"
    labels = _values(recorder.path, MAP_FRONTIERS, POINTS_LABELS)
    assert labels and all(re.fullmatch(r"(★?F\d+ (fused|LLM|CU) \d\.\d\d)?", label) for label in labels)
    assert any(label.startswith("★") for label in labels)  # the chosen frontier is marked
    assert len(_values(recorder.path, MAP_FRONTIERS, "score_cu")) == len(labels)  # every score on hover


def test_the_agents_collision_marks_are_recorded_once_per_change_at_their_cells(tiny_scene, tmp_path, monkeypatch):
    """The cells that closed a passage the map shows free must be visible in a replay too."""
    from l3mvn.agent.planning import LocalPlanner

    marks = np.array([[480, 484], [481, 484], [482, 485]], np.int32)  # beside the start, the map centre
    monkeypatch.setattr(LocalPlanner, "collision_cells", property(lambda self: marks))
    recorder, _, _ = _record(Runner(CONFIG), tiny_scene, "frontier", tmp_path)
    assert recorder.errors == 0
    positions = _rows(recorder.path, MAP_COLLISION_MARKS, POINTS_POSITIONS)
    assert len(positions) == 1  # the same array every step: written once
    assert np.allclose(positions[0], marks[:, ::-1] + 0.5)
    # The exported video draws them too: the last frame holds the marks' colour, and only because of them.
    from l3mvn.run.recording.drawing import VideoOptions, frames
    from l3mvn.run.recording.recorded import read_episode
    from l3mvn.run.viz import COLLISION_RGB

    episode = read_episode(recorder.path)
    assert np.allclose(episode.steps[-1].collision_marks, marks[:, ::-1] + 0.5)
    last = list(frames(episode, VideoOptions(height=240), title_frames=0))[-1]
    assert (last == COLLISION_RGB).all(axis=2).any()
    episode.steps[-1] = dataclasses.replace(episode.steps[-1], collision_marks=None)
    last = list(frames(episode, VideoOptions(height=240), title_frames=0))[-1]
    assert not (last == COLLISION_RGB).all(axis=2).any()


def _rows(path, entity, column):
    """Each logged row of one component column of one entity, in step order."""
    out = []
    for chunk in RrdReader(path).stream():
        batch = chunk.to_record_batch()
        if chunk.entity_path == reader_path(entity) and column in batch.schema.names:
            steps = batch.column("step").to_pylist() if "step" in batch.schema.names else [None] * batch.num_rows
            out += [(s, v) for s, v in zip(steps, batch.column(column).to_pylist()) if v is not None]
    return [v for _, v in sorted(out, key=lambda sv: -1 if sv[0] is None else sv[0])]


def test_only_the_best_three_frontiers_and_the_chosen_one_are_labelled_and_scores_are_series(tiny_scene, tmp_path):
    runner = Runner(CONFIG.replace(agent=AgentConfig(look_around_steps=2)))
    recorder, _, _ = _record(runner, tiny_scene, "cost-utility", tmp_path)
    rows = zip(
        _rows(recorder.path, MAP_FRONTIERS, POINTS_LABELS),
        _rows(recorder.path, MAP_FRONTIERS, "score_cu"),
        _rows(recorder.path, MAP_FRONTIERS, "chosen"),
    )
    for labels, scores, chosen in rows:
        best = set(np.argsort(-np.array(scores), kind="stable")[:LABELLED_FRONTIERS].tolist())
        assert {i for i, label in enumerate(labels) if label} == best | {i for i, c in enumerate(chosen) if c}
    names = _rows(recorder.path, METRICS_FRONTIER_SCORES, "SeriesLines:names")[-1]
    series = _rows(recorder.path, METRICS_FRONTIER_SCORES, "Scalars:scalars")
    frontiers = _rows(recorder.path, METRICS_FRONTIERS, "Scalars:scalars")
    assert names[:2] == ["F0", "F1"] and series
    skipped = frontiers[: len(frontiers) - len(series)]  # before the first frontier there is no line to log
    assert all(count == 0 for (count,) in skipped)
    for row, (count,) in zip(series, frontiers[len(skipped) :]):  # a value per frontier of the step, gaps for others
        assert sum(np.isfinite(v) for v in row) == count
    assert _rows(recorder.path, METRICS_CHOSEN_FRONTIER, "SeriesLines:names")[-1] == ["LLM", "CU", "fused"]


def test_poni_potentials_are_named_as_potentials_not_as_a_language_models_scores(tiny_scene, tmp_path):
    runner = Runner(CONFIG.replace(agent=AgentConfig(look_around_steps=2)))
    recorder, _, _ = _record(runner, tiny_scene, "poni", tmp_path)
    assert _rows(recorder.path, METRICS_CHOSEN_FRONTIER, "SeriesLines:names")[-1] == ["pot", "CU", "fused"]
    labels = [label for row in _rows(recorder.path, MAP_FRONTIERS, POINTS_LABELS) for label in row if label]
    assert labels and not any(" LLM " in label for label in labels)


def test_the_target_is_boxed_on_the_map_and_the_view_is_fitted_to_the_mapped_area(tiny_scene, tmp_path):
    runner = Runner(
        CONFIG.replace(sim=dataclasses.replace(CONFIG.sim, max_steps=60), agent=AgentConfig(look_around_steps=2))
    )
    recorder, _, _ = _record(runner, tiny_scene, "frontier", tmp_path)
    boxes = _rows(recorder.path, MAP_TARGET, "Boxes2D:labels")
    assert boxes and boxes[-1][0] == "target: toilet"
    ranges = [
        c
        for bp in open_recording(recorder.path).blueprints()
        for chunk in RrdReader(recorder.path).stream(store=bp)
        if "VisualBounds2D:range" in chunk.to_record_batch().schema.names
        for c in chunk.to_record_batch().column("VisualBounds2D:range").to_pylist()
        if c
    ]
    final = ranges[-1][0]  # sent at the end: the house mapped (<= 10 x 5 m at 5 cm), with a margin
    assert 0 < final["x_range"][1] - final["x_range"][0] <= 200 * 1.2 + 1
    assert 0 < final["y_range"][1] - final["y_range"][0] <= 200 * 1.2 + 1


def test_two_recordings_written_concurrently_stay_separate(tiny_scene, tmp_path):
    episodes = [_episode(tiny_scene, "toilet"), _episode(tiny_scene, "bed")]
    sessions, recorders = [], []
    for ep, name in zip(episodes, ("random-walk", "oracle")):
        bus = EventBus()
        recorders.append(Recorder.for_episode(tmp_path, "tiny", ep, name).attach(bus))
        sessions.append(Runner(CONFIG).session(tiny_scene, name, bus))  # a runner each: two simulators
        sessions[-1].start(ep)
    while not all(s.done for s in sessions):  # interleave the two loops step by step
        for s in sessions:
            if not s.done:
                s.step()

    for s, rec in zip(sessions, recorders):
        summary = read_recording(rec.path)
        assert rec.errors == 0
        assert summary.steps == tuple(range(s.result.steps + 1))
    assert read_recording(recorders[0].path).recording_id != read_recording(recorders[1].path).recording_id


def test_a_failing_event_is_counted_not_raised_and_the_file_still_closes(runner, tiny_scene, tmp_path):
    episode = _episode(tiny_scene)
    bus = EventBus()
    recorder = Recorder.for_episode(tmp_path, "tiny", episode, "random-walk").attach(bus)
    first = runner.session(tiny_scene, "random-walk", bus).start(episode)
    broken = dataclasses.replace(
        first,
        step=1,
        observation=dataclasses.replace(
            first.observation,
            frame=CameraFrame.of(
                np.zeros((*first.observation.depth.shape, 5), np.uint8),  # no image has five channels
                first.observation.depth,
                first.observation.semantic,
            ),
        ),
    )
    recorder(broken)  # called directly: the bus would swallow an exception, the recorder must not raise one
    assert recorder.errors == 1
    recorder.close()
    assert recorder.closed and read_recording(recorder.path).steps  # what was logged is readable


def test_recording_path_follows_the_pattern_and_parses_back(tmp_path):
    path = recording_path(tmp_path / "recordings", "/data/gibson_semexp", "Tiny", 7, "cost-utility")
    assert path == tmp_path / "recordings" / "gibson-semexp_Tiny_7_cost-utility.rrd"
    assert parse_recording_name(path) == ("gibson-semexp", "Tiny", 7, "cost-utility", None)
    assert parse_recording_name(tmp_path / "holiday.rrd") is None
    with pytest.raises(L3MVNError, match="cannot name a recording"):
        recording_path(tmp_path, "ds", "___", 1, "oracle")
    tag = unique_tag("rerun")
    assert re.fullmatch(r"rerun-\d{8}T\d{6}Z-\d+-[0-9a-f]{6}", tag) and tag != unique_tag("rerun")
    tagged = recording_path(tmp_path, "ds", "Tiny", 7, "oracle", tag)
    assert tagged.name == f"ds_Tiny_7_oracle_{tag}.rrd"
    assert parse_recording_name(tagged) == ("ds", "Tiny", 7, "oracle", tag)


def test_one_path_has_one_writer_at_a_time(tmp_path):
    """A second recorder of a path that is being written is refused before it touches the file."""
    path = tmp_path / "ep.rrd"
    first = Recorder(path, dataset="ds", scene="s", episode_id=0, policy="oracle")
    size = path.stat().st_size
    with pytest.raises(L3MVNError, match=r"recording .*ep.rrd is being written by another recorder"):
        Recorder(path, dataset="ds", scene="s", episode_id=0, policy="oracle")
    assert path.stat().st_size >= size
    first.close()
    assert read_recording(path).application_id == "l3mvn"
    Recorder(path, dataset="ds", scene="s", episode_id=0, policy="oracle").close()  # free again once closed


def test_list_recordings_parses_names_newest_first_and_keeps_foreign_files(tmp_path):
    old = recording_path(tmp_path, "procedural", "house-3", 2, "oracle")
    new = recording_path(tmp_path, "procedural", "house-4", 0, "frontier")
    foreign = tmp_path / "my_run.rrd"
    for i, p in enumerate((old, foreign, new)):
        p.write_bytes(b"x" * (i + 1))
        os.utime(p, (time.time() - 100 + i, time.time() - 100 + i))
    (tmp_path / "notes.txt").write_text("not a recording")

    infos = list_recordings(tmp_path)
    assert [i.path for i in infos] == [new, foreign, old]
    assert (infos[0].dataset, infos[0].scene, infos[0].episode_id, infos[0].policy) == (
        "procedural",
        "house-4",
        0,
        "frontier",
    )
    assert infos[0].size_bytes == 3 and infos[1].policy is None
    assert list_recordings(tmp_path / "absent") == []


def test_a_recording_that_cannot_be_written_is_refused_up_front(tmp_path):
    blocker = tmp_path / "recordings"
    blocker.write_text("a file where the folder should be")
    with pytest.raises(L3MVNError, match="cannot write recording"):
        Recorder(blocker / "x.rrd", dataset="d", scene="s", episode_id=0, policy="oracle")


def _replay_args(*argv):
    parser = argparse.ArgumentParser()
    add_replay_arguments(parser)
    return parser.parse_args(list(argv))


def test_replay_rejects_a_corrupt_recording_naming_the_file(tmp_path):
    bad = tmp_path / "broken.rrd"
    bad.write_bytes(b"definitely not a rerun file")
    with pytest.raises(L3MVNError, match="broken.rrd is not a readable rerun recording"):
        run_replay(_replay_args(str(bad), "--web"))


def test_replay_rejects_a_missing_recording_naming_the_file(tmp_path):
    with pytest.raises(L3MVNError, match="nothere.rrd not found"):
        run_replay(_replay_args(str(tmp_path / "nothere.rrd")))


def test_a_recording_cut_off_mid_write_is_reported_as_unreadable(runner, tiny_scene, tmp_path):
    recorder, _, _ = _record(runner, tiny_scene, "random-walk", tmp_path)
    data = recorder.path.read_bytes()
    cut = tmp_path / "cut.rrd"
    cut.write_bytes(data[: len(data) // 2])
    open_recording(recorder.path)
    with pytest.raises(L3MVNError, match="cut.rrd"):
        read_recording(cut)

"""``l3mvn export``: a video read back from a real recording decodes with one frame per step."""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import re
import shutil
import sys

import av
import cv2
import numpy as np
import pytest

from l3mvn.core.config import Config, SimConfig
from l3mvn.core.errors import L3MVNError
from l3mvn.run.eval.result_videos import add_export_arguments, export_result_video, result_video_name, run_export
from l3mvn.run.events import EventBus
from l3mvn.run.recording import Recorder, read_recording
from l3mvn.run.recording import video as video_module
from l3mvn.run.recording.drawing import PANEL_BG, FrameGeometry, VideoOptions, frames
from l3mvn.run.recording.recorded import read_episode
from l3mvn.run.recording.video import export_video
from l3mvn.run.runner import Runner
from l3mvn.world.episodes import generate_episodes
from l3mvn.world.scenes.procedural import generate_house

MAX_STEPS = 24
CONFIG = Config(sim=dataclasses.replace(SimConfig().with_frame(60, 80), max_steps=MAX_STEPS))


@pytest.fixture(scope="module")
def house():
    return generate_house(3)


def _record(folder, scene, policy, events=None):
    episode = generate_episodes(scene, 1, seed=3, goals=("toilet",))[0]
    bus = EventBus()
    if events is not None:
        bus.subscribe(events.append)
    recorder = Recorder.for_episode(folder, "procedural", episode, policy).attach(bus)
    result = Runner(CONFIG).run(scene, episode, policy, bus)
    return recorder.path, result


@pytest.fixture(scope="module")
def recorded(house, tmp_path_factory):
    """A real frontier-agent episode on a procedural house, recorded by the real recorder."""
    return _record(tmp_path_factory.mktemp("recordings"), house, "frontier")


def _decode(path):
    cap = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        frames.append(frame[..., ::-1])
    cap.release()
    return frames


def test_the_mp4_has_the_title_card_then_one_frame_per_step_at_the_stated_size(recorded, tmp_path):
    path, result = recorded
    steps = read_recording(path).steps
    assert steps == tuple(range(result.steps + 1))  # the reset is step 0
    options = VideoOptions(fps=5, height=240, title_s=1.0)

    video = export_video(path, tmp_path / "ep.mp4", options)

    frames = _decode(video.path)
    assert video.title_frames == 5 and video.steps == len(steps)
    assert len(frames) == video.frames == 5 + len(steps)
    assert {f.shape for f in frames} == {(video.height, video.width, 3)}
    assert video.height == 240 + 56  # the panels, then the text band
    assert 320 + 6 + 0.75 * 240 <= video.width <= 320 + 6 + 1.6 * 240 + 1  # 4:3 camera, the map at its aspect
    title, first_step = frames[0].astype(int), frames[5].astype(int)
    banner = title[5 : video.height // 4 - 5, :].reshape(-1, 3).mean(axis=0)
    failed = result.success == 0.0
    assert (banner[0] > banner[1] + 60) == failed and (banner[1] > banner[0] + 60) == (not failed)  # red / green
    assert all(np.abs(f.astype(int) - title).mean() < 4 for f in frames[:5])  # the card is held
    assert np.abs(first_step - title).mean() > 20  # then the steps begin


def test_each_step_frame_shows_that_steps_map_and_camera(recorded, tmp_path):
    path, _ = recorded
    ep = read_episode(path)
    assert ep.policy == "frontier" and ep.scene == "procedural-0003" and ep.steps[0].goal == "toilet"
    assert ep.result["failure"] and ep.outcome in {"success", f"fail_{ep.result['failure']}"}
    assert [s.step for s in ep.steps] == list(read_recording(path).steps)
    assert all(s.decision for s in ep.steps)
    mapped = [int((s.map_ids[2] > 0).sum()) for s in ep.steps if s.map_ids is not None]
    assert mapped[-1] > mapped[0]  # the map grows as the agent explores
    assert any(s.frontiers is not None and any(s.frontiers.labels) for s in ep.steps)

    options = VideoOptions(height=240, title_s=0)
    decoded = _decode(export_video(path, tmp_path / "ep.mp4", options).path)[1:]
    drawn = list(frames(ep, options, title_frames=0))
    assert len(decoded) == len(drawn) == len(ep.steps)
    assert max(np.abs(a.astype(int) - b).mean() for a, b in zip(decoded, drawn)) < 6  # what was drawn, per step
    first, last = drawn[0][:240, 326:].astype(int), drawn[-1][:240, 326:].astype(int)
    assert np.abs(last - first).mean() > 5  # the map panel shows the map of its own step


def _probe(path):
    """(container format, codec, RGB frames) as PyAV, the library that wrote it, reads ``path``."""
    with av.open(str(path)) as container:
        codec = container.streams.video[0].codec_context.name
        decoded = [f.to_ndarray(format="rgb24") for f in container.decode(video=0)]
        return container.format.name, codec, decoded


def test_the_video_is_h264_in_mp4_with_its_index_first_and_shows_what_was_drawn(recorded, tmp_path):
    """Issue 34 item 1: H.264 plays in every browser; mp4v (MPEG-4 Part 2) did not."""
    path, _ = recorded
    ep = read_episode(path)
    options = VideoOptions(fps=5, height=240, title_s=0.4)
    video = export_video(path, tmp_path / "ep.mp4", options)
    assert video.path == tmp_path / "ep.mp4" and video.codec == "h264"
    container, codec, decoded = _probe(video.path)
    assert "mp4" in container.split(",") and codec == "h264"
    assert len(decoded) == video.frames == 2 + len(ep.steps)
    data = video.path.read_bytes()
    assert 0 < data.find(b"moov") < data.find(b"mdat")  # faststart: a browser can play before the whole file is in
    drawn = list(frames(ep, options, title_frames=0))
    errors = [np.abs(a.astype(int) - b).mean() for a, b in zip(decoded[2:], drawn)]
    assert max(errors) < 4  # lossy, but each frame is the one drawn for its step
    assert np.abs(decoded[2].astype(int) - drawn[-1]).mean() > 3 * errors[0]  # and not any other step's


def test_without_libx264_the_video_is_vp9_in_webm_and_says_so_in_one_line(recorded, tmp_path, monkeypatch, caplog):
    path, _ = recorded
    monkeypatch.setattr(video_module, "h264_available", lambda: False)
    with caplog.at_level(logging.WARNING, logger=video_module.__name__):
        video = export_video(path, tmp_path / "ep.mp4", VideoOptions(height=160))
    assert video.path == tmp_path / "ep.webm" and video.codec == "vp9"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ep.webm"]
    container, codec, decoded = _probe(video.path)
    assert "webm" in container.split(",") and codec == "vp9" and len(decoded) == video.frames
    assert [r.getMessage() for r in caplog.records] == [
        f"this PyAV has no H.264 encoder (libx264): {tmp_path / 'ep.webm'} is VP9 in WebM, not MP4"
    ]


def test_the_export_command_names_the_webm_it_wrote(recorded, tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(video_module, "h264_available", lambda: False)
    assert _cli(str(tmp_path / "one.mp4"), "--recording", str(recorded[0]), "--height", "160") == 0
    assert f"wrote {tmp_path / 'one.webm'}: VP9 WebM, " in capsys.readouterr().out


@pytest.mark.parametrize(
    "break_it, cause",
    [
        (  # an encoder that refuses to open (here: an option it does not know)
            lambda m: m.setattr(
                video_module, "_H264", dataclasses.replace(video_module._H264, options={"preset": "no-such-preset"})
            ),
            "cannot write video .*ep.mp4: .+; nothing was written there",
        ),
        (  # a file that lost its last frame on the way to the disk
            lambda m: m.setattr(video_module, "frames", lambda ep, options: list(frames(ep, options))[:-1]),
            r"cannot write video .*ep.mp4: \d+ of its \d+ frames reached the disk",
        ),
    ],
)
def test_a_failing_encoder_or_a_short_file_is_one_line_and_leaves_nothing(
    recorded, tmp_path, monkeypatch, break_it, cause
):
    break_it(monkeypatch)
    with pytest.raises(L3MVNError, match=cause) as err:
        export_video(recorded[0], tmp_path / "ep.mp4", VideoOptions(height=160))
    assert "\n" not in str(err.value) and list(tmp_path.iterdir()) == []


def test_frames_have_even_sides_as_yuv420p_needs(recorded):
    ep = read_episode(recorded[0])
    for height in (120, 121, 241, 333, 480, 1079):
        geo = FrameGeometry.of(ep, VideoOptions(height=height))
        assert geo.width % 2 == 0 and geo.height % 2 == 0, (height, geo)


@pytest.fixture(scope="module")
def language(house, tmp_path_factory):
    """The same episode under l3mvn-zs (room-type scorer: offline, no model), and the events it published."""
    events = []
    path, _ = _record(tmp_path_factory.mktemp("language"), house, "l3mvn-zs", events)
    return path, events


def test_a_language_episodes_frames_print_the_fusion_line_in_force_at_each_step(language, tmp_path):
    path, events = language
    ep = read_episode(path)
    line, expected = "", []
    for ev in events:  # the rule behind the frontier chosen, until no frontier is the goal any more
        d = ev.decision
        if d is not None and d.chosen_frontier is not None:
            line = next(f for f in d.frontiers if f.id == d.chosen_frontier).fusion.describe()
        elif d is not None and line:
            line = f"no frontier choice in force: the goal is {str(d.goal_kind)!r}, not a frontier"
        expected.append(line)
    assert [s.fusion for s in ep.steps] == expected
    assert ep.has_fusion and "" in expected, "the episode should start before its first choice"
    assert any(s.fusion.startswith("bound B = [0.15, 0.30]; max S_LLM") for s in ep.steps)

    options = VideoOptions(height=240, title_s=0)
    bare = dataclasses.replace(ep, steps=[dataclasses.replace(s, fusion="") for s in ep.steps])
    drawn, without = list(frames(ep, options, title_frames=0)), list(frames(bare, options, title_frames=0))
    h = without[0].shape[0]
    assert h == 240 + 56  # the band without a fusion row, as for a policy without language
    rows = {}
    for s, with_line, no_line in zip(ep.steps, drawn, without):
        assert with_line.shape[0] > h and np.array_equal(with_line[:h], no_line)  # the rest of the frame as before
        row = with_line[h:]
        ink = np.flatnonzero((row != PANEL_BG).any(axis=(0, 2)))
        assert bool(ink.size) == bool(s.fusion)  # a row of text only where the step has a fusion line
        if ink.size:
            assert ink[-1] < with_line.shape[1] - 5  # fitted to the frame (fit_text), never cut at the edge
        rows.setdefault(s.fusion, []).append(row)
    for text, same in rows.items():
        assert all(np.array_equal(same[0], r) for r in same[1:]), f"one line, one picture: {text!r}"
    lines = [r[0] for t, r in rows.items() if t]
    assert len(lines) < 2 or any(not np.array_equal(lines[0], r) for r in lines[1:])  # the text, not a fixed mark

    video = export_video(path, tmp_path / "zs.mp4", options)
    assert video.height == drawn[0].shape[0] and len(_decode(video.path)) == 1 + len(ep.steps)


def test_a_recording_without_language_has_no_fusion_row(recorded):
    ep = read_episode(recorded[0])
    assert not ep.has_fusion and all(s.fusion == "" for s in ep.steps)
    assert next(frames(ep, VideoOptions(height=240), title_frames=0)).shape[0] == 240 + 56


def test_a_gif_is_written_beside_the_mp4(recorded, tmp_path):
    from PIL import Image

    path, _ = recorded
    video = export_video(path, tmp_path / "ep.mp4", VideoOptions(height=160), gif=True)
    assert video.gif == tmp_path / "ep.gif"
    with Image.open(video.gif) as gif:
        assert gif.n_frames == 1 + video.steps and gif.size == (video.width, video.height)


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda d: d / "absent.rrd", r"absent.rrd not found"),
        (
            lambda d: (d / "junk.rrd").write_bytes(b"not rerun at all") and d / "junk.rrd",
            "junk.rrd is not a readable rerun",
        ),
    ],
)
def test_bad_recordings_are_one_line_errors(tmp_path, make, message):
    with pytest.raises(L3MVNError, match=message) as err:
        export_video(make(tmp_path), tmp_path / "x.mp4")
    assert "\n" not in str(err.value)


def test_a_recording_without_a_map_is_refused_naming_the_policy(house, tmp_path):
    path, _ = _record(tmp_path, house, "oracle")
    with pytest.raises(L3MVNError, match=r"holds no map \(oracle keeps none\)") as err:
        export_video(path, tmp_path / "x.mp4")
    assert "\n" not in str(err.value)


def test_bad_options_and_names_are_one_line_errors(recorded, tmp_path):
    with pytest.raises(L3MVNError, match="must end in .mp4"):
        export_video(recorded[0], tmp_path / "x.avi")
    with pytest.raises(L3MVNError, match="--fps must lie"):
        VideoOptions(fps=0)
    with pytest.raises(L3MVNError, match="--height must lie"):
        VideoOptions(height=10)


def _row(path, **kw):
    ep = read_episode(path)
    row = {
        "key": f"{ep.scene}/0/{ep.episode_id}",
        "scene": ep.scene,
        "episode_id": int(ep.episode_id),
        "policy": ep.policy,
        "success": 0.0,
        "failure": "unseen_in_explored",
        "config_hash": "c0ffee",
        "rule": "semexp",
        "goal": "chair",
        "spl": 0.0,
        "dtg": 2.5,
        "steps": 40,
    }
    return {**row, **kw}


def test_a_result_line_finds_its_recording_and_is_named_by_outcome(recorded, tmp_path):
    path, _ = recorded
    video = export_result_video(_row(path), path.parent, tmp_path)
    assert video.path == tmp_path / "fail_unseen_in_explored_procedural-0003_0_frontier.mp4"
    assert result_video_name(_row(path, success=1.0, failure="success")) == "success_procedural-0003_0_frontier.mp4"
    with pytest.raises(L3MVNError, match="no recording of procedural-0003 episode 0 \\(cost-utility\\)"):
        export_result_video(_row(path, policy="cost-utility"), path.parent, tmp_path)


def _cli(*argv):
    """``l3mvn export ARGV`` as the CLI runs it: 0, or 2 with a one-line ``error:`` (``main``'s contract)."""
    parser = argparse.ArgumentParser(prog="l3mvn export")
    add_export_arguments(parser)
    try:
        return run_export(parser.parse_args(list(argv)))
    except L3MVNError as exc:
        print(f"error: {exc}", file=sys.stderr)  # unflattened: the test checks it is one line
        return 2


def test_the_export_command_single_and_batch(recorded, tmp_path, capsys):
    path, _ = recorded
    assert _cli(str(tmp_path / "one.mp4"), "--recording", str(path), "--height", "160") == 0
    assert "one.mp4: " in capsys.readouterr().out and (tmp_path / "one.mp4").stat().st_size > 0

    results = tmp_path / "results.jsonl"
    rows = [
        _row(path),
        _row(path, scene="elsewhere", key="elsewhere/0/0"),
        _row(path, success=1.0, failure="success", key="ok"),
    ]
    results.write_text("".join(json.dumps(r) + "\n" for r in rows))
    out = tmp_path / "videos"
    assert (
        _cli(
            "--results",
            str(results),
            "--recordings",
            str(path.parent),
            "--out",
            str(out),
            "--failures",
            "--height",
            "160",
        )
        == 0
    )
    assert sorted(p.name for p in out.iterdir()) == ["fail_unseen_in_explored_procedural-0003_0_frontier.mp4"]
    captured = capsys.readouterr()
    assert "skipped elsewhere/0/0: no recording" in captured.err and "wrote 1 videos" in captured.out


def test_two_policies_of_one_episode_exported_into_one_folder_keep_both_videos(recorded, tmp_path, capsys):
    """Each result file holds one policy: exported into the same folder, neither overwrites the other."""
    path, _ = recorded
    recordings = tmp_path / "recordings"
    recordings.mkdir()
    shutil.copy(path, recordings / path.name)
    shutil.copy(path, recordings / path.name.replace("_frontier", "_cost-utility"))
    names = {result_video_name(_row(path, policy=p)) for p in ("frontier", "cost-utility")}
    assert len(names) == 2
    out = tmp_path / "videos"
    for policy in ("frontier", "cost-utility"):
        results = tmp_path / f"{policy}.jsonl"
        results.write_text(json.dumps(_row(path, policy=policy)) + "\n")
        assert (
            _cli("--results", str(results), "--recordings", str(recordings), "--out", str(out), "--height", "160") == 0
        )
    assert sorted(p.name for p in out.iterdir()) == sorted(names)
    assert "procedural-0003_0_cost-utility.mp4" in capsys.readouterr().out


@pytest.mark.parametrize(
    "argv, message",
    [
        (["x.mp4"], "export needs VIDEO.mp4 --recording"),
        (["--results", "r.jsonl"], "--results needs --recordings"),
        (["x.mp4", "--recording", "r.rrd", "--out", "d"], "go with --results"),
        (["--results", "absent.jsonl", "--recordings", ".", "--out", "d"], "results file absent.jsonl not found"),
        (["--results", ".", "--recordings", ".", "--out", "d"], "results file . is a folder, not a regular file"),
    ],
)
def test_bad_export_flags_are_one_line_cli_errors(argv, message, capsys):
    assert _cli(*argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and message in err and err.count("\n") == 1


def test_malformed_result_lines_are_named_and_skipped(recorded, tmp_path, capsys):
    """Each bad line is one line on stderr naming it; the good episode is still exported."""
    path, _ = recorded
    bad = tmp_path / "r.jsonl"
    lines = [
        '{"scene": "a", "success": 0}',
        "{oops",
        json.dumps(_row(path)),
        json.dumps(_row(path, episode_id="abc")),
        json.dumps(_row(path)).replace('"dtg": 2.5', '"dtg": 1e400'),
        "[" * 100_000 + "]" * 100_000,
        json.dumps(_row(path)).replace('"spl": 0.0', '"spl": NaN'),
        json.dumps(_row(path, episode_id=[1])),
    ]
    bad.write_text("\n".join(lines) + "\n")
    assert (
        _cli("--results", str(bad), "--recordings", str(path.parent), "--out", str(tmp_path / "o"), "--height", "160")
        == 0
    )
    err = capsys.readouterr().err.splitlines()
    assert [re.search(r"r\.jsonl: skipped line (\d+): ", line).group(1) for line in err] == list("1245678")
    assert "line 4: 'episode_id' is \"abc\", not a whole number >= 0" in err[2]
    assert "nested deeper than" in err[4] and "NaN" in err[5]
    assert [p.name for p in (tmp_path / "o").iterdir()] == ["fail_unseen_in_explored_procedural-0003_0_frontier.mp4"]
    only_bad = tmp_path / "only_bad.jsonl"
    only_bad.write_text("{oops\n")
    assert _cli("--results", str(only_bad), "--recordings", str(path.parent), "--out", str(tmp_path / "o")) == 2
    assert "only_bad.jsonl holds no episode line to export (first problem: line 1: not JSON" in capsys.readouterr().err


@pytest.mark.parametrize("at", [(2, 60), (318, 60), (160, 1), (160, 118), (1, 1), (318, 118)])
def test_a_map_label_beside_the_panel_edge_stays_whole_inside_it(at):
    """A target at the map's left edge read "arget: toilet": the label's box now lies inside the panel,
    and beside the point when there is room, clear of labels already placed."""
    from l3mvn.run.recording.drawing import _place_label

    img = np.zeros((120, 320, 3), np.uint8)
    placed = [(at[0] - 5, at[1] - 5, at[0] + 5, at[1] + 5)]
    box = _place_label(img, "target: toilet", at, placed, (255, 255, 255))
    assert 0 <= box[0] and 0 <= box[1] and box[2] < 320 and box[3] < 120
    assert not (box[0] <= at[0] <= box[2] and box[1] <= at[1] <= box[3])  # never over its own point
    assert img[box[1] : box[3] + 1, box[0] : box[2] + 1].any() and placed[-1] == box

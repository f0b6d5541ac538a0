"""The Episode history folder: every step of the live episode kept, scrubbed back over the main view."""

from __future__ import annotations

import base64
import re
import time

import cv2
import numpy as np
import pytest
from conftest import serve_dashboard

from l3mvn.core.config import Config
from l3mvn.core.errors import L3MVNError
from l3mvn_studio.history_view import history_picture


@pytest.fixture(scope="module")
def dash():
    yield from serve_dashboard(episodes_per_house=2, policy="frontier", cfg=Config().with_frame(120, 160))


def _wait(what, until, timeout: float = 30.0) -> None:
    end = time.monotonic() + timeout
    while not until():
        assert time.monotonic() < end, f"timed out waiting for {what}"
        time.sleep(0.05)


def _start(ctl, index: int):
    scene = ctl.scene_keys[0]
    ctl.reset(scene, ctl.episodes_of(scene)[index].episode_id)
    assert ctl.wait_idle(60)


def _shown(panel) -> np.ndarray:
    src = panel.picture.content.split("src='", 1)[1].split("'", 1)[0]
    png = base64.b64decode(src.split(",", 1)[1])
    return cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)[..., ::-1]


def test_look_back_at_a_step_of_the_live_episode_and_return(dash):
    ctl, panel = dash.controller, dash.view.history
    _start(ctl, 0)
    for _ in range(14):
        ctl.step()
        assert ctl.wait_idle(30)
    _wait("14 steps kept", lambda: panel.steps == list(range(1, 15)))  # the reset has no map yet
    assert panel.step.value == 14 and panel.picture.content == ""  # following the live episode
    panel.show(5)
    assert "l3mvn-main-view" in panel.picture.content and re.match(r"step 5: [a-z\\_]+ \\\[", panel.line.content)
    assert np.array_equal(_shown(panel), panel.picture_at(5)) and not panel.live.disabled
    assert not np.array_equal(panel.picture_at(5), panel.picture_at(14))
    panel.show(14)  # the newest step is the live map
    assert panel.picture.content == "" and panel.live.disabled and panel.line.content.startswith("live: step 14")
    with pytest.raises(L3MVNError, match=r"^step 99 is not in this episode's history; valid: 1\.\.14$"):
        panel.picture_at(99)


def test_a_new_episode_starts_a_new_history(dash):
    ctl, panel = dash.controller, dash.view.history
    _start(ctl, 0)
    ctl.step()
    assert ctl.wait_idle(30)
    _wait("step 1", lambda: 1 in panel.steps)
    _start(ctl, 1)
    _wait("a fresh history", lambda: panel.steps == [] and panel.step.disabled)
    ctl.step()
    assert ctl.wait_idle(30)
    _wait("its first step", lambda: panel.steps == [1])


def test_the_history_picture_draws_frontiers_goal_and_agent_over_the_map(dash):
    ctl = dash.controller
    _start(ctl, 0)
    for _ in range(14):
        ctl.step()
        assert ctl.wait_idle(30)
    view = ctl.snapshot.map
    assert view is not None and view.frontiers
    drawn = history_picture(view)
    assert drawn.shape == view.image.shape
    changed = (drawn != view.image).any(axis=2)
    for f in view.frontiers:  # a disc at each frontier's cell
        y, x = ((np.array(f.cell) - view.origin + 0.5) * view.scale).astype(int)
        assert changed[y, x]


def test_a_target_change_keeps_the_steps_before_it_and_every_step_keeps_its_camera_frames(dash):
    ctl, panel = dash.controller, dash.view.history
    _start(ctl, 0)
    for _ in range(4):
        ctl.step()
        assert ctl.wait_idle(30)
    _wait("4 steps kept", lambda: panel.steps == [1, 2, 3, 4])
    first_goal = ctl.snapshot.event.goal
    other = next(g for g in ctl.session.task.scene.present_goals() if g != first_goal)
    ctl.change_target(other)
    assert ctl.wait_idle(30)
    for _ in range(3):
        ctl.step()
        assert ctl.wait_idle(30)
    _wait("the new segment's steps added to the old ones", lambda: panel.steps == list(range(1, 8)))
    panel.show(2)
    assert panel.line.content.startswith("step 2: ")
    panel.show(4)
    assert f"then new target {other}" in panel.line.content  # the step that was retargeted says so
    panel.show(6)
    assert panel.line.content.startswith(f"step 6 (segment 1, target {other}): ")
    map_only = history_picture(ctl.snapshot.map)  # the live map has the width a kept step's map has
    shown = panel.picture_at(6)
    assert shown.shape[0] > map_only.shape[0] + 20  # the camera strip lies below the map
    strip = shown[-20:]  # the camera frames are pictures, not the dark margin
    assert strip.std() > 5
    _start(ctl, 0)  # a Reset of the same episode starts a new history
    _wait("a fresh history", lambda: panel.steps == [] and panel.step.disabled)

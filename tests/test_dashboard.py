"""The dashboard's controller, driven directly on an in-process server (no browser)."""

from __future__ import annotations

import re
import threading
import time

import pytest
from conftest import serve_dashboard

from l3mvn.core.config import Config, SimConfig
from l3mvn.core.errors import L3MVNError
from l3mvn.run.events import StepEvent
from l3mvn_studio.page_text import md
from l3mvn_studio.state import Notice

SMALL = Config(sim=SimConfig().with_frame(120, 160))


@pytest.fixture(scope="module")
def dash():
    yield from serve_dashboard(episodes_per_house=3, cfg=SMALL, policy="oracle")


@pytest.fixture
def ctl(dash):
    c = dash.controller
    c.pause()
    c.wait_idle()
    c.policy_name = "oracle"
    events: list[StepEvent] = []
    notices: list[Notice] = []
    off = c.bus.subscribe(events.append)
    c.on_notice(notices.append)
    c.events, c.notices = events, notices
    yield c
    off()
    c.pause()
    c.wait_idle()


def _reset(c, index: int = 0):
    scene = c.scene_keys[0]
    c.reset(scene, c.episodes_of(scene)[index].episode_id)
    assert c.wait_idle()
    return c.episodes_of(scene)[index]


def test_reset_publishes_step_zero_of_the_chosen_episode_and_draws_its_map(ctl):
    ep = _reset(ctl, 1)
    snap = ctl.snapshot
    assert ctl.events[-1].episode_key == ep.key and ctl.events[-1].step == 0
    assert snap.event is ctl.events[-1] and snap.error is None
    assert snap.map is not None and snap.map.source == "ground truth"  # oracle keeps no map
    assert snap.frames is not None and snap.frames.rgb.shape == (240, 320, 3)  # 120x160, shown twice as large


def test_step_advances_exactly_one_step(ctl):
    _reset(ctl)
    ctl.step()
    assert ctl.wait_idle()
    assert [e.step for e in ctl.events] == [0, 1]
    assert ctl.snapshot.event.action is not None


def test_run_steps_on_its_own_until_paused(ctl):
    _reset(ctl)
    ctl.set_speed(40)
    ctl.run()
    deadline = time.monotonic() + 5
    while len(ctl.events) < 4 and time.monotonic() < deadline:
        time.sleep(0.02)
    ctl.pause()
    assert ctl.wait_idle()
    n = len(ctl.events)
    time.sleep(0.2)
    assert n >= 4 and len(ctl.events) == n and not ctl.snapshot.running


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -float("inf"), "4", None, True])
def test_a_speed_that_is_not_a_finite_number_is_refused_and_run_goes_on(ctl, bad):
    _reset(ctl)
    ctl.set_speed(40)
    ctl.run()
    with pytest.raises(L3MVNError, match="steps per second must be a number from 0.5 to 60"):
        ctl.set_speed(bad)
    assert ctl.steps_per_second == 40
    n = len(ctl.events)
    deadline = time.monotonic() + 5
    while len(ctl.events) < n + 2 and time.monotonic() < deadline:
        time.sleep(0.02)
    assert len(ctl.events) >= n + 2 or ctl.snapshot.event.done


def test_step_while_run_is_active_is_refused_and_running_goes_on(ctl):
    _reset(ctl)
    ctl.set_speed(2)
    ctl.run()
    with pytest.raises(L3MVNError, match="Pause first"):
        ctl.step()
    assert ctl.running


def test_unknown_scene_or_episode_is_refused_naming_the_valid_choices(ctl):
    with pytest.raises(L3MVNError, match="valid scenes: procedural-0000/0"):
        ctl.reset("../../etc/passwd", 0)
    with pytest.raises(L3MVNError, match="valid episode ids: 0, 1, 2"):
        ctl.reset(ctl.scene_keys[0], 99)
    _reset(ctl)  # and the server keeps serving
    assert ctl.snapshot.event.step == 0


def test_two_resets_at_once_start_one_episode_and_refuse_the_other(ctl):
    scene = ctl.scene_keys[0]
    ids = [e.episode_id for e in ctl.episodes_of(scene)]
    outcomes: list[str] = []
    barrier = threading.Barrier(2)

    def press(episode_id: int) -> None:
        barrier.wait()
        try:
            ctl.reset(scene, episode_id)
            outcomes.append("ok")
        except L3MVNError as exc:
            outcomes.append(str(exc))

    threads = [threading.Thread(target=press, args=(i,)) for i in ids[:2]]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert ctl.wait_idle()
    # Either both ran one after the other, or the second was refused with a message: never a mix.
    assert "ok" in outcomes
    assert all(o == "ok" or "reset is already in progress" in o for o in outcomes)
    starts = [e for e in ctl.events if e.step == 0]
    assert len(starts) == outcomes.count("ok")
    assert ctl.snapshot.event is starts[-1]


def test_manual_goal_on_a_policy_without_one_says_so(ctl):
    _reset(ctl)
    with pytest.raises(L3MVNError, match="does not take manual goals"):
        ctl.set_manual_goal((10, 10))


def test_manual_goal_before_any_episode_or_after_the_end_is_refused(dash):
    from l3mvn.world.datasets import load_episode_set
    from l3mvn_studio.session_worker import DashboardController

    fresh = DashboardController(load_episode_set(None, "val", houses=1, episodes_per_house=1, cfg=SMALL), SMALL)
    try:
        with pytest.raises(L3MVNError, match="no episode yet"):
            fresh.set_manual_goal((1, 1))
        with pytest.raises(L3MVNError, match="no episode yet"):
            fresh.run()
    finally:
        fresh.close()


def test_changing_the_target_mid_episode_starts_a_marked_new_segment(ctl):
    ep = _reset(ctl)
    ctl.step()
    ctl.wait_idle()
    present = ctl.session.env.scene.present_goals()
    other = next(g for g in present if g != ep.goal)
    ctl.change_target(other)
    assert ctl.wait_idle()
    last = ctl.events[-1]
    assert (last.goal, last.segment) == (other, 1)
    assert f"{ep.goal} -> {other}" in ctl.snapshot.segment_note
    with pytest.raises(L3MVNError, match="valid targets"):
        ctl.change_target("spaceship")


def _run_nearest_episode_to_the_end(c, timeout_s: float = 20.0) -> None:
    scene = c.scene_keys[0]
    nearest = min(range(3), key=lambda i: c.episodes_of(scene)[i].geodesic_distance_m)
    _reset(c, nearest)
    c.set_speed(60)
    c.run()
    deadline = time.monotonic() + timeout_s
    while not c.snapshot.event.done and time.monotonic() < deadline:
        time.sleep(0.05)


def test_a_finished_episode_counts_in_the_session_metrics(ctl):
    before = ctl.snapshot.metrics.episodes
    _run_nearest_episode_to_the_end(ctl)
    assert ctl.snapshot.event.done and ctl.snapshot.event.result["success"]
    assert ctl.snapshot.metrics.episodes == before + 1 and ctl.snapshot.metrics.sr > 0
    with pytest.raises(L3MVNError, match="is over"):
        ctl.run()


def test_a_recorded_episode_is_written_and_listed_on_the_page(dash, ctl, tmp_path):
    ctl.record_dir = tmp_path
    ctl.set_record(True)
    _run_nearest_episode_to_the_end(ctl)
    ctl.set_record(False)
    files = list(tmp_path.glob("*.rrd"))
    assert len(files) == 1 and re.fullmatch(r".*_oracle_live-[0-9TZ]+-\d+-[0-9a-f]{6}\.rrd", files[0].name)
    deadline = time.monotonic() + 5
    while md(files[0].name) not in dash.view.recordings.listing.content and time.monotonic() < deadline:
        time.sleep(0.05)
    assert md(files[0].name) in dash.view.recordings.listing.content
    assert dash.view.recordings.pick.value == files[0].name  # offered to "Open in rerun"


def test_an_exception_in_the_worker_is_shown_and_the_worker_keeps_serving(ctl):
    _reset(ctl)
    policy = ctl.session.policy

    def broken(obs):
        raise RuntimeError("language model fell over")

    policy.act = broken
    try:
        ctl.step()
        assert ctl.wait_idle()
    finally:
        del policy.act
    assert "language model fell over" in ctl.snapshot.error
    assert any(n.level == "error" and "language model fell over" in n.text for n in ctl.notices)
    ctl.step()
    assert ctl.wait_idle()
    assert ctl.snapshot.error is None and ctl.events[-1].step == 1


def test_the_page_is_served(dash):
    import urllib.request

    with urllib.request.urlopen(dash.url, timeout=5) as r:
        assert r.status == 200 and b"<html" in r.read().lower()


def _steps(c, n: int) -> None:
    for _ in range(n):
        c.step()
        assert c.wait_idle()


def test_a_manual_goal_becomes_the_long_term_goal_and_is_recorded_as_an_override(ctl):
    ctl.policy_name = "frontier"
    _reset(ctl)
    _steps(ctl, 14)  # past the initial look-around, so frontiers exist
    view = ctl.snapshot.map
    assert view.source == "agent map" and view.frontiers
    target = view.frontiers[-1].cell
    ctl.set_manual_goal(target)
    _steps(ctl, 1)
    d = ctl.events[-1].decision
    assert d.goal_kind == "manual" and d.long_term_goal == target
    assert d.override == f"manual:{target[0]},{target[1]}" and ctl.snapshot.manual_goal == target
    with pytest.raises(L3MVNError, match="outside the 960x960 map"):
        ctl.set_manual_goal((5000, -3))
    ctl.set_manual_goal(None)
    _steps(ctl, 1)
    assert ctl.events[-1].decision.override is None and ctl.snapshot.manual_goal is None


def test_a_step_after_the_end_says_the_episode_has_ended_and_fails_nothing(ctl):
    _run_nearest_episode_to_the_end(ctl)
    assert ctl.snapshot.event.done
    steps, seen = len(ctl.events), len(ctl.notices)
    ctl.step()
    assert ctl.wait_idle()
    told = ctl.notices[seen:]
    assert [(n.level, n.title) for n in told] == [("info", "")], told
    assert re.fullmatch(r"episode \S+ has ended \(SUCCESS\): press Reset for the next one", told[0].text)
    assert len(ctl.events) == steps and ctl.snapshot.error is None


def test_episodes_steered_by_hand_are_counted_apart_from_the_policy_sr_and_spl(dash):
    from dataclasses import replace

    from l3mvn.world.datasets import load_episode_set
    from l3mvn_studio.page_markdown import metrics_markdown
    from l3mvn_studio.session_worker import DashboardController

    cfg = SMALL.replace(sim=replace(SMALL.sim, max_steps=6))
    c = DashboardController(load_episode_set(None, "val", houses=1, episodes_per_house=1, cfg=cfg), cfg)
    scene = c.scene_keys[0]
    episode = c.episodes_of(scene)[0].episode_id

    def finish(policy: str, *, manual_goal: bool = False) -> None:
        c.policy_name = policy
        c.reset(scene, episode)
        assert c.wait_idle()
        if manual_goal:
            c.step()
            assert c.wait_idle()
            c.set_manual_goal((480, 480))
        c.set_speed(60)
        c.run()
        deadline = time.monotonic() + 20
        while not (c.snapshot.event.done and c.wait_idle(0.1)) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert c.snapshot.event.done

    try:
        finish("oracle")
        finish("frontier", manual_goal=True)
        c.policy_name = "teleop"
        c.reset(scene, episode)
        assert c.wait_idle()
        c.drive("stop")
        assert c.wait_idle() and c.snapshot.event.done
        m = c.snapshot.metrics
        assert (m.episodes, m.steered, m.policies) == (1, 2, ("oracle",))
        assert metrics_markdown(m).endswith(f"SPL {m.spl:.2f} (policy oracle); 2 steered by hand, not counted")
    finally:
        c.close()

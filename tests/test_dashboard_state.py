"""A dashboard state the user can trust (issue 16, item 0): the controller and the page's text, no browser.

Each test here failed on the build before the fix: the last snapshot of a run said "running", a Run
pressed during a Reset was lost, notices all vanished after 6 s, a scorer without weights was tried
against the model hub, a manual goal showed its wire token and outlived Clear.
"""

from __future__ import annotations

import time

import numpy as np
import pytest
from conftest import serve_dashboard

from l3mvn.core.config import Config, SimConfig
from l3mvn.core.errors import L3MVNError
from l3mvn.run.events import StepEvent
from l3mvn.run.viz import category_color
from l3mvn.world.datasets import load_episode_set
from l3mvn_studio.frontier_ranking import TOP_LABELS, labelled_frontiers
from l3mvn_studio.map_image import TARGET_RINGS
from l3mvn_studio.model_weights import model_problem, scorer_problems
from l3mvn_studio.page_markdown import legend_html, status_markdown
from l3mvn_studio.session_worker import DashboardController
from l3mvn_studio.state import Notice, Snapshot

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
    snaps: list[Snapshot] = []
    off = c.bus.subscribe(events.append)
    c.on_notice(notices.append)
    c.on_snapshot(snaps.append)
    c.events, c.notices, c.snaps = events, notices, snaps
    yield c
    off()
    c._notice_fns.remove(notices.append)
    c._snapshot_fns.remove(snaps.append)
    c.pause()
    c.wait_idle()


@pytest.fixture
def fresh():
    c = DashboardController(load_episode_set(None, "val", houses=1, episodes_per_house=2, cfg=SMALL), SMALL)
    notices: list[Notice] = []
    snaps: list[Snapshot] = []
    c.on_notice(notices.append)
    c.on_snapshot(snaps.append)
    c.notices, c.snaps = notices, snaps
    yield c
    c.close()


def _nearest(c) -> int:
    scene = c.scene_keys[0]
    eps = c.episodes_of(scene)
    return min(eps, key=lambda e: e.geodesic_distance_m).episode_id


def _until(predicate, timeout: float = 20.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate() and time.monotonic() < deadline:
        time.sleep(0.02)
    assert predicate()


def test_the_last_snapshot_of_a_run_says_finished_not_running(ctl):
    ctl.reset(ctl.scene_keys[0], _nearest(ctl))
    assert ctl.wait_idle()
    ctl.set_speed(60)
    ctl.run()
    _until(lambda: ctl.snapshot.event.done)
    assert ctl.wait_idle()
    last = ctl.snapshot
    assert last.event.done and not last.running
    assert "finished" in status_markdown(last) and "running" not in status_markdown(last).split("\n")[0]
    # Every snapshot that shows the finished step says so: none pairs SUCCESS with "running".
    assert not [s for s in ctl.snaps if s.event is not None and s.event.done and s.running]


def test_an_outcome_stays_until_dismissed(ctl):
    ctl.reset(ctl.scene_keys[0], _nearest(ctl))
    assert ctl.wait_idle()
    ctl.set_speed(60)
    ctl.run()
    _until(lambda: ctl.snapshot.event.done)
    outcome = [n for n in ctl.notices if n.title == "Episode over"]
    assert len(outcome) == 1 and outcome[0].sticky and outcome[0].client_id is None
    assert outcome[0].text.startswith(f"episode {ctl.snapshot.event.episode_key}: SUCCESS, SPL ")


def test_a_run_pressed_during_a_reset_is_queued_and_runs_after_it(fresh):
    scene = fresh.scene_keys[0]
    fresh.set_speed(60)
    fresh.reset(scene, fresh.episodes_of(scene)[0].episode_id)
    fresh.run()  # the reset is still queued or running: before the fix, "no episode yet"
    assert any("Run queued" in n.text for n in fresh.notices)
    assert fresh.snapshot.run_queued and fresh.snapshot.busy.startswith("resetting to episode ")
    _until(lambda: fresh.snapshot.event is not None and fresh.snapshot.event.step >= 3)
    assert not fresh.snapshot.busy and not fresh.snapshot.run_queued
    fresh.pause()


def test_a_reset_is_busy_at_once_and_gives_the_controls_back_after(fresh):
    scene = fresh.scene_keys[0]
    fresh.reset(scene, fresh.episodes_of(scene)[1].episode_id)
    assert fresh.snapshot.busy.startswith("resetting to episode ")  # before the worker even starts
    assert fresh.wait_idle()
    busy = [s.busy for s in fresh.snaps]
    assert busy[0] and not busy[-1] and fresh.snapshot.event.step == 0
    with pytest.raises(L3MVNError, match="a reset is already in progress"):
        fresh.reset(scene, 0)
        fresh.reset(scene, 0)
    assert fresh.wait_idle()


def test_pause_cancels_a_queued_run_and_says_so(fresh):
    scene = fresh.scene_keys[0]
    fresh.reset(scene, fresh.episodes_of(scene)[0].episode_id)
    fresh.run()
    fresh.pause()
    assert fresh.wait_idle()
    assert any("queued Run is cancelled" in n.text for n in fresh.notices)
    time.sleep(0.3)
    assert fresh.snapshot.event.step == 0 and not fresh.snapshot.running


def test_step_before_any_episode_is_refused_at_once_saying_what_to_do(fresh):
    with pytest.raises(L3MVNError, match="no episode yet: pick one and press Reset"):
        fresh.step()


def test_a_scorer_without_weights_on_disk_is_refused_at_once_with_the_reason(fresh):
    problems = scorer_problems()
    if "mlm" not in problems:
        pytest.skip("roberta-large is on this disk: the mlm scorer can load")
    assert fresh.unavailable_scorers == problems
    started = time.monotonic()
    with pytest.raises(L3MVNError, match=r"scorer 'mlm' is unavailable: roberta-large is not on disk .*usable: "):
        fresh.set_scorer("mlm")
    assert time.monotonic() - started < 1.0 and fresh.scorer is None
    assert "roomtype" not in problems and "feedforward" not in problems  # shipped with the package


def test_a_model_on_disk_is_found_and_a_missing_path_is_named(tmp_path):
    (tmp_path / "config.json").write_text("{}")
    assert model_problem(str(tmp_path)) is None
    assert model_problem("minilm") is None
    assert "has no config.json" in model_problem(str(tmp_path.parent))
    assert "not on disk" in model_problem("no-such-org/no-such-model")


def test_a_manual_goal_reads_as_a_frontier_and_goes_with_clear(ctl):
    ctl.policy_name = "frontier"
    ctl.reset(ctl.scene_keys[0], ctl.episodes_of(ctl.scene_keys[0])[0].episode_id)
    assert ctl.wait_idle()
    for _ in range(14):
        ctl.step()
        assert ctl.wait_idle()
    target = ctl.snapshot.map.frontiers[-1]
    ctl.set_manual_goal(target.cell)
    ctl.step()
    assert ctl.wait_idle()
    text = status_markdown(ctl.snapshot)
    assert f"**Manual goal**: frontier F{target.id} at map cell ({target.cell[0]}, {target.cell[1]})" in text
    assert "manual:" not in text
    ctl.set_manual_goal(None)
    assert ctl.wait_idle()
    text = status_markdown(ctl.snapshot)  # before the next step
    assert "Manual goal" not in text and "manual goal cleared" in text


def test_the_target_is_ringed_on_the_map_and_first_in_the_legend(ctl):
    ctl.reset(ctl.scene_keys[0], ctl.episodes_of(ctl.scene_keys[0])[0].episode_id)
    assert ctl.wait_idle()
    view = ctl.snapshot.map  # oracle: the ground-truth plan, the target in it
    assert view.target == ctl.snapshot.event.goal
    img = view.image
    for ring in TARGET_RINGS:
        assert (img == ring).all(axis=2).any(), f"no {ring} ring around the target"
    names = [name for name, _ in view.legend]
    assert view.target in names and len(names) == len(set(names))
    html = legend_html(view.legend, target=view.target)
    assert f"<b>{view.target} (target)</b>" in html
    assert html.index(view.target) < min(html.index(n) for n in names if n != view.target)


def test_map_labels_name_only_the_best_few_frontiers(ctl):
    ctl.policy_name = "frontier"
    ctl.reset(ctl.scene_keys[0], ctl.episodes_of(ctl.scene_keys[0])[0].episode_id)
    assert ctl.wait_idle()
    for _ in range(20):
        ctl.step()
        assert ctl.wait_idle()
        if len(ctl.snapshot.map.frontiers) > TOP_LABELS + 1:
            break
    frontiers = ctl.snapshot.map.frontiers
    assert len(frontiers) > TOP_LABELS + 1
    labelled = labelled_frontiers(frontiers)
    assert len(labelled) <= TOP_LABELS + 1 and {f.id for f in frontiers if f.chosen} <= labelled


def test_random_walk_says_it_is_the_papers_baseline(ctl):
    ctl.policy_name = "random-walk"
    ctl.reset(ctl.scene_keys[0], 0)
    assert ctl.wait_idle()
    assert "the paper's baseline" in status_markdown(ctl.snapshot)


def test_the_legend_swatches_are_told_apart():
    """Every category of the procedural houses and of Gibson has its own, clearly distinct colour."""
    from l3mvn.world.datasets import load_episode_set

    es = load_episode_set(None, "val", houses=1, episodes_per_house=1, cfg=SMALL)
    names = es.scene_of(es.episodes[0]).categories
    colours = np.array([category_color(n) for n in names], dtype=np.float64)
    gaps = np.linalg.norm(colours[:, None] - colours[None], axis=2) + np.eye(len(names)) * 1e9
    assert gaps.min() > 40, f"{names[int(gaps.min(axis=1).argmin())]} looks like another category"


def test_teleop_moves_by_hand_keeps_mapping_and_is_scored(ctl):
    ctl.policy_name = "teleop"
    ctl.reset(ctl.scene_keys[0], ctl.episodes_of(ctl.scene_keys[0])[0].episode_id)
    assert ctl.wait_idle()
    start = ctl.events[-1].pose
    for action in ("turn_left", "move_forward", "look_down"):
        ctl.drive(action)
        assert ctl.wait_idle()
    steps = ctl.events[-3:]
    assert [e.action.name for e in steps] == ["TURN_LEFT", "MOVE_FORWARD", "LOOK_DOWN"]
    assert steps[0].pose.heading != start.heading and steps[-1].decision.map is not None
    assert steps[-1].decision.reason.startswith("driven by hand: look_down (the agent would ")
    with pytest.raises(L3MVNError, match="Step does not apply to policy 'teleop'"):
        ctl.step()
    with pytest.raises(L3MVNError, match="Run does not apply to policy 'teleop'"):
        ctl.run()
    with pytest.raises(L3MVNError, match="unknown action 'fly'"):
        ctl.drive("fly")
    ctl.drive("stop")
    assert ctl.wait_idle()
    last = ctl.events[-1]
    assert last.done and last.result["steps"] == 4 and "spl" in last.result
    assert ctl.snapshot.metrics.steered >= 1


def test_drive_under_another_policy_says_which_one_drives(ctl):
    ctl.reset(ctl.scene_keys[0], 0)  # oracle
    assert ctl.wait_idle()
    with pytest.raises(L3MVNError, match="Drive moves the agent under policy 'teleop' only .*'oracle'"):
        ctl.drive("move_forward")


def test_teleop_refuses_to_act_on_its_own():
    from l3mvn.agent.modular.teleop import TeleopAgent
    from l3mvn.agent.policies.global_policies import GLOBAL_POLICIES

    agent = TeleopAgent(GLOBAL_POLICIES["cost-utility"](), ("chair",), SMALL)
    with pytest.raises(L3MVNError, match="acts only when driven"):
        agent.act(None)


def test_a_run_says_the_speed_it_achieves_beside_the_speed_asked(ctl):
    ctl.reset(ctl.scene_keys[0], _nearest(ctl))
    assert ctl.wait_idle()
    ctl.set_speed(60)
    ctl.run()
    _until(lambda: ctl.snapshot.event.done)
    assert ctl.wait_idle()
    measured = [s for s in ctl.snaps if s.running and s.achieved_steps_per_second is not None]
    assert measured, "a run of several steps measures its rate"
    for s in measured:
        assert 0 < s.achieved_steps_per_second <= 60 * 1.2  # a timer of 60 per second never runs much faster
        assert "Speed: " in status_markdown(s)
    assert ctl.snapshot.achieved_steps_per_second is None  # the run ended: nothing is running at any speed
    assert "Speed: " not in status_markdown(ctl.snapshot)


def test_the_achieved_rate_counts_only_an_uninterrupted_run():
    from l3mvn_studio.page_markdown import speed_words
    from l3mvn_studio.step_rate import StepRate

    rate = StepRate(window=4)
    assert rate.per_second is None
    for t in (0.0, 0.2, 0.4, 0.6, 0.8, 1.0):  # only the last four intervals count
        rate.add(t)
    assert rate.per_second == pytest.approx(5.0)
    rate.add(11.0)  # a slow step pulls the window's rate down
    assert rate.per_second == pytest.approx(4 / 10.6)
    rate.clear()
    rate.add(20.0)
    assert rate.per_second is None
    assert speed_words(3.9, 4) == "Speed: 3.9 steps/s, as asked"
    slow = speed_words(5.5, 20)
    assert slow.startswith("Speed: **5.5 steps/s** of 20 asked") and "182 ms" in slow and "50 ms" in slow


def _episode_start(policy: str = "frontier", *, houses: int = 2, recorded=None):
    """An episode of another episode set than the dashboard's (two houses: the second one's first episode)."""
    from l3mvn_studio.session_worker import EpisodeStart

    cfg = SMALL
    episodes = load_episode_set(None, "val", houses=houses, episodes_per_house=2, cfg=cfg)
    episode = episodes.episodes[-1]
    return EpisodeStart(episodes.name, episodes.scene_of(episode), episode, policy, cfg, recorded=recorded or {})


def test_an_episode_loads_at_a_step_then_the_policy_goes_on_or_teleop_takes_over(fresh):
    """Issue 34: an episode from outside the dashboard's set loads at step K (only its start and K are
    drawn), paused;
    Step continues the same trajectory a straight run takes; teleop then takes over where it stands, and
    the episode counts as steered by hand."""
    from l3mvn.run.runner import Runner

    start = _episode_start()
    straight = Runner(start.config).session(start.scene, "frontier")
    straight.start(start.episode)
    poses = [straight.last_event.pose] + [straight.step().pose for _ in range(7)]
    events: list[StepEvent] = []
    fresh.bus.subscribe(events.append)
    snaps: list[Snapshot] = []
    fresh.on_snapshot(snaps.append)
    fresh.load(start, 6)
    assert fresh.wait_idle(120)
    snap = fresh.snapshot
    assert snap.event.episode_key == start.episode.key and snap.event.step == 6 and not snap.running
    assert snap.policy == "frontier" and fresh.session.episode.key not in {e.key for e in fresh.episodes.episodes}
    # The steps between are not drawn; the start is, so the page takes it for a new episode.
    assert {s.event.step for s in snaps if s.event is not None} == {0, 6}
    assert [e.pose for e in events] == poses[:7]
    assert "loaded" in fresh.notices[-1].text and "diverges" not in fresh.notices[-1].text
    fresh.step()
    assert fresh.wait_idle(60) and fresh.snapshot.event.pose == poses[7]
    fresh.set_policy("teleop")  # a loaded episode: teleop takes it over where it stands
    assert fresh.wait_idle(120)
    assert fresh.snapshot.policy == "teleop" and fresh.snapshot.event.step == 7
    assert fresh.snapshot.event.pose == poses[7] and "teleop took over" in fresh.notices[-1].text
    fresh.drive("stop")
    assert fresh.wait_idle(60) and fresh.snapshot.event.done
    assert fresh.snapshot.metrics.steered == 1 and fresh.snapshot.metrics.episodes == 0


def test_a_replay_that_leaves_its_recording_says_where(fresh):
    from l3mvn.core.types import Pose

    start = _episode_start(recorded={0: Pose(0.0, 0.0, 0.0)})
    fresh.load(start, 2)
    assert fresh.wait_idle(120)
    text = fresh.notices[-1].text
    assert fresh.notices[-1].level == "warning" and "the replay diverges from the recording at step 0" in text
    with pytest.raises(L3MVNError, match="whole number from 0"):
        fresh.load(start, -1)
    with pytest.raises(L3MVNError, match="cannot be replayed"):
        fresh.load(_episode_start("teleop"), 1)

"""The dashboard's controller: one shared navigation session, driven from a worker thread.

Every browser tab acts on the same session. UI callbacks only validate and enqueue: a bad request
raises ``L3MVNError`` at once (the view shows it to the tab that asked), and the work itself (a reset,
a step that may wait on a slow language model) runs on the worker thread, so the page never blocks.
Anything the worker raises is caught, reported as a Notice and in the snapshot, and the worker goes
on serving.
"""

from __future__ import annotations

import functools
import itertools
import logging
import math
import queue
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from numbers import Real
from pathlib import Path

import numpy as np

from l3mvn.agent.modular.teleop import TeleopAgent
from l3mvn.core.categories import GOAL_CATEGORIES
from l3mvn.core.config import Config, config_hash
from l3mvn.core.config.policy import DEFAULT_HEAD, HEAD_SCORER, POLICY_HEADS
from l3mvn.core.errors import L3MVNError
from l3mvn.core.types import Action, Pose, wrap_angle
from l3mvn.run.events import EventBus, StepEvent
from l3mvn.run.recording.catalogue import DEFAULT_RECORD_DIR, unique_tag
from l3mvn.run.registry import (
    TELEOP,
    check_policy,
    keeps_map,
    language_policies,
    names_where,
    reads_language,
    scorer_choice,
    scorer_of,
    with_scorer,
)
from l3mvn.run.runner import Runner
from l3mvn.run.session import EpisodeSession, Steerable
from l3mvn.run.viz import colorize_depth, colorize_semantic
from l3mvn.world.datasets import EpisodeSet
from l3mvn.world.episode import Episode
from l3mvn.world.scenes.scene import SceneMap
from l3mvn_studio.map_image import agent_map_view, ground_truth_view
from l3mvn_studio.model_weights import scorer_problems
from l3mvn_studio.state import Cell, Frames, Metrics, Notice, Snapshot
from l3mvn_studio.step_rate import StepRate

log = logging.getLogger(__name__)

MIN_SPEED, MAX_SPEED = 0.5, 60.0
DEFAULT_SCORER = "policy default"  # the scorer choice that keeps the policy's own
DEFAULT_HEAD_CHOICE = f"default ({DEFAULT_HEAD})"  # the head choice that leaves policy.head unset
MAX_QUEUED_STEPS = 5
FRAME_WIDTH = 320  # camera frames are shown this wide (larger ones subsampled, smaller ones enlarged)
POSE_TOLERANCE = 1e-3  # metres and radians: a recording stores poses as float32


@dataclass(frozen=True)
class EpisodeStart:
    """An episode to load into the live session, run as a result line says: its scene, its policy and
    config, and the poses its recording holds per step (empty without one) to check the replay against.
    The dashboard's own episode set need not hold it."""

    dataset: str  # the name its recordings carry
    scene: SceneMap
    episode: Episode
    policy: str
    config: Config
    stored_hash: str = ""  # the line's config hash ("" when it has none)
    recorded: Mapping[int, Pose] = field(default_factory=dict)


class DashboardController:
    """Shared state + worker thread. Methods are safe to call from any thread."""

    def __init__(
        self,
        episodes: EpisodeSet,
        cfg: Config | None = None,
        *,
        policy: str = "oracle",
        seed: int = 0,
        steps_per_second: float = 4.0,
        record_dir: str | Path | None = None,
    ) -> None:
        if not episodes.episodes:
            raise L3MVNError(f"{episodes.name}/{episodes.split} has no episodes to show")
        self.episodes, self.cfg, self.seed = episodes, cfg or Config(), seed
        # A head file the server was started with (--set policy.head=FILE) stays one of the Head choices.
        started = self.cfg.policy.head
        self._head_files = () if started is None or started in POLICY_HEADS else (started,)
        self.policy_name = check_policy(policy)
        self.scorer: str | None = None
        self.record = False
        self.record_dir = Path(record_dir or DEFAULT_RECORD_DIR)
        self.bus = EventBus()
        self.bus.subscribe(self._on_event)
        self._by_scene: dict[str, list[Episode]] = {}
        for ep in episodes.episodes:
            self._by_scene.setdefault(f"{ep.scene}/{ep.floor}", []).append(ep)
        self._runner = Runner(self.cfg, seed=seed)
        self._swapped_live = False  # a scorer swapped into a warm policy mid-episode (see _runner_fits)
        self._session: EpisodeSession | None = None
        self._trajectory: list[Pose] = []
        self._actions: list[Action] = []  # what moved the agent this episode: teleop replays them to take over
        self._dataset = episodes.name  # the episode set of the episode shown (a loaded one may come from another)
        self._loaded = False  # the episode shown was loaded from a result line (picking teleop takes it over)
        self._quiet = range(0)  # steps stepped through without drawing (loading at a step, taking over)
        self._manual: Cell | None = None
        self._steered = False  # a person chose where the agent went in this episode (a manual goal)
        self._segment_note = ""
        self._recorder_off: Callable[[], None] | None = None
        self._queue: queue.Queue[tuple[str, Callable[[], None], int | None]] = queue.Queue()
        self._lock = threading.Lock()
        self._running = False
        self._reset_pending = False
        self._run_queued = False
        self._busy: dict[int, str] = {}  # jobs on the worker that hold the controls, oldest first
        self._job_ids = itertools.count()
        self._current_job: int | None = None
        self._steps_pending = 0
        self._speed = _clamp_speed(steps_per_second)
        self._rate = StepRate()  # what a Run achieves, said beside the asked speed
        self._seq = 0
        self._snapshot = Snapshot(
            seq=0,
            policy=self.policy_name,
            running=False,
            steps_per_second=self._speed,
            metrics=Metrics(),
            note="Pick an episode and press Reset.",
        )
        self.unavailable_scorers = scorer_problems()
        self._snapshot_fns: list[Callable[[Snapshot], None]] = []
        self._notice_fns: list[Callable[[Notice], None]] = []
        self._closed = threading.Event()
        self._idle = threading.Event()
        self._idle.set()
        self._thread = threading.Thread(target=self._loop, name="l3mvn-session-worker", daemon=True)
        self._thread.start()

    # --- what there is to pick from ----------------------------------------------------------
    @property
    def scene_keys(self) -> list[str]:
        return list(self._by_scene)

    def episodes_of(self, scene_key: str) -> list[Episode]:
        if scene_key not in self._by_scene:
            raise L3MVNError(f"unknown scene {scene_key!r}; valid scenes: {', '.join(self._by_scene)}")
        return self._by_scene[scene_key]

    def head_names(self) -> tuple[str, ...]:
        """The Head dropdown's choices: the default first, then every feed-forward head kind, then the
        head file the server was started with, if any."""
        return (DEFAULT_HEAD_CHOICE,) + POLICY_HEADS + self._head_files

    @property
    def head(self) -> str:
        """The Head choice sessions are built with from the next Reset (``policy.head`` of ``cfg``)."""
        return self.cfg.policy.head or DEFAULT_HEAD_CHOICE

    @staticmethod
    def scorer_names() -> tuple[str, ...]:
        """Scorers offered by ``l3mvn.agent.language``."""
        from l3mvn.agent.language import scorer_names

        return tuple(scorer_names())

    # --- listeners ---------------------------------------------------------------------------
    def on_snapshot(self, fn: Callable[[Snapshot], None]) -> None:
        self._snapshot_fns.append(fn)

    def on_notice(self, fn: Callable[[Notice], None]) -> None:
        self._notice_fns.append(fn)

    @property
    def snapshot(self) -> Snapshot:
        return self._snapshot

    @property
    def session(self) -> EpisodeSession | None:
        return self._session

    @property
    def running(self) -> bool:
        return self._running

    @property
    def steps_per_second(self) -> float:
        return self._speed

    # --- commands (validate now, work on the worker) -----------------------------------------
    def reset(self, scene_key: str, episode_id: int, *, client_id: int | None = None, then_run: bool = False) -> None:
        """Start ``episode_id`` of ``scene_key`` on the worker; ``then_run`` queues a Run after it."""
        episode = self._find_episode(scene_key, episode_id)
        with self._lock:
            if self._reset_pending:
                raise L3MVNError("a reset is already in progress (maybe from another tab); wait for it")
            self._reset_pending, self._running, self._run_queued = True, False, then_run
        self._submit("reset", lambda: self._do_reset(episode), client_id, busy=f"resetting to episode {episode.key}")

    def step(self, *, client_id: int | None = None) -> None:
        """One step on the worker; on an episode that has ended, a notice that says so (nothing to do)."""
        with self._lock:
            session = None if self._reset_pending else self._session
            if self._session is None and not self._reset_pending:
                raise L3MVNError("no episode yet: pick one and press Reset (or Run, which starts it)")
            if session is not None and isinstance(session.policy, TeleopAgent):
                raise L3MVNError(
                    f"Step does not apply to policy {TELEOP!r}: drive with the arrow keys / WASD or the Drive buttons"
                )
        if session is not None and session.done:
            self._notify(_ended(session), client_id=client_id)
            return
        with self._lock:
            if self._running:
                raise L3MVNError("Step is disabled while Run is active: press Pause first")
            if self._steps_pending >= MAX_QUEUED_STEPS:
                raise L3MVNError(f"{self._steps_pending} steps are already queued: the agent is busy")
            self._steps_pending += 1
        self._submit("step", lambda: self._do_step(client_id), client_id)

    def drive(self, action: str, *, client_id: int | None = None) -> None:
        """One step with ``action`` chosen by hand (policy ``teleop`` only), queued like Step."""
        session = self._require_running_episode()
        if not isinstance(session.policy, TeleopAgent):
            raise L3MVNError(
                f"Drive moves the agent under policy {TELEOP!r} only (the episode runs "
                f"{session.policy_name!r}): pick Policy {TELEOP} and press Reset"
            )
        chosen = Action.parse(action)
        with self._lock:
            if self._running:
                raise L3MVNError("Drive is disabled while Run is active: press Pause first")
            if self._steps_pending >= MAX_QUEUED_STEPS:
                raise L3MVNError(f"{self._steps_pending} steps are already queued: the agent is busy")
            self._steps_pending += 1

        def drive_one() -> None:
            self._rate.clear()
            self._require_running_episode().drive(chosen)

        self._submit("step", drive_one, client_id)

    def run(self, *, client_id: int | None = None) -> None:
        """Step on a timer; during a reset, queued to start when it ends (a press is never lost)."""
        with self._lock:
            queued = self._reset_pending
            self._run_queued = self._run_queued or queued
        if queued:
            self._notify("Run queued: it starts as soon as the reset finishes", client_id=client_id)
            self._publish()
            return
        session = self._require_running_episode()
        if isinstance(session.policy, TeleopAgent):
            raise L3MVNError(
                f"Run does not apply to policy {TELEOP!r}: drive with the arrow keys / WASD or the Drive buttons"
            )
        with self._lock:
            self._running = True
        self._publish(note="running")

    def pause(self, *, client_id: int | None = None) -> None:
        with self._lock:
            was, self._running = self._running, False
            queued, self._run_queued = self._run_queued, False
            self._rate.clear()
        if queued:
            self._notify("the queued Run is cancelled: the episode stays at step 0", client_id=client_id)
        if was or queued:
            self._publish(note="paused")

    def set_speed(self, steps_per_second: float) -> None:
        self._speed = _clamp_speed(steps_per_second)
        self._rate.clear()  # the rate said is the one this speed gets

    def set_policy(self, name: str, *, client_id: int | None = None) -> None:
        """The policy of the next Reset; picking teleop on an episode loaded from a result line (paused,
        not over) hands that episode to teleop where it stands instead."""
        self.policy_name = check_policy(name)
        session = self._session
        if (
            name == TELEOP
            and self._loaded
            and session is not None
            and not session.done
            and not self._running
            and not isinstance(session.policy, TeleopAgent)
        ):
            self.take_over(client_id=client_id)
            return
        self._notify(f"policy {name!r} takes effect on the next Reset", client_id=client_id)
        self._publish()  # the page says what the chosen policy will show (a map or not)

    def set_scorer(self, name: str, *, client_id: int | None = None) -> None:
        """Swap the language scorer; one whose weights are not on disk is refused at once, by name."""
        names = (DEFAULT_SCORER,) + self.scorer_names()
        if name not in names:
            raise L3MVNError(f"unknown scorer {name!r}; valid scorers: {', '.join(names)}")
        if name in self.unavailable_scorers:
            usable = ", ".join(n for n in names if n not in self.unavailable_scorers)
            raise L3MVNError(f"scorer {name!r} is unavailable: {self.unavailable_scorers[name]}; usable: {usable}")
        if name == DEFAULT_SCORER:
            self.scorer = None
            self._notify("the policy's own scorer returns on the next Reset", client_id=client_id)
            return
        self.scorer = name
        session = self._session
        if session is None or not reads_language(session.policy_name):
            self._notify(
                f"scorer {name!r} takes effect when a language policy runs ({', '.join(language_policies())})",
                client_id=client_id,
            )
            return
        self._submit("scorer", self._apply_scorer, client_id, busy=f"loading the language scorer {name!r}")

    def set_head(self, name: str, *, client_id: int | None = None) -> None:
        """Set ``policy.head`` for sessions from the next Reset; only feed-forward scoring reads it."""
        if name not in self.head_names():
            raise L3MVNError(f"unknown head {name!r}; valid heads: {', '.join(self.head_names())}")
        head = None if name == DEFAULT_HEAD_CHOICE else name
        self.cfg = self.cfg.replace(policy=replace(self.cfg.policy, head=head))
        scorer = self._scorer_of(self.policy_name)
        if scorer == HEAD_SCORER:
            self._notify(f"head {name!r} takes effect on the next Reset", client_id=client_id)
        else:
            scoring = f"scores with {scorer!r}" if scorer else "uses no language scorer"
            self._notify(
                f"head {name!r} is kept but ignored by policy {self.policy_name!r}, which {scoring}: only "
                f"feed-forward scoring uses a head (policies {', '.join(self.headed_policies())}, "
                f"or Scorer {HEAD_SCORER})",
                client_id=client_id,
            )
        self._publish()  # every tab's Head dropdown follows

    def set_record(self, on: bool, *, client_id: int | None = None) -> None:
        self.record = on
        state = f"on: episodes from the next Reset are saved under {self.record_dir}/" if on else "off"
        self._notify(f"recording {state}", client_id=client_id)

    def set_manual_goal(self, cell: Cell | None, *, client_id: int | None = None) -> None:
        """Make a map cell the long-term goal until reached (None clears it)."""
        session = self._require_running_episode()
        if not isinstance(session.policy, Steerable):
            raise L3MVNError(
                f"policy {session.policy_name!r} does not take manual goals; map-based policies do "
                f"(valid: {', '.join(names_where(lambda spec: spec.map_based))})"
            )
        if cell is not None:
            view = self._snapshot.map
            if view is None or view.source != "agent map":
                raise L3MVNError("the agent has no map yet: step once, then pick a goal on the map")
            cell = (int(cell[0]), int(cell[1]))
            if not view.contains(cell):
                raise L3MVNError(f"cell {cell} is outside the {view.grid_shape[0]}x{view.grid_shape[1]} map")
        self._submit("manual goal", lambda: self._do_manual_goal(session, cell), client_id)

    def load(self, start: EpisodeStart, step: int, *, client_id: int | None = None) -> None:
        """Reset to ``start``'s episode under its own policy and config, step it to ``step`` without
        drawing the steps between (the policy decides each one, as when it was recorded), then pause
        there: Step and Run continue with the policy, ``take_over`` hands it to teleop."""
        if not isinstance(step, int) or isinstance(step, bool) or step < 0:
            raise L3MVNError(f"the step to load at must be a whole number from 0, not {step!r}")
        check_policy(start.policy)
        if start.policy == TELEOP:
            raise L3MVNError(f"an episode of policy {TELEOP!r} cannot be replayed: its actions were given by hand")
        with self._lock:
            if self._reset_pending:
                raise L3MVNError("a reset is already in progress (maybe from another tab); wait for it")
            self._reset_pending, self._running, self._run_queued = True, False, False
        self._submit(
            "load",
            lambda: self._do_load(start, step, client_id),
            client_id,
            busy=f"loading episode {start.episode.key} ({start.policy}) at step {step}",
        )

    def take_over(self, *, client_id: int | None = None) -> None:
        """Teleop drives the episode on from where it stands: the agent is put back on its way by
        replaying the actions taken so far (the map-based agent maps along), and the episode counts as
        hand-steered."""
        session = self._require_running_episode()
        if isinstance(session.policy, TeleopAgent):
            raise L3MVNError("the episode is already driven by hand: use the arrow keys / WASD or the Drive buttons")
        if session.segment:
            raise L3MVNError(f"teleop cannot take over after the target changed: pick Policy {TELEOP} and press Reset")
        with self._lock:
            if self._running:
                raise L3MVNError("teleop takes over a paused episode: press Pause first")
            if self._reset_pending:
                raise L3MVNError("a reset is already in progress (maybe from another tab); wait for it")
            self._reset_pending, self._run_queued = True, False
        self._submit(
            "load",
            lambda: self._do_take_over(session),
            client_id,
            busy=f"teleop takes over at step {session.env.steps}",
        )

    def change_target(self, goal: str, *, client_id: int | None = None) -> None:
        session = self._require_running_episode()
        if goal not in GOAL_CATEGORIES:
            raise L3MVNError(f"unknown target {goal!r}; valid targets: {', '.join(GOAL_CATEGORIES)}")
        present = session.task.scene.present_goals()
        if goal not in present:
            raise L3MVNError(f"target {goal!r} is not in {session.task.scene.key}; present: {', '.join(present)}")
        if goal == session.episode.goal:
            return
        self._submit("target", lambda: self._do_change_target(goal), client_id)

    # --- lifecycle ---------------------------------------------------------------------------
    def wait_idle(self, timeout: float = 10.0) -> bool:
        """Block until queued commands are done (tests; never called from the UI)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self._queue.empty() and self._idle.wait(0.01) and self._queue.empty():
                return True
        return False

    def close(self) -> None:
        self._running = False
        self._closed.set()
        self._queue.put(("close", lambda: None, None))
        self._thread.join(timeout=5.0)
        self._stop_recorder()

    # --- worker ------------------------------------------------------------------------------
    def _submit(self, what: str, fn: Callable[[], None], client_id: int | None, *, busy: str = "") -> None:
        """Queue ``fn`` for the worker; ``busy`` names a job that holds the controls until it ends."""
        self._idle.clear()
        if busy:
            with self._lock:
                job = next(self._job_ids)
                self._busy[job] = busy
            self._publish()
            fn = functools.partial(self._held, job, fn)
        self._queue.put((what, fn, client_id))

    def _held(self, job: int, fn: Callable[[], None]) -> None:
        """Run a controls-holding job; when it ends (or fails) the page gets its controls back."""
        self._current_job = job
        try:
            fn()
        finally:
            with self._lock:
                self._busy.pop(job, None)
                self._current_job = None

    def _loop(self) -> None:
        next_step = time.monotonic()
        while not self._closed.is_set():
            wait = max(next_step - time.monotonic(), 0.0) if self._running else 0.2
            try:
                what, fn, client_id = self._queue.get(timeout=wait)
            except queue.Empty:
                if self._running:
                    self._idle.clear()
                    next_step = time.monotonic() + 1.0 / self._speed
                    self._guarded("run", self._do_run_step, None)
            else:
                self._guarded(what, fn, client_id)
            if self._queue.empty() and not self._running:
                self._idle.set()

    def _guarded(self, what: str, fn: Callable[[], None], client_id: int | None) -> None:
        """Run one worker job; whatever it raises becomes a notice that stays until dismissed (the
        request was accepted earlier, so the user may have looked away) and the snapshot's error.
        Every job but a plain step ends with a snapshot, so the page never keeps a stale busy state."""
        failed = True
        try:
            fn()
            failed = False
        except L3MVNError as exc:
            self._running = False
            self._notify(f"{what}: {exc}", level="warning", client_id=client_id, sticky=True, title="Request failed")
            self._publish(error=str(exc))
        except Exception as exc:  # the page must stay up whatever the agent does
            log.exception("dashboard %s failed", what)
            self._running = False
            self._notify(f"{what} failed: {type(exc).__name__}: {exc}", level="error", sticky=True)
            self._publish(error=f"{what} failed: {type(exc).__name__}: {exc}")
        finally:
            queued = False
            with self._lock:
                if what in ("reset", "load"):
                    self._reset_pending = False
                    queued, self._run_queued = self._run_queued, False
                    teleop = self._session is None or isinstance(self._session.policy, TeleopAgent)
                    self._running = queued and not failed and not teleop
                elif what == "step":
                    self._steps_pending -= 1
            if queued and failed:
                self._notify("the queued Run is cancelled: the reset failed", level="warning", client_id=client_id)
            if failed or what not in ("step", "run"):  # a step's own event already drew it
                self._publish(note="running" if self._running else self._snapshot.note)

    def _do_reset(self, episode: Episode) -> None:
        self._rate.clear()
        scene = self.episodes.scene_of(episode)
        cfg = self._session_config(self.policy_name)
        self._stop_recorder()
        if not self._runner_fits(cfg, self.policy_name):
            self._runner.close()
            self._runner, self._swapped_live = Runner(cfg, seed=self.seed), False
        if reads_language(self.policy_name) and self.policy_name not in self._runner.floor(scene).policies:
            self._set_busy(
                f"loading the language model of {self.policy_name} (a few seconds; the first time an "
                "LLM is converted for torch, tens of seconds)"
            )
            asked = replace(self.cfg.policy, scorer=self.scorer or self.cfg.policy.scorer)
            if fallback := scorer_choice(self.policy_name, asked)[1]:
                self._notify(fallback, level="warning")
        # The same hash ``l3mvn eval`` writes for these settings, so dashboard runs can be matched.
        chash = config_hash(cfg, self.policy_name, self.seed)
        session = self._runner.session(scene, self.policy_name, self.bus, config_hash=chash)
        self._begin(session, self.episodes.name, episode, loaded=False)
        session.start(episode)

    def _begin(self, session: EpisodeSession, dataset: str, episode: Episode, *, loaded: bool) -> None:
        """Make ``session`` the one shown, with a fresh episode's state (and recording), before it starts."""
        self._session, self._dataset, self._loaded = session, dataset, loaded
        self._manual, self._segment_note, self._steered = None, "", False
        if self.record:
            self._start_recorder(dataset, episode, session.policy_name)
        self._trajectory, self._actions = [], []

    def _do_load(self, start: EpisodeStart, step: int, client_id: int | None) -> None:
        self._stop_recorder()
        if self._swapped_live or self._runner.config != start.config:
            self._runner.close()
            self._runner, self._swapped_live = Runner(start.config, seed=self.seed), False
        if reads_language(start.policy) and start.policy not in self._runner.floor(start.scene).policies:
            self._set_busy(f"loading the language model of {start.policy}")
        chash = config_hash(start.config, start.policy, self.seed)
        session = self._runner.session(start.scene, start.policy, self.bus, config_hash=chash)
        self._begin(session, start.dataset, start.episode, loaded=True)
        self._quiet = range(1, step)  # its start is drawn: to the page, a new episode (fresh history, fitted map)
        try:
            session.start(start.episode)
            while session.env.steps < step and not session.done:
                session.step()
        finally:
            self._quiet = range(0)
        key, at = start.episode.key, session.env.steps
        notes = [f"loaded {key} ({start.policy}) at step {at}"]
        if at < step:
            notes.append(f"the episode ended at step {at}, before step {step}")
        else:
            notes.append(f"press Step or Run and {start.policy} goes on; pick Policy {TELEOP} to drive from here")
        if start.stored_hash and start.stored_hash != chash:
            notes.append("the config hash differs from the stored line's (another seed?): the replay may differ")
        diverged = _divergence(start.recorded, self._trajectory)
        if diverged:
            notes.append(diverged)
        self._notify(
            "; ".join(notes),
            level="warning" if diverged else "info",
            client_id=client_id,
            sticky=True,
            title="Episode loaded",
        )
        self._publish(note=notes[0])

    def _do_take_over(self, old: EpisodeSession) -> None:
        assert old.episode is not None
        actions, trajectory, loaded = list(self._actions), list(self._trajectory), self._loaded
        self._stop_recorder()
        session = self._runner.session(
            old.task.scene, TELEOP, self.bus, config_hash=config_hash(self._runner.config, TELEOP, self.seed)
        )
        self._begin(session, self._dataset, old.episode, loaded=loaded)
        self._steered = True
        self._quiet = range(len(actions))  # the same walk goes on: its history stays
        try:
            session.start(old.episode)
            for action in actions:
                session.drive(action)
        finally:
            self._quiet = range(0)
        recorded = dict(enumerate(trajectory))
        diverged = _divergence(recorded, self._trajectory)
        note = f"teleop took over {old.episode.key} at step {session.env.steps}: drive with the arrow keys / WASD"
        self._notify(
            note + (f"; {diverged}" if diverged else "") + "; the episode counts as steered by hand",
            level="warning" if diverged else "info",
        )
        self._publish(note=note)

    def _scorer_of(self, policy: str) -> str | None:
        """The scorer a session of ``policy`` built now scores with (None: not a language policy)."""
        return scorer_of(policy, replace(self.cfg.policy, scorer=self.scorer or self.cfg.policy.scorer))

    @staticmethod
    def headed_policies() -> tuple[str, ...]:
        return names_where(
            lambda spec: spec.language is not None and spec.same_as is None and spec.language.scorer == HEAD_SCORER
        )

    def _session_config(self, policy: str) -> Config:
        """The config a session of ``policy`` is built and hashed with: the Scorer choice for a language
        policy, and the Head only where that scorer reads one (a head elsewhere is refused or ignored)."""
        scorer = self._scorer_of(policy)
        p = self.cfg.policy
        headed = scorer == HEAD_SCORER
        chosen = self.cfg.replace(
            policy=replace(
                p,
                scorer=scorer if self.scorer else p.scorer,
                head=p.head if headed else None,
                embedder=p.embedder if headed else None,
            )
        )
        return with_scorer(policy, chosen)  # as `l3mvn eval` hashes it: the scorer in force written in

    def _runner_fits(self, cfg: Config, policy: str) -> bool:
        """Whether the warm runner builds ``policy`` as ``cfg`` says: its policies are cached by name, so
        another Scorer or Head, or a scorer swapped live into a warm policy, needs a new runner; a policy
        without a language scorer never reads the head."""
        if self._swapped_live:
            return False
        have = self._runner.config
        if self._scorer_of(policy) is None:
            have = have.replace(policy=replace(have.policy, head=cfg.policy.head, embedder=cfg.policy.embedder))
        return have == cfg

    def _set_busy(self, text: str) -> None:
        """Say more about the controls-holding job in progress (what takes long inside it)."""
        with self._lock:
            job = self._current_job
            if job in self._busy:
                self._busy[job] = f"{self._busy[job]}: {text}"
        self._publish()

    def _do_step(self, client_id: int | None) -> None:
        session = self._session
        if session is not None and session.done:  # queued behind the step that ended the episode
            self._notify(_ended(session), client_id=client_id)
            return
        self._rate.clear()
        self._require_running_episode().step()

    def _do_run_step(self) -> None:
        session = self._session
        if session is None or session.done:
            self._running = False
            return
        self._rate.add(time.monotonic())
        session.step()
        if session.done:
            self._running = False

    def _do_manual_goal(self, session: EpisodeSession, cell: Cell | None) -> None:
        session.set_manual_goal(cell)
        self._manual = cell
        self._steered = self._steered or cell is not None
        what = "cleared the manual goal" if cell is None else f"manual long-term goal set to map cell {cell}"
        self._notify(what)
        self._publish(note=what)

    def _do_change_target(self, goal: str) -> None:
        session = self._require_running_episode()
        previous, old = self._segment_note, session.episode.goal
        # Set before the change: the new segment's first event is published inside change_target.
        self._segment_note = (
            f"segment {session.segment + 1}: target changed {old} -> {goal} at step {session.env.steps}"
        )
        try:
            session.change_target(goal)
        except Exception:
            self._segment_note = previous
            raise
        self._notify(self._segment_note)

    def _apply_scorer(self) -> None:
        session = self._session
        if self.scorer is None or session is None:
            return
        try:
            session.set_scorer(self.scorer)
            self._swapped_live = True
        except L3MVNError as exc:
            self._notify(str(exc), level="warning", sticky=True, title="Scorer not applied")

    def _start_recorder(self, dataset: str, episode: Episode, policy: str) -> None:
        """A recording of this run of ``episode`` under a name of its own: the session may run an
        episode many times, and the folder may hold an eval's recording of it (never replaced)."""
        from l3mvn.run.recording import Recorder

        recorder = Recorder.for_episode(self.record_dir, dataset, episode, policy, unique_tag("live")).attach(self.bus)
        self._recorder_off = recorder.close

    def _stop_recorder(self) -> None:
        if self._recorder_off is not None:
            off, self._recorder_off = self._recorder_off, None
            off()

    # --- step events -> snapshots ------------------------------------------------------------
    def _on_event(self, event: StepEvent) -> None:
        """Runs on the worker, right after each step: the map is a live view, so draw it now."""
        stepped_at = time.time()
        session = self._session
        assert session is not None
        self._trajectory.append(event.pose)
        if event.action is not None:
            self._actions.append(event.action)
        if event.step in self._quiet and not event.done:
            return  # stepping to the step an episode is loaded or taken over at: that step is drawn
        decision = event.decision
        if decision is not None and decision.map is not None:
            view = agent_map_view(decision, target=event.goal)
        elif not keeps_map(session.policy_name):
            view = ground_truth_view(session.task.scene, self._trajectory, decision, target=event.goal)
        else:
            view = None  # a map-based agent before its first step
        if decision is not None and decision.goal_kind == "manual" and decision.override:
            self._manual = decision.long_term_goal
        elif decision is not None and self._manual is not None and decision.goal_kind not in ("manual", ""):
            self._manual = None  # the policy dropped it: reached or cleared
        metrics = self._snapshot.metrics
        if event.done:
            with self._lock:
                self._running = False  # this step's snapshot is the last: it must not say "running"
        if event.done and event.result is not None:
            steered = self._steered or isinstance(session.policy, TeleopAgent)
            metrics = metrics.add_steered() if steered else metrics.add(event.result, session.policy_name)
            self._notify(
                _outcome(event) + ("; steered by hand: not counted in the session's SR/SPL" if steered else ""),
                level="info" if event.result.get("success") else "warning",
                sticky=True,
                title="Episode over",
            )
        self._publish(
            event=event,
            frames=self._frames(event),
            map=view,
            metrics=metrics,
            episode_id=session.episode.episode_id,
            scene=session.task.scene.key,
            note="",
            error=None,
            stepped_at=stepped_at,
            achieved_steps_per_second=self._rate.per_second if self._running else None,
        )

    def _frames(self, event: StepEvent) -> Frames:
        obs = event.observation
        k, u = frame_display_steps(obs.rgb.shape[1])

        def enlarged(img: np.ndarray) -> np.ndarray:
            return img.repeat(u, axis=0).repeat(u, axis=1) if u > 1 else img

        return Frames(
            rgb=enlarged(obs.rgb[::k, ::k]),
            depth=enlarged(colorize_depth(obs.depth[::k, ::k], self.cfg.sim.max_depth_m)),
            semantic=enlarged(colorize_semantic(obs.semantic[::k, ::k], obs.categories)),
        )

    def _publish(self, **changes) -> None:
        with self._lock:
            self._seq += 1
            # The policy of the episode shown (the dropdown's choice waits for the next Reset).
            policy = self._session.policy_name if self._session is not None else self.policy_name
            snap = replace(
                self._snapshot,
                seq=self._seq,
                running=self._running,
                policy=policy,
                steps_per_second=self._speed,
                manual_goal=self._manual,
                segment_note=self._segment_note,
                busy="; ".join(self._busy.values()),
                run_queued=self._run_queued,
                **changes,
            )
            self._snapshot = snap
        for fn in list(self._snapshot_fns):
            try:
                fn(snap)
            except Exception:
                log.exception("dashboard view failed on snapshot %d", snap.seq)

    def _notify(
        self, text: str, *, level: str = "info", client_id: int | None = None, sticky: bool = False, title: str = ""
    ) -> None:
        notice = Notice(text=text, level=level, client_id=client_id, sticky=sticky, title=title)
        for fn in list(self._notice_fns):
            try:
                fn(notice)
            except Exception:
                log.exception("dashboard notice failed")

    # --- helpers -----------------------------------------------------------------------------
    def _find_episode(self, scene_key: str, episode_id: int) -> Episode:
        for ep in self.episodes_of(scene_key):
            if ep.episode_id == episode_id:
                return ep
        ids = ", ".join(str(e.episode_id) for e in self._by_scene[scene_key])
        raise L3MVNError(f"unknown episode {episode_id!r} in {scene_key}; valid episode ids: {ids}")

    def _require_running_episode(self) -> EpisodeSession:
        session = self._session
        if session is None or session.episode is None:
            raise L3MVNError("no episode yet: pick one and press Reset")
        if session.done:
            raise L3MVNError(f"episode {session.episode.key} is over: press Reset to start another")
        return session


def _divergence(recorded: Mapping[int, Pose], replayed: list[Pose]) -> str:
    """Where ``replayed`` (one pose per step from 0) first leaves ``recorded``; "" if it never does."""
    for step, pose in enumerate(replayed):
        was = recorded.get(step)
        if was is None:
            continue
        if max(abs(pose.x - was.x), abs(pose.y - was.y), abs(wrap_angle(pose.heading - was.heading))) > POSE_TOLERANCE:
            return (
                f"the replay diverges from the recording at step {step}: recorded ({was.x:.2f}, {was.y:.2f}) "
                f"heading {was.heading:.2f}, replayed ({pose.x:.2f}, {pose.y:.2f}) heading {pose.heading:.2f}"
            )
    return ""


def _verdict(result: dict) -> str:
    return "SUCCESS" if result.get("success") else f"FAILURE ({result.get('failure') or 'not reached'})"


def _outcome(event: StepEvent) -> str:
    """One line for the end of an episode: what happened, in the units the paper reports."""
    r = event.result or {}
    return f"episode {event.episode_key}: {_verdict(r)}, SPL {float(r.get('spl', 0.0)):.2f}, {r.get('steps')} steps"


def _ended(session: EpisodeSession) -> str:
    """The answer to a Step once the episode is over: not a failure, just nothing left to step."""
    assert session.episode is not None
    verdict = _verdict(session.result.to_json())
    return f"episode {session.episode.key} has ended ({verdict}): press Reset for the next one"


def frame_display_steps(width: int) -> tuple[int, int]:
    """(stride, enlargement) that bring a camera frame ``width`` pixels wide to about ``FRAME_WIDTH``:
    a large frame is subsampled, a small one enlarged by whole pixels (blocky, not blurred: the page
    shows what the agent saw)."""
    return max(1, width // FRAME_WIDTH), max(1, FRAME_WIDTH // width)


def check_speed(value: float) -> float:
    """``serve --speed``: a value out of range is refused, never clamped (a user who asked for 100
    steps per second must not silently get 60)."""
    if not (isinstance(value, Real) and not isinstance(value, bool) and MIN_SPEED <= value <= MAX_SPEED):
        raise L3MVNError(
            f"--speed must be a number of steps per second from {MIN_SPEED:g} to {MAX_SPEED:g}, got {value!r}"
        )
    return float(value)


def _clamp_speed(value: float) -> float:
    """``value`` within [MIN_SPEED, MAX_SPEED]; not a finite number is refused (Run waits 1 / speed)."""
    if not isinstance(value, Real) or isinstance(value, bool) or not math.isfinite(value):
        raise L3MVNError(f"steps per second must be a number from {MIN_SPEED:g} to {MAX_SPEED:g}, not {value!r}")
    return float(min(max(value, MIN_SPEED), MAX_SPEED))

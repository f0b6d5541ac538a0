"""The viser page: shared controls in the side panel, the map as a textured plane in the 3D view.

All handles are shared (``server.gui`` / ``server.scene``), so every tab shows the same session and a
new or reloaded tab gets the current state from viser on connect. Only notices about a tab's own
request go to that tab (``client.add_notification``). Snapshots are drawn on a thread of their own
that always takes the newest one, so a fast agent drops frames instead of queueing them.

Nothing a tab sends is trusted: each GUI value is checked against its control before viser applies
it (``_admit_update``), map-click rays are checked before use, and every handler runs through
``_reported``, so whatever goes wrong becomes a notice to the tab that asked and the server goes on.

Scene frame: map cell (row, col) -> (x, y) = ((col + 0.5) res, -(row + 0.5) res), z up toward the
camera, so the top-down view shows the map the way its image is stored (row 0 on top).
"""

from __future__ import annotations

import functools
import logging
import math
import threading

import cv2
import numpy as np
import viser

from l3mvn_studio.client_input import ray_refusal, update_refusal
from l3mvn_studio.compare_view import ComparePanel, EpisodeSource
from l3mvn_studio.language_panel import language_html
from l3mvn_studio.history_view import HistoryPanel
from l3mvn_studio.page_text import code, html, md
from l3mvn_studio.map_image import GT_FLOOR, GT_GOAL, GT_REGION, ground_truth_layer, score_color
from l3mvn_studio.recordings_view import RecordingsPanel
from l3mvn_studio.results_view import ResultsPanel, ResultsSource
from l3mvn_studio.session_worker import DEFAULT_SCORER, FRAME_WIDTH, MAX_SPEED, MIN_SPEED, DashboardController
from l3mvn_studio.state import Cell, FrontierMarker, MapView, Notice, Snapshot
from l3mvn_studio.viser_hooks import (
    check_gui_updates, handle_uuid, ignore_client_messages_except, run_script_on_connect, show_value_to,
)
from l3mvn.core.errors import L3MVNError
from l3mvn.run.registry import DIRECT_POLICIES, POLICY_NAMES, TELEOP
from l3mvn.core.categories import GOAL_CATEGORIES
from l3mvn.run.viz import COLLISION_RGB, legend

log = logging.getLogger(__name__)

# Run and Pause share a slot: the group offers the one that acts now (and Space presses it).
BUTTONS_PAUSED = ("Reset", "Step", "Run")
BUTTONS_RUNNING = ("Reset", "Step", "Pause")
MARKER_RADIUS_M = 0.22
TOP_LABELS = 3  # frontiers labelled on the map (the best by score, plus the chosen one)
NOTICE_SECONDS = 8.0  # how long a passing notice stays; outcomes and failures stay until dismissed
POLICY_NOTES = {
    "random-walk": "random-walk is the paper's baseline: uniformly random actions, STOP among them, "
                   "so most episodes end within a few steps",
}
RENDER_NOTE = ("_Frames from the built-in CPU simulator: flat-shaded boxes, not photographs. "
               "The agent sees exactly these._")
SHORTCUTS_MD = "Keys: `Space` run / pause, `N` step, `R` reset, `F` fit map (not while typing in a field)"
# Policy teleop: button -> action; the keys below press the buttons (only while they are shown).
DRIVE = {"Turn left": "turn_left", "Forward": "move_forward", "Turn right": "turn_right",
         "Look up": "look_up", "Look down": "look_down", "Stop": "stop"}
DRIVE_MD = ("Keys: `W` / `Up` forward, `A` / `Left` and `D` / `Right` turn, `Q` look up, `E` look down, "
            "`X` stop (ends the episode; it is scored like any policy's)")
# Pressed keys click the page's own buttons, so a shortcut goes through the same checks as a click.
SHORTCUTS_JS = """
if (!window.__l3mvnShortcuts) {
  window.__l3mvnShortcuts = true;
  const keys = {" ": ["Pause", "Run"], "n": ["Step"], "r": ["Reset"], "f": ["Fit map in view"]};
  // Drive keys (policy teleop) count only while the Drive buttons are shown; otherwise they stay
  // viser's camera keys.
  const drive = {"w": "Forward", "arrowup": "Forward", "a": "Turn left", "arrowleft": "Turn left",
                 "d": "Turn right", "arrowright": "Turn right", "q": "Look up", "e": "Look down", "x": "Stop"};
  const shown = (name) => Array.from(document.querySelectorAll("button"))
    .some((b) => b.textContent.trim() === name && b.offsetParent !== null);
  const ours = (e) => {
    const t = e.target;
    if (e.ctrlKey || e.metaKey || e.altKey) return null;
    if (t instanceof HTMLElement && (t.isContentEditable || ["INPUT", "TEXTAREA", "SELECT"].includes(t.tagName))) return null;
    const key = e.key.toLowerCase();
    if (drive[key] && shown("Forward")) return [drive[key]];
    return keys[key] || null;
  };
  // A focused button would take Space as a click of its own too: the key is ours alone.
  document.addEventListener("keyup", (e) => { if (ours(e)) { e.preventDefault(); e.stopPropagation(); } }, true);
  document.addEventListener("keydown", (e) => {
    const names = ours(e);
    if (!names) return;
    e.preventDefault();
    e.stopPropagation();
    if (e.repeat) return;
    const buttons = Array.from(document.querySelectorAll("button"));
    for (const name of names) {
      const b = buttons.find((x) => x.textContent.trim() === name && !x.disabled && x.offsetParent !== null);
      if (b) { b.click(); return; }
    }
  }, true);
}
"""
_LEVEL_COLORS = {"info": "blue", "warning": "yellow", "error": "red"}
_CLICKABLE = (viser.GuiButtonHandle, viser.GuiButtonGroupHandle)  # on_click, not on_update; no value to show
_INPUTS = (viser.GuiInputHandle, *_CLICKABLE)  # every control a tab can send values to


def cell_to_xy(cell: Cell, res: float) -> tuple[float, float]:
    return (cell[1] + 0.5) * res, -(cell[0] + 0.5) * res


def xy_to_cell(x: float, y: float, res: float) -> Cell:
    return int(math.floor(-y / res)), int(math.floor(x / res))


_FARTHEST_CELL = 1e9  # farther from the origin than any map (a 48 m map has about 1,000 cells a side)


def ray_to_cell(origin, direction, res: float) -> Cell | None:
    """Where a click ray meets the map plane (z = 0); None when it runs parallel, away, or so far
    off that no map reaches there (a finite 1e308 would overflow as a cell index)."""
    oz, dz = float(origin[2]), float(direction[2])
    if abs(dz) < 1e-9 or -oz / dz < 0:
        return None
    t = -oz / dz
    x, y = float(origin[0]) + t * float(direction[0]), float(origin[1]) + t * float(direction[1])
    if not (abs(x / res) < _FARTHEST_CELL and abs(y / res) < _FARTHEST_CELL):  # NaN and inf fail too
        return None
    return xy_to_cell(x, y, res)


class DashboardView:
    """Builds the page once and keeps it in sync with the controller's snapshots."""

    def __init__(self, server: viser.ViserServer, controller: DashboardController,
                 results: ResultsSource | None = None, compare: EpisodeSource | None = None) -> None:
        self.server, self.ctl = server, controller
        self._latest: Snapshot | None = None
        self._drawn: tuple = (None, None)  # (event, manual goal) the map was last drawn for
        self._wake = threading.Condition()
        self._closed = False
        self._markers: list[tuple[viser.IcosphereHandle, viser.LabelHandle]] = []
        self._frontier_cells: dict[str, Cell] = {}
        self._fitted: tuple | None = None  # (episode, source, crop in cells) the cameras were fitted to
        self._busy_notes: dict[int, viser.NotificationHandle] = {}
        self._gt_key: tuple | None = None  # what the ground-truth layer was last built for
        self._build_gui()
        self.compare = None if compare is None else ComparePanel(
            server.gui, compare, config=controller.cfg, record_dir=controller.record_dir,
            current_policy=controller.policy_name, selected_episode=self._selected_episode, on=self._on, tell=self._tell)
        self.results = None if results is None else ResultsPanel(server.gui, results, on=self._on, tell=self._tell,
                                                                 compare=self.compare)
        self._build_scene()
        panel_inputs = ((() if self.results is None else self.results.inputs)
                        + (() if self.compare is None else self.compare.inputs)
                        + self.recordings.inputs + self.history.inputs)
        self._inputs = {handle_uuid(h): h for h in (*vars(self).values(), *panel_inputs) if isinstance(h, _INPUTS)}
        check_gui_updates(server, self._admit_update)
        ignore_client_messages_except(server, "GuiUpdateMessage", "ScenePointerMessage")  # controls, map clicks
        run_script_on_connect(server, SHORTCUTS_JS)
        controller.on_snapshot(self._on_snapshot)
        controller.on_snapshot(self.history.add)
        controller.on_notice(self._on_notice)
        self._thread = threading.Thread(target=self._draw_loop, name="l3mvn-dashboard-view", daemon=True)
        self._thread.start()
        self._on_snapshot(controller.snapshot)

    # --- layout ------------------------------------------------------------------------------
    def _build_gui(self) -> None:
        gui, ctl = self.server.gui, self.ctl
        gui.configure_theme(control_width="large", show_share_button=False, brand_color=(40, 90, 200))
        gui.add_markdown("**L3MVN Studio**: language-guided ObjectNav, live")
        first = ctl.episodes_of(ctl.scene_keys[0])[0]
        with gui.add_folder("Episode"):
            self.scene = gui.add_dropdown("Scene", ctl.scene_keys)
            self.episode = gui.add_dropdown("Episode", self._episode_labels(ctl.scene_keys[0]))
            self.target = gui.add_dropdown("Target", GOAL_CATEGORIES, initial_value=first.goal,
                                           hint="the episode's goal; changing it mid-episode starts a new segment")
            self.policy = gui.add_dropdown("Policy", POLICY_NAMES, initial_value=ctl.policy_name,
                                           hint="takes effect on the next Reset")
            self.scorer = gui.add_dropdown("Scorer", (DEFAULT_SCORER,) + ctl.scorer_names(),
                                           hint="language policies only; 'policy default' restores theirs on Reset")
            self.scorer_note = gui.add_markdown(_unavailable_markdown(ctl.unavailable_scorers))
            self.head = gui.add_dropdown("Head", ctl.head_names(), initial_value=ctl.head,
                                         hint=f"feed-forward scoring only ({', '.join(ctl.headed_policies())} "
                                              "or Scorer feedforward); other scorers ignore it; takes effect on "
                                              "the next Reset")
            self.controls = gui.add_button_group("Controls", BUTTONS_PAUSED)
            self.speed = gui.add_slider("Steps / s", min=MIN_SPEED, max=MAX_SPEED, step=0.5,
                                        initial_value=ctl.snapshot.steps_per_second)
            self.record = gui.add_checkbox("Record (.rrd)", False, hint="rerun recording of each new episode")
            gui.add_markdown(SHORTCUTS_MD)
        with gui.add_folder("Drive (policy teleop)", visible=ctl.policy_name == TELEOP) as self.drive_folder:
            self.drive_turns = gui.add_button_group("Drive", ("Turn left", "Forward", "Turn right"))
            self.drive_other = gui.add_button_group("Look / stop", ("Look up", "Look down", "Stop"))
            gui.add_markdown(DRIVE_MD)
        with gui.add_folder("Status"):
            self.status = gui.add_markdown("")
            self.metrics = gui.add_markdown("")
            self.fit = gui.add_button("Fit map in view")
            self.auto_fit = gui.add_checkbox("Auto-fit map", True,
                                             hint="refit the view whenever the map outgrows it")
            self.ground_truth = gui.add_checkbox(
                "Ground truth", False,
                hint="overlay what the agent does not know: the whole floor plan, the success region and "
                     "the true goal instances (magenta)")
        with gui.add_folder("Camera"):
            blank = self._placeholder_frame()
            self.rgb = gui.add_image(blank, label="RGB")
            self.depth = gui.add_image(blank, label="Depth (near blue, far red)")
            self.semantic = gui.add_image(blank, label="Semantic (map colours)")
            gui.add_markdown(RENDER_NOTE)
        with gui.add_folder("Frontiers"):
            self.frontier_pick = gui.add_dropdown("Frontier", ("none",), disabled=True)
            self.goal_buttons = gui.add_button_group("Manual goal", ("Go to frontier", "Clear"))
            self.frontier_table = gui.add_markdown(_no_map_markdown(ctl.policy_name, started=False))
        with gui.add_folder("Language"):
            self.language = gui.add_html(language_html(None, ctl.policy_name))
        self.history = HistoryPanel(gui, on=self._on, tell=self._tell)
        self.recordings = RecordingsPanel(gui, lambda: ctl.record_dir, self.server.get_host(), on=self._on, tell=self._tell)
        with gui.add_folder("Legend"):
            self.legend = gui.add_html(_legend_html(legend(GOAL_CATEGORIES), target=first.goal))
        self._listed_episodes = 0
        # Held while the worker resets or loads a model: a change then would apply to a half-built session.
        self._held = (self.scene, self.episode, self.target, self.policy, self.scorer, self.head, self.record)
        self._wire_gui()

    def _wire_gui(self) -> None:
        ctl = self.ctl

        @self._on(self.scene)
        def _(event: viser.GuiEvent) -> None:
            labels = self._episode_labels(self.scene.value)
            self.episode.options = labels
            self.episode.value = labels[0]
            self._follow_selected_episode(event.client_id)

        @self._on(self.episode)
        def _(event: viser.GuiEvent) -> None:
            self._follow_selected_episode(event.client_id)

        @self._on(self.controls)
        def _(event: viser.GuiEvent) -> None:
            self._press(self.controls.value, event.client_id)

        @self._on(self.speed)
        def _(event: viser.GuiEvent) -> None:
            ctl.set_speed(self.speed.value)

        @self._on(self.policy)
        def _(event: viser.GuiEvent) -> None:
            ctl.set_policy(self.policy.value, client_id=event.client_id)
            if self.compare is not None:
                self.compare.follow_policy(self.policy.value)

        @self._on(self.scorer)
        def _(event: viser.GuiEvent) -> None:
            try:
                ctl.set_scorer(self.scorer.value, client_id=event.client_id)
            finally:
                self.scorer.value = ctl.scorer or DEFAULT_SCORER  # what the controller uses, refused or not

        @self._on(self.head)
        def _(event: viser.GuiEvent) -> None:
            try:
                ctl.set_head(self.head.value, client_id=event.client_id)
            finally:
                self.head.value = ctl.head  # what the next Reset builds with, refused or not

        @self._on(self.record)
        def _(event: viser.GuiEvent) -> None:
            try:
                ctl.set_record(self.record.value, client_id=event.client_id)
            finally:
                self.record.value = ctl.record  # the box shows what the controller does, refused or not

        @self._on(self.target)
        def _(event: viser.GuiEvent) -> None:
            self._change_target(self.target.value, event.client_id)

        @self._on(self.goal_buttons)
        def _(event: viser.GuiEvent) -> None:
            if self.goal_buttons.value == "Clear":
                if ctl.snapshot.manual_goal is None:
                    raise L3MVNError("no manual goal to clear: pick a frontier or click the map to set one")
                ctl.set_manual_goal(None, client_id=event.client_id)
                return
            cell = self._frontier_cells.get(self.frontier_pick.value)
            if cell is None:
                raise L3MVNError("no frontier picked: step until the map shows frontiers, then pick one above")
            ctl.set_manual_goal(cell, client_id=event.client_id)

        for group in (self.drive_turns, self.drive_other):
            self._on(group)(lambda event, group=group: ctl.drive(DRIVE[group.value], client_id=event.client_id))

        @self._on(self.ground_truth)
        def _(event: viser.GuiEvent) -> None:
            if self.ground_truth.value and ctl.snapshot.map is None:
                self.ground_truth.value = False
                raise L3MVNError("no episode on the map yet: press Reset, then tick Ground truth")
            self._redraw()

        @self._on(self.fit)
        def _(event: viser.GuiEvent) -> None:
            view = ctl.snapshot.map
            if view is None:
                raise L3MVNError("no map to fit yet: press Reset (or Run) to start an episode")
            self._fit_camera(event.client.camera, view)

    def _on(self, handle):
        """Decorator: run the function when a tab changes or clicks ``handle``, through ``_reported``.

        Assignments made here on the server fire ``on_update`` too (with no client); only a tab's
        own changes are handled, so a handler that sets a value does not run itself again.
        """
        register = handle.on_click if isinstance(handle, _CLICKABLE) else handle.on_update

        def wire(fn):
            reported = self._reported(handle.label, fn)

            def from_tab(event: viser.GuiEvent) -> None:
                if event.client is not None:
                    reported(event)

            register(from_tab)
            return fn

        return wire

    def _reported(self, what: str, fn):
        """``fn(event)`` such that whatever it raises becomes a notice to the tab that sent ``event``.

        A refused request (``L3MVNError``) is a warning with its own message; anything else is a bug,
        logged with its traceback and shown as an error. Without this, viser's thread pool would
        print the traceback and the tab would never know its click did nothing.
        """

        @functools.wraps(fn)
        def run(event) -> None:
            try:
                fn(event)
            except L3MVNError as exc:
                self._tell(event.client_id, str(exc), "warning")
            except Exception as exc:
                log.exception("dashboard: %s failed", what)
                self._tell(event.client_id, f"{what} failed: {type(exc).__name__}: {exc}", "error")

        return run

    def _build_scene(self) -> None:
        scene = self.server.scene
        scene.set_up_direction("+y")
        scene.add_light_ambient("/light", intensity=1.0)
        self.map_plane = scene.add_image("/map", np.zeros((8, 8, 3), np.uint8), 1.0, 1.0, format="png",
                                         cast_shadow=False, receive_shadow=False, visible=False)
        self.map_note = scene.add_label("/map_note", "Press Reset (or Run) to start an episode", position=(0, 0, 0.2),
                                        font_screen_scale=1.4)
        self.agent = scene.add_mesh_simple("/agent", *_arrow_mesh(), color=(230, 30, 40), visible=False)
        # Above the frontier spheres (a top-down camera sees it in front of the chosen one).
        self.ltg = scene.add_icosphere("/goal/long_term", 0.16, (220, 20, 60), visible=False)
        self.ltg_label = scene.add_label("/goal/long_term/label", "long-term goal", position=(0.0, -0.3, 0.1),
                                         anchor="top-center")
        self.stg = scene.add_icosphere("/goal/short_term", 0.08, (255, 150, 0), visible=False)
        self.gt_plane = scene.add_image("/ground_truth", np.zeros((8, 8, 4), np.uint8), 1.0, 1.0, format="png",
                                        cast_shadow=False, receive_shadow=False, visible=False)
        self.gt_label = scene.add_label("/ground_truth_label", "", position=(0, 0, 0.3), visible=False)

        scene.on_click()(self._reported("map click", self._on_map_click))

    # --- input -------------------------------------------------------------------------------
    def _press(self, button: str, client_id: int) -> None:
        ctl = self.ctl
        if button == "Reset":
            ctl.reset(self.scene.value, self._episode_id(self.episode.value), client_id=client_id)
        elif button == "Step":
            ctl.step(client_id=client_id)
        elif button == "Run" and ctl.session is None and not ctl.snapshot.busy:
            # Nothing to run yet: start the selected episode, then run it (a press must never be lost).
            ctl.reset(self.scene.value, self._episode_id(self.episode.value), client_id=client_id, then_run=True)
            self._tell(client_id, f"no episode yet: starting episode {self.episode.value} of {self.scene.value}, "
                                  "then running it")
        elif button == "Run":
            ctl.run(client_id=client_id)
        else:
            ctl.pause(client_id=client_id)

    def _change_target(self, goal: str, client_id: int) -> None:
        """Change the running episode's goal; otherwise say why not and show the goal that holds."""
        snap = self.ctl.snapshot
        try:
            if snap.event is None:
                raise L3MVNError(f"Target changes the goal of a running episode; episode {self.episode.value} "
                                 "looks for its own: press Reset (or Run) to start it")
            self.ctl.change_target(goal, client_id=client_id)
        except L3MVNError:
            self.target.value = snap.event.goal if snap.event is not None else self._selected_episode().goal
            raise

    def _follow_selected_episode(self, client_id: int) -> None:
        """Before an episode runs, Target shows the goal of the episode a Reset would start; while
        one runs, the tab is told that the pick waits for Reset."""
        event = self.ctl.snapshot.event
        if event is None or event.done:
            goal = self._selected_episode().goal
            self.target.value = goal
            if self.ctl.snapshot.map is None:
                self.legend.content = _legend_html(legend(GOAL_CATEGORIES), target=goal)
        else:
            self._tell(client_id, f"episode {self.episode.value} of {self.scene.value} is selected: Reset starts "
                                  f"it ({event.episode_key} goes on until then)")

    def _on_map_click(self, event: viser.SceneClickEvent) -> None:
        problem = ray_refusal(event.ray_origin, event.ray_direction)
        if problem is not None:
            raise L3MVNError(problem)
        view = self.ctl.snapshot.map
        if view is None:
            raise L3MVNError("no map yet: press Reset, then Step")
        cell = ray_to_cell(event.ray_origin, event.ray_direction, view.resolution_m)
        rows, cols = view.cells
        r0, c0 = view.origin
        if cell is None or not (r0 <= cell[0] < r0 + rows and c0 <= cell[1] < c0 + cols):
            raise L3MVNError("that click is outside the map: click on the map or a frontier")
        hit = self._frontier_hit(view, cell)
        self.ctl.set_manual_goal(hit or cell, client_id=event.client_id)

    def _frontier_hit(self, view: MapView, cell: Cell) -> Cell | None:
        reach = (MARKER_RADIUS_M * 1.5 / view.resolution_m) ** 2
        near = [(float((f.cell[0] - cell[0]) ** 2 + (f.cell[1] - cell[1]) ** 2), f.cell) for f in view.frontiers]
        near = [n for n in near if n[0] <= reach]
        return min(near)[1] if near else None

    def _admit_update(self, client_id: int, uuid: str, updates: dict) -> bool:
        """Whether viser may apply a tab's GUI update; runs on viser's event loop, before any state changes.

        A refused update changes nothing anywhere: the tab that sent it is told why and shown the
        value the server holds again; other tabs see nothing. A check that fails refuses too.
        """
        handle = self._inputs.get(uuid)
        try:
            problem = ("that control is not on this page" if handle is None
                       else update_refusal(handle, updates))
            if problem is None:
                return True
            if handle is not None and handle.disabled and self.ctl.snapshot.busy:
                problem = f"{handle.label} is held while the dashboard is busy ({self.ctl.snapshot.busy})"
            log.info("dashboard: refused an update from client %s: %s", client_id, problem)
            self._tell(client_id, problem, "warning")
            client = self.server.get_clients().get(client_id)
            if client is not None and handle is not None and not isinstance(handle, _CLICKABLE):
                show_value_to(client, handle)
        except Exception:
            log.exception("dashboard: checking an update from client %s failed; refused it", client_id)
        return False

    def _tell(self, client_id: int | None, text: str, level: str = "info") -> None:
        self._on_notice(Notice(text, level, client_id))

    def _on_notice(self, notice: Notice) -> None:
        clients = self.server.get_clients()
        targets = [clients[notice.client_id]] if notice.client_id in clients else (
            [] if notice.client_id is not None else list(clients.values()))
        title = _notice_title(notice)
        keep = notice.sticky or notice.level == "error"
        for client in targets:
            client.add_notification(title, notice.text, auto_close_seconds=None if keep else NOTICE_SECONDS,
                                    color=_LEVEL_COLORS[notice.level])

    # --- output ------------------------------------------------------------------------------
    def _on_snapshot(self, snap: Snapshot) -> None:
        with self._wake:
            self._latest = snap
            self._wake.notify()

    def _redraw(self) -> None:
        """Draw the current snapshot again, map included (a display setting changed)."""
        with self._wake:
            self._drawn = (None, None)
            self._latest = self.ctl.snapshot
            self._wake.notify()

    def close(self) -> None:
        with self._wake:
            self._closed = True
            self._wake.notify()
        self._thread.join(timeout=5.0)
        self.recordings.close()
        self.history.close()

    def _draw_loop(self) -> None:
        while True:
            with self._wake:
                while self._latest is None and not self._closed:
                    self._wake.wait()
                if self._closed:
                    return
                snap, self._latest = self._latest, None
            try:
                self._draw(snap)
            except Exception:  # a drawing bug must not stop later updates
                log.exception("dashboard: drawing snapshot %d failed", snap.seq)

    def _draw(self, snap: Snapshot) -> None:
        with self.server.atomic():
            self.status.content = _status_markdown(snap)
            m = snap.metrics
            self.metrics.content = (f"**This server session**: {m.episodes} episodes done, "
                                    f"SR {m.sr:.2f}, SPL {m.spl:.2f}")
            if m.episodes != self._listed_episodes:  # a finished episode may have written a recording
                self._listed_episodes = m.episodes
                self.recordings.refresh()
            buttons = BUTTONS_RUNNING if snap.running or snap.run_queued else BUTTONS_PAUSED
            if tuple(self.controls.options) != buttons:
                self.controls.options = buttons
            for handle in self._held:
                handle.disabled = bool(snap.busy)
            self.drive_folder.visible = snap.policy == TELEOP
            if self.policy.value != self.ctl.policy_name:  # chosen elsewhere (another tab, the CLI's --policy)
                self.policy.value = self.ctl.policy_name
            if self.head.value != self.ctl.head:  # chosen in another tab
                self.head.value = self.ctl.head
            if self.speed.value != snap.steps_per_second:  # a clamped or scripted speed
                self.speed.value = snap.steps_per_second
            self._show_busy(snap.busy)
            if snap.map is None:
                self.frontier_table.content = _no_map_markdown(self.ctl.policy_name, started=snap.event is not None)
            self.language.content = language_html(snap.map, snap.policy)  # viser sends it only when it changed
            drawn = (snap.event, snap.manual_goal)
            if drawn[0] is self._drawn[0] and drawn[1] == self._drawn[1]:  # events hold arrays: by identity
                return
            self._drawn = drawn
            if snap.event is not None and snap.event.step == 0:
                self._fitted = None  # a new episode (the same one again too): fit its first map
            if snap.event is not None and self.target.value != snap.event.goal:
                self.target.value = snap.event.goal
            if snap.frames is not None:
                self.rgb.image = snap.frames.rgb
                self.depth.image = snap.frames.depth
                self.semantic.image = snap.frames.semantic
            if snap.map is not None:
                self._draw_map(snap.map, snap)
            elif snap.event is not None:
                self._hide_map("the agent's map appears after the first step")

    def _show_busy(self, text: str) -> None:
        """A spinner notice in every tab while the worker holds the controls; gone when it is done."""
        clients = self.server.get_clients()
        for client_id, note in list(self._busy_notes.items()):
            if not text or client_id not in clients:
                if client_id in clients:
                    note.remove()
                del self._busy_notes[client_id]
        if not text:
            return
        for client_id, client in clients.items():
            note = self._busy_notes.get(client_id)
            if note is None:
                self._busy_notes[client_id] = client.add_notification(
                    "Working", text, loading=True, with_close_button=False, auto_close_seconds=None)
            elif note.body != text:
                note.body = text

    def _draw_map(self, view: MapView, snap: Snapshot) -> None:
        res = view.resolution_m
        rows, cols = view.cells
        (x0, y0), (x1, y1) = cell_to_xy(view.origin, res), cell_to_xy((view.origin[0] + rows - 1, view.origin[1] + cols - 1), res)
        plane = self.map_plane
        plane.image = view.image[::-1]  # viser's image plane has row 0 at -y; our row 0 is on top
        plane.render_width, plane.render_height = cols * res, rows * res
        plane.position = ((x0 + x1) / 2, (y0 + y1) / 2, 0.0)
        plane.visible = True
        ax, ay = cell_to_xy(view.agent_cell, res)
        self.agent.position = (ax, ay, 0.05)
        self.agent.wxyz = (math.cos(-view.agent_heading / 2), 0.0, 0.0, math.sin(-view.agent_heading / 2))
        self.agent.visible = True
        self._draw_long_term_goal(view, snap.manual_goal)
        self._place(self.stg, view.short_term_goal, res, 0.08)
        self.map_note.text = ("" if view.source == "agent map"
                              else f"ground-truth floor plan: policy {snap.policy!r} keeps no map")
        self.map_note.position = (x0, y0 + 0.4, 0.2)
        self._draw_frontiers(view)
        self._draw_ground_truth(view, snap)
        crop = (view.origin[0], view.origin[1], view.origin[0] + rows, view.origin[1] + cols)
        key = (snap.event.episode_key if snap.event else None, view.source)
        if self._fitted is None or key != self._fitted[0] or (self.auto_fit.value and not _inside(crop, self._fitted[1])):
            self._fitted = (key, crop)
            self._fit_all(view)
        self.legend.content = _legend_html(view.legend, target=view.target, ground_truth=self.ground_truth.value)

    def _draw_ground_truth(self, view: MapView, snap: Snapshot) -> None:
        """On demand, the scene's truth under the agent's knowledge, labelled as such; off, nothing."""
        session, event = self.ctl.session, snap.event
        if (not self.ground_truth.value or event is None or session is None or session.episode is None
                or session.episode.key != event.episode_key):
            self.gt_plane.visible = self.gt_label.visible = False
            return
        key = (event.episode_key, event.goal, view.source, view.world_origin, view.scale)
        if key != self._gt_key:
            task = session.task
            layer = ground_truth_layer(view, task.scene, task.region(event.goal).region, event.goal)
            res = view.resolution_m
            (x0, y0) = cell_to_xy(layer.origin, res)
            (x1, y1) = cell_to_xy((layer.origin[0] + layer.cells[0] - 1, layer.origin[1] + layer.cells[1] - 1), res)
            self.gt_plane.image = layer.image[::-1]
            self.gt_plane.render_width, self.gt_plane.render_height = layer.cells[1] * res, layer.cells[0] * res
            self.gt_plane.position = ((x0 + x1) / 2, (y0 + y1) / 2, 0.02)
            where = layer.goal_cell if layer.goal_cell is not None else view.agent_cell
            gx, gy = cell_to_xy(where, res)
            self.gt_label.position = (gx, gy, 0.3)
            self.gt_label.text = (f"GROUND TRUTH: {event.goal} (not known to the agent)" if layer.goal_cell
                                  else f"GROUND TRUTH: no {event.goal} in this scene")
            self._gt_key = key
        self.gt_plane.visible = self.gt_label.visible = True

    def _draw_long_term_goal(self, view: MapView, manual: Cell | None) -> None:
        """The policy's long-term goal, or a manual goal as soon as it is set (the agent takes it
        on its next step), or nothing once a manual goal is cleared."""
        res, z = view.resolution_m, 2 * MARKER_RADIUS_M + 0.16
        if manual is not None and manual != view.long_term_goal:
            self._place(self.ltg, manual, res, z)
            self.ltg_label.text = "manual goal (from the next step)"
        elif view.goal_kind == "manual" and manual is None:
            self._place(self.ltg, None, res, z)
            self.ltg_label.text = ""
        else:
            self._place(self.ltg, view.long_term_goal, res, z)
            self.ltg_label.text = ("manual goal" if view.goal_kind == "manual"
                                   else f"long-term goal ({view.goal_kind or '-'})")

    def _hide_map(self, note: str) -> None:
        for handle in (self.map_plane, self.agent, self.ltg, self.stg, *(s for s, _ in self._markers)):
            handle.visible = False
        self.ltg_label.text = ""
        self.map_note.text = note
        self.frontier_pick.options, self.frontier_pick.disabled = ("none",), True

    def _place(self, handle, cell: Cell | None, res: float, z: float) -> None:
        if cell is None:
            handle.visible = False
            return
        x, y = cell_to_xy(cell, res)
        handle.position = (x, y, z)
        handle.visible = True

    def _draw_frontiers(self, view: MapView) -> None:
        """A sphere per frontier coloured by its score; labels on the best few only (the rest are
        in the table), so labels do not pile up on each other."""
        res = view.resolution_m
        while len(self._markers) < len(view.frontiers):
            i = len(self._markers)
            sphere = self.server.scene.add_icosphere(f"/frontiers/{i}", MARKER_RADIUS_M, (150, 150, 150))
            label = self.server.scene.add_label(f"/frontiers/{i}/label", "", position=(0.0, 0.3, 0.0),
                                                font_screen_scale=0.75, anchor="bottom-center")
            self._markers.append((sphere, label))
        labelled = _labelled_frontiers(view.frontiers)
        for i, (sphere, label) in enumerate(self._markers):
            if i >= len(view.frontiers):
                sphere.visible = False
                continue
            f = view.frontiers[i]
            x, y = cell_to_xy(f.cell, res)
            sphere.position = (x, y, MARKER_RADIUS_M)
            sphere.color = score_color(_score(f))
            label.text = (("★ " if f.chosen else "") + f.label) if f.id in labelled else ""
            sphere.visible = True
        labels = [f.label for f in view.frontiers]
        self._frontier_cells = {f.label: f.cell for f in view.frontiers}
        if labels:
            self.frontier_pick.options = labels
            self.frontier_pick.disabled = False
        else:
            self.frontier_pick.options = ("none",)
            self.frontier_pick.disabled = True
        self.frontier_table.content = _frontier_markdown(view)

    def _fit_all(self, view: MapView) -> None:
        for client in self.server.get_clients().values():
            self._fit_camera(client.camera, view)
        x, y, z = _fit_pose(view)
        self.server.initial_camera.position = (x, y, z)
        self.server.initial_camera.look_at = (x, y, 0.0)

    def _fit_camera(self, camera, view: MapView) -> None:
        x, y, z = _fit_pose(view)
        camera.up_direction = (0.0, 1.0, 0.0)
        camera.position = (x, y, z)  # moves look_at along with it: set look_at after
        camera.look_at = (x, y, 0.0)

    # --- helpers -----------------------------------------------------------------------------
    def _episode_labels(self, scene_key: str) -> tuple[str, ...]:
        return tuple(f"{ep.episode_id}: {ep.goal}" for ep in self.ctl.episodes_of(scene_key))

    def _selected_episode(self):
        episode_id = self._episode_id(self.episode.value)
        return next(ep for ep in self.ctl.episodes_of(self.scene.value) if ep.episode_id == episode_id)

    def _placeholder_frame(self) -> np.ndarray:
        """A dark frame of the camera's display size (not a 16-px square) until the first one arrives."""
        sim = self.ctl.cfg.sim
        k = max(1, sim.frame_width // FRAME_WIDTH)
        h, w = -(-sim.frame_height // k), -(-sim.frame_width // k)
        img = np.full((h, w, 3), 48, np.uint8)
        cv2.putText(img, "no frame yet: press Reset", (max(4, w // 2 - 100), h // 2), cv2.FONT_HERSHEY_SIMPLEX,
                    0.45 * w / 320, (200, 200, 200), 1, cv2.LINE_AA)
        return img

    @staticmethod
    def _episode_id(label: str) -> int:
        head = label.split(":", 1)[0]
        if not head.strip().isdigit():
            raise L3MVNError(f"unknown episode {label!r}: pick one from the list")
        return int(head)


def _fit_pose(view: MapView) -> tuple[float, float, float]:
    """Camera above the map centre, high enough that a 75 deg view shows all of the crop."""
    res = view.resolution_m
    rows, cols = view.cells
    x, y = cell_to_xy((view.origin[0] + rows // 2, view.origin[1] + cols // 2), res)
    extent = max(rows, cols) * res
    # Shifted right so the map sits left of the control panel.
    return x + 0.2 * extent, y, 0.62 * extent / math.tan(math.radians(75) / 2)


def _inside(crop: tuple[int, int, int, int], fitted: tuple[int, int, int, int]) -> bool:
    """Whether map crop (r0, c0, r1, c1) lies within the crop the cameras were fitted to."""
    return fitted[0] <= crop[0] and fitted[1] <= crop[1] and crop[2] <= fitted[2] and crop[3] <= fitted[3]


def _arrow_mesh() -> tuple[np.ndarray, np.ndarray]:
    """A flat arrowhead pointing along +x (the agent's heading), 0.4 m long."""
    v = np.array([[0.25, 0, 0], [-0.15, 0.14, 0], [-0.07, 0, 0], [-0.15, -0.14, 0]], np.float32)
    return v, np.array([[0, 1, 2], [0, 2, 3]], np.uint32)


def _score(f: FrontierMarker) -> float:
    """What a frontier's colour shows: the fused score where the policy fuses, else cost-utility."""
    return f.fused if f.fused is not None else f.s_cu


def _labelled_frontiers(frontiers: tuple[FrontierMarker, ...]) -> set[int]:
    """Ids of the frontiers labelled on the map: the chosen one and the best ``TOP_LABELS`` by score."""
    best = sorted(frontiers, key=_score, reverse=True)[:TOP_LABELS]
    return {f.id for f in best} | {f.id for f in frontiers if f.chosen}


def _notice_title(notice: Notice) -> str:
    return notice.title or {"info": "L3MVN", "warning": "Request refused", "error": "Error"}[notice.level]


def _status_markdown(snap: Snapshot) -> str:
    ev = snap.event
    lines = []
    if snap.busy:
        lines.append(f"**Working**: {md(snap.busy)}")
    if snap.run_queued:
        lines.append("**Run queued**: it starts when the reset finishes")
    if snap.error:
        lines.append(f"**Error:** {md(snap.error)}")
    if ev is None:
        lines.append(md(snap.note or "No episode yet."))
        return "\n\n".join(lines)
    state = "running" if snap.running else ("finished" if ev.done else "paused")
    lines.append(f"**{md(ev.episode_key)}** ({md(snap.policy)}), target **{md(ev.goal)}**, {state}")
    action = ev.action.name.lower() if ev.action is not None else "(reset)"
    lines.append(f"Step **{ev.step}**, action {code(action)}, segment {md(ev.segment)}")
    dist = ev.ground_truth.get("distance_to_goal_m")
    if dist is not None:
        lines.append(f"Distance to goal: {dist:.2f} m _(ground truth, not known to the agent)_")
    if snap.segment_note:
        lines.append(f"**New segment**: {md(snap.segment_note)}")
    d = ev.decision
    if d is not None and d.goal_kind == "manual" and snap.manual_goal is None:
        lines.append("Goal: manual goal cleared; the policy picks its own on the next step")
    elif d is not None and (d.reason or d.goal_kind):
        lines.append(md(f"Goal: {d.goal_kind or '-'}; {d.reason}".rstrip("; ")))
    if snap.manual_goal is not None:
        lines.append(f"**Manual goal**: {md(_manual_goal_words(snap))}")
    if ev.done and ev.result:
        r = ev.result
        verdict = "**SUCCESS**" if r.get("success") else f"**FAILURE** ({md(r.get('failure'))})"
        lines.append(f"{verdict}: SPL {r.get('spl', 0):.2f}, {md(r.get('steps'))} steps")
    if snap.policy in POLICY_NOTES:
        lines.append(f"_{POLICY_NOTES[snap.policy]}_")
    if snap.note and snap.note not in ("running", "paused"):
        lines.append(f"_{md(snap.note)}_")
    return "\n\n".join(lines)


def _manual_goal_words(snap: Snapshot) -> str:
    """A manual goal as a user reads it: which frontier or map cell, and how far (not a wire token)."""
    cell, view = snap.manual_goal, snap.map
    assert cell is not None
    where = f"map cell ({cell[0]}, {cell[1]})"
    if view is None:
        return where
    frontier = next((f for f in view.frontiers if f.cell == cell), None)
    if frontier is not None:
        where = f"frontier F{frontier.id} at {where}"
    metres = math.hypot(cell[0] - view.agent_cell[0], cell[1] - view.agent_cell[1]) * view.resolution_m
    return f"{where}, {metres:.1f} m from the agent (straight line)"


def _no_map_markdown(policy: str, *, started: bool) -> str:
    """The Frontiers panel without a map: why, for the policy that is chosen."""
    if policy in DIRECT_POLICIES:
        return f"_no frontiers: policy {md(repr(policy))} keeps no map (the map view shows the ground-truth plan)_"
    return ("_frontiers appear after the agent's first steps_" if started
            else f"_policy {md(repr(policy))} builds a map: frontiers appear after Reset and the first steps_")


def _frontier_markdown(view: MapView) -> str:
    if not view.frontiers:
        return ("_no frontiers: the policy keeps no map_" if view.source != "agent map"
                else "_no frontiers on the map right now_")
    rows = ["| | S_LLM | S_CU | fused | objects |", "|---|---|---|---|---|"]
    for f in sorted(view.frontiers, key=_score, reverse=True):
        llm = "-" if f.s_llm is None else f"{f.s_llm:.2f}"
        fused = "-" if f.fused is None else f"{f.fused:.2f}"
        rows.append(f"| {'★' if f.chosen else ''}F{f.id} | {llm} | {f.s_cu:.2f} | {fused} | "
                    f"{md(', '.join(f.objects) or '-')} |")
    queries = [f"- F{f.id} {code(q)}" for f in view.frontiers for q in list(f.queries.values())[:1]]
    note = f"\n\n_Map labels show the best {TOP_LABELS} and the chosen (★) frontier; all are listed here._"
    return "\n".join(rows) + note + ("\n\n**Queries**\n" + "\n".join(queries) if queries else "")


def _unavailable_markdown(problems: dict[str, str]) -> str:
    if not problems:
        return "_every scorer's weights are on disk_"
    lines = "\n".join(f"- {code(name)}: {md(why)}" for name, why in problems.items())
    return f"**Unavailable scorers** (refused if picked):\n{lines}"


def _swatch(rgb, *, ring: bool = False) -> str:
    border = "3px double #000" if ring else "1px solid #888"
    return (f'<span style="display:inline-block;width:11px;height:11px;border:{border};'
            f'background:rgb{tuple(int(v) for v in rgb)};margin-right:4px;vertical-align:middle"></span>')


def _legend_html(categories, *, target: str = "", ground_truth: bool = False) -> str:
    """Map colours, then the object categories the map shows, the target first and ringed as on
    the map; the ground-truth layer's colours when it is on; then the frontier score colour bar."""
    from l3mvn_studio.map_image import FREE, GLIMPSED, GUESSED, OBSTACLE, TRAJECTORY, UNEXPLORED

    fixed = [("unexplored", UNEXPLORED), ("free", FREE), ("seen from afar", GLIMPSED), ("obstacle", OBSTACLE),
             ("obstacle too near for depth (guessed)", GUESSED), ("collision marks", COLLISION_RGB),
             ("trajectory", TRAJECTORY)]
    item = '<span style="display:inline-block;margin:2px 8px 2px 0;font-size:12px">{}</span>'
    cats = sorted(categories, key=lambda c: c[0] != target)
    parts = [item.format(_swatch(rgb) + name) for name, rgb in fixed]
    parts += [item.format(_swatch(rgb, ring=name == target)
                          + (f"<b>{html(name)} (target)</b>" if name == target else html(name))) for name, rgb in cats]
    if ground_truth:
        parts += [item.format(_swatch(rgba[:3]) + f"<b>ground truth</b>: {name}") for name, rgba in
                  (("floor plan", GT_FLOOR), ("success region", GT_REGION), ("goal instances", GT_GOAL))]
    stops = ", ".join(f"rgb{score_color(s / 4)}" for s in range(5))
    bar = (f'<div style="font-size:12px;margin-top:4px">frontier score 0 '
           f'<span style="display:inline-block;width:120px;height:10px;vertical-align:middle;'
           f'background:linear-gradient(to right, {stops})"></span> 1 (fused where the policy fuses, '
           f'else cost-utility)</div>')
    return f'<div style="line-height:1.2">{"".join(parts)}</div>{bar}'

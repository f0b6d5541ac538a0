"""The viser page: the map as a textured plane in the 3D view, between a camera panel and the controls.

This module lays the page out, wires each control to the controller, and keeps the controls in step
with the controller's snapshots. What it draws with lives beside it: where the panels sit
(``page_layout``), the panels' text (``page_markdown``), the 3D view (``scene_drawing``), the thread
that draws (``draw_loop``), notices (``tab_notices``) and the keyboard shortcuts (``key_shortcuts``).

All handles are shared (``server.gui`` / ``server.scene``), so every tab shows the same session and a
new or reloaded tab gets the current state from viser on connect. Only notices about a tab's own
request go to that tab. Snapshots are drawn on a thread of their own that always takes the newest
one, so a fast agent drops frames instead of queueing them.

Nothing a tab sends is trusted: each GUI value is checked against its control before viser applies
it (``client_input.UpdateGate``), map-click rays are checked before use, and every handler runs
through ``_reported``, so whatever goes wrong becomes a notice to the tab that asked and the server
goes on.
"""

from __future__ import annotations

import functools
import logging

import cv2
import numpy as np
import viser

from l3mvn.core.categories import GOAL_CATEGORIES
from l3mvn.core.errors import L3MVNError
from l3mvn.run.registry import TELEOP, policy_names
from l3mvn.run.viz import legend
from l3mvn_studio.client_input import CLICKABLE, UpdateGate, ray_refusal
from l3mvn_studio.compare_view import ComparePanel, EpisodeSource
from l3mvn_studio.draw_loop import DrawLoop
from l3mvn_studio.history_view import HistoryPanel
from l3mvn_studio.key_shortcuts import DRIVE_MD, SHORTCUTS_JS, SHORTCUTS_MD
from l3mvn_studio.language_panel import language_html
from l3mvn_studio.page_layout import MAP_AREA_JS, dock_panels
from l3mvn_studio.page_markdown import (
    frontier_markdown,
    legend_html,
    metrics_markdown,
    no_map_markdown,
    status_markdown,
    unavailable_markdown,
)
from l3mvn_studio.recordings_view import RecordingsPanel
from l3mvn_studio.results_view import ResultsPanel, ResultsSource
from l3mvn_studio.scene_drawing import MapScene, clicked_cell
from l3mvn_studio.session_worker import (
    DEFAULT_SCORER,
    MAX_SPEED,
    MIN_SPEED,
    DashboardController,
    frame_display_steps,
)
from l3mvn_studio.state import Cell, MapView, Snapshot
from l3mvn_studio.tab_notices import TabNotices
from l3mvn_studio.viser_hooks import check_gui_updates, ignore_client_messages_except, run_script_on_connect

log = logging.getLogger(__name__)

# Run and Pause share a slot: the group offers the one that acts now (and Space presses it).
BUTTONS_PAUSED = ("Reset", "Step", "Run")
BUTTONS_RUNNING = ("Reset", "Step", "Pause")
RENDER_NOTE = (
    "_Frames from the built-in CPU simulator: flat-shaded boxes, not photographs. The agent sees exactly these._"
)
PAIR_GAP = 4  # px between the depth and semantic frames
# Policy teleop: button -> action; key_shortcuts' drive keys press the buttons (only while they are shown).
DRIVE = {
    "Turn left": "turn_left",
    "Forward": "move_forward",
    "Turn right": "turn_right",
    "Look up": "look_up",
    "Look down": "look_down",
    "Stop": "stop",
}


class DashboardView:
    """Builds the page once and keeps it in sync with the controller's snapshots."""

    def __init__(
        self,
        server: viser.ViserServer,
        controller: DashboardController,
        results: ResultsSource | None = None,
        compare: EpisodeSource | None = None,
    ) -> None:
        self.server, self.ctl = server, controller
        self.notices = TabNotices(server)
        self._drawn: tuple = (None, None)  # (event, manual goal) the map was last drawn for
        self._frontier_cells: dict[str, Cell] = {}  # the Frontier dropdown's labels -> their cells
        tabs = self._build_gui(results=results is not None, compare=compare is not None)
        self.compare: ComparePanel | None = None
        if compare is not None:
            with tabs["Compare"]:
                self.compare = ComparePanel(
                    server.gui,
                    compare,
                    config=controller.cfg,
                    record_dir=controller.record_dir,
                    current_policy=controller.policy_name,
                    selected_episode=self._selected_episode,
                    on=self._on,
                    tell=self.notices.tell,
                    overlay=self._overlays,
                )
        self.results: ResultsPanel | None = None
        if results is not None:
            with tabs["Results"]:
                self.results = ResultsPanel(
                    server.gui,
                    results,
                    on=self._on,
                    tell=self.notices.tell,
                    compare=self.compare,
                    session=controller,
                    viewer=self.recordings,
                )
        self.map_scene = MapScene(server)
        server.scene.on_click()(self._reported("map click", self._on_map_click))
        panel_inputs = (
            (() if self.results is None else self.results.inputs)
            + (() if self.compare is None else self.compare.inputs)
            + self.recordings.inputs
            + self.history.inputs
        )
        check_gui_updates(
            server,
            UpdateGate(
                server,
                (*vars(self).values(), *panel_inputs),
                busy=lambda: controller.snapshot.busy,
                tell=self.notices.tell,
            ),
        )
        ignore_client_messages_except(server, "GuiUpdateMessage", "ScenePointerMessage")  # controls, map clicks
        run_script_on_connect(server, SHORTCUTS_JS)
        run_script_on_connect(server, MAP_AREA_JS)
        self._draws = DrawLoop(self._draw, name="l3mvn-dashboard-view")
        controller.on_snapshot(self._draws.offer)
        controller.on_snapshot(self.history.add)
        controller.on_notice(self.notices.show)
        self._draws.offer(controller.snapshot)

    def close(self) -> None:
        self._draws.close()
        self.recordings.close()
        self.history.close()

    # --- layout ------------------------------------------------------------------------------
    def _build_gui(self, *, results: bool, compare: bool) -> dict[str, viser.GuiTabHandle]:
        """The page: the map fills what the two docked panels leave free. The camera panel (left) and,
        atop the control panel (right), Status with the buttons that drive the episode never scroll
        away: the keys press those buttons, so they must exist whichever tab is open. Everything else
        is a tab below them, so each gets the panel's full height. Returns the tabs the caller fills
        with its own panels."""
        gui, ctl = self.server.gui, self.ctl
        gui.configure_theme(control_width="large", show_share_button=False, brand_color=(40, 90, 200))
        first = ctl.episodes_of(ctl.scene_keys[0])[0]
        with gui.add_folder("Status"):
            self.status = gui.add_markdown("")
            self.metrics = gui.add_markdown("")
        self.controls = gui.add_button_group("Controls", BUTTONS_PAUSED)
        with gui.add_folder("Drive (policy teleop)", visible=ctl.policy_name == TELEOP) as self.drive_folder:
            self.drive_turns = gui.add_button_group("Drive", ("Turn left", "Forward", "Turn right"))
            self.drive_other = gui.add_button_group("Look / stop", ("Look up", "Look down", "Stop"))
            gui.add_markdown(DRIVE_MD)
        group = gui.add_tab_group()
        names = ("Episode", "Language") + ("Results",) * results + ("Compare",) * compare + ("Recordings",)
        tabs = {name: group.add_tab(name) for name in names}
        with tabs["Episode"]:
            self._build_episode_controls(first.goal)
        with tabs["Language"]:
            self.language = gui.add_html(language_html(None, ctl.policy_name))
        with tabs["Recordings"]:
            self.recordings = RecordingsPanel(
                gui, lambda: ctl.record_dir, self.server.get_host(), on=self._on, tell=self.notices.tell
            )
        # Pictures drawn over the map live here, outside the tabs: a hidden tab's content is not drawn.
        self._overlays = gui.add_folder(None)
        dock_panels(gui, self._build_camera_panel(first.goal))
        self._listed_episodes = 0
        # Held while the worker resets or loads a model: a change then would apply to a half-built session.
        self._held = (self.scene, self.episode, self.target, self.policy, self.scorer, self.head, self.record)
        self._wire_gui()
        return tabs

    def _build_episode_controls(self, goal: str) -> None:
        gui, ctl = self.server.gui, self.ctl
        self.scene = gui.add_dropdown("Scene", ctl.scene_keys)
        self.episode = gui.add_dropdown("Episode", self._episode_labels(ctl.scene_keys[0]))
        self.target = gui.add_dropdown(
            "Target",
            GOAL_CATEGORIES,
            initial_value=goal,
            hint="the episode's goal; changing it mid-episode starts a new segment",
        )
        self.policy = gui.add_dropdown(
            "Policy", policy_names(), initial_value=ctl.policy_name, hint="takes effect on the next Reset"
        )
        self.scorer = gui.add_dropdown(
            "Scorer",
            (DEFAULT_SCORER,) + ctl.scorer_names(),
            hint="language policies only; 'policy default' restores theirs on Reset",
        )
        self.scorer_note = gui.add_markdown(unavailable_markdown(ctl.unavailable_scorers))
        self.head = gui.add_dropdown(
            "Head",
            ctl.head_names(),
            initial_value=ctl.head,
            hint=f"feed-forward scoring only ({', '.join(ctl.headed_policies())} "
            "or Scorer feedforward); other scorers ignore it; takes effect on "
            "the next Reset",
        )
        self.speed = gui.add_slider(
            "Steps / s", min=MIN_SPEED, max=MAX_SPEED, step=0.5, initial_value=ctl.snapshot.steps_per_second
        )
        self.record = gui.add_checkbox("Record (.rrd)", False, hint="rerun recording of each new episode")
        gui.add_markdown(SHORTCUTS_MD)
        with gui.add_folder("Frontiers"):
            self.frontier_pick = gui.add_dropdown("Frontier", ("none",), disabled=True)
            self.goal_buttons = gui.add_button_group("Manual goal", ("Go to frontier", "Clear"))
            self.frontier_table = gui.add_markdown(no_map_markdown(ctl.policy_name, started=False))

    def _build_camera_panel(self, goal: str) -> viser.PanelHandle:
        """What the agent sees and how to read the map, beside the map: RGB at its own size, depth and
        semantics side by side at half of it, the map's switches and legend, and the look back over
        the episode's steps (its pictures cover the map, so it lives with what it covers)."""
        gui = self.server.gui
        panel = gui.add_panel()
        with panel.add_tab("Camera"):
            rgb, pair = self._placeholder_frames()
            self.rgb = gui.add_image(rgb, label="RGB")
            self.depth_semantic = gui.add_image(pair, label="Depth (near blue, far red) | Semantic (map colours)")
            gui.add_markdown(RENDER_NOTE)
            with gui.add_folder("Map"):
                self.fit = gui.add_button("Fit map in view")
                self.auto_fit = gui.add_checkbox(
                    "Auto-fit map", True, hint="refit the view whenever the map outgrows it"
                )
                self.ground_truth = gui.add_checkbox(
                    "Ground truth",
                    False,
                    hint="overlay what the agent does not know: the whole floor plan, the success region and "
                    "the true goal instances (magenta)",
                )
                self.legend = gui.add_html(legend_html(legend(GOAL_CATEGORIES), target=goal))
            self.history = HistoryPanel(gui, on=self._on, tell=self.notices.tell)
        return panel

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
            self._draws.redraw(ctl.snapshot)

        @self._on(self.fit)
        def _(event: viser.GuiEvent) -> None:
            view = ctl.snapshot.map
            if view is None:
                raise L3MVNError("no map to fit yet: press Reset (or Run) to start an episode")
            self.map_scene.fit_camera(event.client.camera, view)

    def _on(self, handle):
        """Decorator: run the function when a tab changes or clicks ``handle``, through ``_reported``.

        Assignments made here on the server fire ``on_update`` too (with no client); only a tab's
        own changes are handled, so a handler that sets a value does not run itself again.
        """
        register = handle.on_click if isinstance(handle, CLICKABLE) else handle.on_update

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
                self.notices.tell(event.client_id, str(exc), "warning")
            except Exception as exc:
                log.exception("dashboard: %s failed", what)
                self.notices.tell(event.client_id, f"{what} failed: {type(exc).__name__}: {exc}", "error")

        return run

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
            self.notices.tell(
                client_id,
                f"no episode yet: starting episode {self.episode.value} of {self.scene.value}, then running it",
            )
        elif button == "Run":
            ctl.run(client_id=client_id)
        else:
            ctl.pause(client_id=client_id)

    def _change_target(self, goal: str, client_id: int) -> None:
        """Change the running episode's goal; otherwise say why not and show the goal that holds."""
        snap = self.ctl.snapshot
        try:
            if snap.event is None:
                raise L3MVNError(
                    f"Target changes the goal of a running episode; episode {self.episode.value} "
                    "looks for its own: press Reset (or Run) to start it"
                )
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
                self.legend.content = legend_html(legend(GOAL_CATEGORIES), target=goal)
        else:
            self.notices.tell(
                client_id,
                f"episode {self.episode.value} of {self.scene.value} is selected: Reset "
                f"starts it ({event.episode_key} goes on until then)",
            )

    def _on_map_click(self, event: viser.SceneClickEvent) -> None:
        problem = ray_refusal(event.ray_origin, event.ray_direction)
        if problem is not None:
            raise L3MVNError(problem)
        view = self.ctl.snapshot.map
        if view is None:
            raise L3MVNError("no map yet: press Reset, then Step")
        self.ctl.set_manual_goal(clicked_cell(view, event.ray_origin, event.ray_direction), client_id=event.client_id)

    # --- output (on the draw loop's thread) ------------------------------------------------------
    def _draw(self, snap: Snapshot, full: bool) -> None:
        with self.server.atomic():
            self._show_controls(snap)
            if full:
                self._drawn = (None, None)
            drawn = (snap.event, snap.manual_goal)
            if drawn[0] is self._drawn[0] and drawn[1] == self._drawn[1]:  # events hold arrays: by identity
                return
            self._drawn = drawn
            self._show_step(snap)

    def _show_controls(self, snap: Snapshot) -> None:
        """What every snapshot may change: status, metrics, which controls are offered or held."""
        self.status.content = status_markdown(snap)
        self.metrics.content = metrics_markdown(snap.metrics)
        if snap.metrics.finished != self._listed_episodes:  # a finished episode may have written a recording
            self._listed_episodes = snap.metrics.finished
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
        self.notices.show_busy(snap.busy)
        if snap.map is None:
            self.frontier_table.content = no_map_markdown(self.ctl.policy_name, started=snap.event is not None)
        self.language.content = language_html(snap.map, snap.policy)  # viser sends it only when it changed

    def _show_step(self, snap: Snapshot) -> None:
        """What only a new step (or manual goal) changes: target, camera frames, the map and its frontiers."""
        if snap.event is not None and self.target.value != snap.event.goal:
            self.target.value = snap.event.goal
        if snap.frames is not None:
            self.rgb.image = snap.frames.rgb
            self.depth_semantic.image = _side_by_side(snap.frames.depth, snap.frames.semantic)
        self.map_scene.draw(
            snap, session=self.ctl.session, ground_truth=self.ground_truth.value, auto_fit=self.auto_fit.value
        )
        view = snap.map
        if view is not None:
            self._offer_frontiers(view)
            self.frontier_table.content = frontier_markdown(view)
            self.legend.content = legend_html(
                view.legend, target=view.target, ground_truth=self.ground_truth.value, frontiers=view.frontiers
            )
        elif snap.event is not None:
            self.frontier_pick.options, self.frontier_pick.disabled = ("none",), True
            # A new episode before its first map: the last episode's legend (its categories, its target)
            # must not stand for this one's.
            self.legend.content = legend_html(legend(GOAL_CATEGORIES), target=snap.event.goal)

    def _offer_frontiers(self, view: MapView) -> None:
        """The Frontier dropdown: the map's frontiers to pick a manual goal from, or none to pick."""
        labels = [f.label for f in view.frontiers]
        self._frontier_cells = {f.label: f.cell for f in view.frontiers}
        if labels:
            self.frontier_pick.options = labels
            self.frontier_pick.disabled = False
        else:
            self.frontier_pick.options = ("none",)
            self.frontier_pick.disabled = True

    # --- helpers -----------------------------------------------------------------------------
    def _episode_labels(self, scene_key: str) -> tuple[str, ...]:
        return tuple(f"{ep.episode_id}: {ep.goal}" for ep in self.ctl.episodes_of(scene_key))

    def _selected_episode(self):
        episode_id = self._episode_id(self.episode.value)
        return next(ep for ep in self.ctl.episodes_of(self.scene.value) if ep.episode_id == episode_id)

    def _placeholder_frames(self) -> tuple[np.ndarray, np.ndarray]:
        """Dark frames of the camera's display size (not 16-px squares) until the first ones arrive:
        the RGB one says what to do, the depth-and-semantic pair is blank."""
        sim = self.ctl.cfg.sim
        k, u = frame_display_steps(sim.frame_width)
        h, w = -(-sim.frame_height // k) * u, -(-sim.frame_width // k) * u
        img = np.full((h, w, 3), 48, np.uint8)
        cv2.putText(
            img,
            "no frame yet: press Reset",
            (max(4, w // 2 - 100), h // 2),
            cv2.FONT_HERSHEY_SIMPLEX,
            0.45 * w / 320,
            (200, 200, 200),
            1,
            cv2.LINE_AA,
        )
        blank = np.full((h, w, 3), 48, np.uint8)
        return img, _side_by_side(blank, blank)

    @staticmethod
    def _episode_id(label: str) -> int:
        head = label.split(":", 1)[0]
        if not head.strip().isdigit():
            raise L3MVNError(f"unknown episode {label!r}: pick one from the list")
        return int(head)


def _side_by_side(left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """Two frames of one size at half that size in one image, about as wide as one frame, a thin light
    gap between them. Every other pixel, not an average: semantic colours stay the legend's."""
    left, right = left[::2, ::2], right[::2, ::2]
    gap = np.full((left.shape[0], PAIR_GAP, 3), 255, np.uint8)
    return np.hstack((left, gap, right))

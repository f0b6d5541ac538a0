"""The Episode history folder: a step slider over the live episode, to look back without a recording.

Every step's map (frontiers coloured by score, the chosen one ringed, the long-term goal and the
agent drawn in) is kept as a PNG with its decision line, encoded off the agent's thread. Moving the
slider back shows that step over the main view; "Back to live" (or the slider at the newest step)
returns to the live map. A new episode, or a new segment of one, starts a new history.
"""

from __future__ import annotations

import math
import queue
import threading
from collections.abc import Callable

import cv2
import numpy as np
import viser

from l3mvn.core.errors import L3MVNError
from l3mvn_studio.compare_view import main_view_html
from l3mvn_studio.map_image import png_bytes, png_rgb, score_color
from l3mvn_studio.page_text import md
from l3mvn_studio.state import MapView, Snapshot

MAX_KEPT = 2000  # steps of one episode kept (~30 KB each); an episode is 500 by default
_AGENT = (220, 40, 40)
_GOAL = (255, 120, 0)


class HistoryPanel:
    """Keeps the live episode's steps and scrubs through them (one history shared by every tab)."""

    def __init__(self, gui: viser.GuiApi, *, on: Callable, tell: Callable) -> None:
        self._tell = tell
        self._lock = threading.Lock()
        self._episode: tuple | None = None  # (scene, episode id, segment) the history belongs to
        self._pictures: dict[int, bytes] = {}
        self._lines: dict[int, str] = {}
        self._todo: queue.SimpleQueue = queue.SimpleQueue()
        self._last_event = None  # a control change republishes the step it is at: kept once
        with gui.add_folder("Episode history", expand_by_default=False):
            self.step = gui.add_slider("Look back to step", min=0, max=1, step=1, initial_value=0, disabled=True)
            self.live = gui.add_button("Back to live", disabled=True)
            self.line = gui.add_markdown("_the steps of the current episode appear here as it runs_")
        self.picture = gui.add_html("")
        self._worker = threading.Thread(target=self._encode_loop, name="l3mvn-history", daemon=True)
        self._worker.start()
        self._wire(on)

    @property
    def inputs(self) -> tuple:
        return (self.step, self.live)

    @property
    def steps(self) -> list[int]:
        with self._lock:
            return sorted(self._pictures)

    def add(self, snap: Snapshot) -> None:
        """Called for every snapshot (on the controller's thread: only queues the work)."""
        if snap.event is None or snap.event is self._last_event:
            return
        self._last_event = snap.event
        episode = (snap.scene, snap.episode_id, snap.event.segment)
        if snap.map is None:  # a reset (no map yet): only the new episode's start
            self._todo.put((episode, None, None, ""))
            return
        d = snap.event.decision
        action = "-" if snap.event.action is None else snap.event.action.name.lower()
        line = f"step {snap.event.step}: " + ("reset" if d is None else f"{action} [{d.goal_kind or '-'}] {d.reason}")
        self._todo.put((episode, snap.event.step, snap.map, line))

    def picture_at(self, step: int) -> np.ndarray:
        with self._lock:
            if step not in self._pictures:
                raise L3MVNError(
                    f"step {step} is not in this episode's history; valid: "
                    f"{min(self._pictures, default=0)}..{max(self._pictures, default=0)}"
                )
            return png_rgb(self._pictures[step])

    def close(self) -> None:
        self._todo.put(None)

    # --- controls ----------------------------------------------------------------------------
    def _wire(self, on: Callable) -> None:
        @on(self.step)
        def _(event) -> None:
            if event.client_id is None:  # the server moving the slider along with the live episode
                return
            self.show(int(self.step.value))

        @on(self.live)
        def _(event) -> None:
            self._back_to_live()

    def show(self, step: int) -> None:
        """Step ``step`` over the main view, or the live map when it is the newest step."""
        steps = self.steps
        if not steps:
            raise L3MVNError("no steps yet: press Reset, then Step or Run")
        step = min(steps, key=lambda s: abs(s - step))
        if step == steps[-1]:
            self._back_to_live()
            return
        picture = self.picture_at(step)
        with self._lock:
            line = self._lines[step]
        self.picture.content = main_view_html(
            picture,
            f"Looking back: {line[:120]}",
            main_view=True,
            note="press Back to live in Episode history for the live map",
        )
        self.line.content = md(line)
        self.live.disabled = False

    def _back_to_live(self) -> None:
        self.picture.content = ""
        self.live.disabled = True
        steps = self.steps
        if steps:
            self.step.value = steps[-1]
            with self._lock:
                self.line.content = f"live: {md(self._lines[steps[-1]])}"

    # --- the encoder -------------------------------------------------------------------------
    def _encode_loop(self) -> None:
        while True:
            item = self._todo.get()
            if item is None:
                return
            episode, step, view, line = item
            png = None if view is None else png_bytes(history_picture(view))
            with self._lock:
                fresh = episode != self._episode
                if fresh:
                    self._episode, self._pictures, self._lines = episode, {}, {}
                if png is not None and len(self._pictures) < MAX_KEPT:
                    self._pictures[step], self._lines[step] = png, line
                first, last = min(self._pictures, default=0), max(self._pictures, default=0)
            looking_back = not self.live.disabled
            if fresh and looking_back:
                self.picture.content = ""  # the step looked at belongs to an episode that is gone
                self.live.disabled = True
            if png is None:
                self.step.disabled = True
                self.line.content = "_the steps of the current episode appear here as it runs_"
                continue
            self.step.min, self.step.max = first, max(last, first + 1)  # a slider needs two ends
            self.step.disabled = False
            if not looking_back or fresh:
                self.step.value = last
                self.line.content = f"live: {md(line)}"


def history_picture(view: MapView) -> np.ndarray:
    """The map as the live view draws it, flattened into one picture: frontiers as discs in their
    score colour (the chosen one ringed), the long-term goal as a cross, the agent as an arrow."""
    img = np.ascontiguousarray(view.image.copy())
    s = view.scale

    def px(cell) -> tuple[int, int]:
        return int((cell[1] - view.origin[1] + 0.5) * s), int((cell[0] - view.origin[0] + 0.5) * s)

    r = max(4, 3 * s)
    for f in view.frontiers:
        score = f.fused if f.fused is not None else f.s_cu
        cv2.circle(img, px(f.cell), r, score_color(score), -1, cv2.LINE_AA)
        cv2.circle(img, px(f.cell), r + 3 if f.chosen else r, (0, 0, 0), 2 if f.chosen else 1, cv2.LINE_AA)
        cv2.putText(
            img,
            f"F{f.id}",
            (px(f.cell)[0] + r + 2, px(f.cell)[1] + 4),
            cv2.FONT_HERSHEY_SIMPLEX,
            0.45,
            (255, 255, 255),
            2,
            cv2.LINE_AA,
        )
        cv2.putText(
            img,
            f"F{f.id}",
            (px(f.cell)[0] + r + 2, px(f.cell)[1] + 4),
            cv2.FONT_HERSHEY_SIMPLEX,
            0.45,
            (0, 0, 0),
            1,
            cv2.LINE_AA,
        )
    if view.long_term_goal is not None:
        cv2.drawMarker(img, px(view.long_term_goal), _GOAL, cv2.MARKER_CROSS, 3 * r, 3, cv2.LINE_AA)
    x, y = px(view.agent_cell)
    tip = (int(x + 3 * r * math.cos(view.agent_heading)), int(y + 3 * r * math.sin(view.agent_heading)))
    cv2.arrowedLine(img, (x, y), tip, _AGENT, 3, cv2.LINE_AA, tipLength=0.4)
    cv2.circle(img, (x, y), r, _AGENT, -1, cv2.LINE_AA)
    return img

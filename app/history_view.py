"""The Episode history folder: a step slider over the live episode, to look back without a recording.

Every step's map (frontiers coloured by score, the chosen one ringed, the long-term goal and the
agent drawn in) is kept as a PNG with its decision line, and the step's camera frames (RGB, depth,
semantics) as a JPEG strip, all encoded off the agent's thread. Moving the slider back shows that
step, map above frames, over the main view; "Back to live" (or the slider at the newest step)
returns to the live map. A Reset starts a new history; a target change does not (it is a new
segment of the same walk: the steps before it stay, and each line names the target it was after).
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
from l3mvn_studio.map_image import frontier_colors, png_bytes, png_rgb
from l3mvn_studio.page_text import md
from l3mvn_studio.state import Frames, MapView, Snapshot

MAX_KEPT = 2000  # steps of one episode kept (~30 KB map + ~10 KB frames each); an episode is 500 by default
STRIP_WIDTH = 160  # each camera frame in a kept strip: enough to recognise what the agent saw
JPEG_QUALITY = 80  # camera frames are photographs of a render: lossy is fine, and 10x smaller than PNG
_AGENT = (220, 40, 40)
_GOAL = (255, 120, 0)


class HistoryPanel:
    """Keeps the live episode's steps and scrubs through them (one history shared by every tab)."""

    def __init__(self, gui: viser.GuiApi, *, on: Callable, tell: Callable) -> None:
        self._tell = tell
        self._lock = threading.Lock()
        self._episode: tuple | None = None  # (scene, episode id, resets seen) the history belongs to
        self._resets = 0
        self._pictures: dict[int, bytes] = {}
        self._frames: dict[int, bytes] = {}
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
        ev = snap.event
        if ev.step == 0 and ev.segment == 0:  # a Reset (also of the same episode again): a new history
            self._resets += 1
        episode = (snap.scene, snap.episode_id, self._resets)
        d = ev.decision
        head = f"step {ev.step}" + (f" (segment {ev.segment}, target {ev.goal})" if ev.segment else "")
        retarget = d is None and ev.segment > 0  # a target change republishes the step it happened at
        if retarget:
            line = f"{head}: new target {ev.goal}"
        elif snap.map is None:  # a reset (no map yet): only the new episode's start
            self._todo.put((episode, None, None, None, "", False))
            return
        else:
            action = "-" if ev.action is None else ev.action.name.lower()
            line = f"{head}: " + ("reset" if d is None else f"{action} [{d.goal_kind or '-'}] {d.reason}")
        self._todo.put((episode, ev.step, snap.map, snap.frames, line, retarget))

    def picture_at(self, step: int) -> np.ndarray:
        """Step ``step`` as it is shown: the map, with the step's camera frames below it when kept."""
        with self._lock:
            if step not in self._pictures:
                raise L3MVNError(
                    f"step {step} is not in this episode's history; valid: "
                    f"{min(self._pictures, default=0)}..{max(self._pictures, default=0)}"
                )
            picture, frames = self._pictures[step], self._frames.get(step)
        return with_frames_below(png_rgb(picture), None if frames is None else jpeg_rgb(frames))

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
            episode, step, view, frames, line, retarget = item
            png = None if view is None else png_bytes(history_picture(view))
            strip = None if frames is None else jpeg_bytes(camera_strip(frames))
            with self._lock:
                fresh = episode != self._episode
                if fresh:
                    self._episode, self._pictures, self._frames, self._lines = episode, {}, {}, {}
                if retarget and step in self._lines:  # keep what the step did, and say what came after it
                    self._lines[step] += f"; then {line.split(': ', 1)[1]}"
                elif png is not None and len(self._pictures) < MAX_KEPT:
                    self._pictures[step], self._lines[step] = png, line
                    if strip is not None:
                        self._frames[step] = strip
                first, last = min(self._pictures, default=0), max(self._pictures, default=0)
                newest = self._lines.get(last, "")
            looking_back = not self.live.disabled
            if fresh and looking_back:
                self.picture.content = ""  # the step looked at belongs to an episode that is gone
                self.live.disabled = True
            if not newest:
                self.step.disabled = True
                self.line.content = "_the steps of the current episode appear here as it runs_"
                continue
            self.step.min, self.step.max = first, max(last, first + 1)  # a slider needs two ends
            self.step.disabled = False
            if not looking_back or fresh:
                self.step.value = last
                self.line.content = f"live: {md(newest)}"


def camera_strip(frames: Frames) -> np.ndarray:
    """RGB, depth and semantics side by side, each ``STRIP_WIDTH`` wide (the kept record of a step's view)."""
    h, w = frames.rgb.shape[:2]
    size = (STRIP_WIDTH, max(1, round(h * STRIP_WIDTH / w)))
    return np.hstack(
        [cv2.resize(f, size, interpolation=cv2.INTER_AREA) for f in (frames.rgb, frames.depth, frames.semantic)]
    )


def with_frames_below(picture: np.ndarray, strip: np.ndarray | None) -> np.ndarray:
    """The map picture with the camera strip under it, scaled to the map's width (dark margin between)."""
    if strip is None:
        return picture
    w = picture.shape[1]
    h = max(1, round(strip.shape[0] * w / strip.shape[1]))
    below = cv2.resize(strip, (w, h), interpolation=cv2.INTER_AREA if w < strip.shape[1] else cv2.INTER_LINEAR)
    return np.vstack([picture, np.full((4, w, 3), 24, np.uint8), below])


def jpeg_bytes(rgb: np.ndarray) -> bytes:
    return cv2.imencode(".jpg", np.ascontiguousarray(rgb[..., ::-1]), (cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY))[
        1
    ].tobytes()


def jpeg_rgb(data: bytes) -> np.ndarray:
    return cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)[..., ::-1]


def history_picture(view: MapView) -> np.ndarray:
    """The map as the live view draws it, flattened into one picture: frontiers as discs in their
    score colour (the chosen one ringed), the long-term goal as a cross, the agent as an arrow."""
    img = np.ascontiguousarray(view.image.copy())
    s = view.scale

    def px(cell) -> tuple[int, int]:
        return int((cell[1] - view.origin[1] + 0.5) * s), int((cell[0] - view.origin[0] + 0.5) * s)

    r = max(4, 3 * s)
    for f, rgb in zip(view.frontiers, frontier_colors(view.frontiers)):
        cv2.circle(img, px(f.cell), r, rgb, -1, cv2.LINE_AA)
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

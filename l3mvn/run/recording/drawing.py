"""Frames of a recorded episode, as its video shows them (``l3mvn export``) and the dashboard's
result and compare views draw them.

One frame per recorded step: the RGB frame beside the top-down map (cropped to what the episode
mapped, the target category boxed, frontiers coloured by score, the best three and the chosen one
labelled, a score colour bar fitted to the step's scores), and under them the step, the target and
the decision (and, for a language policy, the fusion rule's line behind the current choice). A title
card with the outcome (success, or the failure cause, SPL, DTG) opens the video.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import cv2
import numpy as np

from l3mvn.core.errors import L3MVNError
from l3mvn.run.recording.recorded import RecordedEpisode, RecordedStep
from l3mvn.run.viz import (
    AGENT_RGB,
    COLLISION_RGB,
    GOAL_RGB,
    SCORE_SCALE,
    TARGET_RGB,
    TRAJECTORY_RGB,
    colormap,
)

FONT = cv2.FONT_HERSHEY_SIMPLEX  # pictures drawn from recordings (video and the dashboard's compare view)
PANEL_BG = (24, 24, 24)
TEXT_RGB = (235, 235, 235)
_DIM = (160, 160, 160)
_FUSION_RGB = (150, 195, 240)
_SUCCESS_RGB = (40, 170, 70)
_FAILURE_RGB = (200, 45, 45)
_GAP = 6  # pixels between the camera and the map panel


@dataclass(frozen=True)
class VideoOptions:
    """How a video is drawn: ``height`` of the camera and map panels (the text band adds a sixth, and
    two fifths of that again for a recording with a fusion line),
    ``fps`` steps per second, ``title_s`` seconds of title card."""

    fps: float = 4.0
    height: int = 480
    title_s: float = 2.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.fps) and 0 < self.fps <= 60):
            raise L3MVNError(f"--fps must lie in (0, 60], got {self.fps}")
        if not 120 <= self.height <= 2160:
            raise L3MVNError(f"--height must lie in 120..2160 pixels, got {self.height}")
        if not (math.isfinite(self.title_s) and 0 <= self.title_s <= 30):
            raise L3MVNError(f"--title-seconds must lie in 0..30, got {self.title_s}")

    @property
    def title_frames(self) -> int:
        """Frames the title card is held in the MP4 (at least one: every video states its outcome)."""
        return max(1, round(self.title_s * self.fps))


@dataclass(frozen=True)
class FrameGeometry:
    """Where a frame's parts lie, in pixels: the camera and map panels side by side, the text band under them."""

    width: int
    height: int
    panel: int  # camera and map panels are this tall
    camera_w: int
    map_w: int
    band: int
    line: int  # the band's text unit: the band's height without the fusion row

    @classmethod
    def of(cls, ep: RecordedEpisode, options: VideoOptions) -> FrameGeometry:
        """The geometry of every frame of ``ep`` (its camera's aspect, its map crop, a fusion row or not)."""
        first = cv2.imdecode(np.frombuffer(ep.steps[0].rgb_png, np.uint8), cv2.IMREAD_UNCHANGED)
        assert first is not None  # the PNG read_episode encoded
        h0, w0 = first.shape[:2]
        panel = options.height
        camera_w = round(panel * w0 / h0)
        line = max(56, panel // 6)
        r0, r1, c0, c1 = ep.box
        map_w = round(panel * (c1 - c0) / (r1 - r0))
        map_w += (camera_w + _GAP + map_w) % 2  # codecs want even sizes
        line += (panel + line) % 2
        fusion_row = 2 * (round(line * 0.4) // 2) if ep.has_fusion else 0  # even: the height stays even
        band = line + fusion_row
        return cls(camera_w + _GAP + map_w, panel + band, panel, camera_w, map_w, band, line)


def frames(ep: RecordedEpisode, options: VideoOptions, *, title_frames: int | None = None) -> Iterator[np.ndarray]:
    """The title card (``title_frames`` times, default ``options.title_frames``), then one (H, W, 3)
    RGB frame per recorded step."""
    geo = FrameGeometry.of(ep, options)
    card = title_card(ep, geo)
    for _ in range(options.title_frames if title_frames is None else title_frames):
        yield card
    lut = _lut(ep.classes)
    last = ep.steps[-1].step
    for s in ep.steps:
        frame = np.zeros((geo.height, geo.width, 3), np.uint8)
        frame[:] = PANEL_BG
        frame[: geo.panel, : geo.camera_w] = _camera(s, geo)
        x0 = geo.camera_w + _GAP
        frame[: geo.panel, x0 : x0 + geo.map_w] = _map_panel(ep, s, lut, (geo.map_w, geo.panel))
        _band(frame, geo, ep, s, last)
        yield frame


def _camera(s: RecordedStep, geo: FrameGeometry) -> np.ndarray:
    bgr = cv2.imdecode(np.frombuffer(s.rgb_png, np.uint8), cv2.IMREAD_COLOR)
    assert bgr is not None  # the PNG read_episode encoded
    h0 = bgr.shape[0]
    img = np.ascontiguousarray(cv2.resize(bgr, (geo.camera_w, geo.panel), interpolation=cv2.INTER_AREA)[..., ::-1])
    if s.camera_boxes is not None:
        k = geo.panel / h0
        for x0, y0, x1, y1 in s.camera_boxes * k:
            cv2.rectangle(img, (int(x0), int(y0)), (int(x1), int(y1)), (255, 255, 255), 4)
            cv2.rectangle(img, (int(x0), int(y0)), (int(x1), int(y1)), TARGET_RGB, 2)
        x0, y0 = (s.camera_boxes[0, :2] * k).astype(int)
        _label(img, f"target: {s.goal}", (x0, max(y0 - 6, 14)), (255, 255, 255))
    return img


def _lut(classes: dict) -> np.ndarray:
    lut = np.zeros((max(classes, default=0) + 1 if classes else 1, 3), np.uint8)
    lut[:] = 255
    for k, (_, rgb) in classes.items():
        lut[k] = rgb
    return lut


def _map_panel(ep: RecordedEpisode, s: RecordedStep, lut: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    r0, r1, c0, c1 = ep.box
    ids = np.zeros((r1 - r0, c1 - c0), np.uint16)
    if s.map_ids is not None:
        r, c, win = s.map_ids
        top, bottom = max(r, r0), min(r + win.shape[0], r1)
        left, right = max(c, c0), min(c + win.shape[1], c1)
        ids[top - r0 : bottom - r0, left - c0 : right - c0] = win[top - r : bottom - r, left - c : right - c]
    k = size[1] / (r1 - r0)
    img = np.ascontiguousarray(cv2.resize(lut[np.minimum(ids, len(lut) - 1)], size, interpolation=cv2.INTER_NEAREST))

    def px(xy: np.ndarray) -> np.ndarray:
        return np.round((xy - (c0, r0)) * k).astype(np.int32)

    boxes = [] if s.map_boxes is None else [px(b.reshape(2, 2)).ravel() for b in s.map_boxes]
    for x0, y0, x1, y1 in boxes:
        cv2.rectangle(img, (x0 - 2, y0 - 2), (x1 + 2, y1 + 2), (255, 255, 255), 4)
        cv2.rectangle(img, (x0 - 2, y0 - 2), (x1 + 2, y1 + 2), TARGET_RGB, 2)
    half = max(1, int(k / 2))
    if s.collision_marks is not None and len(s.collision_marks):
        _paint_cells(img, px(s.collision_marks), half, np.array(COLLISION_RGB))
    if s.frontier_cells is not None and len(s.frontier_cells.xy):
        _paint_cells(img, px(s.frontier_cells.xy), half, s.frontier_cells.rgb)
    if s.trajectory is not None and len(s.trajectory) > 1:
        cv2.polylines(img, [px(s.trajectory)], False, TRAJECTORY_RGB, max(1, int(k)), cv2.LINE_AA)
    placed: list[tuple[int, int, int, int]] = []
    if s.frontiers is not None:
        centres = px(s.frontiers.xy)
        for (x, y), rgb, r in zip(centres, s.frontiers.rgb, s.frontiers.radii):
            radius = max(4, int(r * k * 0.8))
            cv2.circle(img, (int(x), int(y)), radius, tuple(int(v) for v in rgb), -1, cv2.LINE_AA)
            cv2.circle(img, (int(x), int(y)), radius, (0, 0, 0), 1, cv2.LINE_AA)
            placed.append((x - radius, y - radius, x + radius, y + radius))
        for (x, y), label, rgb in zip(centres, s.frontiers.labels, s.frontiers.rgb):
            if label:  # OpenCV's fonts have no star: the chosen frontier's mark is drawn as "*"
                _place_label(img, label.replace("★", "*"), (int(x), int(y)), placed, tuple(int(v) for v in rgb))
    if boxes:
        x0, y0, x1, _ = boxes[0]
        _place_label(img, f"target: {s.goal}", ((x0 + x1) // 2, y0), placed, (255, 255, 255))
    if s.goal_mark is not None and len(s.goal_mark.xy):
        gx, gy = px(s.goal_mark.xy)[0]
        cv2.drawMarker(img, (int(gx), int(gy)), GOAL_RGB, cv2.MARKER_TILTED_CROSS, max(12, int(6 * k)), 3)
    if s.agent is not None:
        (ax, ay), vec = px(s.agent[0][None])[0], s.agent[1]
        tip = (int(ax + vec[0] * k), int(ay + vec[1] * k))
        cv2.arrowedLine(img, (int(ax), int(ay)), tip, AGENT_RGB, 2, cv2.LINE_AA, tipLength=0.35)
        cv2.circle(img, (int(ax), int(ay)), max(4, int(2 * k)), AGENT_RGB, -1, cv2.LINE_AA)
    _colour_bar(img)
    return img


def _paint_cells(img: np.ndarray, centres: np.ndarray, half: int, rgb: np.ndarray) -> None:
    """A square of side ``2 half + 1`` pixels round each centre (x, y), in one colour or one per cell;
    squares cut at the panel's edge. Vectorised: a long episode lays a thousand collision cells."""
    h, w = img.shape[:2]
    d = np.arange(-half, half + 1)
    ys = (centres[:, 1, None, None] + d[None, :, None]).repeat(len(d), axis=2)
    xs = (centres[:, 0, None, None] + d[None, None, :]).repeat(len(d), axis=1)
    colours = np.broadcast_to(np.asarray(rgb, np.uint8).reshape(-1, 1, 1, 3), (len(centres), len(d), len(d), 3))
    inside = (ys >= 0) & (ys < h) & (xs >= 0) & (xs < w)
    img[ys[inside], xs[inside]] = colours[inside]


def _place_label(img: np.ndarray, text: str, at: tuple[int, int], placed: list, rgb) -> tuple[int, int, int, int]:
    """Put ``text`` beside the point at the first spot (right, left, above, below, further out) that
    lies inside the panel and overlaps no label or marker already placed: labels never cover each
    other, and one beside the map's edge is not cut off (a toilet at the left edge read "arget").
    Returns the box it took."""
    (tw, th), base = cv2.getTextSize(text, FONT, 0.45, 1)
    x, y = at
    h, w = img.shape[:2]
    boxes = [
        (x + dx - 2, y + dy - th - 2, x + dx + tw + 2, y + dy + base + 1)
        for dx, dy in (
            (8, 4),
            (-tw - 8, 4),
            (-tw // 2, -10),
            (-tw // 2, th + 12),
            (8, -14),
            (8, th + 14),
            (-tw - 8, -14),
            (-tw - 8, th + 14),
        )
    ]
    inside = [b for b in boxes if b[0] >= 0 and b[1] >= 0 and b[2] < w and b[3] < h]
    clear = [b for b in inside if all(b[2] < p[0] or b[0] > p[2] or b[3] < p[1] or b[1] > p[3] for p in placed)]
    box = (clear or inside or [_shift_inside(boxes[0], w, h)])[0]
    placed.append(box)
    _label(img, text, (box[0] + 2, box[3] - base - 1), rgb)
    return box


def _shift_inside(box: tuple[int, int, int, int], w: int, h: int) -> tuple[int, int, int, int]:
    dx = max(0, -box[0]) - max(0, box[2] - (w - 1))
    dy = max(0, -box[1]) - max(0, box[3] - (h - 1))
    return box[0] + dx, box[1] + dy, box[2] + dx, box[3] + dy


def _label(img: np.ndarray, text: str, at: tuple[int, int], rgb, scale: float = 0.45) -> None:
    (tw, th), base = cv2.getTextSize(text, FONT, scale, 1)
    x, y = int(at[0]), int(at[1])
    cv2.rectangle(img, (x - 2, y - th - 2), (x + tw + 2, y + base), (20, 20, 20), -1)
    cv2.rectangle(img, (x - 2, y - th - 2), (x + tw + 2, y + base), tuple(int(v) for v in rgb), 1)
    cv2.putText(img, text, (x, y), FONT, scale, (255, 255, 255), 1, cv2.LINE_AA)


def _colour_bar(img: np.ndarray) -> None:
    """The frontier score colormap, bottom left of the map: fitted to each step's frontiers (the
    recorder colours them min-max), so its ends are that step's lowest and highest score."""
    h = img.shape[0]
    w = max(60, img.shape[1] // 5)
    bar = colormap(np.linspace(0, 1, w))
    y0, x0 = h - 26, 40
    cv2.rectangle(img, (4, y0 - 18), (x0 + w + 40, h - 4), (20, 20, 20), -1)
    img[y0 : y0 + 10, x0 : x0 + w] = bar[None]
    cv2.putText(img, "low", (x0 - 32, y0 + 10), FONT, 0.4, TEXT_RGB, 1, cv2.LINE_AA)
    cv2.putText(img, "high", (x0 + w + 4, y0 + 10), FONT, 0.4, TEXT_RGB, 1, cv2.LINE_AA)
    cv2.putText(img, f"frontier score ({SCORE_SCALE}, this step)", (x0, y0 - 5), FONT, 0.4, TEXT_RGB, 1, cv2.LINE_AA)


def _band(frame: np.ndarray, geo: FrameGeometry, ep: RecordedEpisode, s: RecordedStep, last: int) -> None:
    """The step, target and episode; the decision; and the fusion line where the step has one."""
    scale = geo.line / 115
    y = geo.panel + int(geo.line * 0.38)
    head = f"step {s.step}/{last}   find: {s.goal}   {ep.policy} on {ep.scene} #{ep.episode_id}"
    cv2.putText(frame, head, (10, y), FONT, scale, TEXT_RGB, 1, cv2.LINE_AA)
    cv2.putText(
        frame,
        fit_text(s.decision, geo.width - 20, scale * 0.85),
        (10, y + int(geo.line * 0.4)),
        FONT,
        scale * 0.85,
        _DIM,
        1,
        cv2.LINE_AA,
    )
    if s.fusion:  # in its own row under the others: their pixels stay as a recording without one draws them
        baseline = geo.panel + geo.line + int((geo.band - geo.line) * 0.7)
        cv2.putText(
            frame,
            fit_text(s.fusion, geo.width - 20, scale * 0.85),
            (10, baseline),
            FONT,
            scale * 0.85,
            _FUSION_RGB,
            1,
            cv2.LINE_AA,
        )


def fit_text(text: str, width: int, scale: float) -> str:
    """``text`` cut (with an ellipsis) to ``width`` pixels."""
    if cv2.getTextSize(text, FONT, scale, 1)[0][0] <= width:
        return text
    while text and cv2.getTextSize(text + "...", FONT, scale, 1)[0][0] > width:
        text = text[:-1]
    return text + "..."


def title_card(ep: RecordedEpisode, geo: FrameGeometry) -> np.ndarray:
    """The outcome in a coloured banner (green success, red failure), then the episode and metrics."""
    card = np.zeros((geo.height, geo.width, 3), np.uint8)
    card[:] = PANEL_BG
    outcome = ep.outcome
    banner = geo.height // 4
    card[:banner] = _SUCCESS_RGB if outcome == "success" else (_FAILURE_RGB if ep.result else (110, 110, 110))
    title = {"success": "SUCCESS", "unfinished": "NO RESULT (recording cut short)"}.get(
        outcome, f"FAILURE: {outcome.removeprefix('fail_').replace('_', ' ')}"
    )
    scale = geo.height / 360
    cv2.putText(
        card,
        fit_text(title, geo.width - 40, scale * 1.1),
        (20, banner // 2 + int(12 * scale)),
        FONT,
        scale * 1.1,
        (255, 255, 255),
        2,
        cv2.LINE_AA,
    )
    r = ep.result
    goal = ep.steps[0].goal if ep.steps else "?"
    lines = [f"find a {goal} in {ep.scene} (episode {ep.episode_id}, {ep.dataset})", f"policy: {ep.policy}"]
    if r:
        lines.append(f"SPL {_metric(ep, 'spl')}   DTG {_metric(ep, 'dtg')} m   {r.get('steps', '?')} steps")
        lines.append(f"path {_metric(ep, 'path_length_m')} m, shortest {_metric(ep, 'shortest_path_m')} m")
    lines.append("frames: L3MVN Studio's CPU renderer (flat-shaded)")
    for i, line in enumerate(lines):
        colour = _DIM if i == len(lines) - 1 else TEXT_RGB
        cv2.putText(
            card,
            fit_text(line, geo.width - 40, scale * 0.6),
            (20, banner + int((40 + 34 * i) * scale)),
            FONT,
            scale * 0.6,
            colour,
            1,
            cv2.LINE_AA,
        )
    return card


def _metric(ep: RecordedEpisode, name: str) -> str:
    """A result field to two decimals; "-" when it is absent or not a finite number."""
    f = ep.result_number(name)
    return "-" if f is None or not math.isfinite(f) else f"{f:.2f}"

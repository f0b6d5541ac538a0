"""A video of a recorded episode, read back from its ``.rrd`` alone (``l3mvn export`` writes them).

One frame per recorded step: the RGB frame beside the top-down map (cropped to what the episode
mapped, the target category boxed, frontiers coloured by score, the best three and the chosen one
labelled, a score colour bar), and under them the step, the target and the decision (and, for a
language policy, the fusion rule's line behind the current choice, as ``log/fusion`` holds it). A title card
with the outcome (success, or the failure cause, SPL, DTG) opens the video. Everything comes from
the recording (any ``.rrd`` the recorder wrote can be exported, nothing else is needed), through
rerun's own reader: each entity's value at a step is its latest value logged at or before it.
"""

from __future__ import annotations

import io
import math
import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from l3mvn.core.errors import L3MVNError, first_line
from l3mvn.run.recording.catalogue import TIMELINE, open_recording
from l3mvn.run.recording.layout import AGENT_RGB, GOAL_RGB, TARGET_RGB, VIEW_MARGIN, score_colors
from l3mvn.run.viz import COLLISION_RGB
from l3mvn.core.writing import replacing_path, write_file

FONT = cv2.FONT_HERSHEY_SIMPLEX  # pictures drawn from recordings (video and the dashboard's compare view)
PANEL_BG = (24, 24, 24)
TEXT_RGB = (235, 235, 235)
_DIM = (160, 160, 160)
_FUSION_RGB = (150, 195, 240)
_SUCCESS_RGB = (40, 170, 70)
_FAILURE_RGB = (200, 45, 45)
_GAP = 6  # pixels between the camera and the map panel
_MAP_ASPECT = (0.75, 1.6)  # the map panel's width / height, at least and at most
_UNLABELLED = ""


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
class VideoResult:
    path: Path
    gif: Path | None
    title_frames: int
    steps: int
    width: int
    height: int
    fps: float

    @property
    def frames(self) -> int:
        return self.title_frames + self.steps


@dataclass
class _Marks:
    """Points of one entity at one step (map pixels, x = column), with colours and labels."""

    xy: np.ndarray
    rgb: np.ndarray
    labels: list[str]
    radii: np.ndarray


@dataclass
class _Step:
    step: int
    rgb_png: bytes
    goal: str
    decision: str
    fusion: str  # the fusion rule's line in force at this step ("" before a language policy's first choice)
    map_ids: tuple[int, int, np.ndarray] | None  # (row, col) offset and the mapped window of the ids
    frontiers: _Marks | None
    frontier_cells: _Marks | None
    collision_marks: np.ndarray | None  # (N, 2) x, y of the cells the agent's failed steps blocked
    trajectory: np.ndarray | None
    agent: tuple[np.ndarray, np.ndarray] | None  # position and heading vector
    goal_mark: _Marks | None
    camera_boxes: np.ndarray | None  # (N, 4) x0, y0, x1, y1 of the target in the camera frame
    map_boxes: np.ndarray | None  # the same on the map, in map pixels


@dataclass
class RecordedEpisode:
    """An episode as its recording tells it (text fields are what the recorder wrote)."""

    path: Path
    scene: str
    episode_id: str
    dataset: str
    policy: str
    result: dict[str, str]
    classes: dict[int, tuple[str, tuple[int, int, int]]]  # map class id -> (label, colour)
    steps: list[_Step] = field(default_factory=list)
    box: tuple[int, int, int, int] = (0, 1, 0, 1)  # square map crop: rows r0..r1, cols c0..c1 (exclusive)

    @property
    def has_fusion(self) -> bool:
        """Whether any step has a fusion line (a language policy's recording): the band gets a row for it."""
        return any(s.fusion for s in self.steps)

    @property
    def outcome(self) -> str:
        """``success``, ``fail_<cause>`` or ``unfinished`` (no result: the recording was cut)."""
        if not self.result:
            return "unfinished"
        return "success" if _float(self.result.get("success")) == 1.0 else f"fail_{self.result.get('failure', '')}"


# --- reading ---------------------------------------------------------------------------------

_WANTED = {
    "/camera/rgb": ("Image:buffer", "Image:format"),
    "/camera/rgb/target": ("Boxes2D:centers", "Boxes2D:half_sizes"),
    "/map/target": ("Boxes2D:centers", "Boxes2D:half_sizes"),
    "/map": ("AnnotationContext:context",),
    "/map/semantic": ("SegmentationImage:buffer", "SegmentationImage:format"),
    "/map/frontiers": ("Points2D:positions", "Points2D:colors", "Points2D:labels", "Points2D:radii"),
    "/map/frontier_cells": ("Points2D:positions", "Points2D:colors"),
    "/map/collision_marks": ("Points2D:positions",),
    "/map/trajectory": ("LineStrips2D:strips",),
    "/map/agent": ("Points2D:positions", "Arrows2D:vectors"),
    "/map/goal": ("Points2D:positions", "Points2D:colors", "Points2D:labels"),
    "/log/decisions": ("TextLog:text",),
    "/log/fusion": ("TextLog:text",),
    "/log/episode": ("TextLog:text",),
    "/episode": ("TextDocument:text",),
}
_CLEAR = "Clear:is_recursive"
_STATIC = -1


def read_episode(path: str | Path) -> RecordedEpisode:
    """Everything a video draws, read from ``path``; one-line L3MVNError when the file is missing, is
    not a recording, or holds no map (a policy without one, e.g. oracle: nothing to draw)."""
    p = Path(path)
    reader = open_recording(p)
    events: dict[str, list[tuple[int, int, dict | None]]] = {e: [] for e in _WANTED}
    order = 0
    try:
        for chunk in reader.stream(store=reader.recordings()[0]):
            entity = chunk.entity_path
            if entity not in events:
                continue
            batch = chunk.to_record_batch()
            names = set(batch.schema.names)
            steps = batch.column(TIMELINE).to_pylist() if TIMELINE in names else [_STATIC] * batch.num_rows
            for i, step in enumerate(steps):
                order += 1
                if _CLEAR in names and batch.column(_CLEAR)[i].is_valid:
                    events[entity].append((step, order, None))
                    continue
                row = {c: _decode(c, batch.column(c)[i]) for c in _WANTED[entity] if c in names}
                row = {c: v for c, v in row.items() if v is not None}
                if row:
                    events[entity].append((step, order, row))
    except (RuntimeError, ValueError, OSError) as exc:
        raise L3MVNError(f"{p} is not a readable rerun recording: {first_line(exc)}") from None
    for rows in events.values():
        rows.sort(key=lambda e: (e[0], e[1]))
    return _assemble(p, events)


def _decode(column: str, scalar):
    if not scalar.is_valid:
        return None
    if column.endswith(":buffer"):
        return scalar.values.flatten().to_numpy(zero_copy_only=False)
    if column.endswith(":format"):
        return scalar.as_py()[0]
    if column.endswith(":strips"):
        return np.array(scalar.as_py()[0], np.float32).reshape(-1, 2)
    value = scalar.as_py()
    if column.endswith((":positions", ":vectors", ":centers", ":half_sizes")):
        return np.array(value, np.float32).reshape(-1, 2)
    if column.endswith(":colors"):
        packed = np.array(value, np.uint32)
        return np.stack([(packed >> 24) & 255, (packed >> 16) & 255, (packed >> 8) & 255], axis=1).astype(np.uint8)
    if column.endswith(":radii"):
        return np.array(value, np.float32)
    return value


class _LatestAt:
    """An entity's value at each step: its last row logged at or before it (None once cleared)."""

    def __init__(self, rows: list[tuple[int, int, dict | None]]) -> None:
        self.rows, self.i, self.value = rows, 0, None

    def at(self, step: int) -> dict | None:
        while self.i < len(self.rows) and self.rows[self.i][0] <= step:
            self.value = self.rows[self.i][2]
            self.i += 1
        return self.value


def _assemble(path: Path, events: dict) -> RecordedEpisode:
    if not events["/map/semantic"]:
        policy = _card_field(events, "policy") or "its policy"
        raise L3MVNError(f"{path} holds no map ({policy} keeps none): a video needs a map-based policy's "
                         "recording (e.g. frontier, cost-utility, l3mvn-zs)")
    if not events["/camera/rgb"]:
        raise L3MVNError(f"{path} holds no camera frames: nothing to export")
    card = _texts(events, "/episode", "TextDocument:text")
    first = card[0][1] if card else ""
    head = re.search(r"^# (\S+) episode (\S+)", first, re.MULTILINE)
    goal = _match(r"\* goal: \*\*(.+?)\*\*", first) or "?"
    result = dict(re.findall(r"^\| (\w+) \| (.*?) \|$", card[-1][1], re.MULTILINE)) if len(card) > 1 else {}
    result.pop("result", None)
    ep = RecordedEpisode(path=path, scene=head.group(1) if head else path.stem,
                         episode_id=head.group(2) if head else "?", dataset=_card_field(events, "dataset") or "?",
                         policy=_card_field(events, "policy") or "?", result=result,
                         classes=_classes(events["/map"]))
    goals = {s: m.group(1) for s, t in _texts(events, "/log/episode", "TextLog:text")
             if (m := re.search(r"target changed to (.+)$", t))}
    decisions = {s: t for s, t in _texts(events, "/log/decisions", "TextLog:text")}
    latest = {e: _LatestAt(rows) for e, rows in events.items()}
    boxes = []
    for step in sorted({s for s, _, row in events["/camera/rgb"] if row is not None}):
        goal = goals.get(step, goal)
        ids = _map_window(latest["/map/semantic"].at(step))
        frontiers, cells = latest["/map/frontiers"].at(step), latest["/map/frontier_cells"].at(step)
        agent, goal_mark = latest["/map/agent"].at(step), latest["/map/goal"].at(step)
        strips, marks = latest["/map/trajectory"].at(step), latest["/map/collision_marks"].at(step)
        target = latest["/camera/rgb/target"].at(step)
        fusion = latest["/log/fusion"].at(step)  # logged when the rule in force changes, so it holds until then
        ep.steps.append(_Step(
            step=step, rgb_png=_png(latest["/camera/rgb"].at(step)), goal=goal,
            decision=decisions.get(step, "reset: the episode starts" if step == 0 else ""),
            fusion="" if fusion is None else fusion["TextLog:text"][0], map_ids=ids,
            frontiers=_marks(frontiers), frontier_cells=_marks(cells),
            collision_marks=None if marks is None else marks.get("Points2D:positions"),
            trajectory=None if strips is None else strips["LineStrips2D:strips"],
            agent=None if agent is None else (agent["Points2D:positions"][0], agent["Arrows2D:vectors"][0]),
            goal_mark=_marks(goal_mark),
            camera_boxes=_boxes(target), map_boxes=_boxes(latest["/map/target"].at(step))))
        if ids is not None:
            r, c, win = ids
            boxes.append((r, r + win.shape[0], c, c + win.shape[1]))
        for marks in (ep.steps[-1].frontiers, ep.steps[-1].goal_mark):
            if marks is not None and len(marks.xy):
                x, y = marks.xy[:, 0], marks.xy[:, 1]
                boxes.append((int(y.min()), int(y.max()) + 1, int(x.min()), int(x.max()) + 1))
    ep.box = _crop(boxes, _map_size(events["/map/semantic"]))
    return ep


def _boxes(row: dict | None) -> np.ndarray | None:
    """(N, 4) x0, y0, x1, y1 of a Boxes2D row (the recorder logs centres and half sizes)."""
    if row is None:
        return None
    centres, half = row["Boxes2D:centers"], row["Boxes2D:half_sizes"]
    return np.hstack([centres - half, centres + half])


def _texts(events: dict, entity: str, column: str) -> list[tuple[int, str]]:
    return [(s, row[column][0]) for s, _, row in events[entity] if row is not None and row.get(column)]


def _card_field(events: dict, name: str) -> str | None:
    texts = _texts(events, "/episode", "TextDocument:text")
    return _match(rf"\* {name}: `(.+?)`", texts[0][1]) if texts else None


def _match(pattern: str, text: str) -> str | None:
    m = re.search(pattern, text)
    return m.group(1) if m else None


def _classes(rows: list) -> dict[int, tuple[str, tuple[int, int, int]]]:
    out = {}
    for _, _, row in rows:
        for entry in (row or {}).get("AnnotationContext:context", [[]])[0]:
            info = entry["class_description"]["info"]
            rgba = int(info.get("color") or 0)
            rgb = ((rgba >> 24) & 255, (rgba >> 16) & 255, (rgba >> 8) & 255)
            out[int(info["id"])] = (info.get("label") or "", rgb)
    return out


def _image(row: dict, prefix: str) -> np.ndarray:
    fmt, buf = row[f"{prefix}:format"], row[f"{prefix}:buffer"]
    h, w = int(fmt["height"]), int(fmt["width"])
    per_pixel = buf.size // max(h * w, 1)
    if prefix == "Image":
        return buf.reshape(h, w, per_pixel)[..., :3]
    return buf.view(np.uint16 if per_pixel == 2 else np.uint8).reshape(h, w)


def _png(row: dict | None) -> bytes:
    """The RGB frame, PNG-compressed: a 500-step episode of raw 640 x 480 frames would hold 460 MB."""
    rgb = _image(row, "Image")
    return cv2.imencode(".png", cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2BGR))[1].tobytes()


def _map_window(row: dict | None) -> tuple[int, int, np.ndarray] | None:
    """The mapped part of the map's ids (the rest is unexplored, id 0) and where it sits."""
    if row is None:
        return None
    ids = _image(row, "SegmentationImage")
    rows, cols = np.flatnonzero(ids.any(axis=1)), np.flatnonzero(ids.any(axis=0))
    if rows.size == 0:
        return None
    return int(rows[0]), int(cols[0]), ids[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1].copy()


def _map_size(rows: list) -> tuple[int, int]:
    fmt = next(row["SegmentationImage:format"] for _, _, row in rows if row is not None)
    return int(fmt["height"]), int(fmt["width"])


def _marks(row: dict | None) -> _Marks | None:
    if row is None or "Points2D:positions" not in row:
        return None
    xy = row["Points2D:positions"]
    n = len(xy)
    rgb = row.get("Points2D:colors", np.zeros((1, 3), np.uint8))
    labels = list(row.get("Points2D:labels") or [])
    radii = row.get("Points2D:radii", np.ones(1, np.float32))
    return _Marks(xy, np.broadcast_to(rgb, (n, 3)), (labels + [_UNLABELLED] * n)[:n] if len(labels) != 1 or n == 1
                  else labels * n, np.broadcast_to(radii, (n,)))


def _crop(boxes: list, size: tuple[int, int]) -> tuple[int, int, int, int]:
    """One crop for the whole video: every step's mapped area and marks, plus a margin, its aspect
    ratio kept within ``_MAP_ASPECT`` (the map panel takes the crop's shape)."""
    if not boxes:
        return 0, size[0], 0, size[1]
    b = np.array(boxes)
    r0, r1, c0, c1 = b[:, 0].min(), b[:, 1].max(), b[:, 2].min(), b[:, 3].max()
    h, w = (r1 - r0) * (1 + 2 * VIEW_MARGIN) + 2, (c1 - c0) * (1 + 2 * VIEW_MARGIN) + 2
    lo, hi = _MAP_ASPECT
    h, w = max(h, w / hi), max(w, h * lo)
    top, left = round((r0 + r1 - h) / 2), round((c0 + c1 - w) / 2)
    return top, top + math.ceil(h), left, left + math.ceil(w)


# --- drawing ---------------------------------------------------------------------------------

@dataclass(frozen=True)
class _Geometry:
    width: int
    height: int
    panel: int  # camera and map panels are this tall
    camera_w: int
    map_w: int
    band: int
    line: int  # the band's text unit: the band's height without the fusion row

    @classmethod
    def of(cls, ep: RecordedEpisode, options: VideoOptions) -> _Geometry:
        h0, w0 = cv2.imdecode(np.frombuffer(ep.steps[0].rgb_png, np.uint8), cv2.IMREAD_UNCHANGED).shape[:2]
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
    geo = _Geometry.of(ep, options)
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
        frame[: geo.panel, x0: x0 + geo.map_w] = _map_panel(ep, s, lut, (geo.map_w, geo.panel))
        _band(frame, geo, ep, s, last)
        yield frame


def _camera(s: _Step, geo: _Geometry) -> np.ndarray:
    bgr = cv2.imdecode(np.frombuffer(s.rgb_png, np.uint8), cv2.IMREAD_COLOR)
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


def _map_panel(ep: RecordedEpisode, s: _Step, lut: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    r0, r1, c0, c1 = ep.box
    ids = np.zeros((r1 - r0, c1 - c0), np.uint16)
    if s.map_ids is not None:
        r, c, win = s.map_ids
        top, bottom = max(r, r0), min(r + win.shape[0], r1)
        left, right = max(c, c0), min(c + win.shape[1], c1)
        ids[top - r0: bottom - r0, left - c0: right - c0] = win[top - r: bottom - r, left - c: right - c]
    k = size[1] / (r1 - r0)
    img = np.ascontiguousarray(cv2.resize(lut[np.minimum(ids, len(lut) - 1)], size,
                                          interpolation=cv2.INTER_NEAREST))

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
        cv2.polylines(img, [px(s.trajectory)], False, AGENT_RGB, max(1, int(k)), cv2.LINE_AA)
    placed: list[tuple[int, int, int, int]] = []
    if s.frontiers is not None:
        centres = px(s.frontiers.xy)
        for (x, y), rgb, r in zip(centres, s.frontiers.rgb, s.frontiers.radii):
            radius = max(4, int(r * k * 0.8))
            cv2.circle(img, (int(x), int(y)), radius, tuple(int(v) for v in rgb), -1, cv2.LINE_AA)
            cv2.circle(img, (int(x), int(y)), radius, (0, 0, 0), 1, cv2.LINE_AA)
            placed.append((x - radius, y - radius, x + radius, y + radius))
        for (x, y), label, rgb in zip(centres, s.frontiers.labels, s.frontiers.rgb):
            if label:
                _place_label(img, label, (int(x), int(y)), placed, tuple(int(v) for v in rgb))
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
    boxes = [(x + dx - 2, y + dy - th - 2, x + dx + tw + 2, y + dy + base + 1)
             for dx, dy in ((8, 4), (-tw - 8, 4), (-tw // 2, -10), (-tw // 2, th + 12), (8, -14), (8, th + 14),
                            (-tw - 8, -14), (-tw - 8, th + 14))]
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
    """Frontier score 0 (red) .. 1 (green), bottom left of the map."""
    h = img.shape[0]
    w = max(60, img.shape[1] // 5)
    bar = score_colors(np.linspace(0, 1, w))
    y0, x0 = h - 26, 34
    cv2.rectangle(img, (4, y0 - 18), (x0 + w + 26, h - 4), (20, 20, 20), -1)
    img[y0: y0 + 10, x0: x0 + w] = bar[None]
    cv2.putText(img, "0", (x0 - 14, y0 + 10), FONT, 0.4, TEXT_RGB, 1, cv2.LINE_AA)
    cv2.putText(img, "1", (x0 + w + 6, y0 + 10), FONT, 0.4, TEXT_RGB, 1, cv2.LINE_AA)
    cv2.putText(img, "frontier score", (x0, y0 - 5), FONT, 0.4, TEXT_RGB, 1, cv2.LINE_AA)


def _band(frame: np.ndarray, geo: _Geometry, ep: RecordedEpisode, s: _Step, last: int) -> None:
    """The step, target and episode; the decision; and the fusion line where the step has one."""
    scale = geo.line / 115
    y = geo.panel + int(geo.line * 0.38)
    head = f"step {s.step}/{last}   find: {s.goal}   {ep.policy} on {ep.scene} #{ep.episode_id}"
    cv2.putText(frame, head, (10, y), FONT, scale, TEXT_RGB, 1, cv2.LINE_AA)
    cv2.putText(frame, fit_text(s.decision, geo.width - 20, scale * 0.85), (10, y + int(geo.line * 0.4)), FONT,
                scale * 0.85, _DIM, 1, cv2.LINE_AA)
    if s.fusion:  # in its own row under the others: their pixels stay as a recording without one draws them
        baseline = geo.panel + geo.line + int((geo.band - geo.line) * 0.7)
        cv2.putText(frame, fit_text(s.fusion, geo.width - 20, scale * 0.85), (10, baseline), FONT, scale * 0.85,
                    _FUSION_RGB, 1, cv2.LINE_AA)


def fit_text(text: str, width: int, scale: float) -> str:
    """``text`` cut (with an ellipsis) to ``width`` pixels."""
    if cv2.getTextSize(text, FONT, scale, 1)[0][0] <= width:
        return text
    while text and cv2.getTextSize(text + "...", FONT, scale, 1)[0][0] > width:
        text = text[:-1]
    return text + "..."


def title_card(ep: RecordedEpisode, geo: _Geometry) -> np.ndarray:
    """The outcome in a coloured banner (green success, red failure), then the episode and metrics."""
    card = np.zeros((geo.height, geo.width, 3), np.uint8)
    card[:] = PANEL_BG
    outcome = ep.outcome
    banner = geo.height // 4
    card[:banner] = _SUCCESS_RGB if outcome == "success" else (_FAILURE_RGB if ep.result else (110, 110, 110))
    title = {"success": "SUCCESS", "unfinished": "NO RESULT (recording cut short)"}.get(
        outcome, f"FAILURE: {outcome.removeprefix('fail_').replace('_', ' ')}")
    scale = geo.height / 360
    cv2.putText(card, fit_text(title, geo.width - 40, scale * 1.1), (20, banner // 2 + int(12 * scale)), FONT,
                scale * 1.1, (255, 255, 255), 2, cv2.LINE_AA)
    r = ep.result
    goal = ep.steps[0].goal if ep.steps else "?"
    lines = [f"find a {goal} in {ep.scene} (episode {ep.episode_id}, {ep.dataset})", f"policy: {ep.policy}"]
    if r:
        lines.append(f"SPL {_num(r.get('spl'))}   DTG {_num(r.get('dtg'))} m   {r.get('steps', '?')} steps")
        lines.append(f"path {_num(r.get('path_length_m'))} m, shortest {_num(r.get('shortest_path_m'))} m")
    lines.append("frames: L3MVN Studio's CPU renderer (flat-shaded)")
    for i, line in enumerate(lines):
        colour = _DIM if i == len(lines) - 1 else TEXT_RGB
        cv2.putText(card, fit_text(line, geo.width - 40, scale * 0.6), (20, banner + int((40 + 34 * i) * scale)), FONT,
                    scale * 0.6, colour, 1, cv2.LINE_AA)
    return card


def _float(v) -> float | None:
    try:
        return float(v)
    except (TypeError, ValueError):
        return None


def _num(v) -> str:
    f = _float(v)
    return "-" if f is None or not math.isfinite(f) else f"{f:.2f}"


# --- writing ---------------------------------------------------------------------------------

def export_video(recording: str | Path, out: str | Path, options: VideoOptions = VideoOptions(), *,
                 gif: bool = False) -> VideoResult:
    """Write ``out`` (.mp4, OpenCV's mp4v) from ``recording``, and with ``gif`` a GIF beside it (same
    stem; one title frame held ``title_s``, for READMEs). Raises a one-line L3MVNError on bad input.

    The encoder reports no write errors, so the video is written beside ``out`` and read back: only a
    file holding every frame (a full disk leaves a few) is renamed to ``out``."""
    out = Path(out)
    if out.suffix.lower() != ".mp4":
        raise L3MVNError(f"video {out} must end in .mp4 (add --gif for a GIF beside it)")
    ep = read_episode(recording)
    geo = _Geometry.of(ep, options)
    expected = options.title_frames + len(ep.steps)

    def whole(path: Path) -> None:
        capture = cv2.VideoCapture(str(path))
        found = int(capture.get(cv2.CAP_PROP_FRAME_COUNT)) if capture.isOpened() else 0
        capture.release()
        if found != expected:
            raise L3MVNError(f"cannot write video {out}: {found} of its {expected} frames reached the disk (is it "
                             "full?); nothing was written there")

    with replacing_path(out, "video", check=whole) as partial:
        writer = cv2.VideoWriter(str(partial), cv2.VideoWriter_fourcc(*"mp4v"), options.fps, (geo.width, geo.height))
        if not writer.isOpened():
            raise L3MVNError(f"cannot write video {out}: OpenCV could not open it for writing")
        try:
            for frame in frames(ep, options):
                writer.write(np.ascontiguousarray(frame[..., ::-1]))
        finally:
            writer.release()
    gif_path = _write_gif(ep, options, out.with_suffix(".gif")) if gif else None
    return VideoResult(out, gif_path, options.title_frames, len(ep.steps), geo.width, geo.height, options.fps)


def _write_gif(ep: RecordedEpisode, options: VideoOptions, path: Path) -> Path:
    from PIL import Image

    images = (Image.fromarray(f) for f in frames(ep, options, title_frames=1))
    step_ms = round(1000 / options.fps)
    durations = [max(int(options.title_s * 1000), step_ms)] + [step_ms] * len(ep.steps)
    encoded = io.BytesIO()
    try:
        first = next(images)
        first.save(encoded, format="GIF", save_all=True, append_images=images, duration=durations, loop=0)
    except (OSError, ValueError) as exc:
        raise L3MVNError(f"cannot encode GIF {path}: {first_line(exc)}") from None
    return write_file(path, encoded.getvalue(), "GIF")

"""A recorded episode read back from its ``.rrd`` alone: everything a frame of it draws, per step.

Everything comes from the recording (any ``.rrd`` the recorder wrote can be read, nothing else is
needed), through rerun's own reader: each entity's value at a step is its latest value logged at or
before it. The entities and columns read are those ``entities`` names.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from l3mvn.core.errors import L3MVNError, first_line
from l3mvn.run.recording.catalogue import TIMELINE, open_recording
from l3mvn.run.recording.entities import (
    ANNOTATION_CONTEXT,
    ARROWS_VECTORS,
    BOXES_CENTERS,
    BOXES_HALF_SIZES,
    CAMERA_RGB,
    CAMERA_RGB_TARGET,
    CLEAR,
    EPISODE,
    IMAGE_BUFFER,
    IMAGE_FORMAT,
    LOG_DECISIONS,
    LOG_EPISODE,
    LOG_FUSION,
    MAP,
    MAP_AGENT,
    MAP_COLLISION_MARKS,
    MAP_FRONTIER_CELLS,
    MAP_FRONTIERS,
    MAP_GOAL,
    MAP_SEMANTIC,
    MAP_TARGET,
    MAP_TRAJECTORY,
    POINTS_COLORS,
    POINTS_LABELS,
    POINTS_POSITIONS,
    POINTS_RADII,
    SEGMENTATION_BUFFER,
    SEGMENTATION_FORMAT,
    STRIPS,
    TEXT_DOCUMENT,
    TEXT_LOG,
    reader_path,
)
from l3mvn.run.recording.layout import VIEW_MARGIN

_MAP_ASPECT = (0.75, 1.6)  # the map crop's width / height, at least and at most (the map panel takes its shape)
_UNLABELLED = ""


@dataclass
class MapMarks:
    """Points of one entity at one step (map pixels, x = column), with colours and labels."""

    xy: np.ndarray
    rgb: np.ndarray
    labels: list[str]
    radii: np.ndarray


@dataclass
class RecordedStep:
    """One recorded step: what its frame draws, each entity at its latest value at or before the step."""

    step: int
    rgb_png: bytes
    goal: str
    decision: str
    fusion: str  # the fusion rule's line in force at this step ("" before a language policy's first choice)
    map_ids: tuple[int, int, np.ndarray] | None  # (row, col) offset and the mapped window of the ids
    frontiers: MapMarks | None
    frontier_cells: MapMarks | None
    collision_marks: np.ndarray | None  # (N, 2) x, y of the cells the agent's failed steps blocked
    trajectory: np.ndarray | None
    agent: tuple[np.ndarray, np.ndarray] | None  # position and heading vector
    goal_mark: MapMarks | None
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
    steps: list[RecordedStep] = field(default_factory=list)
    box: tuple[int, int, int, int] = (0, 1, 0, 1)  # the map crop of every frame: rows r0..r1, cols c0..c1 (exclusive)

    @property
    def has_fusion(self) -> bool:
        """Whether any step has a fusion line (a language policy's recording): the band gets a row for it."""
        return any(s.fusion for s in self.steps)

    @property
    def outcome(self) -> str:
        """``success``, ``fail_<cause>`` or ``unfinished`` (no result: the recording was cut)."""
        if not self.result:
            return "unfinished"
        return "success" if self.result_number("success") == 1.0 else f"fail_{self.result.get('failure', '')}"

    def result_number(self, name: str) -> float | None:
        """The result field ``name`` as a number; None when it is absent or not one."""
        value = self.result.get(name)
        try:
            return None if value is None else float(value)
        except (TypeError, ValueError):
            return None


_WANTED = {
    CAMERA_RGB: (IMAGE_BUFFER, IMAGE_FORMAT),
    CAMERA_RGB_TARGET: (BOXES_CENTERS, BOXES_HALF_SIZES),
    MAP_TARGET: (BOXES_CENTERS, BOXES_HALF_SIZES),
    MAP: (ANNOTATION_CONTEXT,),
    MAP_SEMANTIC: (SEGMENTATION_BUFFER, SEGMENTATION_FORMAT),
    MAP_FRONTIERS: (POINTS_POSITIONS, POINTS_COLORS, POINTS_LABELS, POINTS_RADII),
    MAP_FRONTIER_CELLS: (POINTS_POSITIONS, POINTS_COLORS),
    MAP_COLLISION_MARKS: (POINTS_POSITIONS,),
    MAP_TRAJECTORY: (STRIPS,),
    MAP_AGENT: (POINTS_POSITIONS, ARROWS_VECTORS),
    MAP_GOAL: (POINTS_POSITIONS, POINTS_COLORS, POINTS_LABELS),
    LOG_DECISIONS: (TEXT_LOG,),
    LOG_FUSION: (TEXT_LOG,),
    LOG_EPISODE: (TEXT_LOG,),
    EPISODE: (TEXT_DOCUMENT,),
}
_BY_READER_PATH = {reader_path(entity): entity for entity in _WANTED}
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
            entity = _BY_READER_PATH.get(chunk.entity_path)
            if entity is None:
                continue
            batch = chunk.to_record_batch()
            names = set(batch.schema.names)
            steps = batch.column(TIMELINE).to_pylist() if TIMELINE in names else [_STATIC] * batch.num_rows
            for i, step in enumerate(steps):
                order += 1
                if CLEAR in names and batch.column(CLEAR)[i].is_valid:
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
    """One cell of a component column as the frames use it (rerun's component types, by name)."""
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
        self.rows, self.i = rows, 0
        self.value: dict | None = None

    def at(self, step: int) -> dict | None:
        while self.i < len(self.rows) and self.rows[self.i][0] <= step:
            self.value = self.rows[self.i][2]
            self.i += 1
        return self.value


def _assemble(path: Path, events: dict) -> RecordedEpisode:
    if not events[MAP_SEMANTIC]:
        policy = _card_field(events, "policy") or "its policy"
        raise L3MVNError(
            f"{path} holds no map ({policy} keeps none): a video needs a map-based policy's "
            "recording (e.g. frontier, cost-utility, l3mvn-zs)"
        )
    if not events[CAMERA_RGB]:
        raise L3MVNError(f"{path} holds no camera frames: nothing to export")
    card = _texts(events, EPISODE, TEXT_DOCUMENT)
    first = card[0][1] if card else ""
    head = re.search(r"^# (\S+) episode (\S+)", first, re.MULTILINE)
    goal = _match(r"\* goal: \*\*(.+?)\*\*", first) or "?"
    result = dict(re.findall(r"^\| (\w+) \| (.*?) \|$", card[-1][1], re.MULTILINE)) if len(card) > 1 else {}
    result.pop("result", None)
    ep = RecordedEpisode(
        path=path,
        scene=head.group(1) if head else path.stem,
        episode_id=head.group(2) if head else "?",
        dataset=_card_field(events, "dataset") or "?",
        policy=_card_field(events, "policy") or "?",
        result=result,
        classes=_classes(events[MAP]),
    )
    goals = {
        s: m.group(1)
        for s, t in _texts(events, LOG_EPISODE, TEXT_LOG)
        if (m := re.search(r"target changed to (.+)$", t))
    }
    decisions = {s: t for s, t in _texts(events, LOG_DECISIONS, TEXT_LOG)}
    latest = {e: _LatestAt(rows) for e, rows in events.items()}
    boxes = []
    for step in sorted({s for s, _, row in events[CAMERA_RGB] if row is not None}):
        goal = goals.get(step, goal)
        ids = _map_window(latest[MAP_SEMANTIC].at(step))
        frontiers, cells = latest[MAP_FRONTIERS].at(step), latest[MAP_FRONTIER_CELLS].at(step)
        agent, goal_mark = latest[MAP_AGENT].at(step), latest[MAP_GOAL].at(step)
        strips, marks = latest[MAP_TRAJECTORY].at(step), latest[MAP_COLLISION_MARKS].at(step)
        target = latest[CAMERA_RGB_TARGET].at(step)
        fusion = latest[LOG_FUSION].at(step)  # logged when the rule in force changes, so it holds until then
        ep.steps.append(
            RecordedStep(
                step=step,
                rgb_png=_png(latest[CAMERA_RGB].at(step)),
                goal=goal,
                decision=decisions.get(step, "reset: the episode starts" if step == 0 else ""),
                fusion="" if fusion is None else fusion[TEXT_LOG][0],
                map_ids=ids,
                frontiers=_marks(frontiers),
                frontier_cells=_marks(cells),
                collision_marks=None if marks is None else marks.get(POINTS_POSITIONS),
                trajectory=None if strips is None else strips[STRIPS],
                agent=None if agent is None else (agent[POINTS_POSITIONS][0], agent[ARROWS_VECTORS][0]),
                goal_mark=_marks(goal_mark),
                camera_boxes=_boxes(target),
                map_boxes=_boxes(latest[MAP_TARGET].at(step)),
            )
        )
        if ids is not None:
            r, c, win = ids
            boxes.append((r, r + win.shape[0], c, c + win.shape[1]))
        for drawn in (ep.steps[-1].frontiers, ep.steps[-1].goal_mark):
            if drawn is not None and len(drawn.xy):
                x, y = drawn.xy[:, 0], drawn.xy[:, 1]
                boxes.append((int(y.min()), int(y.max()) + 1, int(x.min()), int(x.max()) + 1))
    ep.box = _crop(boxes, _map_size(events[MAP_SEMANTIC]))
    return ep


def _boxes(row: dict | None) -> np.ndarray | None:
    """(N, 4) x0, y0, x1, y1 of a Boxes2D row (the recorder logs centres and half sizes)."""
    if row is None:
        return None
    centres, half = row[BOXES_CENTERS], row[BOXES_HALF_SIZES]
    return np.hstack([centres - half, centres + half])


def _texts(events: dict, entity: str, column: str) -> list[tuple[int, str]]:
    return [(s, row[column][0]) for s, _, row in events[entity] if row is not None and row.get(column)]


def _card_field(events: dict, name: str) -> str | None:
    texts = _texts(events, EPISODE, TEXT_DOCUMENT)
    return _match(rf"\* {name}: `(.+?)`", texts[0][1]) if texts else None


def _match(pattern: str, text: str) -> str | None:
    m = re.search(pattern, text)
    return m.group(1) if m else None


def _classes(rows: list) -> dict[int, tuple[str, tuple[int, int, int]]]:
    out = {}
    for _, _, row in rows:
        for entry in (row or {}).get(ANNOTATION_CONTEXT, [[]])[0]:
            info = entry["class_description"]["info"]
            rgba = int(info.get("color") or 0)
            rgb = ((rgba >> 24) & 255, (rgba >> 16) & 255, (rgba >> 8) & 255)
            out[int(info["id"])] = (info.get("label") or "", rgb)
    return out


def _pixels(row: dict, buffer_column: str, format_column: str) -> tuple[np.ndarray, int, int, int]:
    """An image row's flat buffer, its height and width, and the bytes each pixel takes."""
    fmt, buf = row[format_column], row[buffer_column]
    h, w = int(fmt["height"]), int(fmt["width"])
    return buf, h, w, buf.size // max(h * w, 1)


def _png(row: dict | None) -> bytes:
    """The RGB frame, PNG-compressed: a 500-step episode of raw 640 x 480 frames would hold 460 MB."""
    assert row is not None  # read only at the steps that logged a frame
    buf, h, w, per_pixel = _pixels(row, IMAGE_BUFFER, IMAGE_FORMAT)
    rgb = buf.reshape(h, w, per_pixel)[..., :3]
    return cv2.imencode(".png", cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2BGR))[1].tobytes()


def _map_window(row: dict | None) -> tuple[int, int, np.ndarray] | None:
    """The mapped part of the map's ids (the rest is unexplored, id 0) and where it sits."""
    if row is None:
        return None
    buf, h, w, per_pixel = _pixels(row, SEGMENTATION_BUFFER, SEGMENTATION_FORMAT)
    ids = buf.view(np.uint16 if per_pixel == 2 else np.uint8).reshape(h, w)
    rows, cols = np.flatnonzero(ids.any(axis=1)), np.flatnonzero(ids.any(axis=0))
    if rows.size == 0:
        return None
    return int(rows[0]), int(cols[0]), ids[rows[0] : rows[-1] + 1, cols[0] : cols[-1] + 1].copy()


def _map_size(rows: list) -> tuple[int, int]:
    fmt = next(row[SEGMENTATION_FORMAT] for _, _, row in rows if row is not None)
    return int(fmt["height"]), int(fmt["width"])


def _marks(row: dict | None) -> MapMarks | None:
    if row is None or POINTS_POSITIONS not in row:
        return None
    xy = row[POINTS_POSITIONS]
    n = len(xy)
    rgb = row.get(POINTS_COLORS, np.zeros((1, 3), np.uint8))
    labels = list(row.get(POINTS_LABELS) or [])
    radii = row.get(POINTS_RADII, np.ones(1, np.float32))
    return MapMarks(
        xy,
        np.broadcast_to(rgb, (n, 3)),
        (labels + [_UNLABELLED] * n)[:n] if len(labels) != 1 or n == 1 else labels * n,
        np.broadcast_to(radii, (n,)),
    )


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

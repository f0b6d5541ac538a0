"""Where the map's labels go: each beside its point, no two overlapping, none over a marker.

The map's labels are sized in scene metres (``em_m``: one em at the current zoom's wanted pixel
size), so boxes placed apart in metres stay apart however the view is zoomed afterwards: zooming
scales the map and its labels together. Placement is greedy, most important label first: each
takes the first candidate spot (right, left, above, below, the diagonals, then the same a ring
further out) whose box overlaps no label placed so far and no marker. A label moved off its point
gets a leader line back to it; one with no free spot is left out (the Frontiers table lists every
frontier), which keeps the map readable where frontiers crowd.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

# Average advance of a character of the page's sans-serif stack, in ems: measured in chromium at
# 0.50 (lower-case words) to 0.55 (a frontier's "F3 0.27"). A label is anchored at the side of its
# box nearest its point, so an estimate on the wide side only leaves room on the far side.
CHAR_EM = 0.58
LINE_EM = 1.45  # a label's box height (line height plus viser's background padding)
PAD_EM = 0.45  # the box's side padding together
GAP_EM = 0.3  # space kept between a label and anything else
RINGS = 4  # how far out (in box heights) a label may be moved from its point


@dataclass(frozen=True)
class Box:
    """An axis-aligned box in scene metres (x right, y up)."""

    x0: float
    y0: float
    x1: float
    y1: float

    def overlaps(self, other: Box, gap: float = 0.0) -> bool:
        return not (
            self.x1 + gap <= other.x0
            or other.x1 + gap <= self.x0
            or self.y1 + gap <= other.y0
            or other.y1 + gap <= self.y0
        )

    def inside(self, other: Box) -> bool:
        return other.x0 <= self.x0 and other.y0 <= self.y0 and self.x1 <= other.x1 and self.y1 <= other.y1

    @classmethod
    def around(cls, x: float, y: float, half_w: float, half_h: float | None = None) -> Box:
        h = half_w if half_h is None else half_h
        return cls(x - half_w, y - h, x + half_w, y + h)


@dataclass(frozen=True)
class LabelRequest:
    """A label wanted beside point ``at`` (scene metres), outside the marker of radius ``clear_m`` there."""

    text: str
    at: tuple[float, float]
    clear_m: float


@dataclass(frozen=True)
class PlacedLabel:
    """A label's estimated ``box``; drawn with its ``anchor`` side (viser's names) at ``at``, the
    middle of the box's side nearest its point."""

    text: str
    at: tuple[float, float]
    anchor: str
    box: Box
    leader: tuple[tuple[float, float], tuple[float, float]] | None  # from the point to the box, when moved off


def label_size(text: str, em_m: float) -> tuple[float, float]:
    """Estimated (width, height) in metres of ``text``'s label box at one em = ``em_m``."""
    return (CHAR_EM * len(text) + PAD_EM) * em_m, LINE_EM * em_m


def place_labels(
    requests: Sequence[LabelRequest], *, em_m: float, markers: Sequence[Box], bounds: Box | None = None
) -> list[PlacedLabel | None]:
    """Each request's label, in order of importance (the first is placed first), or None where no
    spot within ``RINGS`` is free of ``markers`` and of the labels placed before it; labels stay
    within ``bounds`` when given."""
    placed: list[Box] = []
    out: list[PlacedLabel | None] = []
    gap = GAP_EM * em_m
    for req in requests:
        w, h = label_size(req.text, em_m)
        spot = _first_free(req, w, h, gap, placed, markers, bounds)
        if spot is None:
            out.append(None)
            continue
        (cx, cy), ring = spot
        box = Box.around(cx, cy, w / 2, h / 2)
        placed.append(box)
        leader = None
        if ring:
            nx, ny = min(max(req.at[0], box.x0), box.x1), min(max(req.at[1], box.y0), box.y1)
            leader = (req.at, (nx, ny))
        out.append(PlacedLabel(req.text, *_anchor(box, cx - req.at[0], cy - req.at[1]), box, leader))
    return out


def _anchor(box: Box, dx: float, dy: float) -> tuple[tuple[float, float], str]:
    """The anchor point and viser anchor name of a box whose centre lies (dx, dy) off its point."""
    cx, cy = (box.x0 + box.x1) / 2, (box.y0 + box.y1) / 2
    x, horizontal = (box.x0, "left") if dx > 0 else (box.x1, "right") if dx < 0 else (cx, "center")
    y, vertical = (box.y0, "bottom") if dy > 0 else (box.y1, "top") if dy < 0 else (cy, "center")
    return (x, y), f"{vertical}-{horizontal}"


def _first_free(
    req: LabelRequest, w: float, h: float, gap: float, placed: list[Box], markers: Sequence[Box], bounds: Box | None
) -> tuple[tuple[float, float], int] | None:
    x, y = req.at
    for ring in range(RINGS + 1):
        reach = req.clear_m + gap + ring * (h + gap)
        dx, dy = reach + w / 2, reach + h / 2
        for ox, oy in ((dx, 0.0), (-dx, 0.0), (0.0, dy), (0.0, -dy), (dx, dy), (-dx, dy), (dx, -dy), (-dx, -dy)):
            box = Box.around(x + ox, y + oy, w / 2, h / 2)
            if bounds is not None and not box.inside(bounds):
                continue
            if any(box.overlaps(p, gap) for p in placed) or any(box.overlaps(m) for m in markers):
                continue
            return (x + ox, y + oy), ring
    return None

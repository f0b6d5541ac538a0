"""The report's charts as inline SVG, drawn here so the page needs no script library and no network.

Every text that reaches a chart (a file name, a policy, a category) is escaped; shapes carry only
numbers this module computed. Colours are the Okabe-Ito palette, told apart with colour blindness.
"""

from __future__ import annotations

import math
from html import escape

from l3mvn.run.eval.paired import Estimate, Pairing
from l3mvn_studio.report_data import LengthCurves, Run

COLOURS = ("#0072B2", "#E69F00", "#009E73", "#CC79A7", "#56B4E9", "#D55E00", "#000000", "#F0E442")
_FONT = 12


def run_colour(index: int) -> str:
    return COLOURS[index % len(COLOURS)]


def causes_chart(runs: list[Run]) -> str:
    """Failure causes as horizontal bars, one group per cause and one bar per run: the share of the
    run's episodes (runs may hold different numbers of episodes), labelled with the count."""
    causes = list(dict.fromkeys(c for run in runs for c in run.causes))
    if not causes:
        return '<p class="empty">No episode failed.</p>'
    label_w, bar_w, bar_h, gap = 190, 420, 14, 10
    group_h = bar_h * len(runs) + gap
    top = 8
    height = top + group_h * len(causes) + 44
    width = label_w + bar_w + 110
    peak = max(run.causes.get(c, 0) / len(run.rows) for run in runs for c in causes)
    scale = _nice_ceiling(peak)
    out = [_svg_open(width, height, "Failure causes: share of each run's episodes")]
    ticks = 4 if _mantissa(scale) == 2 else 5  # ticks on round shares
    for k in range(ticks + 1):
        x = label_w + bar_w * k / ticks
        out.append(_line(x, top, x, top + group_h * len(causes), "grid"))
        out.append(_text(x, height - 28, _percent(scale * k / ticks), "middle"))
    out.append(_text(label_w + bar_w / 2, height - 9, "share of the run's episodes", "middle", "axis-label"))
    for i, cause in enumerate(causes):
        y0 = top + i * group_h
        out.append(_text(label_w - 8, y0 + group_h / 2, cause.replace("_", " "), "end"))
        for j, run in enumerate(runs):
            count = run.causes.get(cause, 0)
            share = count / len(run.rows)
            y = y0 + j * bar_h
            w = bar_w * share / scale
            out.append(
                f'<rect x="{label_w}" y="{y:.1f}" width="{w:.1f}" height="{bar_h - 2}" fill="{run_colour(j)}">'
                f"<title>{escape(run.label)}: {count} of {len(run.rows)} episodes {escape(cause)}</title></rect>"
            )
            said = f"{count} ({share:.1%})" if count else "0"
            out.append(_text(label_w + w + 4, y + bar_h / 2, said, "start", "value"))
    out.append("</svg>")
    return "".join(out)


def length_chart(curves: LengthCurves, runs: list[Run], measure: int, name: str) -> str:
    """``name`` (SR: ``measure`` 0, SPL: 1) per episode-length bin, one line per run with its 95%
    interval as a vertical bar; the bins' ranges and episode counts are written under the axis."""
    if not curves.bins:
        return f'<p class="empty">No row carries a {escape(curves.axis)}: no chart.</p>'
    left, plot_w, top, plot_h = 56, 440, 14, 230
    width, height = left + plot_w + 20, top + plot_h + 70
    step = plot_w / len(curves.bins)
    shown = [pair[measure] for b in curves.bins for pair in b.per_run if pair[measure].n]
    # SR near 1 would be a flat line along the top of a 0..1 axis: the axis starts just below the lowest interval
    floor = max(0.0, math.floor(min((e.low for e in shown), default=0.0) * 5 - 0.5) / 5)
    out = [_svg_open(width, height, f"{name} against {curves.axis}")]
    ticks = round((1 - floor) / 0.2) if floor > 0 else 5
    for k in range(ticks + 1):
        value = floor + (1 - floor) * k / ticks
        y = top + plot_h * (1 - k / ticks)
        out.append(_line(left, y, left + plot_w, y, "grid"))
        out.append(_text(left - 6, y, f"{value:.1f}", "end"))
    out.append(_text(14, top + plot_h / 2, name, "middle", "axis-label", rotate=True))
    for i, b in enumerate(curves.bins):
        x = left + step * (i + 0.5)
        n = max((pair[measure].n for pair in b.per_run), default=0)
        out.append(_text(x, top + plot_h + 16, f"{b.low:g}–{b.high:g}", "middle"))
        out.append(_text(x, top + plot_h + 30, f"n={n}", "middle", "value"))
    out.append(_text(left + plot_w / 2, height - 8, curves.axis, "middle", "axis-label"))
    spread = min(step * 0.5, 14 * len(runs))
    for j, run in enumerate(runs):
        colour = run_colour(j)
        offset = (j - (len(runs) - 1) / 2) * (spread / max(len(runs), 1))
        points = []
        for i, b in enumerate(curves.bins):
            e = b.per_run[j][measure]
            if e.n == 0:
                continue
            x = left + step * (i + 0.5) + offset
            y, y_low, y_high = (top + plot_h * (1 - (v - floor) / (1 - floor)) for v in (e.mean, e.low, e.high))
            out.append(
                f'<line x1="{x:.1f}" y1="{y_low:.1f}" x2="{x:.1f}" y2="{y_high:.1f}" stroke="{colour}" '
                'stroke-width="2" opacity="0.6"/>'
            )
            out.append(
                f'<circle cx="{x:.1f}" cy="{y:.1f}" r="4" fill="{colour}"><title>{escape(run.label)}: {name} '
                f"{_interval(e)} over {e.n} episodes</title></circle>"
            )
            points.append(f"{x:.1f},{y:.1f}")
        if len(points) > 1:
            out.append(f'<polyline points="{" ".join(points)}" fill="none" stroke="{colour}" stroke-width="1.5"/>')
    out.append("</svg>")
    return "".join(out)


def difference_chart(pairing: Pairing) -> str:
    """The paired differences B - A per category as intervals around their mean, SR and SPL side by
    side, with the zero line: an interval that crosses it is no evidence of a difference."""
    names = list(pairing.rows)
    label_w, panel_w, gap, top, row_h = 130, 260, 60, 24, 22
    width, height = label_w + 2 * panel_w + gap + 20, top + row_h * len(names) + 34
    reach = max((max(abs(d.low), abs(d.high)) for diffs in pairing.rows.values() for d in diffs), default=0.0)
    scale = _nice_ceiling(max(reach, 0.05))
    out = [_svg_open(width, height, "Paired differences B - A per category, with 95% intervals")]
    for p, measure in enumerate(("SR", "SPL")):
        x0 = label_w + p * (panel_w + gap)
        mid = x0 + panel_w / 2
        out.append(_text(mid, 12, f"{measure}: B - A", "middle", "axis-label"))
        bottom = top + row_h * len(names)
        out.append(_line(x0, bottom + 2, x0 + panel_w, bottom + 2, "grid"))
        out.append(_line(mid, top - 4, mid, bottom + 2, "zero"))
        for k in (-1, 0, 1):
            out.append(_text(mid + k * panel_w / 2, height - 14, f"{k * scale:+.2f}" if k else "0", "middle"))
        for i, name in enumerate(names):
            d = pairing.rows[name][p]
            y = top + row_h * (i + 0.5)
            x_low, x_high = (mid + v / scale * panel_w / 2 for v in (d.low, d.high))
            x = mid + d.mean / scale * panel_w / 2
            colour = "#009E73" if d.low > 0 else "#D55E00" if d.high < 0 else "#666666"
            out.append(
                f'<line x1="{x_low:.1f}" y1="{y:.1f}" x2="{x_high:.1f}" y2="{y:.1f}" stroke="{colour}" '
                'stroke-width="3"/>'
            )
            out.append(
                f'<circle cx="{x:.1f}" cy="{y:.1f}" r="4" fill="{colour}"><title>{escape(name)}: {measure} '
                f"{d.mean:+.3f} [{d.low:+.3f}, {d.high:+.3f}] over {d.n} episodes</title></circle>"
            )
    for i, name in enumerate(names):
        out.append(_text(label_w - 8, top + row_h * (i + 0.5), f"{name} ({pairing.rows[name][0].n})", "end"))
    out.append("</svg>")
    return "".join(out)


def legend(runs: list[Run]) -> str:
    """The runs' colours, as HTML beside the charts."""
    items = "".join(
        f'<li><svg width="12" height="12" aria-hidden="true"><rect width="12" height="12" fill="{run_colour(j)}"/>'
        f"</svg>{escape(run.label)}</li>"
        for j, run in enumerate(runs)
    )
    return f'<ul class="legend">{items}</ul>'


def _percent(share: float) -> str:
    return f"{share:.0%}" if round(share * 100, 6).is_integer() else f"{share:.1%}"


def _interval(e: Estimate) -> str:
    return f"{e.mean:.3f} [{e.low:.3f}, {e.high:.3f}]"


def _mantissa(x: float) -> float:
    return round(x / 10 ** math.floor(math.log10(x)), 6)


def _nice_ceiling(x: float) -> float:
    """The smallest of 1, 2, 2.5, 5 times a power of ten that is at least ``x`` (an axis end)."""
    if x <= 0:
        return 1.0
    power = 10 ** math.floor(math.log10(x))
    return next(m * power for m in (1, 2, 2.5, 5, 10) if m * power >= x - 1e-12)


def _svg_open(width: float, height: float, title: str) -> str:
    return (
        f'<svg class="chart" viewBox="0 0 {width:.0f} {height:.0f}" width="{width:.0f}" height="{height:.0f}" '
        f'role="img" xmlns="http://www.w3.org/2000/svg"><title>{escape(title)}</title>'
    )


def _line(x1: float, y1: float, x2: float, y2: float, cls: str) -> str:
    return f'<line class="{cls}" x1="{x1:.1f}" y1="{y1:.1f}" x2="{x2:.1f}" y2="{y2:.1f}"/>'


def _text(x: float, y: float, text: str, anchor: str, cls: str = "tick", *, rotate: bool = False) -> str:
    turn = f' transform="rotate(-90 {x:.1f} {y:.1f})"' if rotate else ""
    return (
        f'<text class="{cls}" x="{x:.1f}" y="{y:.1f}" text-anchor="{anchor}" dominant-baseline="middle" '
        f'font-size="{_FONT}"{turn}>{escape(text)}</text>'
    )

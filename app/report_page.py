"""The report as one HTML page: its CSS and JS from the shipped ``static`` folder inlined, its charts
inline SVG and its videos data: URIs, so the file opens from a disk, offline, with no server.

Every string that comes from a result file goes through ``html.escape``; the page's Content Security
Policy lets only its own inlined script and style run and loads nothing from anywhere (media and
images only from data: URIs), so even a string that slipped through could neither run nor fetch.
"""

from __future__ import annotations

import base64
import hashlib
import math
from html import escape
from importlib import resources

from l3mvn.run.eval.paired import LEVEL, RESAMPLES, Estimate
from l3mvn_studio.report_charts import causes_chart, difference_chart, legend, length_chart, run_colour
from l3mvn_studio.report_data import SEED, FileComparison, ReportData, Run
from l3mvn_studio.report_videos import VideoChoice

# Settings under which SR and SPL mean something else: a difference in them is named as a trap.
TRAPS = ("sim.max_steps", "task.success_rule", "task.success_distance_m", "task.view_point_distance_m")
_NAMES = {"success": "SR", "spl": "SPL", "dtg": "DTG (m)"}


def render_page(data: ReportData, videos: VideoChoice, title: str) -> str:
    css, js = _asset("report.css"), _asset("report.js")
    policy = (
        "default-src 'none'; "
        f"style-src '{_digest(css)}'; script-src '{_digest(js)}'; media-src data:; img-src data:; "
        "base-uri 'none'; form-action 'none'"
    )
    sections = [
        _settings(data),
        _summary(data),
        _categories(data),
        _pairs(data),
        _causes(data),
        _lengths(data),
        _videos(data, videos),
    ]
    toc = "".join(f'<a href="#{anchor}">{name}</a>' for anchor, name, _ in sections if _)
    body = "".join(html for _, _, html in sections if html)
    return (
        "<!doctype html>\n"
        '<html lang="en"><head><meta charset="utf-8">'
        f'<meta http-equiv="Content-Security-Policy" content="{policy}">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f"<title>{escape(title)}</title><style>{css}</style></head>"
        f'<body><main>{_header(data, title)}<nav class="toc">{toc}</nav>{body}'
        f"<footer>Intervals: {LEVEL:.0%} percentile bootstrap over episodes ({RESAMPLES:,} resamples, seed {SEED}); "
        "paired differences resample the shared episodes. SR and SPL count every episode (an episode "
        "without a path counts 0); DTG averages the episodes that have one. Written by <code>l3mvn report</code>."
        f"</footer></main><script>{js}</script></body></html>\n"
    )


def _asset(name: str) -> str:
    return resources.files("l3mvn_studio.static").joinpath(name).read_text(encoding="utf-8")


def _digest(text: str) -> str:
    return "sha256-" + base64.b64encode(hashlib.sha256(text.encode("utf-8")).digest()).decode("ascii")


def _header(data: ReportData, title: str) -> str:
    rows = "".join(
        f'<tr><td class="name">{_swatch(j)}{escape(run.label)}</td>'
        f'<td>{len(run.rows)}</td><td class="name">{escape(run.rows[0]["rule"])}</td>'
        f'<td class="name">{escape(str(run.path))}</td></tr>'
        for j, run in enumerate(data.runs)
    )
    return (
        f"<header><h1>{escape(title)}</h1>"
        f"<p>{len(data.files)} result file{'s' if len(data.files) != 1 else ''}, {len(data.runs)} "
        f"run{'s' if len(data.runs) != 1 else ''} (one policy of one file each).</p>"
        '<table><thead><tr><th class="name">run</th><th>episodes</th><th class="name">success rule</th>'
        f'<th class="name">file</th></tr></thead><tbody>{rows}</tbody></table></header>'
    )


def _swatch(j: int) -> str:
    box = f'<rect width="10" height="10" fill="{run_colour(j)}"/>'
    return f'<svg width="10" height="10" aria-hidden="true">{box}</svg> '


def _settings(data: ReportData) -> tuple[str, str, str]:
    """Shown first: a config difference, not the policy, may be what moved the numbers."""
    parts = []
    for c in data.comparisons:
        parts.append(_comparison_settings(data, c))
    if data.notes:
        items = "".join(f"<li>{escape(n)}</li>" for n in data.notes)
        parts.append(f'<div class="warning"><h3>Lines left out or merged</h3><ul>{items}</ul></div>')
    if not parts:
        return "settings", "Settings", ""
    return (
        "settings",
        "Settings",
        f'<section id="settings"><h2>Settings and episodes compared</h2>{"".join(parts)}</section>',
    )


def _comparison_settings(data: ReportData, c: FileComparison) -> str:
    first = data.files[0].name
    vs = f"<code>{escape(c.path.name)}</code> against <code>{escape(first)}</code>"
    shared = _shared_line(c)
    if not c.settings:
        return f'<div class="ok">{vs}: the stored settings are the same (beside the policy). {shared}</div>'
    traps = [s for s in c.settings if s.split(":", 1)[0] in TRAPS]
    items = "".join(
        f'<li class="{"trap" if s in traps else "setting"}"><code>{escape(s)}</code></li>' for s in c.settings
    )
    warning = (
        f'<p class="trap">{escape(", ".join(t.split(":", 1)[0] for t in traps))} '
        f"{'differs' if len(traps) == 1 else 'differ'}: SR and SPL are not "
        "comparable across these settings; the differences below measure them as much as the policy.</p>"
        if traps
        else ""
    )
    return (
        f'<div class="warning"><h3>Settings differ: {vs}</h3>{warning}'
        f"<p>{len(c.settings)} setting{'s' if len(c.settings) != 1 else ''} beside the policy "
        f"(the first file's value → this file's):</p><ul>{items}</ul><p>{shared}</p></div>"
    )


def _shared_line(c: FileComparison) -> str:
    if c.pairing is None:
        return f"No paired differences: {escape(c.why_unpaired or '')}"
    p = c.pairing
    n = p.rows["all"][0].n
    if p.only_a or p.only_b:
        return (
            f"{n} episodes shared and paired; left out: {p.only_a} only in the first file, {p.only_b} only in this one."
        )
    return f"All {n} episodes are shared and paired."


def _cell(e: Estimate, digits: int = 3) -> str:
    if e.n == 0 or math.isnan(e.mean):
        return '<td data-value="">–</td>'
    return (
        f'<td data-value="{e.mean:.6f}">{e.mean:.{digits}f}'
        f'<span class="ci">[{e.low:.{digits}f}, {e.high:.{digits}f}]</span></td>'
    )


def _summary(data: ReportData) -> tuple[str, str, str]:
    rows = "".join(
        f'<tr><td class="name">{_swatch(j)}{escape(run.label)}</td><td>{len(run.rows)}</td>'
        + "".join(_cell(run.overall[m], 2 if m == "dtg" else 3) for m in _NAMES)
        + f"<td>{sum(run.causes.values())}</td></tr>"
        for j, run in enumerate(data.runs)
    )
    heads = "".join(f"<th>{name} <small>[{LEVEL:.0%}]</small></th>" for name in _NAMES.values())
    table = (
        '<div class="scroll"><table class="sortable" id="summary-table"><thead><tr><th class="name">run</th>'
        f"<th>episodes</th>{heads}<th>failures</th></tr></thead><tbody>{rows}</tbody></table></div>"
    )
    return "summary", "Summary", f'<section id="summary"><h2>Summary</h2>{table}</section>'


def _categories(data: ReportData) -> tuple[str, str, str]:
    goals = sorted({g for run in data.runs for g in run.per_category})
    tables = []
    for measure, name in _NAMES.items():
        heads = "".join(
            f"<th>{_swatch(j)}{escape(run.policy)}<br><small>{escape(run.path.name)}</small></th>"
            for j, run in enumerate(data.runs)
        )
        body = ""
        for goal in goals:
            cells = "".join(
                _cell(run.per_category[goal][measure], 2 if measure == "dtg" else 3)
                if goal in run.per_category
                else '<td data-value="">–</td>'
                for run in data.runs
            )
            n = max((len([r for r in run.rows if r["goal"] == goal]) for run in data.runs), default=0)
            body += f'<tr><td class="name">{escape(goal)}</td><td>{n}</td>{cells}</tr>'
        tables.append(
            f'<h3>{name} per goal category</h3><div class="scroll"><table class="sortable per-category">'
            f'<thead><tr><th class="name">category</th><th>episodes</th>{heads}</tr></thead><tbody>{body}</tbody>'
            "</table></div>"
        )
    return (
        "categories",
        "Per category",
        f'<section id="categories"><h2>Per goal category</h2>'
        f'<p class="note">Mean with its {LEVEL:.0%} interval; a category of a few episodes has a wide one.</p>'
        f"{''.join(tables)}</section>",
    )


def _pairs(data: ReportData) -> tuple[str, str, str]:
    if not data.comparisons:
        return "paired", "Paired differences", ""
    parts = []
    for c in data.comparisons:
        head = f"<h3><code>{escape(c.path.name)}</code> − <code>{escape(data.files[0].name)}</code></h3>"
        if c.pairing is None:
            parts.append(f'{head}<p class="note">{escape(c.why_unpaired or "")}</p>')
            continue
        p = c.pairing
        body = ""
        for name, diffs in p.rows.items():
            for d in diffs:
                trend = "up" if d.low > 0 else "down" if d.high < 0 else ""
                body += (
                    f'<tr><td class="name">{escape(name)}</td><td>{d.n}</td><td class="name">{_NAMES[d.measure]}</td>'
                    f"<td>{d.mean_a:.3f}</td><td>{d.mean_b:.3f}</td>"
                    f'<td data-value="{d.mean:.6f}" class="{trend}">{_signed(d.mean)}'
                    f'<span class="ci">[{_signed(d.low)}, {_signed(d.high)}]</span></td>'
                    f"<td>{d.wins} / {d.losses}</td></tr>"
                )
        parts.append(
            f"{head}<p>A: {escape(p.a)} ({escape(p.policies[0])}); B: {escape(p.b)} ({escape(p.policies[1])}). "
            f"{_shared_line(c)}</p>"
            '<div class="scroll"><table class="sortable paired"><thead><tr><th class="name">category</th>'
            '<th>episodes</th><th class="name">measure</th><th>A</th><th>B</th>'
            f"<th>B − A [{LEVEL:.0%}]</th><th>B better / worse</th></tr></thead><tbody>{body}</tbody></table></div>"
            f"<figure>{difference_chart(p)}<figcaption>Each episode is its own control: B − A per episode, "
            "its mean and interval. Green: B higher, orange: B lower, grey: the interval crosses 0 "
            "(no evidence either way).</figcaption></figure>"
        )
    return (
        "paired",
        "Paired differences",
        f'<section id="paired"><h2>Paired differences against {escape(data.files[0].name)}</h2>'
        f"{''.join(parts)}</section>",
    )


def _signed(v: float) -> str:
    """A difference with its sign; a bootstrap bound of -0.0001 reads +0.000, not -0.000."""
    text = f"{v:+.3f}"
    return "+0.000" if text == "-0.000" else text


def _causes(data: ReportData) -> tuple[str, str, str]:
    return (
        "causes",
        "Failure causes",
        f'<section id="causes"><h2>Failure causes</h2>{legend(data.runs)}'
        f"<figure>{causes_chart(data.runs)}<figcaption>Failed episodes by the cause the task scored, as a "
        "share of each run's episodes.</figcaption></figure></section>",
    )


def _lengths(data: ReportData) -> tuple[str, str, str]:
    curves = data.lengths
    left = [f"{run.label}: {n}" for run, n in zip(data.runs, curves.left_out) if n]
    note = (
        f'<p class="note">Rows without a {escape(curves.axis)} are left out ({escape("; ".join(left))}).</p>'
        if left
        else ""
    )
    charts = "".join(
        f"<figure>{length_chart(curves, data.runs, k, name)}<figcaption>{name} per {escape(curves.axis)} bin "
        f"(bins of about equal episode counts), with {LEVEL:.0%} intervals.</figcaption></figure>"
        for k, name in enumerate(("SR", "SPL"))
    )
    return (
        "lengths",
        "Episode length",
        f'<section id="lengths"><h2>SR and SPL against episode length</h2>{legend(data.runs)}{note}'
        f'<div class="charts">{charts}</div></section>',
    )


def _videos(data: ReportData, videos: VideoChoice) -> tuple[str, str, str]:
    if videos.folder is None:
        body = (
            '<p class="note">No videos were given: run <code>l3mvn report ... --videos DIR</code> with the folder '
            "<code>l3mvn eval --video DIR</code> or <code>l3mvn export --results ... --out DIR</code> wrote.</p>"
        )
        return "videos", "Videos", f'<section id="videos"><h2>Episode videos</h2>{body}</section>'
    mib = videos.size / (1 << 20)
    lines = [
        f"{len(videos.embedded)} of the {videos.found} videos found in <code>{escape(str(videos.folder))}</code> "
        f"embedded ({mib:.1f} MiB), failures first."
    ]
    if videos.left_out:
        lines.append(f"{videos.left_out} left out (--max-videos {videos.limit}).")
    if videos.missing:
        lines.append(f"{videos.missing} episodes have no video in the folder.")
    problems = "".join(f"<li>could not read {escape(p)}</li>" for p in videos.problems)
    figures = "".join(_figure(data.runs, v) for v in videos.embedded)
    filters = (
        '<div class="filters" data-for="video-grid">'
        '<button type="button" data-show="all" aria-pressed="true">all</button>'
        '<button type="button" data-show="fail" aria-pressed="false">failures</button>'
        '<button type="button" data-show="success" aria-pressed="false">successes</button></div>'
        if videos.embedded
        else ""
    )
    body = (
        f'<p class="note" id="video-count">{" ".join(lines)}</p>'
        + (f'<ul class="notes">{problems}</ul>' if problems else "")
        + f'{filters}<div class="videos" id="video-grid">{figures}</div>'
    )
    return "videos", "Videos", f'<section id="videos"><h2>Episode videos</h2>{body}</section>'


def _figure(runs: list[Run], video) -> str:
    row = video.row
    outcome = "success" if row["success"] == 1 else "fail"
    said = "success" if outcome == "success" else f"failed: {row['failure'].replace('_', ' ')}"
    spl = f"{row['spl']:.2f}" if row["spl"] is not None else "–"
    return (
        f'<figure data-outcome="{outcome}"><video controls preload="auto" src="{video.data_uri()}"></video>'
        f'<figcaption><span class="outcome {outcome}">{escape(said)}</span> · {_swatch(video.run)}'
        f"{escape(runs[video.run].label)}<br>{escape(row['scene'])} episode {row['episode_id']}, goal "
        f"{escape(row['goal'])}, {row['steps']} steps, SPL {spl}<br><small>{escape(video.name)}</small>"
        "</figcaption></figure>"
    )

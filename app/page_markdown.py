"""The side panel's text for a snapshot: status, metrics, the Frontiers table, the scorer note and the legend.

Pure functions of the snapshot's records, so each can be tested without a server; the view only
assigns the strings. Every value that comes from a file, a config or a client goes through
``page_text`` (``md``, ``code``, ``html``): the markup around it is ours, the value never becomes markup.
"""

from __future__ import annotations

import math

from l3mvn.agent.frontiers.types import POTENTIALS_RULE
from l3mvn.run.registry import keeps_map
from l3mvn.run.viz import AGENT_RGB, COLLISION_RGB, GOAL_RGB, SCORE_SCALE, category_color, colormap
from l3mvn_studio.frontier_ranking import TOP_LABELS, frontier_score
from l3mvn_studio.language_panel import query_of
from l3mvn_studio.map_image import (
    FREE,
    GLIMPSED,
    GT_FLOOR,
    GT_GOAL,
    GT_REGION,
    GUESSED,
    OBSTACLE,
    TRAJECTORY,
    UNEXPLORED,
    score_range,
)
from l3mvn_studio.page_text import code, html, md
from l3mvn_studio.state import MapView, Metrics, Snapshot

SPEED_KEPT = 0.9  # a Run within 10% of the asked speed is "as asked" (the timer's own jitter is a few %)
POLICY_NOTES = {
    "random-walk": "random-walk is the paper's baseline: uniformly random actions, STOP among them, "
    "so most episodes end within a few steps",
}


def status_markdown(snap: Snapshot) -> str:
    """The Status folder: what the worker is doing, the episode, its step, goal and outcome."""
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
    if snap.running and snap.achieved_steps_per_second is not None:
        lines.append(speed_words(snap.achieved_steps_per_second, snap.steps_per_second))
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


def speed_words(achieved: float, asked: float) -> str:
    """The Run's speed as achieved beside the asked one; slower than asked says where the time goes."""
    if achieved >= SPEED_KEPT * asked:
        return f"Speed: {achieved:.1f} steps/s, as asked"
    return (
        f"Speed: **{achieved:.1f} steps/s** of {asked:g} asked: a step (agent, simulator, drawing) takes "
        f"{1000 / achieved:.0f} ms here, longer than the {1000 / asked:.0f} ms wait asked for"
    )


def metrics_markdown(metrics: Metrics) -> str:
    line = f"**This server session**: {metrics.episodes} episodes done, SR {metrics.sr:.2f}, SPL {metrics.spl:.2f}"
    if metrics.policies:
        which = "policy" if len(metrics.policies) == 1 else "policies"
        line += f" ({which} {md(', '.join(metrics.policies))})"
    if metrics.steered:
        line += f"; {metrics.steered} steered by hand, not counted"
    return line


def no_map_markdown(policy: str, *, started: bool) -> str:
    """The Frontiers panel without a map: why, for the policy that is chosen."""
    if not keeps_map(policy):
        return f"_no frontiers: policy {md(repr(policy))} keeps no map (the map view shows the ground-truth plan)_"
    return (
        "_frontiers appear after the agent's first steps_"
        if started
        else f"_policy {md(repr(policy))} builds a map: frontiers appear after Reset and the first steps_"
    )


def frontier_markdown(view: MapView) -> str:
    """The Frontiers table, best score first, then each frontier's query for the target: the sentence
    the Language folder shows (a zero-shot scorer asks one per goal, a feed-forward head one for all)."""
    if not view.frontiers:
        return (
            "_no frontiers: the policy keeps no map_"
            if view.source != "agent map"
            else "_no frontiers on the map right now_"
        )
    # PONI's frontiers carry the target's object potential where a language policy's carry S_LLM.
    score = "potential" if view.fusion is not None and view.fusion.rule == POTENTIALS_RULE else "S_LLM"
    rows = [f"| | {score} | S_CU | fused | objects |", "|---|---|---|---|---|"]
    for f in sorted(view.frontiers, key=frontier_score, reverse=True):
        llm = "-" if f.s_llm is None else f"{f.s_llm:.2f}"
        fused = "-" if f.fused is None else f"{f.fused:.2f}"
        rows.append(
            f"| {'★' if f.chosen else ''}F{f.id} | {llm} | {f.s_cu:.2f} | {fused} | {md(', '.join(f.objects) or '-')} |"
        )
    queries = [f"- F{f.id} {code(q)}" for f in view.frontiers if (q := query_of(f, view.target))]
    note = f"\n\n_Map labels show the best {TOP_LABELS} and the chosen (★) frontier; all are listed here._"
    return "\n".join(rows) + note + ("\n\n**Queries**\n" + "\n".join(queries) if queries else "")


def unavailable_markdown(problems: dict[str, str]) -> str:
    """Which scorers cannot load their weights, and why (they are refused if picked)."""
    if not problems:
        return "_every scorer's weights are on disk_"
    lines = "\n".join(f"- {code(name)}: {md(why)}" for name, why in problems.items())
    return f"**Unavailable scorers** (refused if picked):\n{lines}"


def legend_html(categories, *, target: str = "", ground_truth: bool = False, frontiers=()) -> str:
    """Map colours, then the object categories the map shows, the target first and ringed as on
    the map; the ground-truth layer's colours when it is on; then the frontier score colour bar,
    fitted to the scores of ``frontiers`` (this step's) with its two ends' scores written out.
    The target is listed even before the map shows it: its colour is what the user looks out for."""
    fixed = [
        ("unexplored", UNEXPLORED),
        ("free", FREE),
        ("seen from afar", GLIMPSED),
        ("obstacle", OBSTACLE),
        ("obstacle too near for depth (guessed)", GUESSED),
        ("collision marks", COLLISION_RGB),
        ("trajectory", TRAJECTORY),
        ("agent", AGENT_RGB),
        ("long-term goal", GOAL_RGB),
    ]
    item = '<span style="display:inline-block;margin:2px 8px 2px 0;font-size:12px">{}</span>'
    cats = list(categories)
    if target and target not in (name for name, _ in cats):
        cats.append((target, category_color(target)))
    cats.sort(key=lambda c: c[0] != target)
    parts = [item.format(_swatch(rgb) + name) for name, rgb in fixed]
    parts += [
        item.format(
            _swatch(rgb, ring=name == target) + (f"<b>{html(name)} (target)</b>" if name == target else html(name))
        )
        for name, rgb in cats
    ]
    if ground_truth:
        parts += [
            item.format(_swatch(rgba[:3]) + f"<b>ground truth</b>: {name}")
            for name, rgba in (("floor plan", GT_FLOOR), ("success region", GT_REGION), ("goal instances", GT_GOAL))
        ]
    return f'<div style="line-height:1.2">{"".join(parts)}</div>{_score_bar(tuple(frontiers))}'


def _score_bar(frontiers: tuple) -> str:
    """The colour bar with the scale's ends: this step's lowest and highest frontier score."""
    stops = ", ".join(f"rgb{tuple(int(v) for v in rgb)}" for rgb in colormap([s / 4 for s in range(5)]))
    ends = score_range(frontiers)
    if ends is None:
        low, high, note = "low", "high", "no frontiers this step"
    elif ends[1] - ends[0] < 1e-9:
        low = high = f"{ends[0]:.2f}"
        note = f"all {len(frontiers)} frontiers score alike"
    else:
        low, high = f"{ends[0]:.2f}", f"{ends[1]:.2f}"
        note = f"{SCORE_SCALE} over this step's {len(frontiers)} frontiers"
    return (
        f'<div style="font-size:12px;margin-top:4px" class="l3mvn-score-scale">frontier score {low} '
        f'<span style="display:inline-block;width:120px;height:10px;vertical-align:middle;'
        f'background:linear-gradient(to right, {stops})"></span> {high} ({note}; fused where the policy fuses, '
        f"else cost-utility)</div>"
    )


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


def _swatch(rgb, *, ring: bool = False) -> str:
    border = "3px double #000" if ring else "1px solid #888"
    return (
        f'<span style="display:inline-block;width:11px;height:11px;border:{border};'
        f'background:rgb{tuple(int(v) for v in rgb)};margin-right:4px;vertical-align:middle"></span>'
    )

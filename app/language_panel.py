"""The dashboard's Language folder: why the prior (a language model, or PONI's potentials) preferred
a frontier, as HTML.

For the chosen frontier and the best few others: the scorer's p(goal | frontier) for every goal as
bars in the map's category colours (the target ringed and named, as in the legend), the sentence the
model read, a distance head's expected metres to each goal, and the fusion rule of the choice with the
numbers it compared (``l3mvn.agent.frontiers.Fusion.describe``). Pure functions of the snapshot's records:
the view only assigns the string.
"""

from __future__ import annotations

from l3mvn.agent.frontiers import Fusion
from l3mvn.agent.frontiers.types import POTENTIALS_RULE as POTENTIALS
from l3mvn.run.registry import language_policies, names_where, scores_frontiers
from l3mvn.run.viz import category_color
from l3mvn_studio.page_text import html
from l3mvn_studio.state import FrontierMarker, MapView

SHOWN_FRONTIERS = 4  # the chosen frontier and the best others by fused score
BAR_PX = 130  # the width of p = 1
_MUTED = "#666"


def uses_language(policy: str) -> bool:
    """Whether the folder has scores to show for ``policy``: a language policy's, or PONI's potentials."""
    return scores_frontiers(policy)


def language_html(view: MapView | None, policy: str, *, shown: int = SHOWN_FRONTIERS) -> str:
    """The whole folder for one snapshot: a note when there is nothing to show, else the rule line and
    one card per shown frontier (chosen first)."""
    if not uses_language(policy):
        names = ", ".join(language_policies() + names_where(lambda spec: spec.prior and spec.same_as is None))
        return _note(
            f"Policy <b>{html(policy)}</b> uses no prior: it chooses its goals without a language model "
            f"or a learned one. Pick a policy that scores frontiers ({html(names)}) and press Reset to see "
            "its scores here."
        )
    if view is None or view.fusion is None or not view.frontiers:
        return _note(
            f"Policy <b>{html(policy)}</b> scores frontiers with a prior: its scores appear "
            "here when the agent first chooses a frontier (after the look-around)."
        )
    score = _score_name(view.fusion)
    cards = "".join(
        frontier_card_html(f, view.target, score) for f in shown_frontiers(view.frontiers, view.fusion, shown)
    )
    return (
        f'<div style="font-size:12px;line-height:1.35">{fusion_html(view.fusion, view.frontiers, view.goal_kind)}'
        f"{_key(view)}{cards}</div>"
    )


def shown_frontiers(
    frontiers: tuple[FrontierMarker, ...], fusion: Fusion | None, shown: int = SHOWN_FRONTIERS
) -> list[FrontierMarker]:
    """The chosen frontier, then the rule's pick (when commitment kept another), then the best
    others by fused score; at most ``shown``, never fewer than those first two."""
    pick = None if fusion is None else fusion.ids[fusion.choice]
    first = [f for f in frontiers if f.chosen] + [f for f in frontiers if f.id == pick and not f.chosen]
    taken = {f.id for f in first}
    rest = sorted(
        (f for f in frontiers if f.id not in taken), key=lambda f: -(f.fused if f.fused is not None else f.s_cu)
    )
    return first + rest[: max(0, shown - len(first))]


def fusion_html(fusion: Fusion, frontiers: tuple[FrontierMarker, ...], goal_kind: str = "") -> str:
    """The rule line (rule name, its numbers, winner against runner-up), and why the agent's goal
    differs from the rule's pick where it does (commitment, or a goal that is not a frontier)."""
    pick = fusion.ids[fusion.choice]
    chosen = next((f.id for f in frontiers if f.chosen), None)
    lines = [
        f"<b>Scored by</b> <code>{html(fusion.scorer or 'an unnamed scorer')}</code>",
        f"<b>Fusion rule</b> (<code>{html(fusion.rule)}</code>, branch <i>{html(fusion.branch)}</i>): "
        f"{html(fusion.describe())}",
    ]
    if chosen is not None and chosen != pick:
        lines.append(
            f"The rule picked F{pick}; the agent keeps F{chosen}, the frontier it already pursues "
            f"(F{pick} is not better by the commitment margin)."
        )
    elif chosen is None:
        kind = html(goal_kind or "none")
        lines.append(f"The goal now is not a frontier ({kind}); these are the scores of the last frontier choice.")
    return "".join(f'<div style="margin-bottom:4px">{line}</div>' for line in lines)


def frontier_card_html(f: FrontierMarker, target: str, score: str = "S_LLM") -> str:
    """One frontier: its scores (the target's named ``score``), objects and query, then a bar per goal
    (target ringed and first)."""
    head = (
        f"<b>{'★ ' if f.chosen else ''}F{f.id}</b>{' (chosen)' if f.chosen else ''} &middot; "
        f"{score} {_num(f.s_llm)} &middot; S_CU {f.s_cu:.2f} &middot; fused {_num(f.fused)} &middot; "
        f"{f.distance_m:.1f} m away"
    )
    objects = html(", ".join(f.objects)) or "none"
    query = query_of(f, target)
    said = html(query) if query else ("read from the map" if score != "S_LLM" else "no query: no informative object")
    goals = sorted(f.llm_scores, key=lambda g: g != target)
    bars = "".join(bar_html(g, f.llm_scores[g], target=g == target, metres=f.expected_m.get(g)) for g in goals)
    border = "2px solid #333" if f.chosen else "1px solid #ccc"
    return (
        f'<div style="border:{border};border-radius:4px;padding:4px 6px;margin:6px 0">'
        f"<div>{head}</div>"
        f'<div style="color:{_MUTED}">objects: {objects}</div>'
        f'<div style="margin:2px 0"><i>{said}</i></div>'
        f"{bars or _note('no per-goal scores')}</div>"
    )


def bar_html(goal: str, p: float, *, target: bool, metres: float | None = None) -> str:
    """One goal's row: swatch-coloured bar of length ``p``, its value, and metres where a head gives them."""
    rgb = "rgb" + str(tuple(int(v) for v in category_color(goal)))
    width = max(0.0, min(1.0, float(p))) * BAR_PX
    name = f"<b>{html(goal)} (target)</b>" if target else html(goal)
    ring = "outline:2px solid #000;outline-offset:1px;" if target else ""
    tail = "" if metres is None else f' <span style="color:{_MUTED}">{metres:.1f} m</span>'
    return (
        f'<div style="display:flex;align-items:center;gap:6px;margin:1px 0">'
        f'<span style="width:118px;flex:none;overflow:hidden;white-space:nowrap">{name}</span>'
        f'<span style="width:{BAR_PX}px;flex:none;background:#eee;height:10px;display:inline-block">'
        f'<span data-goal="{html(goal)}" style="display:block;height:10px;width:{width:.1f}px;background:{rgb};'
        f'{ring}"></span></span>'
        f"<span>{p:.2f}{tail}</span></div>"
    )


def query_of(f: FrontierMarker, target: str) -> str:
    """The sentence the model read for ``target``: its own (zero-shot asks one per goal) or the one
    sentence a feed-forward head reads for all goals."""
    return f.queries.get(target) or next(iter(f.queries.values()), "")


def _score_name(fusion: Fusion) -> str:
    return "potential" if fusion.rule == POTENTIALS else "S_LLM"


def _key(view: MapView) -> str:
    metres = any(f.expected_m for f in view.frontiers)
    if view.fusion is not None and view.fusion.rule == POTENTIALS:
        return (
            f'<div style="color:{_MUTED};margin-bottom:2px">Bars: the object potential PONI predicts at the '
            "frontier for every goal (1 at the goal, 0 at its range or beyond), the target ringed; metres: "
            "the distance on to each goal it implies"
            + (
                f", plus what the {html(view.fusion.words)} words of the frontier's window add"
                if view.fusion.words
                else ""
            )
            + ".</div>"
        )
    text = (
        "Bars: the scorer's p(goal | frontier) for every goal, the target ringed; S_LLM is the target's "
        "score as the rule reads it"
    )
    if metres:
        text += "; metres: the head's expected distance from the frontier to each goal"
    return f'<div style="color:{_MUTED};margin-bottom:2px">{text}.</div>'


def _note(text: str) -> str:
    return f'<div style="font-size:12px"><i>{text}</i></div>'


def _num(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f}"

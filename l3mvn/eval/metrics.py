"""Success, SPL, DTG, per category, and a failure cause per episode (Anderson et al. 2018).

SPL = S * l / max(l, p), with ``l`` the shortest path length under the summary's success rule and
``p`` the path actually walked. DTG = geodesic distance to the success region at the end.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import asdict, dataclass, field

FAILURE_CAUSES = (
    "success",
    "false_stop",  # called stop outside the success region
    "never_saw_target",  # ran out of steps without the target ever in view
    # ... although the agent's map covered most of the reachable floor: the target hides behind
    # something (a toilet behind a sink in a narrow bathroom) and shows only from a few places
    "unseen_in_explored",
    "saw_target_not_reached",  # saw it, never entered the success region
    "timeout",  # was in the success region at some point but never stopped there
    "stuck",  # ran out of steps while colliding most of the time
    # The start has no path to the success region on the ground-truth floor: no agent can succeed.
    # Scored as a failure (SR and SPL 0, DTG left out) and counted apart in the summary, so a
    # dataset's infeasible episodes neither vanish from the denominator nor pass for agent failures.
    "no_path",
)


@dataclass
class EpisodeOutcome:
    """What the runner observed during one episode; turned into metrics by ``score_episode``."""

    stopped: bool
    in_success_region: bool
    steps: int
    path_length_m: float
    shortest_path_m: float
    final_distance_m: float
    saw_target: bool
    entered_region: bool
    recent_collision_rate: float
    agent_reported_stuck: bool = False
    # Fraction of the reachable floor the agent's map marks explored (None: the policy keeps no map).
    coverage: float | None = None


@dataclass
class EpisodeResult:
    """One line of results.jsonl."""

    key: str
    scene: str
    floor: int
    episode_id: int
    goal: str
    policy: str
    success: float
    spl: float
    dtg: float
    failure: str
    steps: int
    path_length_m: float
    shortest_path_m: float
    rule: str
    config_hash: str
    seconds: float = 0.0
    extra: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        d = asdict(self)
        for k in ("spl", "dtg", "path_length_m", "shortest_path_m", "seconds"):
            d[k] = _round(d[k])
        return d


def _round(v: float) -> float | None:
    return None if not math.isfinite(v) else round(float(v), 4)


STUCK_COLLISION_RATE = 0.5
# Coverage above which a target never seen counts as hidden rather than not yet explored.
EXPLORED_COVERAGE = 0.9


def score_episode(o: EpisodeOutcome) -> tuple[float, float, float, str]:
    """(success, spl, dtg, failure cause)."""
    success = 1.0 if (o.stopped and o.in_success_region) else 0.0
    spl = o.shortest_path_m / max(o.shortest_path_m, o.path_length_m, 1e-9) if success else 0.0
    if success:
        cause = "success"
    elif not math.isfinite(o.shortest_path_m):
        cause = "no_path"
    elif o.stopped:
        cause = "false_stop"
    elif o.agent_reported_stuck or o.recent_collision_rate >= STUCK_COLLISION_RATE:
        cause = "stuck"
    elif o.entered_region:
        cause = "timeout"
    elif o.saw_target:
        cause = "saw_target_not_reached"
    elif o.coverage is not None and o.coverage >= EXPLORED_COVERAGE:
        cause = "unseen_in_explored"
    else:
        cause = "never_saw_target"
    return success, spl, o.final_distance_m, cause


def summarize(results: list[dict], rule: str | None = None) -> dict:
    """Aggregate result lines (dicts as written to JSONL) into SR / SPL / DTG, per goal and causes."""
    rules = sorted({r["rule"] for r in results})
    if len(rules) > 1:
        raise ValueError(f"results mix success rules {rules}; summarise them separately")
    summary = _aggregate(results)
    summary["rule"] = rule or (rules[0] if rules else "semexp")
    summary["policies"] = sorted({r["policy"] for r in results})
    summary["per_category"] = {
        goal: _aggregate([r for r in results if r["goal"] == goal])
        for goal in sorted({r["goal"] for r in results})
    }
    summary["failure_causes"] = dict(Counter(r["failure"] for r in results).most_common())
    summary["no_path"] = summary["failure_causes"].get("no_path", 0)
    return summary


def _aggregate(rows: list[dict]) -> dict:
    n = len(rows)
    if n == 0:
        return {"episodes": 0, "success": 0.0, "spl": 0.0, "dtg": float("nan")}
    dtgs = [r["dtg"] for r in rows if r["dtg"] is not None and math.isfinite(r["dtg"])]
    return {
        "episodes": n,
        "success": round(sum(r["success"] for r in rows) / n, 4),
        "spl": round(sum(r["spl"] or 0.0 for r in rows) / n, 4),
        "dtg": round(sum(dtgs) / len(dtgs), 4) if dtgs else float("nan"),
    }


def format_summary(summary: dict) -> str:
    """A plain-text table: overall, per category, failure causes; names the rule."""
    lines = [
        f"policy: {', '.join(summary.get('policies', [])) or '-'}   success rule: {summary['rule']}",
        f"{'category':<14}{'episodes':>9}{'SR':>8}{'SPL':>8}{'DTG (m)':>9}",
    ]
    rows = [("all", summary)] + list(summary.get("per_category", {}).items())
    for name, s in rows:
        lines.append(f"{name:<14}{s['episodes']:>9}{s['success']:>8.3f}{s['spl']:>8.3f}{s['dtg']:>9.3f}")
    causes = summary.get("failure_causes", {})
    if causes:
        lines.append("failure causes: " + ", ".join(f"{k} {v}" for k, v in causes.items()))
    if summary.get("no_path"):
        lines.append(f"{summary['no_path']} episodes have no path from start to goal: scored as failures "
                     "(SR and SPL 0), left out of DTG")
    return "\n".join(lines)

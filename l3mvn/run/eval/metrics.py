"""Summaries of result lines: SR / SPL / DTG overall and per category, and failure causes.

Each line was scored by the task (``l3mvn.world.task.scoring``); this module only aggregates them.
"""

from __future__ import annotations

import math
from collections import Counter


def summarize(results: list[dict], rule: str | None = None) -> dict:
    """Aggregate result lines (dicts as written to JSONL) into SR / SPL / DTG, per goal and causes."""
    rules = sorted({r["rule"] for r in results})
    if len(rules) > 1:
        raise ValueError(f"results mix success rules {rules}; summarise them separately")
    summary = _aggregate(results)
    summary["rule"] = rule or (rules[0] if rules else "semexp")
    summary["policies"] = sorted({r["policy"] for r in results})
    summary["per_category"] = {
        goal: _aggregate([r for r in results if r["goal"] == goal]) for goal in sorted({r["goal"] for r in results})
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
        lines.append(
            f"{summary['no_path']} episodes have no path from start to goal: scored as failures "
            "(SR and SPL 0), left out of DTG"
        )
    return "\n".join(lines)

"""Why an episode failed, split into what the world allowed and what the agent did.

``score_episode`` gives every result line a cause from what the agent saw and did. Joined with the
scene audit's verdict on the episode (``l3mvn scenes audit --json``), a failure is charged to the
world when no reachable pose of the goal's success region lets the agent's own mapper confirm the
goal, and to the agent otherwise.
"""

from __future__ import annotations

from collections import Counter

from l3mvn.core.errors import L3MVNError

# World: the floor the success rule counts is missing, no path leads to it, or the goal never maps
# to enough cells from there. Audit reasons map onto these three.
WORLD_CAUSES = {
    "no_floor": "world: lost floor",
    "no_region": "world: lost floor",
    "unreachable": "world: object unreachable",
    "erased": "world: hidden",
    "buried": "world: hidden",
    "occluded": "world: hidden",
    "outside_only": "world: hidden",
    "hidden": "world: hidden",
}
# Agent: the goal could be confirmed, and this is how the agent missed it.
AGENT_CAUSES = {
    "never_saw_target": "agent: never looked",
    "unseen_in_explored": "agent: never looked",
    "stuck": "agent: stuck",
    "false_stop": "agent: false stop",
    "timeout": "agent: in region, no stop",
}
CLASSES = (
    *dict.fromkeys(WORLD_CAUSES.values()),
    *dict.fromkeys(AGENT_CAUSES.values()),
    "agent: glimpsed, not confirmed",
    "agent: confirmed, not reached",
    "agent: saw, not reached",
)  # result lines written before ``extra.confirmed`` existed


def classify_failure(row: dict, audit: dict | None) -> str | None:
    """The class of a failed result line (None for a success). ``audit``: the audit's record of the
    same episode (``EpisodeAudit`` as JSON), or None when the episode was not audited."""
    if row.get("success"):
        return None
    if audit is not None and not audit["confirmable"]:
        reason = (audit.get("reason") or "hidden").split(",")[0].strip()
        return WORLD_CAUSES.get(reason, "world: hidden")
    cause = row["failure"]
    if cause == "no_path":
        return "world: object unreachable"
    if cause == "saw_target_not_reached":
        confirmed = row.get("extra", {}).get("confirmed")
        if confirmed is None:
            return "agent: saw, not reached"
        return "agent: confirmed, not reached" if confirmed else "agent: glimpsed, not confirmed"
    return AGENT_CAUSES[cause]


def failure_table(rows: list[dict], audits: dict[str, dict]) -> Counter:
    """Counts per class over the failed lines of ``rows``; ``audits`` maps episode keys to records.
    A failure the audit has no record of is an error, not an agent failure: the audit was run on
    another dataset or without its episode files."""
    missing = [r["key"] for r in rows if not r.get("success") and r["key"] not in audits]
    if missing:
        raise L3MVNError(
            f"the audit has no record of {len(missing)} failed episode(s), e.g. {missing[0]}: "
            "audit the same dataset and split, with its episode files"
        )
    return Counter(classify_failure(r, audits[r["key"]]) for r in rows if not r.get("success"))

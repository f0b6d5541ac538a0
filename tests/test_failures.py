"""Failure classes: the audit charges the world, the result line charges the agent."""

from __future__ import annotations

import pytest

from l3mvn.core.errors import L3MVNError
from l3mvn.world.task.failures import CLASSES, classify_failure, failure_table


def _row(key: str, failure: str, confirmed: bool | None = None) -> dict:
    extra = {} if confirmed is None else {"coverage": 0.9, "confirmed": confirmed}
    return {"key": key, "success": float(failure == "success"), "failure": failure, "extra": extra}


def _audit(key: str, confirmable: bool, reason: str | None = None) -> dict:
    return {"key": key, "confirmable": confirmable, "reason": reason}


def test_a_goal_the_world_does_not_let_the_agent_confirm_is_charged_to_the_world():
    assert (
        classify_failure(_row("A/0/1", "never_saw_target"), _audit("A/0/1", False, "no_floor")) == "world: lost floor"
    )
    assert (
        classify_failure(_row("A/0/1", "stuck"), _audit("A/0/1", False, "unreachable")) == "world: object unreachable"
    )
    assert classify_failure(_row("A/0/1", "timeout"), _audit("A/0/1", False, "erased,hidden")) == "world: hidden"


def test_a_confirmable_goal_is_charged_to_the_agent_by_what_it_did():
    ok = _audit("A/0/1", True)
    assert classify_failure(_row("A/0/1", "unseen_in_explored"), ok) == "agent: never looked"
    assert (
        classify_failure(_row("A/0/1", "saw_target_not_reached", confirmed=False), ok)
        == "agent: glimpsed, not confirmed"
    )
    assert (
        classify_failure(_row("A/0/1", "saw_target_not_reached", confirmed=True), ok) == "agent: confirmed, not reached"
    )
    assert classify_failure(_row("A/0/1", "false_stop"), None) == "agent: false stop"
    assert classify_failure(_row("A/0/1", "success"), ok) is None


def test_the_table_counts_failures_only_and_every_class_is_listed():
    rows = [_row("A/0/1", "success"), _row("A/0/2", "stuck"), _row("A/0/3", "stuck")]
    audits = {"A/0/2": _audit("A/0/2", True), "A/0/3": _audit("A/0/3", False, "occluded")}
    table = failure_table(rows, audits)
    assert table == {"agent: stuck": 1, "world: hidden": 1}
    assert set(table) <= set(CLASSES)


def test_a_failure_the_audit_never_saw_is_an_error_not_the_agents():
    with pytest.raises(L3MVNError, match="no record of 1 failed episode"):
        failure_table([_row("A/0/1", "success"), _row("B/0/2", "stuck")], {})

"""app/compare.py: the first differing decision, unequal lengths, bad inputs, and two real runs."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from l3mvn.core.config import Config
from l3mvn.core.errors import L3MVNError
from l3mvn_studio.compare import (
    PICTURE_HEIGHT,
    Contender,
    EpisodeSource,
    StepDecision,
    check_contender,
    comparable_policies,
    compare_recordings,
    first_difference,
    parse_decision,
    run_comparison,
)

SOURCE = EpisodeSource(None, "val", houses=1, episodes_per_house=2, seed=0)
KEY = "procedural-0000/0/0"


def _small(max_steps: int) -> Config:
    cfg = Config().with_frame(120, 160)
    return cfg.replace(sim=dataclasses.replace(cfg.sim, max_steps=max_steps))


def _d(
    step: int,
    action: str = "move_forward",
    kind: str = "frontier",
    frontier: int | None = 1,
    cell: tuple[int, int] | None = (10, 20),
    reason: str = "why",
) -> StepDecision:
    return StepDecision(step, action, kind, frontier, cell, f"{action} [{kind}] F{frontier} {reason}")


def test_identical_decisions_have_no_difference_whatever_the_reasons_say():
    a = [_d(k) for k in range(5)]
    b = [_d(k, reason="other words") for k in range(5)]
    assert first_difference(a, b) is None


@pytest.mark.parametrize(
    "change",
    [
        {"action": "turn_left"},
        {"kind": "look"},
        {"frontier": 2},
        {"frontier": None},
        {"cell": (10, 21)},
        {"cell": None},
    ],
)
def test_the_first_step_that_differs_in_any_decision_field(change):
    a = [_d(k) for k in range(8)]
    b = [_d(k) for k in range(3)] + [_d(k, **change) for k in range(3, 8)]
    assert first_difference(a, b) == 3
    assert first_difference(b, a) == 3


def test_unequal_lengths_differ_where_only_one_goes_on():
    a = [_d(k) for k in range(4)]
    b = [_d(k) for k in range(7)]
    assert first_difference(a, b) == 4
    assert first_difference(b, a) == 4
    assert first_difference([], []) is None


def test_decisions_parse_from_the_recorders_line_and_goal_marker():
    d = parse_decision(7, "move_forward [frontier] F3 nearest frontier (1.6 m)", np.array([[20.5, 10.5]]))
    assert (d.step, d.action, d.goal_kind, d.frontier, d.goal_cell) == (7, "move_forward", "frontier", 3, (10, 20))
    d = parse_decision(9, "stop [target] toilet 0.52 m away: stop", None)
    assert (d.action, d.goal_kind, d.frontier, d.goal_cell) == ("stop", "target", None, None)
    assert parse_decision(0, "reset: the episode starts", None).action == "reset"
    assert parse_decision(4, "(no decision logged)", None).action == ""


def test_bad_inputs_are_one_line_errors_naming_the_choices():
    with pytest.raises(L3MVNError, match="unknown policy 'nope'; choose one of .*cost-utility") as e:
        check_contender("nope")
    assert "\n" not in str(e.value)
    with pytest.raises(
        L3MVNError, match="'teleop' cannot be compared: it is driven by hand and cannot run by itself; choose one of "
    ):
        check_contender("teleop")
    with pytest.raises(L3MVNError, match="keeps no map"):
        check_contender("oracle")
    assert "teleop" not in comparable_policies() and "cost-utility" in comparable_policies()
    with pytest.raises(
        L3MVNError,
        match=r"episode 'procedural-0000/0/9' is not in this episode set; valid "
        r"episodes: procedural-0000/0/0, procedural-0000/0/1$",
    ):
        run_comparison(
            SOURCE,
            "procedural-0000/0/9",
            Contender("frontier", _small(10)),
            Contender("cost-utility", _small(10)),
            "unused",
        )


def test_two_policies_on_one_episode(tmp_path):
    c = run_comparison(SOURCE, KEY, Contender("frontier", _small(60)), Contender("cost-utility", _small(60)), tmp_path)
    assert c.a.label == "A: frontier" and c.b.label == "B: cost-utility"
    assert len(c.a.pictures) == len(c.a.decisions) == c.a.last_step + 1
    k = c.first_difference
    assert k is not None and 0 < k < c.steps, "nearest and cost-utility frontiers part early in this house"
    assert [d.key for d in c.a.decisions[:k]] == [d.key for d in c.b.decisions[:k]]
    assert c.a.decisions[k].key != c.b.decisions[k].key
    assert c.difference_line.startswith(f"decisions first differ at step {k}: A <")
    # the composed picture is A's step beside B's step, read back from the recordings alone
    again = compare_recordings(c.a.recording, c.b.recording, KEY)
    assert np.array_equal(again.picture(k), c.picture(k))
    assert not np.array_equal(c.picture(k), c.picture(0))
    assert c.picture(k).shape[1] > c.a.picture(k).shape[1] + c.b.picture(k).shape[1]
    # one crop for both maps: before their decisions part, both sides draw the same map pixel for pixel
    assert c.a.picture(0).shape == c.b.picture(0).shape
    assert np.array_equal(c.a.picture(0)[:PICTURE_HEIGHT], c.b.picture(0)[:PICTURE_HEIGHT])


def test_two_configs_of_one_policy_and_unequal_lengths(tmp_path):
    """Same policy, seed and episode; only max_steps differs: the runs agree step for step until the
    shorter one ends, which holds its last picture marked as ended."""
    c = run_comparison(SOURCE, KEY, Contender("frontier", _small(20)), Contender("frontier", _small(32)), tmp_path)
    assert c.a.recording != c.b.recording  # two configs of one policy do not share a recording
    assert c.a.last_step == 20 and c.b.last_step == 32 and c.steps == 33
    assert c.first_difference == 21
    assert c.difference_line.startswith("decisions first differ at step 21: A <ended at step 20>; B <")
    assert c.a.decision_line(25).startswith("A: frontier: ended at step 20 (FAILURE")
    assert np.array_equal(c.a.picture(25), c.a.picture(20))
    late, last = c.picture(25), c.picture(20)
    width_a = c.a.picture(20).shape[1]
    assert not np.array_equal(late[:, :width_a], last[:, :width_a])  # the "ended" banner

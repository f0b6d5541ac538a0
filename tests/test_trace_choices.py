"""bench/trace_choices.py: each choice names the frontier taken, the rule's pick where commitment kept
another, and the oracle's, with every frontier's numbers and its true metres on."""

import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from l3mvn.agent.decision import Decision
from l3mvn.agent.frontiers import Frontier, Fusion
from l3mvn.agent.frontiers.types import POTENTIALS_RULE
from l3mvn.core.types import Action

SCRIPT = Path(__file__).resolve().parents[1] / "bench" / "trace_choices.py"


@pytest.fixture(scope="module")
def trace(bench_script):
    return bench_script("trace_choices")


# PONI's record of a choice among the three frontiers of ``_frontiers``.
POTENTIALS = Fusion(
    rule=POTENTIALS_RULE,
    branch="least total",
    choice=0,
    ids=(10, 11, 12),
    s_llm=(0.5, 0.4, 0.3),
    explore=(0.1, 0.1, 0.1),
    compared=(5.4, 6.3, 9.0),
)


def _decision(took, fusion=None):
    return Decision(action=Action.parse("move_forward"), frontiers=_frontiers(fusion), chosen_frontier=took)


def _frontiers(fusion=None):
    cells = np.zeros((1, 2), np.int64)
    out = [Frontier(10 + k, cells, (100, 100 + 20 * k), 5 + k, 1.0 + k, 1.0, 1.0 + k, 0.5 - 0.1 * k) for k in range(3)]
    return [replace(f, fusion=fusion) for f in out]


def test_a_choice_kept_by_commitment_names_the_rules_pick_and_the_oracles(trace):
    decision = _decision(1, replace(POTENTIALS, expected_m=(4.6, 5.1, 7.0)))
    lines = trace.choice_lines(46, decision, np.array([9.0, 0.7, np.inf]))
    assert lines[0] == "step 46: took F11 (kept by commitment; the rule picked F10); oracle F11"
    assert lines[2].startswith("  *o F11") and "compared   6.30" in lines[2] and "expected   5.1 m" in lines[2]
    assert "true on   inf m" in lines[3] and len(lines) == 4


def test_a_policy_without_a_fusion_record_shows_s_cu_and_no_expected_metres(trace):
    decision = _decision(0)
    lines = trace.choice_lines(13, decision, np.array([3.0, 1.0, 2.0]))
    assert lines[0] == "step 13: took F10; oracle F11"  # costs 1, 2, 3: totals 4, 3, 5
    assert "compared   0.50" in lines[1] and "expected" not in "".join(lines)


def test_the_goals_frontier_is_ranked_least_first_for_metres_and_highest_first_for_scores(trace):
    metres = _decision(0, POTENTIALS)
    assert trace.goal_frontier(metres, np.array([9.0, 0.7, 1.2])) == (1, 2)  # the better ranked of two
    at_first = np.array([0.5, 9.0, 9.0])
    for rule, rank in (("expected", 1), (POTENTIALS_RULE, 1), ("paper", 3)):
        decision = _decision(0, replace(POTENTIALS, rule=rule))
        assert trace.goal_frontier(decision, at_first) == (0, rank)
    scores = _decision(0)
    assert trace.goal_frontier(scores, np.array([3.0, 2.0, 1.2])) == (2, 3)  # S_CU 0.5, 0.4, 0.3
    assert trace.goal_frontier(scores, np.array([3.0, 2.0, 1.6])) is None


def test_the_episode_line_counts_the_choices_that_listed_and_took_the_goals_frontier(trace):
    fusion = replace(POTENTIALS, expected_m=(4.6, 4.1, 7.0))
    tally = trace.GoalFrontierTally()
    for took, truth in ((0, [3.0, 0.7, 9.0]), (1, [3.0, 0.7, 9.0]), (0, [3.0, 2.0, 9.0]), (0, [3.0, 0.9, 1.1])):
        tally.add(_decision(took, fusion), np.array(truth))
    assert tally.line() == (
        "goal's frontier (<= 1.5 m from the goal) listed at 3 of 4 choices, taken at 1; its median rank 2 of 3 "
        "by the rule's totals; "
        "expected metres on, against the frontier taken: median -0.5 m"
    )
    scores = trace.GoalFrontierTally()
    scores.add(_decision(0), np.array([3.0, 2.0, 1.2]))
    assert scores.line().endswith("taken at 0; its median rank 3 of 3 by S_CU")  # no record: no expected metres
    empty = trace.GoalFrontierTally()
    empty.add(_decision(0), np.ones(3) * 5)
    assert empty.line() == "goal's frontier (<= 1.5 m from the goal) listed at 0 of 1 choices"


def test_bad_arguments_are_one_line_errors_before_any_walk(tmp_path):
    def run(*extra):
        return subprocess.run(
            [sys.executable, str(SCRIPT), "--dataset", str(tmp_path), "--episode", "A/0/1", *extra],
            capture_output=True,
            text=True,
        )

    for extra, words in (
        (("--policy", "poni", "--frame", "48"), "frame size must look like 120x160"),
        (("--policy", "poni", "--frame", "0x5"), "frame size must be positive"),
        (("--policy", "ponix"), "unknown policy 'ponix'"),
        (("--policy", "poni", "--set", "agent.teleport=1"), "unknown setting 'teleport'"),
    ):
        done = run(*extra)
        assert done.returncode != 0 and done.stderr.startswith("error:") and words in done.stderr, done.stderr
        assert len(done.stderr.strip().splitlines()) == 1

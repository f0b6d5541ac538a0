"""The fusion record a language policy attaches to its choice: the numbers it shows are the numbers
the rule used (each test recomputes the choice from the record alone), and its line says them."""

import json

import numpy as np
import pytest
from conftest import first_frontier_choice

from l3mvn.agent.frontiers import Frontier, Fusion
from l3mvn.agent.language import GOALS
from l3mvn.agent.policies.global_policies import unit_scores
from l3mvn.agent.policies.language_policy import LanguageFrontierPolicy

RNG = np.random.default_rng(0)


def _frontier(
    i: int, objects: tuple[str, ...], s_cu: float, utility: float = 10.0, cost: float | None = None
) -> Frontier:
    return Frontier(
        id=i,
        cells=np.array([[i, i]]),
        center=(i, i),
        size=10,
        distance_m=1.0 + i,
        utility=utility,
        cost=1.0 + i if cost is None else cost,
        s_cu=s_cu,
        objects=objects,
    )


@pytest.fixture(scope="module")
def rooms():
    return LanguageFrontierPolicy("l3mvn-ff", "feedforward", head="rooms")


def _paper_from_record(fusion: Fusion) -> tuple[str, int, np.ndarray]:
    """The paper's rule recomputed from the record only: (branch, choice, fused)."""
    lo, hi = fusion.bound
    s, e = np.array(fusion.s_llm), np.array(fusion.explore)
    if s.max() > hi:
        return "language", int(np.argmax(s)), s
    if s.max() < lo:
        return "exploration", int(np.argmax(e)), lo + e * (hi - lo)
    fused = np.maximum(s, lo + e * (hi - lo))
    return "fused", int(np.argmax(fused)), fused


@pytest.mark.parametrize(
    ("objects", "s_cu", "goal", "branch"),
    [
        ((("chair",), ("sink", "bathtub", "shower")), (1.0, 0.0), "toilet", "language"),
        ((("sink", "bathtub", "shower"), ("toilet", "sink")), (0.2, 0.9), "tv", "exploration"),
        (((), ("chair",), ()), (0.1, 0.8, 0.5), "bed", "fused"),
    ],
)
def test_the_paper_rule_recomputed_from_its_record_gives_the_policys_choice_and_scores(
    rooms, objects, s_cu, goal, branch
):
    frontiers = [_frontier(i, o, c) for i, (o, c) in enumerate(zip(objects, s_cu))]
    sel = rooms.select(frontiers, None, goal, RNG)
    fusion = sel.fusion
    assert (fusion.rule, fusion.bound, fusion.exploration) == ("paper", (0.15, 0.30), "cost-utility")
    assert fusion.s_llm == tuple(ls.s_llm for ls in sel.language)  # the S_LLM the cards show
    assert fusion.explore == s_cu and fusion.ids == tuple(range(len(frontiers)))
    again, choice, fused = _paper_from_record(fusion)
    assert (again, choice) == (fusion.branch, fusion.choice) == (branch, sel.frontier)
    assert np.array_equal(fused, fusion.compared)
    assert np.array_equal(sel.scores, unit_scores(fused))  # what the agent's commitment reads: [0, 1]
    assert [ls.fused for ls in sel.language] == list(fusion.compared)
    assert all(ls.expected_m == {} for ls in sel.language)  # the room head predicts no distances


def test_the_expected_rule_shows_cost_bonus_and_the_heads_metres_of_every_frontier():
    policy = LanguageFrontierPolicy("l3mvn-ff", "feedforward", selection="expected", head="frontiers")
    frontiers = [
        _frontier(0, ("chair", "couch"), 1.0, utility=40.0, cost=2.0),
        _frontier(1, ("sink", "towel"), 0.5, utility=10.0, cost=3.5),
        _frontier(2, (), 0.0, utility=5.0, cost=6.0),
    ]
    sel = policy.select(frontiers, None, "toilet", RNG)
    fusion = sel.fusion
    assert (fusion.rule, fusion.branch) == ("expected", "least total")
    assert fusion.cost_m == (2.0, 3.5, 6.0)
    assert fusion.bonus_m == tuple(f.utility / policy.cu_lambda for f in frontiers)
    metres = policy.scorer.expected_distance([f.objects for f in frontiers])
    k = policy.scorer.goals.index("toilet")
    assert fusion.expected_m == tuple(metres[:, k])
    total = np.array(fusion.cost_m) - np.array(fusion.bonus_m) + np.array(fusion.expected_m)
    assert np.array_equal(total, fusion.compared) and int(np.argmin(total)) == fusion.choice == sel.frontier
    for ls, row in zip(sel.language, metres):  # every goal's metres, on each frontier's record
        assert set(ls.expected_m) == set(GOALS)
        assert ls.expected_m == pytest.approx(dict(zip(policy.scorer.goals, row)), abs=1e-3)
    line = fusion.describe()
    i = fusion.choice
    terms = f"{fusion.cost_m[i]:.1f} - {fusion.bonus_m[i]:.1f} + {fusion.expected_m[i]:.1f} = {total[i]:.1f} m"
    assert f"F{i} {terms} beats" in line


def test_the_official_rule_records_the_no_object_stand_in_it_compared():
    policy = LanguageFrontierPolicy("l3mvn-ff", "feedforward", selection="official_code", head="rooms")
    frontiers = [_frontier(0, (), 0.3, utility=5.0), _frontier(1, (), 0.9, utility=20.0)]
    sel = policy.select(frontiers, None, "bed", RNG)
    fusion = sel.fusion
    assert (fusion.branch, fusion.threshold, fusion.choice, sel.frontier) == ("utility", 0.2, 1, 1)
    assert fusion.compared == pytest.approx((0.1 + 0.1 * 5 / 20, 0.2))  # 0.1 + 0.1 U / max U
    assert max(fusion.compared) <= fusion.threshold and int(np.argmax(fusion.explore)) == fusion.choice
    assert fusion.describe() == "official code: max S_LLM 0.20 <= 0.2, so the best S_CU: F1 0.90 beats F0 0.30"


def test_the_fusion_line_names_the_bound_the_branch_and_the_winner_against_the_runner_up():
    fusion = Fusion(
        rule="paper",
        branch="fused",
        choice=2,
        ids=(0, 1, 2),
        s_llm=(0.16, 0.10, 0.22),
        explore=(0.6, 0.2, 0.4),
        compared=(0.24, 0.18, 0.27),
        bound=(0.15, 0.30),
    )
    assert fusion.describe() == (
        "bound B = [0.15, 0.30]; max S_LLM 0.22 is inside B, so fused = "
        "max(S_LLM, 0.15 + 0.15 x S_CU): F2 0.27 beats F0 0.24"
    )
    alone = Fusion(
        rule="paper",
        branch="language",
        choice=0,
        ids=(4,),
        s_llm=(0.5,),
        explore=(1.0,),
        compared=(0.5,),
        bound=(0.15, 0.30),
        exploration="nearest",
    )
    assert alone.describe().endswith("language alone decides: F4 0.50 (the only frontier)")


def test_the_agents_frontiers_carry_the_record_of_the_choice_that_scored_them(tiny_scene):
    shown = first_frontier_choice(tiny_scene, "l3mvn-zs")
    fusion = shown.frontiers[0].fusion
    assert all(f.fusion is fusion for f in shown.frontiers)  # one record per choice
    assert fusion.ids == tuple(f.id for f in shown.frontiers)
    assert fusion.s_llm == tuple(f.s_llm for f in shown.frontiers)
    assert [f.fused for f in shown.frontiers] == list(fusion.compared)
    assert fusion.choice == shown.chosen_frontier  # no earlier frontier to keep: the rule's pick stands
    as_json = json.loads(json.dumps(shown.frontiers[0].to_dict()))
    assert as_json["fusion"]["line"] == fusion.describe() and as_json["fusion"]["bound"] == [0.15, 0.30]
    assert as_json["expected_m"] == {}

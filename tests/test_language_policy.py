"""The paper's fusion of S_LLM with S_CU, with the shipped feed-forward scorer (offline MiniLM)."""

import numpy as np
import pytest
from conftest import first_frontier_choice

from l3mvn.agent.frontiers import Frontier
from l3mvn.agent.policies.language_policy import LanguageFrontierPolicy
from l3mvn.core.config import PolicyConfig
from l3mvn.core.errors import L3MVNError
from l3mvn.run.registry import policy_names


def _frontier(i: int, objects: tuple[str, ...], s_cu: float, utility: float = 10.0) -> Frontier:
    return Frontier(
        id=i,
        cells=np.array([[i, i]]),
        center=(i, i),
        size=10,
        distance_m=1.0 + i,
        utility=utility,
        cost=1.0 + i,
        s_cu=s_cu,
        objects=objects,
    )


@pytest.fixture(scope="module")
def policy():
    return LanguageFrontierPolicy("l3mvn-ff", "feedforward", head="rooms")  # the paper's recipe


def test_confident_language_wins_over_exploration(policy):
    frontiers = [_frontier(0, ("chair",), 1.0), _frontier(1, ("sink", "bathtub", "shower"), 0.0)]
    sel = policy.select(frontiers, None, "toilet", np.random.default_rng(0))
    assert sel.frontier == 1 and sel.language[1].s_llm > 0.30
    assert "language" in sel.reason
    assert sel.language[1].queries == {"all goals": "This frontier contains shower, bathtub, and sink."}
    assert sum(sel.language[1].llm_scores.values()) == pytest.approx(1.0, abs=1e-3)
    assert all(f.s_llm is None and not f.queries for f in frontiers)  # the policy scores, it does not write


def test_language_below_the_bound_defers_to_cost_utility(policy):
    frontiers = [_frontier(0, ("sink", "bathtub", "shower"), 0.2), _frontier(1, ("toilet", "sink"), 0.9)]
    sel = policy.select(frontiers, None, "tv", np.random.default_rng(0))
    assert max(ls.s_llm for ls in sel.language) < 0.15
    assert sel.frontier == 1 and "exploration" in sel.reason


def test_in_between_fuses_with_cost_utility_rescaled_into_the_bound(policy):
    # No informative object: uniform 1/6 = 0.167, inside B = [0.15, 0.30].
    frontiers = [_frontier(0, (), 0.1), _frontier(1, ("chair",), 0.8), _frontier(2, (), 0.5)]
    sel = policy.select(frontiers, None, "bed", np.random.default_rng(0))
    assert sel.frontier == 1 and "fused" in sel.reason
    assert sel.language[1].fused == pytest.approx(0.15 + 0.8 * 0.15)
    assert sel.language[0].fused == pytest.approx(1 / 6, abs=1e-6)


def test_commitment_reads_the_paper_rules_scores_on_the_scale_of_every_other_policy(policy):
    """The paper rule ranks by fused scores inside the bound B (0.15-0.30 below sup B): the agent's
    commitment margin (0.15) must read them scaled into [0, 1] over the list, as it reads S_CU, or it
    keeps the frontier pursued so far against any other that exploration alone prefers."""
    from l3mvn.agent.modular.exploration import ExplorationGoals
    from l3mvn.agent.planning import LocalPlanner
    from l3mvn.core.config import Config

    frontiers = [_frontier(0, ("sink", "bathtub", "shower"), 0.2), _frontier(1, ("toilet", "sink"), 0.9)]
    sel = policy.select(frontiers, None, "tv", np.random.default_rng(0))
    assert "exploration" in sel.reason and sel.language[0].fused == pytest.approx(0.15 + 0.2 * 0.15)
    assert sel.scores == pytest.approx([0.0, 1.0])
    config = Config()
    goals = ExplorationGoals(policy, config, LocalPlanner.for_sim(config.planner, config.map.resolution_m, config.sim))
    goals.frontiers, goals.cell, goals.frontier = frontiers, frontiers[0].center, 0
    assert goals.commit(sel) is sel  # S_CU 0.9 against 0.2: cost-utility would leave frontier 0 too


def test_official_code_feedforward_falls_back_to_best_utility_below_0_2():
    policy = LanguageFrontierPolicy("l3mvn-ff", "feedforward", selection="official_code", head="rooms")
    frontiers = [_frontier(0, (), 0.3, utility=5.0), _frontier(1, (), 0.9, utility=20.0)]
    sel = policy.select(frontiers, None, "bed", np.random.default_rng(0))
    assert sel.frontier == 1 and "utility" in sel.reason


def test_table_ii_ablations_are_named_policies():
    assert {"near+llm", "exp", "exp+llm", "l3mvn-zs", "l3mvn-ff"} <= set(policy_names())


def test_unknown_selection_is_a_clear_error():
    with pytest.raises(L3MVNError, match="unknown selection 'best'.*paper, official_code"):
        PolicyConfig(selection="best")


def test_the_agent_shows_each_frontier_with_the_scores_the_language_policy_gave_it(tiny_scene):
    shown = first_frontier_choice(tiny_scene, "l3mvn-zs")
    assert all(f.s_llm is not None and f.fused is not None and f.llm_scores for f in shown.frontiers)
    chosen = shown.frontiers[shown.chosen_frontier]
    assert chosen.reason and shown.reason.endswith(chosen.reason)

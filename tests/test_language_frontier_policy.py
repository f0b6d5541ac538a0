"""The frontier-trained head at run time: its queries, its distances, and the ``expected`` selection."""

import os

os.environ.setdefault("HF_HUB_OFFLINE", "1")

import numpy as np
import pytest
import torch

from l3mvn.agent.frontiers import Frontier
from l3mvn.agent.language import GOALS, make_scorer
from l3mvn.agent.language.head import GoalHead, save_head
from l3mvn.agent.policies.language_policy import LanguageFrontierPolicy
from l3mvn.core.errors import L3MVNError


@pytest.fixture(scope="module")
def head_file(tmp_path_factory):
    """A frontier head with fixed random weights: what it predicts does not matter here, only that
    the policy and scorer use its numbers as metres."""
    torch.manual_seed(0)
    head = GoalHead(384, len(GOALS)).eval()
    path = tmp_path_factory.mktemp("head") / "frontiers.pt"
    save_head(head, {"kind": "frontiers", "object_filter": "all", "encoder": "minilm", "goals": list(GOALS)}, path)
    return path


def _frontier(i: int, objects: tuple[str, ...], cost: float, s_cu: float, utility: float = 5.0) -> Frontier:
    return Frontier(
        id=i,
        cells=np.array([[10, 10 + i]]),
        center=(10, 10 + i),
        size=int(utility),
        distance_m=cost,
        utility=utility,
        cost=cost,
        s_cu=s_cu,
        objects=objects,
    )


def test_frontier_head_queries_name_exactly_each_frontier_objects(head_file):
    scorer = make_scorer("feedforward", head=head_file)
    assert scorer.predicts_distance and scorer.object_filter == "all"
    # A goal category alone still gets a query (the room-list filter dropped it), and nothing is added.
    assert scorer.queries(("chair",)) == {"all goals": "This frontier contains chair."}
    assert scorer.queries(("vase", "couch", "book")) == {"all goals": "This frontier contains book, couch, and vase."}
    metres = scorer.expected_distance([("chair",), (), ("vase", "couch", "book")])
    assert metres.shape == (3, len(GOALS)) and np.isfinite(metres).all()


def test_expected_selection_takes_least_travel_plus_expected_metres(head_file):
    policy = LanguageFrontierPolicy("l3mvn-ff", "feedforward", selection="expected", head=str(head_file))
    frontiers = [
        _frontier(0, ("sink",), 1.0, 1.0),
        _frontier(1, ("couch", "vase"), 2.0, 0.5, utility=60.0),
        _frontier(2, ("bed",), 3.0, 0.0),
    ]
    sel = policy.select(frontiers, None, "toilet", np.random.default_rng(0))
    metres = policy.scorer.expected_distance([f.objects for f in frontiers])[:, GOALS.index("toilet")]
    total = np.array([1.0, 2.0, 3.0]) - np.array([5.0, 60.0, 5.0]) / policy.cu_lambda + metres  # C - U / lambda + prior
    assert sel.frontier == int(np.argmin(total))
    assert sel.scores[sel.frontier] == 1.0 and sel.scores.min() == 0.0
    s_llm = [ls.s_llm for ls in sel.language]  # p(frontier is nearest the goal): a distribution over frontiers
    assert sum(s_llm) == pytest.approx(1.0) and int(np.argmax(s_llm)) == int(np.argmin(metres))
    assert "expected" in sel.reason


def test_a_flat_head_under_expected_selection_chooses_exactly_as_cost_utility(tmp_path):
    head = GoalHead(384, len(GOALS)).eval()
    with torch.no_grad():
        head.net[-1].weight.zero_()
        head.net[-1].bias.fill_(4.0)  # the same 4 m beyond every frontier: no information
    path = save_head(
        head,
        {"kind": "frontiers", "object_filter": "all", "encoder": "minilm", "goals": list(GOALS)},
        tmp_path / "flat.pt",
    )
    policy = LanguageFrontierPolicy("l3mvn-ff", "feedforward", selection="expected", head=str(path), cu_lambda=40.0)
    # S_CU = U - 40 C: the big far frontier (80 - 40 * 1.5 = 20) beats the small near one (10 - 40 * 0.5 = -10).
    frontiers = [_frontier(0, ("sink",), 0.5, 0.0, utility=10.0), _frontier(1, ("bed",), 1.5, 1.0, utility=80.0)]
    assert policy.select(frontiers, None, "toilet", np.random.default_rng(0)).frontier == 1


def test_expected_selection_needs_a_head_that_predicts_distances():
    with pytest.raises(L3MVNError, match="selection 'expected' needs a scorer that predicts distances") as err:
        LanguageFrontierPolicy("l3mvn-zs", "roomtype", selection="expected", paradigm="zero-shot")
    assert "\n" not in str(err.value)
    with pytest.raises(L3MVNError, match="applies to the feedforward scorer only"):
        LanguageFrontierPolicy("l3mvn-zs", "roomtype", head="rooms")


def test_rooms_head_keeps_the_paper_recipe():
    scorer = make_scorer("feedforward", head="rooms")
    assert scorer.kind == "rooms" and not scorer.predicts_distance and scorer.object_filter == "entropy"
    with pytest.raises(L3MVNError, match="predicts p\\(goal\\), not distances"):
        scorer.expected_distance([("sink",)])


def test_a_head_file_reads_the_embedder_it_names_and_refuses_another(head_file, tmp_path):
    from l3mvn.core.config import PolicyConfig

    scorer = make_scorer("feedforward", head=str(head_file))
    assert scorer.model_name == "minilm" and scorer.label == "feedforward (frontiers head on minilm)"
    assert make_scorer("feedforward", head=str(head_file), model="all-MiniLM-L6-v2").model_name == "minilm"
    with pytest.raises(L3MVNError, match="reads 'minilm' embeddings, not 'smollm2-135m'") as err:
        make_scorer("feedforward", head=str(head_file), model="smollm2-135m")
    assert "\n" not in str(err.value)
    with pytest.raises(L3MVNError, match="no shipped head of kind 'frontiers' for embedder 'gemma3-270m'"):
        make_scorer("feedforward", head="frontiers", model="gemma3-270m")
    with pytest.raises(L3MVNError, match="reads a bag of objects"):
        make_scorer("feedforward", head="rooms-bag", model="minilm")
    assert PolicyConfig(head=str(head_file)).head == str(head_file)
    with pytest.raises(L3MVNError, match=r"or a head file \(\*\.pt"):
        PolicyConfig(head=str(tmp_path / "head.json"))
    with pytest.raises(L3MVNError, match="policy.embedder must name"):
        PolicyConfig(embedder=" ")


def test_the_embedder_reaches_only_the_feed_forward_scorer(head_file, capsys):
    from l3mvn.core.config import PolicyConfig
    from l3mvn.run.cli import main
    from l3mvn.run.registry import check_options

    policy = LanguageFrontierPolicy("l3mvn-ff", "feedforward", head=str(head_file), embedder="minilm")
    assert policy.scorer.model_name == "minilm"
    with pytest.raises(L3MVNError, match="the embedder 'minilm' applies to the feedforward scorer only"):
        LanguageFrontierPolicy("l3mvn-zs", "roomtype", embedder="minilm")
    with pytest.raises(L3MVNError, match="--embedder applies to the feedforward scorer only; policy 'cost-utility'"):
        check_options("cost-utility", PolicyConfig(embedder="minilm"))
    argv = ["eval", "--policy", "l3mvn-ff", "--houses", "1", "--episodes-per-house", "1"]
    assert main(argv + ["--head", "frontiers", "--embedder", "gemma3-270m"]) == 2
    assert "no shipped head of kind 'frontiers' for embedder 'gemma3-270m'" in capsys.readouterr().err

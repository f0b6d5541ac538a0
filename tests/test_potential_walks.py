"""PONI's second training stage: samples from the agent's own walks (the choices it faces), the
listwise loss over them, the choice regret that picks the epoch, and the command line around them."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest
import torch
from torch import nn

from l3mvn.agent.potentials import CHANNELS, OUTPUTS, PotentialModel, PotentialNet, expected_totals
from l3mvn.agent.potentials.model import GEOMETRY
from l3mvn.core.categories import GIBSON_CATEGORIES, GOAL_CATEGORIES
from l3mvn.core.config import PotentialConfig
from l3mvn.run.cli import main
from l3mvn.run.potentials.train import TrainOptions, _walk_loss, choice_regret, fit_walks
from l3mvn.run.potentials.walks import WalkJob, WalkSet, walk_floor, walk_floors
from l3mvn.world.scenes.procedural import generate_house

SMALL = PotentialConfig(input_window_m=6.4)  # 32 network cells a side
FRAME = (60, 80)


pytestmark = pytest.mark.usefixtures("one_torch_thread")  # tiny nets: see conftest


@pytest.fixture(scope="module")
def walked() -> list[WalkSet]:
    return [walk_floor(WalkJob(seed, 2, 1, FRAME, SMALL)) for seed in (0, 1)]


# --- the walks ---------------------------------------------------------------------------------------------
def test_each_choice_holds_the_window_the_frontiers_and_the_true_metres_of_the_goals_the_house_holds(walked):
    for seed, walks in zip((0, 1), walked):
        assert len(walks) >= 2
        assert walks.features.shape == (len(walks), len(CHANNELS), 32, 32) and walks.features.dtype == np.uint8
        assert walks.houses == [generate_house(seed).key] * len(walks)
        scene = generate_house(seed)
        present = [g in scene.categories and scene.category_mask(g).any() for g in GOAL_CATEGORIES]
        for i in range(len(walks)):
            cost, metres, cells = walks.frontiers(i)
            assert len(cost) >= 2 and metres.shape == (len(cost), len(GOAL_CATEGORIES)) and len(cells) == len(cost)
            assert 0 <= walks.choice[i] < len(cost) and (cost >= 0).all()
            assert all(((c >= 0) & (c < 32 * 32)).all() and len(np.unique(c)) == len(c) for c in cells)
            for g, held in enumerate(present):
                column = metres[:, g]
                if held:  # a goal of the house: metres on from every frontier on its floor
                    assert np.isfinite(column).any() and (column[np.isfinite(column)] >= 0).all()
                else:
                    assert np.isnan(column).all()
        assert {GOAL_CATEGORIES[g] for g in walks.goal} <= {g for g, held in zip(GOAL_CATEGORIES, present) if held}


def test_joined_walks_keep_every_choice_as_it_was(walked):
    joined = walk_floors([WalkJob(seed, 2, 1, FRAME, SMALL) for seed in (0, 1)], workers=1)
    parts = [(w, i) for w in walked for i in range(len(w))]
    assert len(joined) == len(parts) and joined.houses == walked[0].houses + walked[1].houses
    for k, (part, i) in enumerate(parts):
        for got, want in zip(joined.frontiers(k)[:2], part.frontiers(i)[:2]):
            np.testing.assert_array_equal(got, want)
        for got, want in zip(joined.frontiers(k)[2], part.frontiers(i)[2]):
            np.testing.assert_array_equal(got, want)
        np.testing.assert_array_equal(joined.features[k], part.features[i])
        np.testing.assert_array_equal(joined.size_m(k), part.size_m(i))
        np.testing.assert_array_equal(joined.objects(k), part.objects(i))
        assert len(joined.size_m(k)) == len(joined.frontiers(k)[0])
        assert joined.choice[k] == part.choice[i] and joined.goal[k] == part.goal[i]
    # The size bonus is cost-utility's utility over its lambda: never negative, and wider frontiers earn some.
    assert (joined.frontier_size_m >= 0).all() and joined.frontier_size_m.max() > 0
    # Furnished houses put objects in some frontiers' windows: the language input is recorded.
    assert joined.frontier_objects.shape == (len(joined.frontier_cost), len(GIBSON_CATEGORIES))
    assert joined.frontier_objects.any()
    empty = WalkSet.join([], 32)
    assert len(empty) == 0 and empty.features.shape == (0, len(CHANNELS), 32, 32)


# --- the loss and the regret, on a hand-built choice ---------------------------------------------------------
BED = GOAL_CATEGORIES.index("bed")


def _choice(
    metres_bed: tuple[float, float],
    cost: tuple[float, float] = (1.0, 1.0),
    choice: int = 0,
    size_m: tuple[float, float] = (0.0, 0.0),
) -> WalkSet:
    """One choice between two frontiers read at network cells 0 and 5 of a 4x4 window; only the bed
    is in the house."""
    metres = np.full((2, len(GOAL_CATEGORIES)), np.nan, np.float32)
    metres[:, BED] = metres_bed
    return WalkSet(
        features=np.zeros((1, len(CHANNELS), 4, 4), np.uint8),
        goal=np.array([BED], np.int8),
        choice=np.array([choice], np.int16),
        houses=["h"],
        frontier_sample=np.zeros(2, np.int32),
        frontier_cost=np.array(cost, np.float32),
        frontier_metres=metres,
        cell_frontier=np.array([0, 1], np.int32),
        cell_index=np.array([0, 5], np.int32),
        frontier_size_m=np.array(size_m, np.float32),
        frontier_objects=np.zeros((2, len(GIBSON_CATEGORIES)), bool),
    )


def _logits(bed_at: tuple[float, float]) -> torch.Tensor:
    """Window logits: everything at -4, the bed's at cells 0 and 5 as given."""
    out = torch.full((1, len(OUTPUTS), 4, 4), -4.0)
    out[0, 1 + BED].view(-1)[0], out[0, 1 + BED].view(-1)[5] = bed_at
    return out


class _Fixed(nn.Module):
    def __init__(self, logits: torch.Tensor) -> None:
        super().__init__()
        self.logits = logits

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.logits.expand(len(x), -1, -1, -1)


def test_the_loss_is_lower_when_the_potentials_order_frontiers_as_the_true_totals_do():
    walks, cfg = _choice((2.0, 10.0)), PotentialConfig()
    right = _walk_loss(_logits((3.0, -3.0)), walks, np.array([0]), cfg, tau_m=1.0)
    wrong = _walk_loss(_logits((-3.0, 3.0)), walks, np.array([0]), cfg, tau_m=1.0)
    assert float(right) < float(wrong)
    # 11 m more travel to the frontier 8 m nearer the bed: the other is now the better total, and the
    # same potentials, which barely tell the two totals apart, cost more.
    far = _walk_loss(_logits((3.0, -3.0)), _choice((2.0, 10.0), cost=(12.0, 1.0)), np.array([0]), cfg, tau_m=1.0)
    assert float(far) > float(right) + 0.3
    logits = _logits((0.0, 0.0)).requires_grad_()
    _walk_loss(logits, walks, np.array([0]), cfg, tau_m=1.0).backward()
    grad = logits.grad[0, 1 + BED].reshape(-1)
    assert grad[0] < 0 < grad[5]  # raise the nearer frontier's bed potential, lower the farther's
    assert (logits.grad[0, 2 + BED :] == 0).all()  # goals the house lacks teach nothing


def test_choice_regret_is_the_true_total_of_the_frontier_the_policy_takes_less_the_least():
    walks, cfg = _choice((2.0, 10.0), choice=1), PotentialConfig()
    wrong = choice_regret(_Fixed(_logits((-3.0, 3.0))), walks, cfg)
    assert wrong["regret_m"] == pytest.approx(8.0) and wrong["goal_regret_m"] == pytest.approx(8.0)
    assert wrong["walker_regret_m"] == pytest.approx(8.0) and wrong["nearest_goal_regret_m"] == 0.0
    right = choice_regret(_Fixed(_logits((3.0, -3.0))), walks, cfg)
    assert right["regret_m"] == 0.0 and right["choices"] == 1


def test_expected_totals_are_the_same_numbers_for_numpy_and_torch_with_the_size_bonus_where_set():
    cost, potentials = np.array([1.0, 4.0]), np.random.default_rng(0).random((2, len(OUTPUTS)))
    size = np.array([0.5, 2.0])
    for cfg, less in ((PotentialConfig(), size), (PotentialConfig(size_bonus=False), 0.0)):
        got = expected_totals(cost, potentials, cfg, size)
        want = (cost - less)[:, None] - cfg.area_bonus_m * potentials[:, :1] + cfg.range_m * (1.0 - potentials[:, 1:])
        np.testing.assert_allclose(got, want)
        from_torch = expected_totals(torch.tensor(cost), torch.tensor(potentials), cfg, torch.tensor(size))
        np.testing.assert_allclose(from_torch.numpy(), want)


def test_the_loss_and_regret_read_the_size_bonus_the_policy_adds():
    # Bed 2 m beyond frontier 0 and 4 m beyond frontier 1, the potentials say so; frontier 1 is 3 m
    # wider by the size bonus: with the bonus the totals the policy compares prefer it (regret 2 m),
    # without it they do not (regret 0), and the loss is lower for the criterion that orders them right.
    walks = _choice((2.0, 4.0), size_m=(0.0, 3.0))
    logits = _logits((float(np.log(5.0)), float(np.log(2.0))))  # potentials 10/12 and 8/12: 2 and 4 m on
    on, off = PotentialConfig(), PotentialConfig(size_bonus=False)
    assert choice_regret(_Fixed(logits), walks, on)["regret_m"] == pytest.approx(2.0)
    assert choice_regret(_Fixed(logits), walks, off)["regret_m"] == 0.0
    idx = np.array([0])
    assert float(_walk_loss(logits, walks, idx, off, tau_m=1.0)) < float(_walk_loss(logits, walks, idx, on, tau_m=1.0))


# --- the stage ------------------------------------------------------------------------------------------------
def test_fine_tuning_keeps_the_weights_whose_val_choices_regret_least(walked):
    torch.manual_seed(0)
    net = PotentialNet(width=8)
    options = TrainOptions(walk_epochs=2, batch=2, walk_learning_rate=5e-3)
    tuned, history = fit_walks(net, walked[0], walked[1], SMALL, options)
    assert [row["walk_epoch"] for row in history] == [0, 1, 2]
    assert "train_loss" not in history[0] and all(math.isfinite(row["train_loss"]) for row in history[1:])
    best = min(row["val_regret_m"] for row in history)
    assert choice_regret(tuned, walked[1], SMALL)["regret_m"] == pytest.approx(best)


# --- the command line -----------------------------------------------------------------------------------------
def _error_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "\n" not in err
    return err


def test_poni_train_walks_after_drawing_and_continues_from_a_checkpoint(tmp_path, capsys):
    first, plain = tmp_path / "first.pt", PotentialConfig(size_bonus=False)
    draw = ["--procedural-houses", "2", "--samples-per-procedural", "2", "--epochs", "1", "--width", "8"]
    walk = ["--walk-procedural-houses", "2", "--walk-episodes-per-procedural", "1", "--walk-epochs", "1"]
    assert main(["poni", "train", *draw, *walk, "--no-size-bonus", "--workers", "1", "--out", str(first)]) == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert summary["windows"]["train"] >= 1 and summary["windows"]["walks_train"] >= 1
    assert PotentialModel.load(first, plain).geometry["size_bonus"] == 0.0  # trained for the policy without it
    shown = PotentialModel.load(first, plain).training
    assert [row["walk_epoch"] for row in shown["walk_history"]] == [0, 1] and len(shown["history"]) == 1
    assert shown["options"]["walk_epochs"] == 1 and shown["init"] is None
    second = tmp_path / "second.pt"
    only_walks = ["--procedural-houses", "0", *walk, "--walk-epochs", "0", "--init", str(first)]
    assert main(["poni", "train", *only_walks, "--workers", "1", "--out", str(second)]) == 0
    capsys.readouterr()
    again = PotentialModel.load(second, PotentialConfig())
    assert again.training["init"] == str(first) and again.training["history"] == []
    # Fine-tuning may change the criterion: the second checkpoint is for the policy with the size bonus.
    assert again.geometry == {k: float(getattr(PotentialConfig(), k)) for k in GEOMETRY}
    for mine, theirs in zip(
        again.net.state_dict().values(), PotentialModel.load(first, plain).net.state_dict().values()
    ):
        assert torch.equal(mine, theirs)  # no stage had data or epochs: the weights it started from
    # PONI walks with the checkpoint it fine-tunes, and its walks are its own choices, not cost-utility's.
    third = tmp_path / "third.pt"
    own = ["--procedural-houses", "0", *walk, "--walker", "poni", "--init", str(first)]
    assert main(["poni", "train", *own, "--workers", "1", "--out", str(third)]) == 0
    assert json.loads(capsys.readouterr().out.strip().splitlines()[-1])["windows"]["walks_train"] >= 1
    assert PotentialModel.load(third, PotentialConfig()).training["options"]["walker"] == "poni"
    poni = replace(plain, checkpoint=str(first))
    by = {w: walk_floor(WalkJob(0, 2, 1, FRAME, poni, w)) for w in ("cost-utility", "poni")}
    assert not np.array_equal(by["poni"].frontier_cost, by["cost-utility"].frontier_cost)


@pytest.mark.parametrize(
    ("argv", "says"),
    [
        (["--walk-tau-m", "0"], "--walk-tau-m must be a positive number"),
        (["--walk-learning-rate", "nan"], "--walk-learning-rate must be a positive number"),
        (["--init", "missing.pt"], "does not exist"),
        (["--procedural-houses", "0", "--walk-procedural-houses", "0"], "nothing to train on"),
        (["--walker", "poni"], "--walker poni walks with the checkpoint it fine-tunes: give --init"),
    ],
)
def test_poni_train_refuses_bad_walk_settings_in_one_line(tmp_path, capsys, argv, says):
    assert main(["poni", "train", *argv, "--out", str(tmp_path / "x.pt"), "--workers", "1"]) == 2
    assert says in _error_line(capsys) and not (tmp_path / "x.pt").exists()


def test_the_shipped_checkpoint_went_through_both_stages_then_the_size_bonus_and_records_its_scores():
    model = PotentialModel.load(None, PotentialConfig())
    training, before = model.training, model.training["previous"]
    assert before["history"] and before["walk_history"] and before["init"] is None  # both stages, from scratch
    assert training["walk_history"] and not training["history"] and model.geometry["size_bonus"] == 1.0
    assert training["houses"]["test"] and not set(training["houses"]["test"]) & set(training["houses"]["val"])
    for split in ("walks_val", "walks_test"):
        scores = training["scores"][split]
        assert scores["choices"] > 0 and all(math.isfinite(v) for v in scores.values()), split

"""The PONI policy: the network's input window, its training samples and training, its checkpoint, the
policy's frontier choice, and where it shows (registry, Language folder, CLI)."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from scipy import ndimage as ndi
from test_global_policies import _map
from test_language_panel import _view

from l3mvn.agent.frontiers import Frontier
from l3mvn.agent.frontiers.types import POTENTIALS_RULE
from l3mvn.agent.mapping import SemanticMap
from l3mvn.agent.potentials import (
    CHANNELS,
    OUTPUTS,
    PotentialModel,
    PotentialNet,
    PotentialPolicy,
    WindowGrid,
    window_features,
)
from l3mvn.agent.potentials.model import GEOMETRY
from l3mvn.core.categories import GIBSON_CATEGORIES, GOAL_CATEGORIES
from l3mvn.core.config import Config, PotentialConfig, override
from l3mvn.core.errors import L3MVNError
from l3mvn.run.cli import main
from l3mvn.run.potentials import samples
from l3mvn.run.potentials.samples import NO_LABEL, HouseTruth, RevealOptions
from l3mvn.run.potentials.train import TrainOptions, draw_samples, evaluate, fit
from l3mvn.run.registry import policy_names, reads_language, scores_frontiers
from l3mvn.world.scenes.procedural import generate_house
from l3mvn.world.scenes.scene import SceneMap
from l3mvn_studio.language_panel import language_html
from l3mvn_studio.state import FrontierMarker

# A small window (32 cells of 0.2 m) keeps sampling and training quick; the geometry is otherwise the default.
SMALL = PotentialConfig(input_window_m=6.4)
QUICK_REVEAL = RevealOptions(max_views=4, rays=180)


pytestmark = pytest.mark.usefixtures("one_torch_thread")  # tiny nets: see conftest


def _one_line_error(call, *args, **kwargs) -> str:
    with pytest.raises(L3MVNError) as info:
        call(*args, **kwargs)
    message = str(info.value)
    assert "\n" not in message
    return message


# --- the input window ---------------------------------------------------------------------------------
def _layers(n: int = 16) -> tuple[np.ndarray, np.ndarray]:
    return np.zeros((n, n), bool), np.zeros((n, n), bool)


# Two 5 cm map cells per 0.1 m network cell, 8 network cells a side: a 16x16 map is exactly one window.
TWO_BY_TWO = PotentialConfig(cell_m=0.1, input_window_m=0.8)


def test_window_channels_are_explored_share_then_obstacle_and_categories_any():
    explored, obstacle = _layers()
    explored[0, 0] = True  # one of the four map cells of network cell (0, 0)
    explored[4:6, 6] = True  # two of the four of (2, 3)
    obstacle[3, 3] = True  # one of the four of (1, 1)
    names = ("bed", "tv", "not-a-semexp-category")
    categories = np.zeros((3, 16, 16), bool)
    categories[0, 15, 15] = True
    categories[1, 5, 4] = True
    categories[2] = True  # a map category SemExp lacks is not read at all
    grid = WindowGrid.around((8, 8), 0.05, TWO_BY_TWO)
    assert grid == WindowGrid(2, (0, 0), 8)
    out = window_features(explored, obstacle, categories, names, grid)
    expected = np.zeros((len(CHANNELS), 8, 8), np.float32)
    expected[0, 0, 0], expected[0, 2, 3] = 0.25, 0.5
    expected[1, 1, 1] = 1.0
    expected[CHANNELS.index("bed"), 7, 7] = 1.0
    expected[CHANNELS.index("tv"), 2, 2] = 1.0
    assert CHANNELS[:2] == ("explored", "obstacle") and CHANNELS[2:] == GIBSON_CATEGORIES
    assert out.dtype == np.float32 and np.array_equal(out, expected)


def test_a_window_partly_off_the_map_is_zero_padded_and_one_wholly_off_is_all_zeros():
    explored, obstacle = _layers()
    explored[:] = True
    obstacle[:] = True
    categories = np.ones((1, 16, 16), bool)
    corner = window_features(explored, obstacle, categories, ("chair",), WindowGrid.around((0, 0), 0.05, TWO_BY_TWO))
    on_map = np.zeros((8, 8), bool)
    on_map[4:, 4:] = True  # the window starts 8 map cells (4 network cells) above and left of the map
    for k in (0, 1, CHANNELS.index("chair")):
        assert np.array_equal(corner[k] == 1.0, on_map) and not corner[k][~on_map].any()
    away = WindowGrid.around((100, -50), 0.05, TWO_BY_TWO)
    assert not window_features(explored, obstacle, categories, ("chair",), away).any()


@pytest.mark.parametrize("cell_m", [0.12, 0.025])
def test_a_network_cell_that_is_no_whole_multiple_of_the_map_cell_is_refused(cell_m):
    cfg = PotentialConfig(cell_m=cell_m, input_window_m=cell_m * 8)
    message = _one_line_error(WindowGrid.around, (10, 10), 0.05, cfg)
    assert "poni.cell_m" in message and "whole multiple of the map's cell" in message


def test_to_window_maps_cells_to_network_cells_and_flags_those_outside():
    grid = WindowGrid(2, (10, 20), 8)
    wr, wc, inside = grid.to_window(np.array([10, 11, 25, 26, 9]), np.array([20, 21, 35, 20, 20]))
    assert wr.tolist() == [0, 0, 7, 8, -1] and wc.tolist() == [0, 0, 7, 0, 0]
    assert inside.tolist() == [True, True, True, False, False]


# --- the config section ---------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"cell_m": 0.0}, "poni.cell_m must be a positive number"),
        ({"input_window_m": -25.6}, "poni.input_window_m must be a positive number"),
        ({"range_m": math.nan}, "poni.range_m must be a positive number"),
        ({"area_scale_m2": math.inf}, "poni.area_scale_m2 must be a positive number"),
        ({"area_bonus_m": -1.0}, "poni.area_bonus_m must be a non-negative number"),
        ({"input_window_m": 1.0}, "whole multiple of 8 cells"),  # 5 cells
        ({"input_window_m": 25.5}, "whole multiple of 8 cells"),  # 127.5 cells
        ({"checkpoint": "  "}, "poni.checkpoint must name a .pt file"),
    ],
)
def test_bad_poni_settings_are_refused_in_one_line(kwargs, message):
    assert message in _one_line_error(PotentialConfig, **kwargs)


def test_poni_settings_are_set_from_the_command_line_and_rechecked():
    assert Config().poni == PotentialConfig() and PotentialConfig().window_cells == 128
    cfg = override(Config(), ["poni.area_bonus_m=0", "poni.checkpoint=model.pt"])
    assert cfg.poni.area_bonus_m == 0.0 and cfg.poni.checkpoint == "model.pt"
    assert "whole multiple of 8 cells" in _one_line_error(override, Config(), ["poni.input_window_m=25"])


# --- training samples from a full house ---------------------------------------------------------------------
def _without(scene: SceneMap, category: str) -> SceneMap:
    objects = scene.objects.copy()
    objects[scene.categories.index(category)] = False
    return SceneMap(
        name=scene.name,
        floor=scene.floor,
        categories=scene.categories,
        navigable=scene.navigable,
        objects=objects,
        origin_cm=scene.origin_cm,
    )


def test_a_sample_is_a_uint8_window_labelled_at_some_cells_and_the_same_seed_gives_the_same_sample():
    truth = HouseTruth(generate_house(0), SMALL, QUICK_REVEAL)
    sample = truth.sample(np.random.default_rng(3))
    assert sample is not None and sample.house == "procedural-0000/0"
    assert sample.features.dtype == np.uint8 and sample.features.shape == (len(CHANNELS), 32, 32)
    assert sample.labels.dtype == np.uint8 and sample.labels.shape == (len(OUTPUTS), 32, 32)
    labelled = sample.labels != NO_LABEL
    assert labelled[0].any() and not labelled[0].all() and sample.labels[labelled].max() <= 254
    assert sample.labels[0][labelled[0]].max() > 0  # some frontier opens onto unexplored floor
    for g in np.flatnonzero(truth.present):  # every goal in the house is labelled where the area is
        assert np.array_equal(labelled[1 + g], labelled[0])
    assert sample.features[0].any() and sample.features.max() == 255
    again = truth.sample(np.random.default_rng(3))
    assert np.array_equal(again.features, sample.features) and np.array_equal(again.labels, sample.labels)
    other = truth.sample(np.random.default_rng(4))
    assert not np.array_equal(other.labels, sample.labels)


def test_a_goal_absent_from_the_house_has_no_label_anywhere():
    house = generate_house(1)
    truth = HouseTruth(_without(house, "toilet"), SMALL, QUICK_REVEAL)
    toilet = 1 + GOAL_CATEGORIES.index("toilet")
    assert not truth.present[toilet - 1] and truth.present.sum() >= 4
    rng = np.random.default_rng(0)
    drawn = [s for s in (truth.sample(rng) for _ in range(4)) if s is not None]
    assert drawn
    for s in drawn:
        assert (s.labels[toilet] == NO_LABEL).all()
        assert any((s.labels[1 + g] != NO_LABEL).any() for g in np.flatnonzero(truth.present))


def test_object_labels_are_the_potential_of_the_geodesic_metres_at_frontier_cells(monkeypatch):
    """With one map cell per network cell, each labelled cell is a frontier cell labelled
    ``1 - goal_m / range_m``: higher nearer the goal."""
    cfg = PotentialConfig(cell_m=0.05, input_window_m=6.4)
    seen_grid = []

    def spy(explored, obstacle, categories, names, grid):
        seen_grid.append((explored.copy(), grid))
        return window_features(explored, obstacle, categories, names, grid)

    monkeypatch.setattr(samples, "window_features", spy)
    truth = HouseTruth(generate_house(2), cfg, QUICK_REVEAL)
    sample = truth.sample(np.random.default_rng(1))
    assert sample is not None and len(seen_grid) == 1
    seen, grid = seen_grid[0]
    assert grid.factor == 1
    unseen_near = ndi.binary_dilation(~seen, np.ones((3, 3), bool))
    checked = 0
    for g in np.flatnonzero(truth.present):
        wr, wc = np.nonzero(sample.labels[1 + g] != NO_LABEL)
        rows, cols = wr + grid.origin[0], wc + grid.origin[1]
        assert seen[rows, cols].all() and truth.floor[rows, cols].all()  # explored floor
        assert unseen_near[rows, cols].all()  # next to the unexplored: the frontier, not all explored floor
        goal_m = truth.goal_m[g, rows, cols]
        want = np.rint(np.clip(1.0 - goal_m / cfg.range_m, 0.0, 1.0) * 254)
        assert np.abs(sample.labels[1 + g, wr, wc].astype(int) - want).max() <= 1
        near, far = int(np.argmin(goal_m)), int(np.argmax(goal_m))
        if goal_m[near] < goal_m[far]:
            assert sample.labels[1 + g, wr[near], wc[near]] > sample.labels[1 + g, wr[far], wc[far]]
            checked += 1
    assert checked


def _closed_room() -> SceneMap:
    """A 1 m room (rows and columns 10-29) with a bed in it, walled off from a second room (columns
    32-37) by two wall cells."""
    free = np.zeros((40, 40), bool)
    free[10:30, 10:30] = True
    free[10:30, 32:38] = True
    objects = np.zeros((len(GIBSON_CATEGORIES), 40, 40), bool)
    objects[GIBSON_CATEGORIES.index("bed"), 18:22, 20:24] = True
    return SceneMap(
        name="Closed",
        floor=0,
        categories=GIBSON_CATEGORIES,
        navigable=free & ~objects.any(0),
        objects=objects,
        free_recovery_cells=0,
    )


def test_a_view_reveals_its_room_and_walls_but_nothing_beyond_and_sees_past_objects():
    truth = HouseTruth(_closed_room(), SMALL, RevealOptions(rays=720, range_m=5.0))
    seen = np.zeros((40, 40), bool)
    truth.reveal((20, 15), seen)
    assert seen[10:30, 10:30].all()  # the whole room, the bed and the floor behind it
    assert seen[20, 30] and seen[9, 15] and seen[20, 9]  # the first wall cell of each side
    assert not seen[20, 31] and not seen[10:30, 32:38].any()  # the wall's far cell and the next room
    assert not seen[:, :8].any() and not seen[:8].any()


# --- training -----------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def sample_sets():
    train = draw_samples([(0, 4), (1, 4)], SMALL, QUICK_REVEAL, seed=0, workers=1)
    val = draw_samples([(2, 3)], SMALL, QUICK_REVEAL, seed=1, workers=1)
    return train, val


def test_fit_lowers_the_training_loss_and_the_net_scores_finite_numbers(sample_sets):
    train, val = sample_sets
    assert len(train) >= 6 and len(val) >= 2
    net, history = fit(train, val, SMALL, TrainOptions(epochs=3, batch=2, width=8, learning_rate=5e-3))
    assert [row["epoch"] for row in history] == [1, 2, 3]
    assert history[-1]["train_loss"] < history[0]["train_loss"]
    scores = evaluate(net, val, SMALL)
    assert scores["windows"] == len(val)
    for key in ("loss", "regret_m", "metres_mae", "chance_regret_m"):
        assert math.isfinite(scores[key]) and scores[key] >= 0, key


# --- the checkpoint -------------------------------------------------------------------------------------------
def _model(cfg: PotentialConfig = SMALL) -> PotentialModel:
    torch.manual_seed(0)
    return PotentialModel(PotentialNet(width=8).eval(), {k: float(getattr(cfg, k)) for k in GEOMETRY})


def test_a_saved_model_loads_with_the_same_predictions_in_zero_to_one(tmp_path):
    model = _model()
    path = tmp_path / "poni.pt"
    model.save(path)
    loaded = PotentialModel.load(path, SMALL)
    features = np.random.default_rng(0).random((len(CHANNELS), 32, 32)).astype(np.float32)
    out = model.predict(features)
    assert out.shape == (len(OUTPUTS), 32, 32) and out.min() >= 0.0 and out.max() <= 1.0
    assert np.array_equal(loaded.predict(features), out)
    assert loaded.geometry == model.geometry and loaded.source == str(path) and loaded.label == "poni (poni.pt)"


def test_a_missing_unreadable_or_foreign_checkpoint_is_refused_in_one_line(tmp_path):
    missing = _one_line_error(PotentialModel.load, tmp_path / "missing.pt", SMALL)
    assert "does not exist" in missing and "l3mvn poni train" in missing
    garbage = tmp_path / "garbage.pt"
    garbage.write_bytes(b"\x00\x01not a checkpoint\xff" * 10)
    assert "cannot read PONI checkpoint" in _one_line_error(PotentialModel.load, garbage, SMALL)
    path = tmp_path / "poni.pt"
    _model().save(path)
    other = _one_line_error(PotentialModel.load, path, PotentialConfig(input_window_m=6.4, range_m=10.0))
    assert "poni.range_m=12.0 (config 10.0)" in other
    blob = torch.load(path, weights_only=True)
    for name, change, says in (
        ("keys.pt", {"state": None, "channels": None}, "not a PONI checkpoint"),
        ("channels.pt", {"channels": list(reversed(CHANNELS))}, "was trained on channels"),
        ("outputs.pt", {"outputs": list(OUTPUTS[:-1])}, "was trained on channels"),
        ("width.pt", {"width": 16}, "weights do not fit the network"),
    ):
        changed = {k: v for k, v in {**blob, **change}.items() if v is not None}
        torch.save(changed, tmp_path / name)
        assert says in _one_line_error(PotentialModel.load, tmp_path / name, SMALL), name


def test_a_checkpoint_fixes_its_size_bonus_and_one_saved_before_it_existed_was_trained_without(tmp_path):
    path = tmp_path / "poni.pt"
    _model().save(path)  # trained with the size bonus (the default)
    without = replace(SMALL, size_bonus=False)
    message = _one_line_error(PotentialModel.load, path, without)
    assert "poni.size_bonus=true (config false)" in message
    assert PotentialModel.load(path, without, to_fine_tune=True).geometry["size_bonus"] == 1.0
    blob = torch.load(path, weights_only=True)
    older = tmp_path / "older.pt"
    torch.save({**blob, "geometry": {k: v for k, v in blob["geometry"].items() if k != "size_bonus"}}, older)
    assert PotentialModel.load(older, without).geometry["size_bonus"] == 0.0
    assert "poni.size_bonus=false (config true)" in _one_line_error(PotentialModel.load, older, SMALL)


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="no /dev/full to stand for a full disk")
def test_a_checkpoint_that_cannot_be_written_is_one_error_and_leaves_no_part_file(tmp_path):
    assert "PONI checkpoint" in _one_line_error(_model().save, "/dev/full")
    (tmp_path / "poni.pt").mkdir()  # a folder where the file should go
    assert "poni.pt" in _one_line_error(_model().save, tmp_path / "poni.pt")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["poni.pt"]


# --- the policy ---------------------------------------------------------------------------------------------
# An 8-cell window of 0.2 m on a 64-cell map of 5 cm, the agent in the middle: map cells 16-47 are in it.
# The arithmetic tests read the area bonus alone; the size bonus has its own below.
POLICY_CFG = PotentialConfig(input_window_m=1.6, range_m=12.0, area_bonus_m=3.0, size_bonus=False)


def _sem_map(n: int = 64) -> SemanticMap:
    explored = np.zeros((n, n), bool)
    explored[20:44, 20:44] = True
    return _map(explored, np.zeros_like(explored))


def _frontier(i: int, cells: list[tuple[int, int]], cost: float, utility: float = 1.0) -> Frontier:
    return Frontier(
        id=i,
        cells=np.array(cells),
        center=cells[0],
        size=len(cells),
        distance_m=cost,
        utility=utility,
        cost=cost,
        s_cu=0.5,
    )


# Frontier 0 in network cell (1, 1), frontier 1 in (6, 6), frontier 2 off the window on both sides.
AT = {0: (1, 1), 1: (6, 6)}
CELLS = {0: [(20, 20), (21, 22)], 1: [(40, 40)], 2: [(2, 3), (60, 61)]}


def _policy(monkeypatch, predicted: np.ndarray, cfg: PotentialConfig = POLICY_CFG) -> PotentialPolicy:
    model = _model(cfg)

    def predict(features: np.ndarray) -> np.ndarray:
        assert features.shape == (len(CHANNELS), 8, 8) and features[0].any()
        return predicted

    monkeypatch.setattr(model, "predict", predict)
    return PotentialPolicy(model, cfg, 40.0)


def _potentials(area: float = 0.5, objects: float = 0.5, at: dict | None = None) -> np.ndarray:
    """Uniform potentials, with ``at[(channel, frontier)] = value`` at that frontier's network cell."""
    out = np.full((len(OUTPUTS), 8, 8), objects, np.float32)
    out[0] = area
    for (channel, k), value in (at or {}).items():
        out[(OUTPUTS.index(channel), *AT[k])] = value
    return out


def _select(policy: PotentialPolicy, costs: tuple[float, ...], goal: str = "bed"):
    frontiers = [_frontier(i, CELLS[i], c) for i, c in enumerate(costs)]
    return policy.select(frontiers, _sem_map(), goal, np.random.default_rng(0))


def test_equal_potentials_pick_the_least_cost_less_area_bonus(monkeypatch):
    assert _select(_policy(monkeypatch, _potentials()), (3.0, 1.0)).frontier == 1
    bonus = _potentials(area=0.0, at={("area", 0): 1.0})  # 3 - 3 m bonus beats 1 - 0
    assert _select(_policy(monkeypatch, bonus), (3.0, 1.0)).frontier == 0
    small = _potentials(area=0.0, at={("area", 0): 0.5})  # 3 - 1.5 m does not
    assert _select(_policy(monkeypatch, small), (3.0, 1.0)).frontier == 1


def test_a_high_goal_potential_beats_a_nearer_frontier_when_its_metres_outweigh_the_cost(monkeypatch):
    far_but_near_goal = _potentials(at={("bed", 0): 0.9})  # 12 x 0.4 = 4.8 m saved > 2 m more travel
    chosen = _select(_policy(monkeypatch, far_but_near_goal), (3.0, 1.0))
    assert chosen.frontier == 0 and chosen.cell == CELLS[0][0]
    slight = _potentials(at={("bed", 0): 0.6})  # 12 x 0.1 = 1.2 m saved < 2 m
    assert _select(_policy(monkeypatch, slight), (3.0, 1.0)).frontier == 1
    other_goal = _potentials(at={("toilet", 0): 0.9})
    assert _select(_policy(monkeypatch, other_goal), (3.0, 1.0)).frontier == 1
    assert _select(_policy(monkeypatch, other_goal), (3.0, 1.0), goal="toilet").frontier == 0


def test_a_frontier_outside_the_window_reads_potential_zero(monkeypatch):
    policy = _policy(monkeypatch, _potentials(area=1.0, objects=1.0))
    frontiers = [_frontier(i, CELLS[i], c) for i, c in enumerate((2.0, 2.0, 0.0))]
    potentials = policy.frontier_potentials(frontiers, _sem_map())
    assert potentials.shape == (3, len(OUTPUTS))
    assert (potentials[:2] == 1.0).all() and (potentials[2] == 0.0).all()
    chosen = _select(policy, (2.0, 2.0, 0.0))
    assert chosen.frontier == 0  # 2 - 3 + 0 beats 0 - 0 + 12
    assert chosen.fusion.compared == pytest.approx((-1.0, -1.0, 12.0))
    assert chosen.language[2].expected_m["bed"] == 12.0 and set(chosen.language[2].llm_scores.values()) == {0.0}


def test_a_frontier_partly_in_the_window_reads_its_best_cell_inside(monkeypatch):
    policy = _policy(monkeypatch, _potentials(objects=0.1, at={("bed", 1): 0.8}))
    both = [_frontier(0, [(0, 0), (24, 24), (40, 40)], 1.0)]  # off the window, in cell (2, 2) and in (6, 6)
    assert policy.frontier_potentials(both, _sem_map())[0, OUTPUTS.index("bed")] == pytest.approx(0.8)


def test_the_selection_records_every_goals_potential_and_its_metres_and_a_potentials_fusion(monkeypatch):
    predicted = _potentials(area=0.25, objects=0.5, at={("bed", 0): 0.75, ("tv", 1): 0.125})
    chosen = _select(_policy(monkeypatch, predicted), (3.0, 1.0, 2.0))
    assert len(chosen.language) == 3
    for k, score in enumerate(chosen.language):
        assert set(score.llm_scores) == set(GOAL_CATEGORIES) == set(score.expected_m)
        assert score.s_llm == score.llm_scores["bed"] and score.queries == {}
        for goal, p in score.llm_scores.items():
            assert score.expected_m[goal] == pytest.approx(12.0 * (1.0 - p), abs=1e-3), (k, goal)
    assert chosen.language[0].llm_scores["bed"] == 0.75 and chosen.language[1].llm_scores["tv"] == 0.125
    assert chosen.language[0].expected_m["bed"] == 3.0 and chosen.language[2].expected_m["bed"] == 12.0
    fusion = chosen.fusion
    assert fusion.rule == POTENTIALS_RULE and fusion.ids == (0, 1, 2) and fusion.choice == chosen.frontier == 0
    assert fusion.describe().startswith("PONI")
    assert fusion.s_llm == (0.75, 0.5, 0.0) and fusion.explore == (0.25, 0.25, 0.0)
    assert fusion.cost_m == (3.0, 1.0, 2.0) and fusion.bonus_m == (0.75, 0.75, 0.0)
    assert fusion.compared == pytest.approx((5.25, 6.25, 14.0))  # cost - bonus + 12 x (1 - p)
    assert chosen.scores.tolist() == pytest.approx([1.0, 1.0 - 1.0 / 8.75, 0.0])
    assert chosen.reason.startswith("PONI: 3.0 m to frontier")


def test_the_size_bonus_is_cost_utilitys_utility_over_lambda_and_the_record_names_it(monkeypatch):
    sized = replace(POLICY_CFG, size_bonus=True)
    predicted = _potentials(area=0.0, at={("bed", 1): 0.6})  # frontier 1: 12 x 0.1 = 1.2 m nearer the bed
    frontiers = [_frontier(0, CELLS[0], 2.0, utility=120.0), _frontier(1, CELLS[1], 2.0, utility=40.0)]
    chosen = _policy(monkeypatch, predicted, sized).select(frontiers, _sem_map(), "bed", np.random.default_rng(0))
    assert chosen.frontier == 0  # 3 m of size bonus against 1 m outweighs 1.2 m nearer the bed
    assert chosen.fusion.bonus_m == pytest.approx((3.0, 1.0)) and chosen.fusion.compared == pytest.approx((5.0, 5.8))
    assert "frontier size" in chosen.fusion.describe() and "3.0 m bonus" in chosen.reason
    plain = _policy(monkeypatch, predicted).select(frontiers, _sem_map(), "bed", np.random.default_rng(0))
    assert plain.frontier == 1 and "frontier size" not in plain.fusion.describe()


def test_a_size_bonus_without_a_positive_cu_lambda_is_refused_in_one_line():
    sized = replace(POLICY_CFG, size_bonus=True)
    message = _one_line_error(PotentialPolicy, _model(sized), sized, 0.0)
    assert "frontiers.cu_lambda must be positive" in message and "poni.size_bonus=false" in message
    assert PotentialPolicy(_model(POLICY_CFG), POLICY_CFG, 0.0).cu_lambda == 0.0


def test_no_frontier_gives_no_selection_and_an_unknown_goal_is_refused(monkeypatch):
    policy = _policy(monkeypatch, _potentials())
    assert policy.select([], _sem_map(), "bed", np.random.default_rng(0)) is None
    message = _one_line_error(_select, policy, (1.0, 2.0), goal="sink")
    assert "'sink'" in message and "potted plant" in message


# --- registry and dashboard ------------------------------------------------------------------------------
def test_poni_is_a_policy_that_scores_frontiers_without_language():
    assert "poni" in policy_names()
    assert scores_frontiers("poni") and not reads_language("poni")
    assert scores_frontiers("l3mvn-zs") and not scores_frontiers("cost-utility") and not scores_frontiers("nope")


def _marker(i: int, chosen: bool) -> FrontierMarker:
    scores = {g: 0.1 * (k + 1) for k, g in enumerate(GOAL_CATEGORIES)}
    return FrontierMarker(
        id=i,
        cell=(i, i),
        size=10,
        distance_m=1.0 + i,
        s_cu=0.5,
        s_llm=scores["bed"],
        fused=1.0 - 0.5 * i,
        objects=(),
        queries={},
        reason="",
        chosen=chosen,
        llm_scores=scores,
        expected_m={g: round(12.0 * (1 - p), 3) for g, p in scores.items()},
    )


def test_the_language_folder_shows_poni_potentials_and_names_it_for_policies_without_a_prior(monkeypatch):
    chosen = _select(_policy(monkeypatch, _potentials(at={("bed", 0): 0.9})), (3.0, 1.0))
    view = _view((_marker(0, True), _marker(1, False)), fusion=chosen.fusion, target="bed")
    html = language_html(view, "poni")
    assert "object potential" in html and "read from the map" in html
    assert html.count("&middot; potential ") == 2 and "S_LLM" not in html
    assert chosen.fusion.describe().split(":")[0] in html
    note = language_html(None, "cost-utility")
    assert "uses no prior" in note and "poni" in note and "l3mvn-zs" in note
    assert "scores frontiers with a prior" in language_html(None, "poni")


# --- the command line ---------------------------------------------------------------------------------------
def _error_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "\n" not in err
    return err


def test_poni_train_refuses_an_out_that_is_no_pt_and_show_a_missing_file(tmp_path, capsys):
    assert main(["poni", "train", "--out", str(tmp_path / "x.txt"), "--procedural-houses", "1"]) == 2
    assert ".pt" in _error_line(capsys) and not (tmp_path / "x.txt").exists()
    assert main(["poni", "show", str(tmp_path / "missing.pt")]) == 2
    assert "l3mvn poni train" in _error_line(capsys)
    assert main(["poni", "train", "--out", str(tmp_path / "y.pt"), "--width", "12"]) == 2
    assert "--width a multiple of 8" in _error_line(capsys)


def test_eval_refuses_a_broken_checkpoint_once_before_any_episode(tmp_path, capsys):
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"not a checkpoint")
    out = tmp_path / "r.jsonl"
    for checkpoint, said in ((tmp_path / "missing.pt", "does not exist"), (bad, "cannot read PONI checkpoint")):
        argv = ["eval", "--policy", "poni", "--houses", "1", "--episodes", "2", "--frame", "60x80"]
        assert main([*argv, "--set", f"poni.checkpoint={checkpoint}", "--out", str(out)]) == 2
        assert said in _error_line(capsys)  # one line: no error row per episode
        assert not out.exists()


def test_poni_trains_shows_and_runs_an_episode_from_the_command_line(tmp_path, capsys, monkeypatch):
    checkpoint = tmp_path / "p.pt"
    argv = ["--procedural-houses", "3", "--samples-per-procedural", "2", "--epochs", "1", "--width", "8"]
    argv += ["--walk-procedural-houses", "0"]  # the first stage alone (test_potential_walks runs both)
    assert main(["poni", "train", *argv, "--workers", "1", "--out", str(checkpoint)]) == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert summary["out"] == str(checkpoint) and summary["windows"]["train"] >= 1
    assert main(["poni", "show", str(checkpoint)]) == 0
    shown = json.loads(capsys.readouterr().out)
    assert shown["geometry"] == {k: float(getattr(PotentialConfig(), k)) for k in GEOMETRY}
    assert shown["options"]["width"] == 8 and shown["checkpoint"] == str(checkpoint)
    chosen = []
    select = PotentialPolicy.select

    def counted(self, *args):
        chosen.append(select(self, *args))
        return chosen[-1]

    monkeypatch.setattr(PotentialPolicy, "select", counted)
    results = tmp_path / "poni.jsonl"
    sets = ["--set", "sim.max_steps=30", "--set", f"poni.checkpoint={checkpoint}"]
    episode = ["--houses", "1", "--episodes", "1", "--frame", "60x80", "--out", str(results)]
    assert main(["eval", "--policy", "poni", *episode, *sets]) == 0
    row = json.loads(results.read_text().splitlines()[0])
    assert row["policy"] == "poni" and row["config"]["poni"]["checkpoint"] == str(checkpoint)
    assert row["config"]["poni"]["range_m"] == PotentialConfig().range_m
    assert chosen and chosen[0].fusion.scorer == "poni (p.pt)"  # the episode chose with the trained net

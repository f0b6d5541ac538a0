"""l3mvn-ff's map head: PONI's expected metres corrected by the words of each frontier's window."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
import torch

from l3mvn.agent.frontiers import Frontier
from l3mvn.agent.potentials import CHANNELS, OUTPUTS, PotentialModel, PotentialNet, PotentialPolicy, objects_hot
from l3mvn.agent.potentials.language_map import (
    LanguageMapHead,
    LanguageResidual,
    is_language_map,
    map_head_file,
    shipped_language_map,
    window_sentences,
)
from l3mvn.agent.potentials.model import GEOMETRY
from l3mvn.core.categories import GIBSON_CATEGORIES, GOAL_CATEGORIES
from l3mvn.core.config import PotentialConfig
from l3mvn.core.errors import L3MVNError
from l3mvn.core.paths import file_sha256
from l3mvn.run.cli import main
from l3mvn.run.potentials.language_map import LanguageMapOptions, Lists, fit_language_map, prepare, regret
from l3mvn.run.potentials.train import choice_regret
from l3mvn.run.potentials.walks import WalkSet
from tests.test_potentials import CELLS, POLICY_CFG, _model, _potentials, _sem_map

TOILET = GOAL_CATEGORIES.index("toilet")


pytestmark = pytest.mark.usefixtures("one_torch_thread")  # tiny nets: see conftest


def _poni_file(tmp_path, cfg: PotentialConfig = PotentialConfig()) -> tuple[PotentialModel, str]:
    torch.manual_seed(0)
    model = PotentialModel(PotentialNet(width=8).eval(), {k: float(getattr(cfg, k)) for k in GEOMETRY})
    path = tmp_path / "poni.pt"
    model.save(path)
    return model, str(path)


def _head(sha: str, embeddings: dict[str, np.ndarray], net: LanguageResidual | None = None) -> LanguageMapHead:
    """A head whose sentences are already embedded (the cache every head keeps), so no embedder loads."""
    head = LanguageMapHead(net or LanguageResidual(4, 8), "minilm", sha, {}, "words.pt")
    head._cache.update(embeddings)
    return head


def _even_model(monkeypatch) -> PotentialModel:
    """A model that rates every cell alike: the choice turns on travel and words alone."""
    model = _model(POLICY_CFG)
    monkeypatch.setattr(model, "predict", lambda features: _potentials())
    return model


def _frontiers(objects: list[tuple[str, ...]], costs: tuple[float, ...]) -> list[Frontier]:
    return [
        Frontier(
            id=i,
            cells=np.array(CELLS[i]),
            center=CELLS[i][0],
            size=len(CELLS[i]),
            distance_m=c,
            utility=1.0,
            cost=c,
            s_cu=0.5,
            objects=o,
        )
        for i, (o, c) in enumerate(zip(objects, costs))
    ]


def test_window_sentences_are_the_feed_forward_sentence_of_the_semexp_categories_held():
    hot = objects_hot([("sink", "bed", "lamp"), ()])
    assert hot.shape == (2, len(GIBSON_CATEGORIES)) and hot[0].sum() == 2 and not hot[1].any()  # no lamp channel
    first, empty = window_sentences(hot)
    assert "bed" in first and "sink" in first and "lamp" not in first and first != empty


def test_an_untrained_head_chooses_as_poni_and_records_each_frontiers_sentence():
    model = _model(POLICY_CFG)  # a random net: the potentials differ between the frontiers
    objects = [("sink",), ("bed", "chair")]
    sentences = window_sentences(objects_hot(objects))
    rng = np.random.default_rng(0)
    head = _head("x", {s: rng.random(4).astype(np.float32) for s in sentences})
    frontiers = _frontiers(objects, (3.0, 1.0))
    plain = PotentialPolicy(model, POLICY_CFG, 40.0).select(frontiers, _sem_map(), "toilet", rng)
    worded = PotentialPolicy(model, POLICY_CFG, 40.0, head, "l3mvn-ff").select(frontiers, _sem_map(), "toilet", rng)
    assert plain is not None and worded is not None
    assert worded.frontier == plain.frontier and worded.fusion.compared == plain.fusion.compared
    assert worded.fusion.scorer == "poni (untrained) + minilm words (words.pt)"
    assert [s.queries for s in worded.language] == [{"toilet": s} for s in sentences]
    assert worded.reason.startswith("PONI + words:") and plain.language[0].queries == {}


def test_the_heads_metres_are_added_to_ponis_and_move_the_choice(monkeypatch):
    model = _even_model(monkeypatch)
    objects = [("sink",), ("bed",)]
    sink, bed = window_sentences(objects_hot(objects))
    net = LanguageResidual(4, 8)
    with torch.no_grad():  # hidden unit 0 passes input 0; it takes 5 m off the toilet's metres
        net.net[0].weight.zero_()
        net.net[0].bias.zero_()
        net.net[0].weight[0, 0] = 1.0
        net.net[2].weight[TOILET, 0] = -5.0
    head = _head("x", {sink: np.array([1, 0, 0, 0], np.float32), bed: np.zeros(4, np.float32)}, net)
    frontiers = _frontiers(objects, (3.0, 1.0))
    rng = np.random.default_rng(0)
    plain = PotentialPolicy(model, POLICY_CFG, 40.0).select(frontiers, _sem_map(), "toilet", rng)
    worded = PotentialPolicy(model, POLICY_CFG, 40.0, head).select(frontiers, _sem_map(), "toilet", rng)
    assert plain is not None and worded is not None
    np.testing.assert_allclose(np.subtract(worded.fusion.compared, plain.fusion.compared), [-5.0, 0.0])
    assert plain.frontier == 1 and worded.frontier == 0  # 3 - 5 m beats 1 m with the potentials equal
    assert worded.language[0].expected_m["toilet"] == pytest.approx(plain.language[0].expected_m["toilet"] - 5.0)
    # Another goal reads its own output: the bed's metres are PONI's.
    again = PotentialPolicy(model, POLICY_CFG, 40.0, head).select(frontiers, _sem_map(), "bed", rng)
    assert (
        again is not None
        and again.fusion.compared
        == PotentialPolicy(model, POLICY_CFG, 40.0).select(frontiers, _sem_map(), "bed", rng).fusion.compared
    )


def _lists(n: int, rng: np.random.Generator) -> Lists:
    """Choices between two frontiers that PONI rates alike; for the toilet, the one whose window
    sentence is 1 is truly 4 m nearer. Other goals are not in the house."""
    sentence = np.stack([rng.permutation(2) for _ in range(n)])
    true = np.full((n, 2, len(GOAL_CATEGORIES)), np.nan)
    true[:, :, TOILET] = np.where(sentence == 1, 2.0, 6.0)
    return Lists(np.zeros((n, 2, len(GOAL_CATEGORIES))), true, np.ones((n, 2), bool), sentence, np.full(n, TOILET))


def test_fitting_learns_what_the_words_say_and_keeps_poni_where_they_say_nothing():
    rng = np.random.default_rng(0)
    embeddings = torch.eye(2)
    train, val = _lists(64, rng), _lists(32, rng)
    options = LanguageMapOptions(hidden=8, epochs=40, batch=16, learning_rate=1e-2)
    net, history = fit_language_map(train, val, embeddings, options, log=lambda line: None)
    assert history[0]["val_regret_m"] == pytest.approx(2.0)  # PONI's ties go to the first frontier: half lose 4 m
    assert regret(net, embeddings, val)["regret_m"] == 0.0 and [r["epoch"] for r in history] == list(range(41))
    # Words that cannot tell the frontiers apart (both windows read alike): epoch 0, PONI, is kept.
    flat = _lists(32, rng)
    flat.sentence[:] = 0
    net, _ = fit_language_map(flat, flat, embeddings, options, log=lambda line: None)
    for param in net.net[2].parameters():
        assert torch.equal(param, torch.zeros_like(param))


def _walk_set(metres: np.ndarray, cost: np.ndarray, choices: int) -> WalkSet:
    """``choices`` choices among the same frontiers (``cost`` (F,), ``metres`` (F, goals)), each with
    its own random window and size bonuses, every frontier three cells of it."""
    rng = np.random.default_rng(1)
    f = len(cost)
    return WalkSet(
        rng.integers(0, 256, (choices, len(CHANNELS), 32, 32), dtype=np.uint8),
        np.full(choices, TOILET, np.int8),
        np.zeros(choices, np.int16),
        ["house"] * choices,
        np.repeat(np.arange(choices, dtype=np.int32), f),
        np.tile(cost.astype(np.float32), choices),
        np.tile(metres.astype(np.float32), (choices, 1)),
        np.repeat(np.arange(choices * f, dtype=np.int32), 3),
        rng.integers(0, 32 * 32, choices * f * 3).astype(np.int32),
        rng.uniform(0.0, 3.0, choices * f).astype(np.float32),
        np.zeros((choices * f, len(GIBSON_CATEGORIES)), bool),
    )


def test_the_heads_regret_at_zero_is_ponis_choice_regret_and_an_off_floor_frontier_counts_worst():
    torch.manual_seed(3)
    net = PotentialNet(width=8).eval()
    poni = PotentialModel(net, {k: float(getattr(POLICY_CFG, k)) for k in GEOMETRY})
    cost = np.array([1.0, 2.0, 3.5, 0.5])
    metres = np.random.default_rng(2).uniform(0.5, 9.0, (4, len(GOAL_CATEGORIES)))
    walks = _walk_set(metres, cost, 6)
    cfg = replace(POLICY_CFG, size_bonus=True)  # the totals carry the size bonus, as the shipped PONI's do
    sentences: dict[str, int] = {}
    lists = prepare(walks, poni, cfg, sentences)
    zero = LanguageResidual(4, 8)  # the untrained head: PONI's own choices
    embeddings = torch.zeros(len(sentences), 4)
    ours, theirs = regret(zero, embeddings, lists), choice_regret(net, walks, cfg)
    assert ours["regret_m"] == pytest.approx(theirs["regret_m"]) and ours["regret_m"] > 0
    assert ours["goal_regret_m"] == pytest.approx(theirs["goal_regret_m"])
    # A frontier off the true floor (no metres on): the worst known total, whatever its travel.
    lists.true[:, 0, :] = np.nan
    lists.totals[:] = 10.0
    lists.totals[:, 0, :] = 0.0  # every choice takes it
    known = cost[1:, None] + metres[1:]
    assert regret(zero, embeddings, lists)["regret_m"] == pytest.approx(float((known.max(0) - known.min(0)).mean()))


def test_a_head_saves_loads_and_is_refused_over_another_poni_checkpoint(tmp_path):
    _, poni = _poni_file(tmp_path)
    net = LanguageResidual(4, 8)
    with torch.no_grad():
        net.net[2].bias[TOILET] = 1.5
    path = tmp_path / "words.pt"
    LanguageMapHead(net, "minilm", file_sha256(poni), {"note": "test"}, str(path)).save(path)
    loaded = LanguageMapHead.load(path, poni)
    assert loaded.encoder == "minilm" and loaded.training == {"note": "test"} and loaded.net.hidden == 8
    assert torch.equal(loaded.net.net[2].bias, net.net[2].bias)
    assert map_head_file(str(path)) == path and map_head_file("map") == shipped_language_map()
    assert map_head_file("rooms") is None and map_head_file(poni) is None  # a PONI checkpoint is no head
    other = tmp_path / "other"
    other.mkdir()
    _, second = _poni_file(other, PotentialConfig(size_bonus=False))
    with pytest.raises(L3MVNError, match="corrects another PONI checkpoint") as err:
        LanguageMapHead.load(path, second)
    assert "\n" not in str(err.value)
    for bad, says in ((tmp_path / "none.pt", "does not exist"), (poni, "is not a map head")):
        with pytest.raises(L3MVNError, match=says):
            LanguageMapHead.load(bad, poni)
    (tmp_path / "junk.pt").write_bytes(b"not torch")
    with pytest.raises(L3MVNError, match="cannot read map head"):
        LanguageMapHead.load(tmp_path / "junk.pt", poni)
    assert not is_language_map(tmp_path / "junk.pt")  # asked again once the file changes, not from memory
    LanguageMapHead(net, "minilm", file_sha256(poni), {}, "").save(tmp_path / "junk.pt")
    assert is_language_map(tmp_path / "junk.pt") and map_head_file(str(tmp_path / "junk.pt")) is not None


def _error_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "\n" not in err
    return err


def test_train_language_walks_fits_saves_and_the_head_runs_in_an_episode(tmp_path, capsys):
    _, poni = _poni_file(tmp_path)
    out = tmp_path / "words.pt"
    walk = ["--walk-procedural-houses", "2", "--walk-episodes-per-procedural", "1", "--walk-procedural-first", "5"]
    argv = ["poni", "train-language", *walk, "--epochs", "2", "--hidden", "8", "--workers", "1"]
    assert main([*argv, "--poni", poni, "--out", str(out)]) == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert summary["out"] == str(out) and summary["choices"]["train"] >= 1
    head = LanguageMapHead.load(out, poni)
    assert [row["epoch"] for row in head.training["history"]] == [0, 1, 2]
    assert main(["poni", "show", str(out)]) == 0  # what it reads and corrects, without its weights
    shown = json.loads(capsys.readouterr().out)
    assert shown["kind"] == "language-map" and shown["poni_sha256"] == head.poni_sha256 and "state" not in shown
    assert head.training["walking"]["walk_procedural_first"] == 5 and head.training["poni_checkpoint"] == "poni.pt"
    results = tmp_path / "ff.jsonl"
    sets = ["--set", "sim.max_steps=30", "--set", f"poni.checkpoint={poni}"]
    episode = ["--houses", "1", "--episodes", "1", "--frame", "60x80", "--out", str(results)]
    assert main(["eval", "--policy", "l3mvn-ff", "--head", str(out), *episode, *sets]) == 0
    row = json.loads(results.read_text().splitlines()[0])
    assert row["policy"] == "l3mvn-ff" and row["config"]["policy"]["head"] == str(out)


@pytest.mark.parametrize(
    ("argv", "says"),
    [
        (["--policy", "l3mvn-ff", "--selection", "expected"], "--selection and --embedder apply to the object-list"),
        (["--policy", "near+llm"], "use it with l3mvn-ff"),
        (["--policy", "l3mvn-ff", "--set", "poni.checkpoint=missing.pt"], "does not exist"),
    ],
)
def test_the_map_head_refuses_what_it_cannot_honour_before_any_episode(tmp_path, capsys, argv, says):
    out = tmp_path / "r.jsonl"
    assert main(["eval", *argv, "--head", "map", "--houses", "1", "--episodes", "1", "--out", str(out)]) == 2
    assert says in _error_line(capsys) and not out.exists()


def test_train_language_refuses_bad_settings_in_one_line(tmp_path, capsys, monkeypatch):
    base = ["poni", "train-language", "--walk-procedural-houses", "0", "--workers", "1"]
    assert main([*base, "--out", str(tmp_path / "x.txt")]) == 2
    assert "--out must be a .pt file" in _error_line(capsys)
    assert main([*base, "--out", str(tmp_path / "x.pt"), "--learning-rate", "nan"]) == 2
    assert "--learning-rate must be a positive number" in _error_line(capsys)
    assert main([*base, "--out", str(tmp_path / "x.pt")]) == 2
    assert "nothing to walk" in _error_line(capsys) and not (tmp_path / "x.pt").exists()
    walks = ["--walk-procedural-houses", "1", "--walk-episodes-per-procedural", "1"]
    from l3mvn.run.potentials import language_map

    monkeypatch.setattr(language_map, "walk_splits", lambda *a, **k: pytest.fail("walked before refusing"))
    assert main([*base, *walks, "--out", str(tmp_path / "x.pt"), "--encoder", str(tmp_path / "no-model")]) == 2
    assert "no-model" in _error_line(capsys) and not (tmp_path / "x.pt").exists()  # refused before walking


def test_the_shipped_map_head_corrects_the_shipped_poni_and_records_its_scores():
    from l3mvn.agent.potentials import shipped_checkpoint

    head = LanguageMapHead.load(None, shipped_checkpoint())
    assert head.encoder == "minilm" and head.training["poni_checkpoint"] == "poni.pt"
    scores = head.training["scores"]
    assert {"val", "test"} <= set(scores) and all({"head", "poni"} <= set(s) for s in scores.values())
    assert len(OUTPUTS) - 1 == head.net.net[2].out_features

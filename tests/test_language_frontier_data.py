"""Frontier data and the frontier-trained head: windows, queries, labels, split and determinism.

The house is drawn by hand: a hall (what the agent has mapped) with door A on its left into a room
holding a toilet and door B on its right into a room holding a bed. A sink stands by door A and a
couch by door B, 4 m apart, so a +-3 m window sees one each.
"""

import json

import numpy as np
import pytest
import torch
from conftest import write_frontier_file

from l3mvn.agent.frontiers import extract_frontiers
from l3mvn.agent.language.frontier_file import frontier_query, load_choices
from l3mvn.agent.language.frontier_head import house_split, train_frontier_head
from l3mvn.agent.language.vocabulary import GOALS
from l3mvn.agent.mapping import SemanticMap
from l3mvn.core.categories import GIBSON_CATEGORIES
from l3mvn.core.config import Config, FrontierConfig
from l3mvn.core.errors import L3MVNError
from l3mvn.run.eval.frontier_data import label_frontiers, read_done, window_object_distances
from l3mvn.world.baselines import object_distances
from l3mvn.world.scenes.scene import SceneMap
from l3mvn.world.task import ObjectNavTask

SIZE, RES = 200, 0.05
HALL = (80, 120, 60, 141)  # rows r0:r1, cols c0:c1 (walls on its border)
DOOR_ROWS = slice(95, 106)


def _house() -> SceneMap:
    nav = np.zeros((SIZE, SIZE), bool)
    r0, r1, c0, c1 = HALL
    nav[r0 + 3 : r1 - 3, c0 + 3 : c1 - 3] = True
    nav[40:160, 5 : c0 - 3] = True  # left room (door A)
    nav[40:160, c1 + 3 : 195] = True  # right room (door B)
    nav[DOOR_ROWS, c0 - 4 : c0 + 4] = True
    nav[DOOR_ROWS, c1 - 4 : c1 + 4] = True
    objects = np.zeros((len(GIBSON_CATEGORIES), SIZE, SIZE), bool)
    objects[GIBSON_CATEGORIES.index("toilet"), 60:66, 20:26] = True
    objects[GIBSON_CATEGORIES.index("bed"), 60:90, 160:185] = True
    nav &= ~objects.any(axis=0)
    return SceneMap(name="Drawn", floor=0, categories=GIBSON_CATEGORIES, navigable=nav, objects=objects)


def _agent_map() -> SemanticMap:
    """The hall as mapped: explored inside and on its walls, both doorways open; a sink by door A and
    a couch by door B. Map cell (r, c) is world ((c + 0.5) * RES, (r + 0.5) * RES), as in the scene."""
    r0, r1, c0, c1 = HALL
    explored = np.zeros((SIZE, SIZE), bool)
    explored[r0:r1, c0:c1] = True
    obstacle = explored.copy()
    obstacle[r0 + 1 : r1 - 1, c0 + 1 : c1 - 1] = False
    obstacle[DOOR_ROWS, c0] = obstacle[DOOR_ROWS, c1 - 1] = False
    cats = np.zeros((len(GIBSON_CATEGORIES), SIZE, SIZE), bool)
    cats[GIBSON_CATEGORIES.index("sink"), 95:98, 66:69] = True
    cats[GIBSON_CATEGORIES.index("couch"), 104:107, 131:134] = True
    half = SIZE // 2
    return SemanticMap(
        obstacle=obstacle,
        explored=explored,
        visited=np.zeros_like(explored),
        categories=cats,
        category_names=GIBSON_CATEGORIES,
        looked=explored,
        resolution_m=RES,
        start_xy=((half) * RES, (half) * RES),
        agent_cell=(100, 100),
        agent_heading=0.0,
        local_cells=SIZE,
        footprint_radius_cells=2,
    )


def _frontiers(sem_map: SemanticMap, cfg: FrontierConfig | None = None):
    cfg = cfg or FrontierConfig()
    rows, cols = np.indices(sem_map.obstacle.shape)
    dist = np.hypot(rows - 100, cols - 100) * RES  # straight line stands in for the planner's field
    found = extract_frontiers(
        sem_map.explored,
        sem_map.obstacle,
        sem_map.agent_cell,
        dist,
        sem_map.categories,
        sem_map.category_names,
        cfg,
        resolution_m=RES,
    )
    assert len(found) == 2
    return sorted(found, key=lambda f: f.center[1])  # door A (left) first


def test_a_frontier_window_is_local_and_each_frontier_sees_its_own_objects():
    sem_map = _agent_map()
    a, b = _frontiers(sem_map)
    assert a.objects == ("sink",) and b.objects == ("couch",)
    near_a = window_object_distances(a, sem_map, FrontierConfig().window_cells(RES))
    assert list(near_a) == ["sink"] and 0.2 < near_a["sink"] < 0.6
    # The window is +-window_m: a smaller one loses the couch, a larger one sees both objects.
    assert _frontiers(sem_map, FrontierConfig(window_m=0.2))[1].objects == ()
    assert _frontiers(sem_map, FrontierConfig(window_m=4.5))[0].objects == ("couch", "sink")


def test_the_frontier_query_names_exactly_the_frontier_objects_even_a_goal_alone():
    assert frontier_query(("sink",)) == "This frontier contains sink."
    assert frontier_query(("chair",)) == "This frontier contains chair."  # a goal category is an object too
    assert frontier_query(("vase", "Sofa", "dining-table")) == "This frontier contains couch, dining table, and vase."
    assert frontier_query(()) == "This frontier contains nothing."


def test_labels_put_the_toilet_behind_door_a_and_the_bed_behind_door_b():
    scene, sem_map = _house(), _agent_map()
    task = ObjectNavTask(scene, Config())
    fields = {g: object_distances(task, g) for g in ("toilet", "bed")}
    a, b = label_frontiers(_frontiers(sem_map), sem_map, fields, FrontierConfig().window_cells(RES))
    assert a["goal_m"]["toilet"] < b["goal_m"]["toilet"] - 3.0
    assert b["goal_m"]["bed"] < a["goal_m"]["bed"] - 3.0
    assert a["goal_m"]["tv"] is None  # the house has none
    assert (
        a["objects"] == {"sink": pytest.approx(a["objects"]["sink"])} and a["query"] == "This frontier contains sink."
    )


def test_house_split_is_by_house_and_never_puts_one_house_on_two_sides(tmp_path):
    houses = [f"House{i}" for i in range(200)]
    sides = {h: house_split(h) for h in houses}
    assert set(sides.values()) == {"train", "val", "test"}
    assert all(house_split(h) == sides[h] for h in houses)  # a pure function of the name
    path = write_frontier_file(tmp_path, houses=["Allensville", "Hiteman", "Merom", "Coffeen"])
    by_house = {}
    for c in load_choices(path):
        by_house.setdefault(c.house, set()).add(house_split(c.house))
    assert all(len(s) == 1 for s in by_house.values())
    assert by_house["Hiteman"] == {"val"} and by_house["Merom"] == {"test"} and by_house["Coffeen"] == {"train"}


def test_training_is_deterministic_for_a_seed_and_learns_the_toilet_side(tmp_path):
    data = write_frontier_file(tmp_path)
    one = train_frontier_head([data], out=tmp_path / "a.pt", epochs=30, seed=3)
    two = train_frontier_head([data], out=tmp_path / "b.pt", epochs=30, seed=3)
    a, b = torch.load(tmp_path / "a.pt", weights_only=True), torch.load(tmp_path / "b.pt", weights_only=True)
    assert all(torch.equal(a["state_dict"][k], b["state_dict"][k]) for k in a["state_dict"])
    assert one["val"] == two["val"] and one["houses"]["val"] == ["Hiteman"]
    assert one["val"]["regret_m"] < one["val"]["nearest_regret_m"]  # the sink side wins on the unseen house
    assert a["meta"]["kind"] == "frontiers" and a["meta"]["houses"]["train"] == ["Allensville", "Coffeen"]


def test_resume_keeps_finished_episodes_and_drops_a_block_cut_off(tmp_path):
    path = tmp_path / "f.jsonl"
    done = json.dumps({"house": "H", "episode": "H/0/0", "seed": 0, "goal": "bed", "mapped": [], "frontiers": []})
    path.write_text(
        "\n".join(
            [
                done,
                json.dumps({"done": "H/0/0", "seed": 0, "choices": 1}),
                done.replace("H/0/0", "H/0/1"),
                '{"house": "H", "epis',
            ]
        )
        + "\n"
    )
    finished, houses, keep = read_done(path)
    assert finished == {("H/0/0", 0)} and houses == set() and len(keep) == 2


def test_resume_drops_a_procedural_house_until_all_its_episodes_are_done(tmp_path):
    path = tmp_path / "f.jsonl"
    row = {"house": "P", "episode": "P/0/0", "seed": 0, "goal": "bed", "mapped": [], "frontiers": []}
    lines = [
        json.dumps(row),
        json.dumps({"done": "P/0/0", "seed": 0, "choices": 1, "procedural": 7, "of": 2}),
        json.dumps(row | {"house": "Q", "episode": "Q/0/0"}),
        json.dumps({"done": "Q/0/0", "seed": 0, "choices": 1, "procedural": 8, "of": 1}),
    ]
    path.write_text("\n".join(lines) + "\n")
    finished, houses, keep = read_done(path)
    assert houses == {(8, 0)} and finished == {("Q/0/0", 0)} and keep == lines[2:]


def test_a_malformed_frontier_file_is_one_line_error(tmp_path):
    path = tmp_path / "bad.jsonl"
    path.write_text('{"house": "H", "goal": "bed"}\n')
    with pytest.raises(L3MVNError, match=r"bad.jsonl:1: not a frontier-data line") as err:
        load_choices(path)
    assert "\n" not in str(err.value)
    with pytest.raises(L3MVNError, match="not found"):
        load_choices(tmp_path / "missing.jsonl")


def test_generation_is_deterministic_for_a_seed_and_resumes_where_it_stopped(tiny_dataset, tmp_path):
    from l3mvn.run.eval.frontier_data import generate_frontier_data

    first, second = tmp_path / "a.jsonl", tmp_path / "b.jsonl"
    summary = generate_frontier_data(str(tiny_dataset), "val", first, houses=["Tiny"], limit=2)
    assert summary["houses"] == 1 and summary["choices"] > 0 and summary["episodes"] >= 1
    lines = first.read_text().splitlines()
    assert sum('"done"' in line for line in lines) == 2
    # Cut off inside the second episode's block: resume redoes that episode only, to the same bytes.
    done_at = next(i for i, line in enumerate(lines) if '"done"' in line)
    second.write_text("\n".join(lines[: done_at + 1] + [lines[-1][:25]]) + "\n")
    calls = []
    generate_frontier_data(
        str(tiny_dataset),
        "val",
        second,
        houses=["Tiny"],
        limit=2,
        resume=True,
        progress=lambda done, total: calls.append((done, total)),
    )
    assert second.read_text() == first.read_text()
    assert calls[-1] == (1, 1)
    row = next(json.loads(line) for line in lines if '"frontiers"' in line)
    assert set(row["frontiers"][0]["goal_m"]) == set(GOALS) and row["frontiers"][0]["query"].startswith("This frontier")
    with pytest.raises(L3MVNError, match="exists; pass --resume"):
        generate_frontier_data(str(tiny_dataset), "val", first, houses=["Tiny"], limit=2)
    with pytest.raises(L3MVNError, match="unknown house.*valid: Tiny, Wee"):
        generate_frontier_data(str(tiny_dataset), "val", tmp_path / "c.jsonl", houses=["Nowhere"])
    with pytest.raises(L3MVNError, match="cannot walk frontier data.*valid: .*cost-utility"):
        generate_frontier_data(str(tiny_dataset), "val", tmp_path / "c.jsonl", policy="oracle-frontier")


def test_procedural_houses_are_walked_beside_a_dataset_and_resume_by_house(tiny_dataset, tmp_path):
    from l3mvn.run.eval.frontier_data import generate_frontier_data

    first, second = tmp_path / "a.jsonl", tmp_path / "b.jsonl"
    kw = {"houses": ["Tiny"], "limit": 1, "procedural_houses": 2, "procedural_seed": 3, "episodes_per_procedural": 2}
    summary = generate_frontier_data(str(tiny_dataset), "val", first, **kw)
    choices = load_choices(first)
    assert {c.house for c in choices} == {"Tiny", "procedural-0003", "procedural-0004"}
    assert summary["houses"] == 3
    lines = first.read_text().splitlines()
    ends = [json.loads(line) for line in lines if '"done"' in line]
    assert [e.get("procedural") for e in ends] == [None, 3, 3, 4, 4] and {e.get("of") for e in ends[1:]} == {2}
    # Cut off after the last house's first episode: resume walks that whole house again, to the same bytes.
    cut = max(i for i, line in enumerate(lines) if '"done"' in line and '"procedural": 4' not in line)
    second.write_text("\n".join(lines[: cut + 2]) + "\n")
    calls = []
    generate_frontier_data(
        str(tiny_dataset), "val", second, resume=True, progress=lambda d, t: calls.append((d, t)), **kw
    )
    assert second.read_text() == first.read_text() and calls[-1] == (1, 1)
    alone = tmp_path / "p.jsonl"
    generate_frontier_data(None, "val", alone, procedural_houses=1, procedural_seed=3)
    assert alone.read_text().splitlines() == [line for line in lines if '"procedural-0003' in line]
    with pytest.raises(L3MVNError, match="nothing to walk: give --dataset, --procedural-houses"):
        generate_frontier_data(None, "val", tmp_path / "c.jsonl")
    with pytest.raises(L3MVNError, match="--houses picks houses of --dataset"):
        generate_frontier_data(None, "val", tmp_path / "c.jsonl", houses=["Tiny"], procedural_houses=1)
    with pytest.raises(L3MVNError, match="--episodes-per-procedural >= 1"):
        generate_frontier_data(None, "val", tmp_path / "c.jsonl", procedural_houses=1, episodes_per_procedural=0)

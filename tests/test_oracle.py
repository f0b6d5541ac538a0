"""The shortest-path oracle's corner fallback, and episodes no agent can finish (no path to the goal)."""

import json
import math

from l3mvn.core.config import Config, SimConfig
from l3mvn.core.types import Action, Pose
from l3mvn.run.cli import main
from l3mvn.world.baselines import OraclePolicy
from l3mvn.world.episode import Episode
from l3mvn.world.sim.simulator import BuiltinSimulator
from l3mvn.world.task import ObjectNavTask


def _episode(scene, goal="toilet") -> Episode:
    r, c = 55, 40  # west room, well inside the floor
    x, y = scene.cell_center(r, c)
    return Episode(episode_id=0, scene=scene.name, floor=0, start=Pose(x, y, 0.0), goal=goal)


def test_when_no_forward_move_helps_the_oracle_turns_towards_the_path(tiny_scene, monkeypatch):
    env = BuiltinSimulator(tiny_scene, SimConfig())
    oracle = OraclePolicy(env, ObjectNavTask(tiny_scene, Config(sim=env.cfg)))
    episode = _episode(tiny_scene)
    obs = env.reset(episode)
    oracle.reset(episode)
    monkeypatch.setattr(env, "forward_result", lambda pose: (pose, 0.0))  # every move blocked
    r, c = tiny_scene.cell_of(obs.pose.x, obs.pose.y)
    tr, tc = oracle._descend(r, c)
    assert oracle._field[tr, tc] < oracle._field[r, c]  # the look-ahead lies downhill
    tx, ty = tiny_scene.cell_center(tr, tc)
    err = (math.atan2(ty - obs.pose.y, tx - obs.pose.x) - obs.pose.heading + math.pi) % (2 * math.pi) - math.pi
    assert oracle.act(obs) == (Action.TURN_LEFT if err > 0 else Action.TURN_RIGHT)


def test_infeasible_episodes_are_failures_counted_apart_and_the_run_finishes(shut_dataset, tmp_path, capsys):
    out = tmp_path / "results.jsonl"
    assert (
        main(
            [
                "eval",
                "--dataset",
                str(shut_dataset),
                "--split",
                "val",
                "--policy",
                "oracle",
                "--frame",
                "60x80",
                "--out",
                str(out),
                "--json",
            ]
        )
        == 0
    )
    printed = capsys.readouterr().out
    summary = json.loads(printed.strip().splitlines()[-1])
    rows = {r["episode_id"]: r for r in map(json.loads, out.read_text().splitlines())}
    assert len(rows) == 6 and summary["episodes"] == 6
    blocked = [r for r in rows.values() if r["failure"] == "no_path"]
    assert len(blocked) == summary["no_path"] == 5
    assert all(r["success"] == 0 and r["spl"] == 0 and r["shortest_path_m"] is None for r in blocked)
    assert all(r["steps"] == 1 for r in blocked)  # the oracle knows there is no way and stops
    assert rows[5]["success"] == 1.0 and summary["success"] == round(1 / 6, 4)
    assert "5 episodes have no path from start to goal" in printed


def test_the_oracle_succeeds_where_each_goal_has_a_single_view_point(tmp_path, capsys):
    """habitat's 0.1 m around one view point is a few cells: the greedy walk stalls beside it and
    the oracle searches its way in over the motion model (without the search each of these episodes fails)."""
    import gzip

    from l3mvn.world.datasets.hm3d_export import export_hm3d

    export_hm3d(tmp_path, 4, seed=3)
    for content in (tmp_path / "objectnav_hm3d_v2" / "val" / "content").glob("*.json.gz"):
        data = json.loads(gzip.decompress(content.read_bytes()))
        for goals in data["goals_by_category"].values():
            for goal in goals:
                goal["view_points"] = [goal["view_points"][len(goal["view_points"]) // 2]]
        content.write_bytes(gzip.compress(json.dumps(data).encode()))
    out = tmp_path / "oracle.jsonl"
    assert (
        main(
            [
                "eval",
                "--dataset",
                str(tmp_path / "objectnav_hm3d_v2"),
                "--scenes",
                str(tmp_path / "scene_datasets"),
                "--split",
                "val",
                "--policy",
                "oracle",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    rows = [json.loads(line) for line in out.read_text().splitlines()]
    assert len(rows) == 24 and [r["key"] for r in rows if r["success"] != 1] == []

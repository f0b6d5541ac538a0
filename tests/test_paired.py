"""Two result files compared episode by episode: paired differences with bootstrap intervals."""

from __future__ import annotations

import json

import pytest

from l3mvn.core.errors import L3MVNError
from l3mvn.run.cli import main
from l3mvn.run.eval.paired import compare_results, format_pairing


def _row(key: str, goal: str, success: float, spl: float, policy: str, max_steps: int = 500) -> dict:
    scene, floor, episode = key.split("/")
    return {
        "key": key,
        "scene": scene,
        "floor": int(floor),
        "episode_id": int(episode),
        "goal": goal,
        "policy": policy,
        "success": success,
        "spl": spl,
        "dtg": 0.0 if success else 2.0,
        "failure": "success" if success else "never_saw_target",
        "steps": 40,
        "path_length_m": 5.0,
        "shortest_path_m": 4.0,
        "rule": "semexp",
        "config_hash": policy,
        "seconds": 1.0,
        "extra": {},
        "config": {"sim": {"max_steps": max_steps}, "policy": {"scorer": None}},
    }


def _write(path, rows) -> str:
    path.write_text("".join(json.dumps(r) + "\n" for r in rows))
    return str(path)


def test_the_difference_is_paired_per_episode_with_an_interval_around_it(tmp_path):
    goals = ["toilet", "bed"] * 20
    a = [_row(f"H/0/{i}", g, 1.0, 0.5, "cost-utility") for i, g in enumerate(goals)]
    b = [_row(f"H/0/{i}", g, 1.0, 0.6 if g == "toilet" else 0.5, "l3mvn-zs") for i, g in enumerate(goals)]
    b[0] = _row("H/0/0", "toilet", 0.0, 0.0, "l3mvn-zs")  # one toilet lost
    b.append(_row("H/0/99", "bed", 1.0, 1.0, "l3mvn-zs"))  # only in B: left out
    pairing = compare_results(_write(tmp_path / "a.jsonl", a), _write(tmp_path / "b.jsonl", b))
    success, spl = pairing.rows["all"]
    assert (success.n, success.mean, success.wins, success.losses) == (40, pytest.approx(-1 / 40), 0, 1)
    assert spl.mean == pytest.approx((19 * 0.1 - 0.5) / 40) and spl.low <= spl.mean <= spl.high
    toilet = pairing.rows["toilet"][1]
    assert toilet.n == 20 and toilet.wins == 19 and toilet.losses == 1
    assert pairing.rows["bed"][1].mean == 0.0 and pairing.rows["bed"][1].low == pairing.rows["bed"][1].high == 0.0
    assert (pairing.only_a, pairing.only_b) == (0, 1)


def test_settings_that_differ_are_named_before_the_numbers(tmp_path, capsys):
    a = _write(tmp_path / "a.jsonl", [_row("H/0/0", "bed", 1.0, 0.5, "cost-utility", max_steps=100)])
    b = _write(tmp_path / "b.jsonl", [_row("H/0/0", "bed", 1.0, 0.5, "l3mvn-zs", max_steps=250)])
    assert main(["compare-results", a, b]) == 0
    out = capsys.readouterr().out
    assert "settings that differ (beside the policy): sim.max_steps: 100 -> 250" in out
    assert out.index("settings that differ") < out.index("| all |")
    assert "| all | 1 | success | 1.000 | 1.000 | +0.000 | [+0.000, +0.000] | 0 / 0 |" in format_pairing(
        compare_results(a, b)
    )


def test_files_that_share_no_episode_are_one_line(tmp_path, capsys):
    a = _write(tmp_path / "a.jsonl", [_row("H/0/0", "bed", 1.0, 0.5, "p")])
    b = _write(tmp_path / "b.jsonl", [_row("K/0/0", "bed", 1.0, 0.5, "p")])
    with pytest.raises(L3MVNError, match="share no episode"):
        compare_results(a, b)
    assert main(["compare-results", a, str(tmp_path / "missing.jsonl")]) == 2
    assert "missing.jsonl" in capsys.readouterr().err

"""bench/rule_ablation.py: every rule's switch is a real setting, and its table pairs and signs right."""

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from l3mvn.core.config import Config, config_dict, override

SCRIPT = Path(__file__).resolve().parents[1] / "bench" / "rule_ablation.py"


@pytest.fixture(scope="module")
def ablation(bench_script):
    return bench_script("rule_ablation")


def test_every_rule_switch_changes_the_config(ablation):
    default = config_dict(Config())
    names = [r.name for r in ablation.RULES]
    assert len(names) == len(set(names))
    for rule in ablation.RULES:
        changed = config_dict(override(Config(), list(rule.off)))
        assert changed != default, rule.name


def _row(scene, episode, success, spl, steps):
    return {
        "key": f"{scene}/0/{episode}",
        "scene": scene,
        "episode_id": episode,
        "goal": "bed",
        "policy": "frontier",
        "config_hash": "c0",
        "rule": "semexp",
        "success": int(success),
        "spl": spl if success else 0.0,
        "dtg": 0.0 if success else 2.0,
        "failure": "success" if success else "never_saw_target",
        "steps": steps,
        "path_length_m": steps * 0.25,
    }


def test_gain_is_default_minus_rule_off_split_by_house(ablation):
    base, off = {}, {}
    for e in range(4):
        for scene, rule_helps in (("Decide", True), ("Kept", False)):
            b = _row(scene, e, True, 0.8, 50)
            if rule_helps:  # without the rule: every other episode fails, the rest walk longer
                o = _row(scene, e, e % 2 == 1, 0.4, 90)
            else:
                o = _row(scene, e, True, 0.8, 50)
            base[b["key"]], off[o["key"]] = b, o
    rule = ablation.RULES[0]
    row = ablation.table_row(rule, base, off, {"Kept"}, seed=0)
    sr, _, spl, _ = row.decide
    assert sr == pytest.approx(0.5) and spl == pytest.approx(0.6)
    assert row.held_out[0] == 0 and row.held_out[2] == 0
    assert row.changed == 4 and row.steps == pytest.approx((4 * 90 + 4 * 50) / 8)
    no_held_out = ablation.table_row(rule, base, off, set(), seed=0)
    assert math.isnan(no_held_out.held_out[0])


def test_table_only_names_a_missing_run_and_unknown_rules(tmp_path):
    def run(*extra):
        return subprocess.run(
            [sys.executable, str(SCRIPT), "--dataset", "x", "--policy", "frontier", "--out", str(tmp_path), *extra],
            capture_output=True,
            text=True,
        )

    missing = run("--table-only")
    assert missing.returncode != 0 and "frontier_base.jsonl does not exist" in missing.stderr
    unknown = run("--rules", "keep_heading,teleport", "--table-only")
    assert unknown.returncode != 0 and "unknown rule(s) teleport" in unknown.stderr and "keep_heading" in unknown.stderr


def test_table_only_prints_a_row_per_rule(ablation, tmp_path):
    base = [_row("Decide", e, True, 0.8, 50) for e in range(3)]
    off = [_row("Decide", e, e > 0, 0.8 if e else 0.0, 50 if e else 500) for e in range(3)]
    for name, rows in (("base", base), ("keep_heading", off)):
        (tmp_path / f"frontier_{name}.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    done = subprocess.run(
        [
            sys.executable,
            str(SCRIPT),
            "--dataset",
            "x",
            "--policy",
            "frontier",
            "--out",
            str(tmp_path),
            "--rules",
            "keep_heading",
            "--table-only",
            "--held-out",
            "Elsewhere",
        ],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    line = next(li for li in done.stdout.splitlines() if li.startswith("| keep_heading"))
    assert "+0.333" in line and "| 1 | 200 |" in line


def test_set_reaches_every_configuration_before_the_rules_own(ablation, tmp_path, monkeypatch):
    """``--set policy.head=map`` ablates the rules of l3mvn-ff's map head: the default and each rule-off
    run carry it, and a rule's own setting comes after it (the later ``--set`` wins in ``l3mvn eval``)."""
    import argparse

    seen = []
    monkeypatch.setattr(
        ablation.subprocess, "run", lambda cmd, **kw: seen.append(cmd) or subprocess.CompletedProcess(cmd, 0)
    )
    args = argparse.Namespace(
        dataset="x", split="train", policy="l3mvn-ff", frame="480x640", workers=2, seed=0, set=["policy.head=map"]
    )
    ablation.run_eval(args, "base", (), tmp_path / "a.jsonl")
    ablation.run_eval(args, "commitment", ("agent.commitment_margin=0",), tmp_path / "b.jsonl")
    sets = [[c[i + 1] for i, a in enumerate(c) if a == "--set"] for c in seen]
    assert sets == [["policy.head=map"], ["policy.head=map", "agent.commitment_margin=0"]]


def test_a_bad_set_is_refused_before_any_run(tmp_path):
    done = subprocess.run(
        [sys.executable, str(SCRIPT), "--dataset", "x", "--policy", "poni", "--out", str(tmp_path / "o")]
        + ["--set", "agent.teleport=1"],
        capture_output=True,
        text=True,
    )
    assert done.returncode != 0 and done.stderr.startswith("error:") and "teleport" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and not (tmp_path / "o").exists()

"""The paper's tables as one command: every row we can run, beside the paper's numbers."""

from __future__ import annotations

import json

from l3mvn.core.config import Config
from l3mvn.run.cli import main
from l3mvn.run.eval.paper_tables import TABLES, TableRun, run_table


def _run(tmp_path, **kw) -> TableRun:
    return TableRun(None, "val", Config().with_frame(60, 80), tmp_path, episodes=1, houses=1, **kw)


def test_table_two_runs_every_row_and_names_the_stand_in_for_the_detector(tmp_path):
    text = run_table("paper-2", _run(tmp_path, seg_noise=0.2))
    lines = {line.split(" | ")[0].lstrip("| "): line for line in text.splitlines() if line.startswith("| ")}
    assert "0.490 / 0.231 / 4.335" in lines["Near + LLM"] and "(seg-noise 0.2) | 1 |" in lines["Near + LLM"]
    assert "(seg-noise" not in lines["Exp + LLM + GT Seg"] and lines["Exp + LLM + GT Seg"].endswith("| 1 |")
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "paper-2_exp+llm.jsonl",
        "paper-2_exp+llm_seg-noise.jsonl",
        "paper-2_exp_seg-noise.jsonl",
        "paper-2_near+llm_seg-noise.jsonl",
    ]
    sizes = {p.name: p.stat().st_size for p in tmp_path.iterdir()}
    assert run_table("paper-2", _run(tmp_path, seg_noise=0.2)) == text  # a second call resumes: nothing re-runs
    assert {p.name: p.stat().st_size for p in tmp_path.iterdir()} == sizes


def test_table_one_runs_its_rows_and_names_those_it_cannot_run_and_why(tmp_path, capsys):
    assert (
        main(["table", "paper-1", "--houses", "1", "--episodes", "1", "--frame", "60x80", "--results", str(tmp_path)])
        == 0
    )
    out = capsys.readouterr().out
    assert "| SemExp | 0.652 / 0.336 / 1.520 | 0.379 / 0.188 / 2.943 | not run |  |" in out
    assert "- SemExp: SemExp's global policy is a network trained with reinforcement learning" in out
    assert "- PONI: " not in out and "| PONI | 0.736 / 0.410 / 1.250 |" in out  # PONI runs: its own network
    assert "| L3MVN (Feed-forward), map head: PONI + words (not in the paper) | - | - | " in out
    ran = [(row.policy, row.head) for row in TABLES["paper-1"][1] if row.policy is not None]
    names = [f"paper-1_{p}_{h}-head.jsonl" if h else f"paper-1_{p}.jsonl" for p, h in ran]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(names) and "paper-1_l3mvn-ff_map-head.jsonl" in names
    row = json.loads((tmp_path / "paper-1_l3mvn-ff_map-head.jsonl").read_text().splitlines()[0])
    assert row["config"]["policy"]["head"] == "map"
    plain = json.loads((tmp_path / "paper-1_l3mvn-ff.jsonl").read_text().splitlines()[0])
    assert plain["config"]["policy"]["head"] is None

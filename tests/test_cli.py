"""The command line as a user meets it: one-line errors, the summary contract, the PNG render."""

import json
import subprocess
import sys

import pytest
from PIL import Image

from l3mvn.run.cli import main


def test_eval_oracle_on_a_dataset_prints_a_json_summary_last(tiny_dataset, tmp_path, capsys):
    out = tmp_path / "results.jsonl"
    code = main(
        [
            "eval",
            "--dataset",
            str(tiny_dataset),
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
    assert code == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert {"episodes", "success", "spl", "dtg"} <= set(summary)
    assert summary["episodes"] == 8 and summary["success"] == 1.0 and summary["rule"] == "semexp"
    rows = [json.loads(line) for line in out.read_text().splitlines()]
    assert len(rows) == 8 and all(r["policy"] == "oracle" and r["config_hash"] for r in rows)
    assert all("failure" in r and "config" in r for r in rows)


def test_resume_skips_finished_episodes(tiny_dataset, tmp_path, capsys):
    out = tmp_path / "results.jsonl"
    args = [
        "eval",
        "--dataset",
        str(tiny_dataset),
        "--split",
        "val",
        "--policy",
        "random-walk",
        "--frame",
        "60x80",
        "--out",
        str(out),
        "--json",
    ]
    assert main(args + ["--episodes", "3"]) == 0
    assert main(args + ["--resume"]) == 0
    keys = [json.loads(line)["key"] for line in out.read_text().splitlines()]
    assert len(keys) == 8 == len(set(keys))
    assert json.loads(capsys.readouterr().out.strip().splitlines()[-1])["episodes"] == 8


def test_geodesic_rule_is_named_in_the_summary(tiny_dataset, capsys):
    assert (
        main(
            [
                "eval",
                "--dataset",
                str(tiny_dataset),
                "--split",
                "val",
                "--policy",
                "oracle",
                "--frame",
                "60x80",
                "--rule",
                "geodesic",
                "--episodes",
                "2",
                "--json",
            ]
        )
        == 0
    )
    assert json.loads(capsys.readouterr().out.strip().splitlines()[-1])["rule"] == "geodesic"


@pytest.mark.parametrize(
    "argv,message",
    [
        (["eval", "--dataset", "/nonexistent", "--policy", "oracle"], "dataset directory /nonexistent does not exist"),
        (["eval", "--policy", "oracle", "--set", "max_stepz=3"], "unknown setting 'max_stepz'"),
        (["eval", "--policy", "oracle", "--resume"], "--resume needs --out"),
        (["render", "--scene", "Nowhere"], "unknown scene 'Nowhere'"),
        (["eval", "--policy", "frontier", "--selection", "official_code"], "apply to language policies only"),
        (["eval", "--policy", "random-walk", "--seg-noise", "0.2"], "does not read the semantic frames"),
    ],
)
def test_bad_input_is_one_line_on_stderr_with_status_2(argv, message, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and message in err and len(err.splitlines()) == 1


def test_unknown_split_names_the_available_ones(tiny_dataset, capsys):
    assert main(["scenes", "--dataset", str(tiny_dataset), "--split", "test"]) == 2
    assert "available splits: val" in capsys.readouterr().err


def test_bad_flag_value_is_rejected_by_the_parser_without_traceback():
    proc = subprocess.run(
        [sys.executable, "-m", "l3mvn.run.cli", "eval", "--policy", "teleport"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2 and "invalid choice: 'teleport'" in proc.stderr
    assert "Traceback" not in proc.stderr


def test_scenes_lists_floors_and_goals(tiny_dataset, capsys):
    assert main(["scenes", "--dataset", str(tiny_dataset), "--split", "val"]) == 0
    out = capsys.readouterr().out
    assert "Tiny" in out and "Wee" in out and "toilet" in out


def test_render_writes_rgb_depth_semantic_side_by_side(tiny_dataset, tmp_path):
    png = tmp_path / "frame.png"
    assert (
        main(
            [
                "render",
                "--dataset",
                str(tiny_dataset),
                "--split",
                "val",
                "--scene",
                "Tiny",
                "--frame",
                "48x64",
                "--pose",
                "2.5,3.0,0",
                "--out",
                str(png),
            ]
        )
        == 0
    )
    assert Image.open(png).size == (3 * 64 + 2 * 4, 48)


def test_generated_procedural_episodes_form_a_semexp_dataset(tmp_path, capsys):
    assert (
        main(["episodes", "generate", "--houses", "1", "--per-scene", "3", "--out", str(tmp_path), "--split", "val"])
        == 0
    )
    assert (
        main(["eval", "--dataset", str(tmp_path), "--split", "val", "--policy", "oracle", "--frame", "48x64", "--json"])
        == 0
    )
    assert json.loads(capsys.readouterr().out.strip().splitlines()[-1])["episodes"] == 3


def test_an_interrupted_eval_still_summarises_what_finished(tiny_dataset, tmp_path, capsys, monkeypatch):
    import l3mvn.run.eval.backends as backends

    real = backends.run_local

    def two_then_ctrl_c(job, keys, workers):
        rows = real(job, keys, workers)
        yield next(rows)
        yield next(rows)
        raise KeyboardInterrupt

    monkeypatch.setattr(backends, "run_local", two_then_ctrl_c)
    out = tmp_path / "results.jsonl"
    assert (
        main(
            [
                "eval",
                "--dataset",
                str(tiny_dataset),
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
        == 130
    )
    captured = capsys.readouterr()
    assert json.loads(captured.out.strip().splitlines()[-1])["episodes"] == 2
    assert "summary of the 2 of 8 episodes finished" in captured.err
    assert len(out.read_text().splitlines()) == 2


def test_set_agent_field_changes_the_hash_and_what_the_agent_does(tiny_dataset, tmp_path):
    rows = {}
    for name, extra in (("default", []), ("no_look_around", ["--set", "agent.look_around_steps=0"])):
        out = tmp_path / f"{name}.jsonl"
        assert (
            main(
                [
                    "eval",
                    "--dataset",
                    str(tiny_dataset),
                    "--split",
                    "val",
                    "--policy",
                    "frontier",
                    "--frame",
                    "60x80",
                    "--episodes",
                    "1",
                    "--out",
                    str(out),
                    *extra,
                ]
            )
            == 0
        )
        rows[name] = json.loads(out.read_text().splitlines()[0])
    assert rows["default"]["config_hash"] != rows["no_look_around"]["config_hash"]
    assert rows["no_look_around"]["config"]["agent"]["look_around_steps"] == 0
    assert rows["default"]["steps"] != rows["no_look_around"]["steps"]  # no initial 360-degree turn


def test_config_lists_every_field_and_refuses_a_mistyped_one(capsys):
    assert main(["config", "--set", "agent.replan_every=5"]) == 0
    out = capsys.readouterr().out
    assert "agent.replan_every = 5" in out and "task.success_rule = semexp" in out and "hash" in out
    assert main(["config", "--set", "agent.replan_evry=5"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: unknown setting 'replan_evry' in section agent; valid:") and "\n" not in err


def test_an_eval_imports_no_neural_network_no_recorder_and_no_dashboard(tmp_path):
    """Torch, rerun and viser take seconds to import; a map-based eval needs none of them (a warm
    machine runs a one-episode check in about two seconds)."""
    code = (
        "import sys\n"
        "from l3mvn_studio.cli import main\n"
        "try:\n"
        "    main(['eval', '--help'])\n"
        "except SystemExit:\n"
        "    pass\n"
        f"main(['eval', '--policy', 'frontier', '--houses', '1', '--episodes', '1', '--frame', '120x160', "
        f"'--set', 'sim.max_steps=20', '--out', {str(tmp_path / 'r.jsonl')!r}])\n"
        "print(sorted(m for m in ('torch', 'rerun', 'viser', 'transformers') if m in sys.modules))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().splitlines()[-1] == "[]"

"""A researcher's own policy and scorer, installed from a package of their own, run without a fork.

The package is built and installed here by pip (into a folder of its own, found through PYTHONPATH),
exactly as `pip install` of a colleague's project would install it: its entry points under
``l3mvn.policies`` and ``l3mvn.scorers`` are what the registry reads.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

PACKAGE = {
    "pyproject.toml": """
        [build-system]
        requires = ["setuptools>=68"]
        build-backend = "setuptools.build_meta"

        [project]
        name = "bump-and-turn"
        version = "0.1"

        [project.entry-points."l3mvn.policies"]
        bump-and-turn = "bump_and_turn:SPEC"
        not-a-spec = "bump_and_turn:NOT_A_SPEC"
        broken = "bump_and_turn_missing:SPEC"

        [project.entry-points."l3mvn.scorers"]
        sink-means-toilet = "bump_and_turn:SinkMeansToilet"
        """,
    "bump_and_turn.py": '''
        """Walk straight on; after a bump, turn left and walk on. Stop after 40 steps."""
        from l3mvn.agent.language import Scorer
        from l3mvn.core.types import Action
        from l3mvn.run.registry import PolicySpec


        class BumpAndTurn:
            def reset(self, episode):
                self.steps = 0

            def change_target(self, goal):
                pass

            def act(self, obs):
                self.steps += 1
                if self.steps > 40:
                    return Action.STOP
                return Action.TURN_LEFT if obs.collided else Action.MOVE_FORWARD


        SPEC = PolicySpec("bump-and-turn", lambda ctx: BumpAndTurn(), "walks until it bumps, then turns",
                          map_based=False)
        NOT_A_SPEC = object()


        class SinkMeansToilet(Scorer):
            """A toy prior: a sink says toilet, anything else says nothing."""

            def _raw_scores(self, pairs):
                return [5.0 if goal == "toilet" and "sink" in objects else 0.0 for objects, goal in pairs]
        ''',
}


@pytest.fixture(scope="module")
def plugin_path(tmp_path_factory) -> Path:
    """The package above, built and installed by pip into a folder of its own."""
    root = tmp_path_factory.mktemp("plugin")
    source, target = root / "src", root / "site"
    source.mkdir()
    for name, text in PACKAGE.items():
        (source / name).write_text(textwrap.dedent(text).lstrip())
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "install",
            "--quiet",
            "--no-deps",
            "--no-build-isolation",
            "--no-index",
            "--disable-pip-version-check",
            "--target",
            str(target),
            str(source),
        ],
        check=True,
        capture_output=True,
        text=True,
        timeout=300,
    )
    return target


def _l3mvn(plugin_path: Path, *args: str, **kw) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(plugin_path), os.environ.get("PYTHONPATH", "")])}
    return subprocess.run(
        [sys.executable, "-m", "l3mvn_studio.cli", *args], capture_output=True, text=True, env=env, timeout=600, **kw
    )


def test_a_policy_from_an_installed_package_runs_in_eval(plugin_path, tmp_path):
    out = tmp_path / "results.jsonl"
    run = _l3mvn(
        plugin_path,
        "eval",
        "--policy",
        "bump-and-turn",
        "--houses",
        "1",
        "--episodes",
        "2",
        "--frame",
        "120x160",
        "--out",
        str(out),
    )
    assert run.returncode == 0, run.stderr
    rows = [json.loads(line) for line in out.read_text().splitlines()]
    assert len(rows) == 2 and {r["policy"] for r in rows} == {"bump-and-turn"}
    assert all(r["steps"] <= 41 and r["failure"] in ("false_stop", "success", "never_saw_target") for r in rows)
    # The plugins that are not what their group expects are left out, each named once on stderr.
    assert "'not-a-spec'" in run.stderr and "not an l3mvn.run.registry.PolicySpec" in run.stderr
    assert "'broken'" in run.stderr and "ModuleNotFoundError" in run.stderr


def test_a_broken_plugin_asked_for_by_name_is_refused_in_one_line_saying_why(plugin_path):
    from l3mvn.run.registry import policy_names

    run = _l3mvn(plugin_path, "eval", "--policy", "broken", "--houses", "1", "--episodes", "1")
    assert run.returncode == 2
    assert "invalid choice: 'broken'" in run.stderr and "bump-and-turn" in run.stderr
    assert "bump-and-turn" not in policy_names()  # this process never had the package on its path


def test_a_scorer_from_an_installed_package_scores_for_a_language_policy(plugin_path, tmp_path):
    out = tmp_path / "results.jsonl"
    run = _l3mvn(
        plugin_path,
        "eval",
        "--policy",
        "l3mvn-zs",
        "--scorer",
        "sink-means-toilet",
        "--houses",
        "1",
        "--episodes",
        "1",
        "--frame",
        "120x160",
        "--out",
        str(out),
    )
    assert run.returncode == 0, run.stderr
    row = json.loads(out.read_text().splitlines()[0])
    assert row["config"]["policy"]["scorer"] == "sink-means-toilet"
    check = _l3mvn(plugin_path, "eval", "--policy", "l3mvn-zs", "--scorer", "no-such-scorer", "--houses", "1")
    assert check.returncode == 2 and "sink-means-toilet" in check.stderr and "no-such-scorer" in check.stderr


@pytest.fixture
def plugin_installed(plugin_path, monkeypatch):
    """The package on this process's path, with the registry read afresh (and again afterwards)."""
    import importlib

    from l3mvn.run import registry

    monkeypatch.syspath_prepend(str(plugin_path))
    importlib.invalidate_caches()
    registry._registry.cache_clear()
    yield
    monkeypatch.undo()
    importlib.invalidate_caches()
    registry._registry.cache_clear()


def test_a_policy_from_an_installed_package_is_offered_in_the_dashboard_and_runs_there(plugin_installed):
    from conftest import serve_dashboard

    for dash in serve_dashboard(episodes_per_house=1, policy="bump-and-turn"):
        assert "bump-and-turn" in dash.view.policy.options and dash.view.policy.value == "bump-and-turn"
        scene = dash.controller.scene_keys[0]
        dash.controller.reset(scene, dash.controller.episodes_of(scene)[0].episode_id)
        assert dash.controller.wait_idle()
        dash.controller.step()
        assert dash.controller.wait_idle()
        assert dash.controller.snapshot.error is None and dash.controller.snapshot.event.step == 1

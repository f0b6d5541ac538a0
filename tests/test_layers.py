"""The layering of the packages, read from the source: no module imports one above it, and the two
sides of the simulator wall never import each other.

``l3mvn.core`` is the contract both sides share. The world side (``l3mvn.world``: scenes, simulator,
task, episodes, the ground-truth baselines) and the agent side (``l3mvn.agent``: perception, mapping,
frontiers, planning, language, global policies, the map agent) each import ``core`` only; the run side
(``l3mvn.run``) puts them together; the dashboard (``l3mvn_studio``, the repository's ``app/``) sits on
top, and the library never imports it. So an agent that reads ground truth is a failing test here, not
a convention. README.md's layout table states the same layers.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# Which sides a side may import (besides its own, layer by layer below).
SIDES: dict[str, set[str]] = {
    "core": set(),
    "world": {"core"},
    "agent": {"core"},
    "run": {"core", "world", "agent"},
    "studio": {"core", "world", "agent", "run"},
}
# Within a side, lowest first; a unit may import units of lower layers of its own side only.
LAYERS: dict[str, list[set[str]]] = {
    "core": [
        {"errors"},
        {"frames"},
        {"types", "config", "grid", "paths", "writing", "categories", "json_values", "plugins", "compiled"},
        {"camera"},
    ],
    "world": [{"episode", "scenes"}, {"sim"}, {"task"}, {"episodes"}, {"datasets"}, {"baselines"}],
    "agent": [
        {"mapping", "frontiers", "planning", "language"},
        {"decision", "perception", "looking"},
        {"policies"},
        {"modular", "potentials"},
    ],
    "run": [
        {"events", "viz", "serving"},
        {"session"},
        {"registry"},
        {"runner", "recording"},
        {"eval", "audit", "potentials"},
        {"cli"},
    ],
    "studio": [{"*"}],
}
Unit = tuple[str, str]  # (side, package or module right under it)


def _unit(module: str) -> Unit | None:
    parts = module.split(".")
    if parts[0] in ("l3mvn_studio", "app"):
        return ("studio", "*")
    if parts[0] != "l3mvn" or len(parts) < 3 or parts[1] not in SIDES:
        return None
    return parts[1], parts[2]


def _imports(base: Path = ROOT) -> list[tuple[str, Unit, Unit]]:
    """(file, importing unit, imported unit) for every absolute import of ours under ``base``, at any
    depth (an import inside a function is a dependency too)."""
    found = []
    for root, package in (("l3mvn", "l3mvn"), ("app", "l3mvn_studio")):
        for path in sorted((base / root).rglob("*.py")):
            rel = path.relative_to(base)
            own = _unit(".".join((package, *rel.with_suffix("").parts[1:])))
            if own is None:  # l3mvn/__init__.py and the sides' own __init__
                continue
            for node in ast.walk(ast.parse(path.read_text())):
                names = (
                    [node.module]
                    if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module
                    else ([a.name for a in node.names] if isinstance(node, ast.Import) else [])
                )
                for name in names:
                    target = _unit(name)
                    if target is None and name.split(".")[0] == "l3mvn" and name != "l3mvn":
                        target = ("?", name)  # l3mvn.<not a side>: a module outside the layout
                    if target is not None and target != own:
                        found.append((str(rel), own, target))
    return found


def _layer(unit: Unit) -> int:
    side, name = unit
    for i, layer in enumerate(LAYERS.get(side, [])):
        if name in layer or "*" in layer:
            return i
    raise AssertionError(f"{side}.{name} is in no layer: add it to LAYERS (and README.md's layout table)")


def _allowed(own: Unit, target: Unit) -> bool:
    if own[0] != target[0]:
        return target[0] in SIDES[own[0]]
    return _layer(target) < _layer(own)


def _problems(base: Path = ROOT) -> list[str]:
    return [
        f"{file}: {'.'.join(own)} imports {'.'.join(target)}"
        for file, own, target in _imports(base)
        if not _allowed(own, target)
    ]


def test_every_unit_of_every_side_has_a_layer():
    for side in ("core", "world", "agent", "run"):
        folder = ROOT / "l3mvn" / side
        units = {p.name for p in folder.iterdir() if p.is_dir() and (p / "__init__.py").exists()}
        units |= {p.stem for p in folder.glob("*.py") if p.stem != "__init__"}
        for unit in units:
            _layer((side, unit))
    assert {p.name for p in (ROOT / "l3mvn").iterdir() if (p / "__init__.py").exists()} == set(SIDES) - {"studio"}
    assert [p.name for p in (ROOT / "l3mvn").glob("*.py")] == ["__init__.py"], "every module belongs to a side"


def test_no_unit_imports_one_above_it_or_across_the_simulator_wall():
    problems = _problems()
    assert not problems, "\n".join(problems)


def test_the_library_never_imports_the_dashboard():
    assert not [f for f, own, target in _imports() if target[0] == "studio" and own[0] != "studio"]


def test_an_agent_that_reads_the_world_or_the_task_fails_this_test(tmp_path):
    agent = tmp_path / "l3mvn" / "agent" / "modular"
    agent.mkdir(parents=True)
    (agent / "cheat.py").write_text(
        "def f():\n    from l3mvn.world.task import ObjectNavTask\n"
        "import l3mvn.world.sim.simulator\nfrom l3mvn.core.types import Pose\n"
    )
    assert set(_problems(tmp_path)) == {
        "l3mvn/agent/modular/cheat.py: agent.modular imports world.task",
        "l3mvn/agent/modular/cheat.py: agent.modular imports world.sim",
    }


def test_the_world_never_reads_the_agent_and_nothing_reads_upwards(tmp_path):
    (tmp_path / "l3mvn" / "world" / "task").mkdir(parents=True)
    (tmp_path / "l3mvn" / "world" / "task" / "x.py").write_text(
        "from l3mvn.agent.mapping import SemanticMap\nfrom l3mvn.run.eval.job import EvalJob\n"
        "from l3mvn.world.datasets import EpisodeSet\nfrom app.server import y\nimport l3mvn.loose\n"
    )
    assert set(_problems(tmp_path)) == {
        "l3mvn/world/task/x.py: world.task imports agent.mapping",
        "l3mvn/world/task/x.py: world.task imports run.eval",
        "l3mvn/world/task/x.py: world.task imports world.datasets",
        "l3mvn/world/task/x.py: world.task imports studio.*",
        "l3mvn/world/task/x.py: world.task imports ?.l3mvn.loose",
    }

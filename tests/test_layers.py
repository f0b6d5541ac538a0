"""The layering of the packages, read from the source: no module imports one above it.

Data flows one way (sim -> observation -> mapping -> frontiers -> global policy -> local planner ->
action); the simulator moves and renders, the task judges, eval runs jobs, and the library never
imports the application (``app``). README.md's layout table states the same layers.
"""

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# Lowest first; a package may import its own layer's packages only where listed in SIBLINGS.
LAYERS = [
    {"errors"},
    {"types", "config", "grid", "paths", "writing"},
    {"viz", "scenes", "perception", "events", "serving"},
    {"sim", "task", "language"},
    {"episodes", "mapping", "frontiers", "planning"},
    {"datasets", "looking"},
    {"policies"},
    {"agent"},
    {"registry", "session"},
    {"runner", "recording"},
    {"eval"},
    {"cli"},
    {"app"},
]
SIBLINGS: set[tuple[str, str]] = set()


def _package(module: str) -> str | None:
    parts = module.split(".")
    if parts[0] == "app":
        return "app"
    if parts[0] != "l3mvn" or len(parts) < 2:
        return None
    return parts[1]


def _imports(base: Path = ROOT) -> list[tuple[str, str, str]]:
    """(file, importing package, imported package) for every absolute import of ours under ``base``,
    at any depth (an import inside a function is a dependency too)."""
    found = []
    for root in ("l3mvn", "app"):
        for path in sorted((base / root).rglob("*.py")):
            rel = path.relative_to(base)
            own = _package(".".join(rel.with_suffix("").parts))
            if own is None:  # l3mvn/__init__.py
                continue
            for node in ast.walk(ast.parse(path.read_text())):
                names = [node.module] if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module else (
                    [a.name for a in node.names] if isinstance(node, ast.Import) else [])
                for name in names:
                    target = _package(name)
                    if target is not None and target != own:
                        found.append((str(rel), own, target))
    return found


def _layer(package: str) -> int:
    for i, layer in enumerate(LAYERS):
        if package in layer:
            return i
    raise AssertionError(f"package {package!r} is in no layer: add it to LAYERS (and README.md's layout table)")


def test_every_package_has_a_layer():
    packages = {p.name for p in (ROOT / "l3mvn").iterdir() if p.is_dir() and (p / "__init__.py").exists()}
    packages |= {p.stem for p in (ROOT / "l3mvn").glob("*.py") if p.stem != "__init__"}
    for package in packages | {"app"}:
        _layer(package)


def test_no_package_imports_one_above_it():
    upward = [f"{file}: {own} (layer {_layer(own)}) imports {target} (layer {_layer(target)})"
              for file, own, target in _imports()
              if _layer(target) > _layer(own) or (_layer(target) == _layer(own) and (own, target) not in SIBLINGS)]
    assert not upward, "\n".join(upward)


def test_the_library_never_imports_the_app():
    assert not [f for f, own, target in _imports() if target == "app" and own != "app"]


def test_the_reader_finds_a_lazy_upward_import(tmp_path):
    (tmp_path / "l3mvn" / "sim").mkdir(parents=True)
    (tmp_path / "l3mvn" / "sim" / "x.py").write_text("def f():\n    from l3mvn.eval.job import EvalJob\n"
                                                     "import l3mvn.app_free\nfrom app.server import y\n")
    assert set(_imports(tmp_path)) == {("l3mvn/sim/x.py", "sim", "eval"), ("l3mvn/sim/x.py", "sim", "app_free"),
                                       ("l3mvn/sim/x.py", "sim", "app")}

"""What ``l3mvn report`` shows, computed from result files: per run SR / SPL / DTG with bootstrap
intervals (overall and per goal category), failure causes, SR and SPL against episode length, the
settings that differ between files and the paired differences against the first file.

Rows are read only through the result-line format's reader (``episode_lines``), and pairs only
through ``paired.compare_results``: the report never parses a line or pairs episodes itself. A "run"
is one policy's rows of one file (a file may hold several policies; each is summarised apart).
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from l3mvn.core.errors import L3MVNError
from l3mvn.run.eval.paired import Estimate, Pairing, bootstrap_mean, compare_results, config_differences
from l3mvn.run.eval.results import episode_lines
from l3mvn.world.task.scoring import FAILURE_CAUSES

MEASURES = ("success", "spl", "dtg")
SEED = 0  # the bootstrap's: the same files give the same page
LENGTH_BINS = 5
MIN_PER_BIN = 20  # episodes of a run a length bin should hold: fewer, and its interval spans most of [0, 1]


@dataclass(frozen=True)
class Run:
    """One policy's episode rows of one result file (one row per episode key, the last one)."""

    path: Path
    policy: str
    rows: tuple[dict, ...]
    overall: dict[str, Estimate]  # by measure
    per_category: dict[str, dict[str, Estimate]]  # goal -> measure -> estimate
    causes: dict[str, int]  # failure cause -> episodes, in FAILURE_CAUSES order, success left out

    @property
    def label(self) -> str:
        return f"{self.path.name} ({self.policy})"


@dataclass(frozen=True)
class FileComparison:
    """A later file against the first: its differing settings, and the paired differences (or why none)."""

    path: Path
    settings: tuple[str, ...]  # "section.field: A -> B"
    pairing: Pairing | None
    why_unpaired: str | None


@dataclass(frozen=True)
class LengthBin:
    low: float
    high: float
    per_run: tuple[tuple[Estimate, Estimate], ...]  # (SR, SPL) per run, in run order


@dataclass(frozen=True)
class LengthCurves:
    """SR and SPL per episode-length bin; ``axis`` names what the length is."""

    axis: str
    bins: tuple[LengthBin, ...]
    left_out: tuple[int, ...]  # per run: rows without a length


@dataclass
class ReportData:
    files: list[Path]
    runs: list[Run]
    comparisons: list[FileComparison]
    lengths: LengthCurves
    notes: list[str] = field(default_factory=list)  # per file: lines left out, repeats, mixed configs


def read_report_data(paths: list[str | Path]) -> ReportData:
    """Everything the page shows for ``paths`` (the first is the reference), or a one-line L3MVNError
    when a file cannot be read or holds no episode row."""
    if not paths:
        raise L3MVNError("report needs at least one result file (.jsonl)")
    files = [Path(p) for p in paths]
    repeated = sorted({str(p) for p in files if files.count(p) > 1})
    if repeated:
        raise L3MVNError(f"result file {repeated[0]} is given twice; give each file once")
    rng = np.random.default_rng(SEED)
    per_file, notes, configs = [], [], []
    for path in files:
        file_runs, file_notes, config = _read_file(path, rng)
        per_file.append(file_runs)
        notes += file_notes
        configs.append(config)
    comparisons = [
        _compare((files[0], configs[0], per_file[0]), (path, config, file_runs))
        for path, config, file_runs in zip(files[1:], configs[1:], per_file[1:])
    ]
    runs = [run for file_runs in per_file for run in file_runs]
    return ReportData(files, runs, comparisons, _length_curves(runs, rng), notes)


def _read_file(path: Path, rng: np.random.Generator) -> tuple[list[Run], list[str], dict | None]:
    read = episode_lines(path)
    if not read.rows:
        first = f" (first problem: {read.problems[0]})" if read.problems else " (it is empty)"
        raise L3MVNError(f"{path} is not an eval result file: no episode row{first}")
    notes = [f"{path.name}: {len(read.problems)} lines left out (first: {read.problems[0]})"] if read.problems else []
    # a resumed run's later line of an episode wins
    by_episode = {(row["policy"], row["key"]): row for _, row in read.rows}
    if len(by_episode) < len(read.rows):
        repeats = len(read.rows) - len(by_episode)
        notes.append(f"{path.name}: {repeats} lines repeat an episode of their policy; the last of each counts")
    rows = list(by_episode.values())
    rules = sorted({r["rule"] for r in rows})
    if len(rules) > 1:
        raise L3MVNError(f"{path} mixes success rules ({', '.join(rules)}): report each rule's rows in its own file")
    policies = sorted({r["policy"] for r in rows})
    for policy in policies:
        hashes = sorted({r["config_hash"] for r in rows if r["policy"] == policy})
        if len(hashes) > 1:
            notes.append(
                f"{path.name}: {policy} ran with {len(hashes)} configs ({', '.join(hashes)}); "
                "they are summarised together"
            )
    runs = [_run(path, policy, [r for r in rows if r["policy"] == policy], rng) for policy in policies]
    config = rows[0].get("config")
    return runs, notes, config if isinstance(config, dict) else None


def _run(path: Path, policy: str, rows: list[dict], rng: np.random.Generator) -> Run:
    goals = sorted({r["goal"] for r in rows})
    counted = Counter(r["failure"] for r in rows)
    return Run(
        path,
        policy,
        tuple(rows),
        _estimates(rows, rng),
        {g: _estimates([r for r in rows if r["goal"] == g], rng) for g in goals},
        {cause: counted[cause] for cause in FAILURE_CAUSES if cause != "success" and counted[cause]},
    )


def _estimates(rows: list[dict], rng: np.random.Generator) -> dict[str, Estimate]:
    """SR and SPL over every row (a missing SPL counts 0, as the eval summary counts it); DTG over the
    rows that have one (an episode without a path has none)."""
    return {
        "success": bootstrap_mean([float(r["success"]) for r in rows], rng),
        "spl": bootstrap_mean([float(r["spl"] or 0.0) for r in rows], rng),
        "dtg": bootstrap_mean([float(r["dtg"]) for r in rows if r["dtg"] is not None], rng),
    }


def _compare(first: tuple[Path, dict | None, list[Run]], other: tuple[Path, dict | None, list[Run]]) -> FileComparison:
    """``other`` against the first file. Pairs match episode keys, so a file of several policies
    (whose rows share keys) is not paired: which of its rows would stand for the episode?"""
    (first_path, first_config, first_runs), (path, config, runs) = first, other
    if first_config is None or config is None:
        missing = first_path if first_config is None else path
        settings: tuple[str, ...] = (f"{missing.name} stores no config: its settings cannot be checked",)
    else:
        settings = tuple(config_differences(first_config, config))
    mixed = next(((p, r) for p, r in ((first_path, first_runs), (path, runs)) if len(r) > 1), None)
    if mixed is not None:
        policies = ", ".join(run.policy for run in mixed[1])
        why = (
            f"{mixed[0].name} holds {len(mixed[1])} policies ({policies}): paired differences need one policy per file"
        )
        return FileComparison(path, settings, None, why)
    try:
        return FileComparison(path, settings, compare_results(first_path, path, seed=SEED), None)
    except L3MVNError as exc:
        return FileComparison(path, settings, None, str(exc))


def _length(row: dict, key: str) -> float | None:
    v = row.get(key)
    if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v):
        return float(v)
    return None


def _length_curves(runs: list[Run], rng: np.random.Generator) -> LengthCurves:
    """Bins of (nearly) equal episode counts over the pooled lengths, the same edges for every run.
    The geodesic start distance is a property of the episode, so every policy is binned alike; rows
    without one (older files) fall back to the steps the policy took, named so on the axis."""
    key, axis = "shortest_path_m", "geodesic start distance (m)"
    if not any(_length(r, key) is not None for run in runs for r in run.rows):
        key, axis = "steps", "steps taken"
    pooled = np.array([x for run in runs for r in run.rows if (x := _length(r, key)) is not None])
    left_out = tuple(sum(_length(r, key) is None for r in run.rows) for run in runs)
    if pooled.size == 0:
        return LengthCurves(axis, (), left_out)
    largest = max(len(run.rows) - n for run, n in zip(runs, left_out))
    count = max(1, min(LENGTH_BINS, largest // MIN_PER_BIN))
    edges = np.unique(np.round(np.quantile(pooled, np.linspace(0, 1, count + 1)), 1))
    if edges.size < 2:
        edges = np.array([edges[0], edges[0]])
    inner = edges[1:-1]
    bins = []
    for i in range(edges.size - 1):
        per_run = []
        for run in runs:
            # every value lands in a bin, also one rounding left just outside the outer edges
            inside = [r for r in run.rows if (x := _length(r, key)) is not None and _bin(inner, x) == i]
            per_run.append(
                (
                    bootstrap_mean([float(r["success"]) for r in inside], rng),
                    bootstrap_mean([float(r["spl"] or 0.0) for r in inside], rng),
                )
            )
        bins.append(LengthBin(float(edges[i]), float(edges[i + 1]), tuple(per_run)))
    return LengthCurves(axis, tuple(bins), left_out)


def _bin(inner: np.ndarray, x: float) -> int:
    """The bin of ``x`` given the edges between bins (half-open: a value on an edge goes up)."""
    return int(np.searchsorted(inner, x, side="right"))

"""Two or more result files side by side: what differs in their configs, then each file's SR, SPL and
DTG with intervals, then the paired differences against the first file (``l3mvn.run.eval.paired``).

Only episodes every file holds are compared (the rest are counted per file): a difference between
files is then a difference on the same episodes. Settings that differ between the files come first,
since a config difference, not the policy, may be what moved the numbers.
"""

from __future__ import annotations

import json
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from l3mvn.core.errors import L3MVNError
from l3mvn.run.eval.paired import LEVEL, RESAMPLES, Pairing, compare_results, config_differences
from l3mvn_studio.results import EpisodeRow, ResultFile

MEASURES = (("SR", "success"), ("SPL", "spl"), ("DTG", "dtg"))


@dataclass(frozen=True)
class Estimate:
    """A mean over episodes with its bootstrap interval (``LEVEL``)."""

    mean: float
    low: float
    high: float


@dataclass(frozen=True)
class FileSummary:
    """One file on the shared episodes: its policies and each measure of ``MEASURES``."""

    name: str
    policies: str
    measures: dict[str, Estimate]
    left_out: int  # its episodes some other file lacks


@dataclass(frozen=True)
class FilesComparison:
    """The comparison of ``files[0]`` (A) with each later file (B)."""

    names: tuple[str, ...]
    config_notes: tuple[str, ...]  # "B.jsonl: section.field: A -> B", every setting that differs from A
    shared: int  # episodes every file holds
    summaries: tuple[FileSummary, ...]
    pairings: tuple[Pairing, ...]  # A against each later file, on the shared episodes
    solved_by_one: tuple[tuple[str, tuple[str, ...], tuple[str, ...]], ...]  # (B, solved by A only, by B only)


def compare_files(files: list[ResultFile], *, seed: int = 0, resamples: int = RESAMPLES) -> FilesComparison:
    """Compare ``files`` (two or more) on the episodes they all hold; one-line L3MVNError when there are
    fewer than two or they share no episode."""
    if len(files) < 2:
        raise L3MVNError(f"pick at least two result files to compare (have {len(files)})")
    by_key = [_by_key(f.rows) for f in files]
    shared = sorted(set.intersection(*(set(rows) for rows in by_key)))
    if not shared:
        names = ", ".join(f.path.name for f in files)
        raise L3MVNError(f"{names} share no episode: compare runs of the same episodes")
    first = by_key[0][shared[0]].raw.get("config")
    notes = []
    for f, rows in zip(files[1:], by_key[1:], strict=True):
        other = rows[shared[0]].raw.get("config")
        for line in config_differences(
            first if isinstance(first, dict) else {}, other if isinstance(other, dict) else {}
        ):
            notes.append(f"{f.path.name}: {line}")
    rng = np.random.default_rng(seed)
    summaries = tuple(
        FileSummary(
            f.path.name,
            ", ".join(sorted({rows[k].policy for k in shared})),
            {label: _estimate([_value(rows[k], field) for k in shared], rng, resamples) for label, field in MEASURES},
            len(rows) - len(shared),
        )
        for f, rows in zip(files, by_key, strict=True)
    )
    with tempfile.TemporaryDirectory(prefix="l3mvn-compare-") as tmp:
        paths = [_shared_lines(Path(tmp) / f"{i}.jsonl", rows, shared) for i, rows in enumerate(by_key)]
        pairings = tuple(compare_results(paths[0], p, seed=seed, resamples=resamples) for p in paths[1:])
    for pairing, f in zip(pairings, files[1:], strict=True):
        pairing.a, pairing.b = files[0].path.name, f.path.name
    solved = tuple(
        (
            f.path.name,
            tuple(k for k in shared if by_key[0][k].success and not rows[k].success),
            tuple(k for k in shared if rows[k].success and not by_key[0][k].success),
        )
        for f, rows in zip(files[1:], by_key[1:], strict=True)
    )
    return FilesComparison(tuple(f.path.name for f in files), tuple(notes), len(shared), summaries, pairings, solved)


def _by_key(rows: tuple[EpisodeRow, ...]) -> dict[str, EpisodeRow]:
    """A file's rows by episode key (a later line of an episode, from a resumed run, wins: as paired.py)."""
    return {str(r.raw["key"]): r for r in rows}


def _value(row: EpisodeRow, field: str) -> float:
    value = {"success": float(row.success), "spl": row.spl, "dtg": row.dtg}[field]
    return float("nan") if value is None else float(value)


def _estimate(values: list[float], rng: np.random.Generator, resamples: int) -> Estimate:
    """The mean of the finite ``values`` and a percentile bootstrap interval over episodes."""
    v = np.array([x for x in values if np.isfinite(x)])
    if not len(v):
        return Estimate(float("nan"), float("nan"), float("nan"))
    boot = v[rng.integers(0, len(v), size=(resamples, len(v)))].mean(axis=1)
    low, high = np.quantile(boot, [(1 - LEVEL) / 2, (1 + LEVEL) / 2])
    return Estimate(float(v.mean()), float(low), float(high))


def _shared_lines(path: Path, rows: dict[str, EpisodeRow], keys: list[str]) -> Path:
    """The lines of ``keys`` as a result file of their own: paired.py then pairs exactly the shared episodes."""
    path.write_text("".join(json.dumps(rows[k].raw) + "\n" for k in keys))
    return path

"""Two or more result files side by side: what differs in their configs, then each file's SR, SPL and
DTG with intervals, then the paired differences against the first file (``l3mvn.run.eval.paired``).

Only episodes every file holds are compared (the rest are counted per file): a difference between
files is then a difference on the same episodes. Settings that differ between the files come first,
since a config difference, not the policy, may be what moved the numbers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from l3mvn.core.errors import L3MVNError
from l3mvn.run.eval.paired import RESAMPLES, Estimate, Pairing, bootstrap_mean, config_differences, pair_rows
from l3mvn_studio.results import EpisodeRow, ResultFile

MEASURES = (("SR", "success"), ("SPL", "spl"), ("DTG", "dtg"))


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
    lines = [{k: rows[k].raw for k in shared} for rows in by_key]  # only the episodes every file holds
    pairings = tuple(
        pair_rows(lines[0], other, files[0].path.name, f.path.name, seed=seed, resamples=resamples)
        for f, other in zip(files[1:], lines[1:], strict=True)
    )
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
    """The mean of the finite ``values`` (an episode without a DTG has none) with its interval."""
    return bootstrap_mean([x for x in values if np.isfinite(x)], rng, resamples)

"""Two result files on the same episodes, compared episode by episode.

On a few hundred episodes, SR moves by about +-0.025 between seeds: two summaries side by side say
little. Paired, each episode is its own control: the difference B - A per episode, its mean, and a 95%
interval from a bootstrap over episodes (resampled with replacement, seeded), overall and per goal
category. Episodes only one file holds are counted and left out; settings that differ between the
files are named first (a config difference, not the policy, may be what moved the numbers).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from l3mvn.core.errors import L3MVNError
from l3mvn.run.eval.results import episode_lines

RESAMPLES = 10_000
LEVEL = 0.95


@dataclass(frozen=True)
class Estimate:
    """A mean over ``n`` episodes with its bootstrap interval (all nan when ``n`` is 0)."""

    mean: float
    low: float
    high: float
    n: int


def bootstrap_mean(values: list[float], rng: np.random.Generator, resamples: int = RESAMPLES) -> Estimate:
    """The mean of ``values`` and its percentile bootstrap interval (episodes resampled with replacement)."""
    if not values:
        return Estimate(math.nan, math.nan, math.nan, 0)
    v = np.asarray(values, dtype=float)
    boot = v[rng.integers(0, len(v), size=(resamples, len(v)))].mean(axis=1)
    low, high = np.quantile(boot, [(1 - LEVEL) / 2, (1 + LEVEL) / 2])
    return Estimate(float(v.mean()), float(low), float(high), len(v))


@dataclass(frozen=True)
class Difference:
    """The mean per-episode difference B - A of one measure over ``n`` episodes, with a bootstrap
    interval; ``wins`` / ``losses``: episodes where B is higher / lower."""

    measure: str
    n: int
    mean_a: float
    mean_b: float
    mean: float
    low: float
    high: float
    wins: int
    losses: int


@dataclass
class Pairing:
    """What two result files share: the per-category differences and what could not be paired."""

    a: str
    b: str
    policies: tuple[str, str]
    rows: dict[str, list[Difference]] = field(default_factory=dict)  # "all" and each category
    only_a: int = 0
    only_b: int = 0
    config_differences: list[str] = field(default_factory=list)


def compare_results(path_a: str | Path, path_b: str | Path, *, seed: int = 0, resamples: int = RESAMPLES) -> Pairing:
    """Pair the valid rows of two result files by episode key (see the module docstring)."""
    return pair_rows(_rows(path_a), _rows(path_b), str(path_a), str(path_b), seed=seed, resamples=resamples)


def pair_rows(
    a: dict[str, dict], b: dict[str, dict], name_a: str, name_b: str, *, seed: int = 0, resamples: int = RESAMPLES
) -> Pairing:
    """``compare_results`` on rows already read (episode key -> result row), e.g. the episodes that
    several files share."""
    keys = sorted(set(a) & set(b))
    if not keys:
        raise L3MVNError(f"{name_a} and {name_b} share no episode: compare two runs of the same episodes")
    pairing = Pairing(
        name_a, name_b, (_policy(a), _policy(b)), only_a=len(set(a) - set(b)), only_b=len(set(b) - set(a))
    )
    pairing.config_differences = config_differences(a[keys[0]].get("config", {}), b[keys[0]].get("config", {}))
    rng = np.random.default_rng(seed)
    groups = {"all": keys}
    for key in keys:
        groups.setdefault(str(a[key].get("goal")), []).append(key)
    for name, members in groups.items():
        pairing.rows[name] = [
            _difference(measure, [a[k] for k in members], [b[k] for k in members], rng, resamples)
            for measure in ("success", "spl")
        ]
    return pairing


def config_differences(a: dict, b: dict, prefix: str = "") -> list[str]:
    """``section.field: A -> B`` for every setting that differs between two stored configs."""
    out = []
    for key in sorted(set(a) | set(b)):
        va, vb = a.get(key), b.get(key)
        if isinstance(va, dict) and isinstance(vb, dict):
            out += config_differences(va, vb, f"{prefix}{key}.")
        elif va != vb:
            out.append(f"{prefix}{key}: {va!r} -> {vb!r}")
    return out


def format_pairing(p: Pairing) -> str:
    """A markdown table per measure: categories as rows, A, B, B - A with its interval, wins / losses."""
    lines = [f"A: {p.a} ({p.policies[0]})", f"B: {p.b} ({p.policies[1]})"]
    if p.config_differences:
        lines.append("settings that differ (beside the policy): " + "; ".join(p.config_differences))
    if p.only_a or p.only_b:
        lines.append(f"left out: {p.only_a} episodes only in A, {p.only_b} only in B")
    lines += [
        "",
        f"| category | n | measure | A | B | B - A | {int(LEVEL * 100)}% interval | B better / worse |",
        "|---|---:|---|---:|---:|---:|---|---|",
    ]
    for name, diffs in p.rows.items():
        for d in diffs:
            lines.append(
                f"| {name} | {d.n} | {d.measure} | {d.mean_a:.3f} | {d.mean_b:.3f} | {d.mean:+.3f} | "
                f"[{d.low:+.3f}, {d.high:+.3f}] | {d.wins} / {d.losses} |"
            )
    return "\n".join(lines)


def _rows(path: str | Path) -> dict[str, dict]:
    """The file's episode rows by key (a later line of an episode, from a resumed run, wins)."""
    rows = {row["key"]: row for _, row in episode_lines(path).rows}
    if not rows:
        raise L3MVNError(f"{path} holds no valid result line")
    return rows


def _policy(rows: dict[str, dict]) -> str:
    return ", ".join(sorted({str(r.get("policy")) for r in rows.values()}))


def _difference(measure: str, a: list[dict], b: list[dict], rng: np.random.Generator, resamples: int) -> Difference:
    va = np.array([float(r[measure] or 0.0) for r in a])
    vb = np.array([float(r[measure] or 0.0) for r in b])
    d = vb - va
    e = bootstrap_mean(list(d), rng, resamples)
    return Difference(
        measure,
        len(d),
        float(va.mean()),
        float(vb.mean()),
        e.mean,
        e.low,
        e.high,
        int((d > 0).sum()),
        int((d < 0).sum()),
    )

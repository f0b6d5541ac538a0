"""The paper's Table I (comparative study) and Table II (ablation), one command each.

``l3mvn table paper-1 --dataset D`` runs every row the project has on the dataset's episodes (each into
a result file of its own under ``--results``, resumed on a second call) and prints the paper's numbers
beside ours; a row the project cannot run is named with the reason. The paper's numbers are copied
from its tables (Gibson and HM3D val); ours are on whatever dataset is given, with the success rule it
defaults to, so the columns compare a method's rank and its gaps, not its absolute numbers.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import TextIO

from l3mvn.core.config import Config
from l3mvn.core.config.policy import MAP_HEAD
from l3mvn.run.eval.evaluation import evaluate
from l3mvn.run.eval.job import EvalJob
from l3mvn.run.eval.metrics import summarize


@dataclass(frozen=True)
class PaperRow:
    """A row of the paper: its name, its numbers per dataset (success, SPL, DTG), and the policy that
    runs it here (None: why it cannot); ``seg_noise``: the row used a trained detector, not ground-truth
    segmentation, which ``--seg-noise`` stands in for; ``head``: the feed-forward head the row runs
    with, in place of the configured one."""

    method: str
    paper: dict[str, tuple[float, float, float] | None]
    policy: str | None
    missing: str = ""
    seg_noise: bool = False
    head: str | None = None


TABLES: dict[str, tuple[str, tuple[PaperRow, ...]]] = {
    "paper-1": (
        "Table I: results of the comparative study (the paper: Gibson and HM3D val, Mask R-CNN segmentation)",
        (
            PaperRow("Random Walking", {"Gibson": (0.030, 0.030, 2.580), "HM3D": (0.000, 0.000, 7.600)}, "random-walk"),
            PaperRow(
                "Frontier Based Method", {"Gibson": (0.417, 0.214, 2.634), "HM3D": (0.237, 0.123, 5.414)}, "frontier"
            ),
            PaperRow(
                "Random Sample on Map",
                {"Gibson": (0.544, 0.288, 1.918), "HM3D": (0.300, 0.143, 4.761)},
                "random-sample",
            ),
            PaperRow(
                "SemExp",
                {"Gibson": (0.652, 0.336, 1.520), "HM3D": (0.379, 0.188, 2.943)},
                None,
                "SemExp's global policy is a network trained with reinforcement learning in habitat; "
                "its checkpoint and training are not part of this project",
            ),
            PaperRow("PONI", {"Gibson": (0.736, 0.410, 1.250), "HM3D": None}, "poni"),
            PaperRow("L3MVN (Zero-Shot)", {"Gibson": (0.761, 0.377, 1.101), "HM3D": (0.504, 0.231, 4.427)}, "l3mvn-zs"),
            PaperRow(
                "L3MVN (Feed-forward)", {"Gibson": (0.769, 0.388, 1.008), "HM3D": (0.542, 0.255, 3.934)}, "l3mvn-ff"
            ),
            PaperRow("L3MVN (Feed-forward), map head: PONI + words (not in the paper)", {}, "l3mvn-ff", head=MAP_HEAD),
            PaperRow("Exp (cost-utility; not a row of the paper's table)", {}, "cost-utility"),
            PaperRow("Frontier oracle (ground truth; not in the paper)", {}, "oracle-frontier"),
        ),
    ),
    "paper-2": (
        "Table II: ablation (the paper: HM3D val; rows 1-3 with Mask R-CNN segmentation, row 4 ground truth)",
        (
            PaperRow("Near + LLM", {"HM3D": (0.490, 0.231, 4.335)}, "near+llm", seg_noise=True),
            PaperRow("Exp", {"HM3D": (0.518, 0.244, 4.084)}, "exp", seg_noise=True),
            PaperRow("Exp + LLM", {"HM3D": (0.542, 0.255, 3.934)}, "exp+llm", seg_noise=True),
            PaperRow("Exp + LLM + GT Seg", {"HM3D": (0.664, 0.364, 3.195)}, "exp+llm"),
        ),
    ),
}
PAPER_DATASETS = ("Gibson", "HM3D")


@dataclass(frozen=True)
class TableRun:
    """Where a table's runs come from and go: the episode source, the config, the result folder."""

    dataset: str | None
    split: str
    config: Config
    results: Path
    episodes: int | None = None
    workers: int = 1
    seg_noise: float = 0.0  # stands in for the paper's detector in the rows that used one
    scenes: str | None = None
    houses: int = 5
    episodes_per_house: int = 10
    seed: int = 0


def run_table(name: str, run: TableRun, stream: TextIO | None = None) -> str:
    """Run every row the project has (resuming each row's result file) and return the table."""
    title, rows = TABLES[name]
    ours: dict[str, dict | None] = {}
    for row in rows:
        if row.policy is None:
            continue
        noise = run.seg_noise if row.seg_noise else 0.0
        policy = replace(run.config.policy, seg_noise=noise, head=row.head or run.config.policy.head)
        config = replace(run.config, policy=policy)
        job = EvalJob.create(
            run.dataset,
            run.split,
            houses=run.houses,
            episodes_per_house=run.episodes_per_house,
            seed=run.seed,
            config=config,
            policy=row.policy,
            scenes=run.scenes,
        )
        episodes = job.load().episodes[: run.episodes] if run.episodes else job.load().episodes
        out = (
            run.results
            / f"{name}_{row.policy}{f'_{row.head}-head' if row.head else ''}{'_seg-noise' if noise else ''}.jsonl"
        )
        done = evaluate(job, episodes, out=str(out), resume=True, workers=run.workers, stream=stream)
        ours[row.method] = summarize(list(done.rows.values())) if done.rows else None
    return format_table(title, rows, ours, run)


def format_table(title: str, rows: tuple[PaperRow, ...], ours: dict[str, dict | None], run: TableRun) -> str:
    """A markdown table: each row's paper numbers (success / SPL / DTG per dataset) and ours."""
    source = run.dataset or "procedural houses"
    datasets = [d for d in PAPER_DATASETS if any(d in r.paper for r in rows)]
    head = [
        "| method | " + " | ".join(f"paper {d}" for d in datasets) + f" | ours ({source}) | n |",
        "|---|" + "---|" * (len(datasets) + 2),
    ]
    notes = []
    for row in rows:
        paper = [_triple(row.paper.get(d)) for d in datasets]
        summary = ours.get(row.method)
        if row.policy is None:
            ours_cell, n = "not run", ""
            notes.append(f"- {row.method}: {row.missing}.")
        elif summary is None:
            ours_cell, n = "no episode finished", "0"
        else:
            ours_cell = _triple((summary["success"], summary["spl"], summary["dtg"]))
            n = str(summary["episodes"])
            if row.seg_noise:
                ours_cell += f" (seg-noise {run.seg_noise:g})" if run.seg_noise else " (ground-truth segmentation)"
        head.append(f"| {row.method} | " + " | ".join(paper) + f" | {ours_cell} | {n} |")
    lines = [title, "", *head, "", "Each cell: success / SPL / DTG (m)."]
    if any(r.seg_noise for r in rows):
        lines.append(
            "Rows the paper ran with a trained detector run here with `--seg-noise` "
            f"{run.seg_noise:g} standing in for it (0: ground-truth segmentation)."
        )
    return "\n".join(lines + notes)


def _triple(values: tuple[float, float, float] | None) -> str:
    if values is None:
        return "-"
    success, spl, dtg = values
    return f"{success:.3f} / {spl:.3f} / {dtg:.3f}"

"""Evaluation throughput: steps/s end to end, time per stage, episodes/hour, peak memory per worker,
and scaling from 1 to N workers for local processes and Ray.

    .venv/bin/python bench/bench_throughput.py --policy oracle --workers 1,2 --backends local,ray

Prints a markdown table and writes the scaling curve (speed-up over one in-process worker) as a PNG.
Wall times are end to end, worker start-up included, as a user sees them; a Ray cluster is started
once beforehand (a cluster outlives runs), its actors per run.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import os
import sys
import time
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

from l3mvn.core.config import Config
from l3mvn.core.errors import L3MVNError
from l3mvn.run.eval.backends import run_local
from l3mvn.run.eval.job import EvalJob, is_error_row

REPO = Path(__file__).resolve().parents[1]


@dataclass
class Run:
    policy: str
    backend: str
    workers: int
    wall_s: float
    first_row_s: float
    rows: list[dict] = field(default_factory=list)

    @property
    def ok(self) -> list[dict]:
        return [r for r in self.rows if not is_error_row(r)]

    @property
    def steps(self) -> int:
        return sum(r["steps"] for r in self.ok)

    def per_step_ms(self) -> dict[str, float]:
        """Mean time per step of each stage: the simulator (render included), the rest of the loop,
        and whatever the policy reports in Decision.timings_ms."""
        totals: dict[str, float] = defaultdict(float)
        for r in self.ok:
            totals["sim"] += r["timing"]["sim_s"] * 1000
            totals["policy+loop"] += r["timing"]["policy_s"] * 1000
            for stage, ms in r["timing"]["stages_ms"].items():
                totals[f"policy.{stage}"] += ms
        return {k: v / max(self.steps, 1) for k, v in totals.items()}

    def peak_rss_mb(self) -> float:
        """Largest peak resident memory among this run's worker processes."""
        per_worker: dict[str, float] = {}
        for r in self.ok:
            per_worker[r["worker"]] = max(per_worker.get(r["worker"], 0.0), r["peak_rss_mb"])
        return max(per_worker.values(), default=float("nan"))


def measure(job: EvalJob, keys: list[str], backend: str, workers: int) -> Run:
    t0 = time.perf_counter()
    if backend == "ray":
        from l3mvn.run.eval.ray_backend import run_ray

        rows_iter = run_ray(job, keys, address=None, num_workers=workers)
    else:
        rows_iter = run_local(job, keys, workers)
    run = Run(job.policy, backend, workers, 0.0, 0.0)
    for row in rows_iter:
        if not run.rows:
            run.first_row_s = time.perf_counter() - t0
        run.rows.append(row)
    run.wall_s = time.perf_counter() - t0
    errors = [r for r in run.rows if is_error_row(r)]
    if errors:
        print(f"warning: {len(errors)} error rows in {backend}x{workers}: {errors[0]['error']}", file=sys.stderr)
    return run


def table(runs: list[Run]) -> str:
    base = {r.policy: r for r in runs if r.backend == "local" and r.workers == 1}
    stages = sorted({s for r in runs for s in r.per_step_ms()})
    head = [
        "policy",
        "backend",
        "workers",
        "episodes",
        "steps",
        "wall s",
        "first row s",
        "steps/s",
        "episodes/h",
        "speed-up",
        "peak RSS/worker MB",
    ] + [f"{s} ms/step" for s in stages]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in runs:
        b = base.get(r.policy)
        ms = r.per_step_ms()
        cells = [
            r.policy,
            r.backend,
            str(r.workers),
            str(len(r.ok)),
            str(r.steps),
            f"{r.wall_s:.1f}",
            f"{r.first_row_s:.1f}",
            f"{r.steps / r.wall_s:.0f}",
            f"{len(r.ok) / r.wall_s * 3600:.0f}",
            f"{b.wall_s / r.wall_s:.2f}" if b else "-",
            f"{r.peak_rss_mb():.0f}",
        ]
        cells += [f"{ms[s]:.2f}" if s in ms else "-" for s in stages]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def plot(runs: list[Run], path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 4))
    base = {r.policy: r for r in runs if r.backend == "local" and r.workers == 1}
    most = max(r.workers for r in runs)
    ax.plot([1, most], [1, most], "k:", label="linear")
    series: dict[tuple[str, str], list[Run]] = defaultdict(list)
    for r in runs:
        series[(r.policy, r.backend)].append(r)
    for (policy, backend), rs in sorted(series.items()):
        rs.sort(key=lambda r: r.workers)
        ax.plot(
            [r.workers for r in rs], [base[policy].wall_s / r.wall_s for r in rs], "o-", label=f"{policy} / {backend}"
        )
    ax.set_xlabel("workers")
    ax.set_ylabel("speed-up over 1 in-process worker (end to end)")
    ax.set_title(title, fontsize=9)
    ax.set_xticks(range(1, most + 1))
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def _ints(text: str) -> list[int]:
    return sorted({int(v) for v in text.split(",")})


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--dataset", default=None, help="SemExp-format dataset (default: procedural houses)")
    p.add_argument("--split", default="val")
    p.add_argument("--houses", type=int, default=2)
    p.add_argument("--episodes-per-house", type=int, default=6)
    p.add_argument("--episodes", type=int, default=None, help="run only the first N episodes")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--policy", action="append", default=None, help="repeatable (default: oracle)")
    p.add_argument("--frame", default="480x640", help="render size HxW (default 480x640, the paper's)")
    p.add_argument("--max-steps", type=int, default=None)
    p.add_argument("--workers", type=_ints, default=[1, 2], help="comma-separated worker counts (default 1,2)")
    p.add_argument("--backends", default="local,ray", help="comma-separated: local, ray (default both)")
    p.add_argument("--plot", type=Path, default=REPO / "docs" / "scaling.png")
    args = p.parse_args(argv)

    h, w = (int(v) for v in args.frame.lower().split("x"))
    config = Config().with_frame(h, w)
    if args.max_steps:
        config = config.replace(sim=dataclasses.replace(config.sim, max_steps=args.max_steps))
    backends = [b.strip() for b in args.backends.split(",") if b.strip()]
    runs: list[Run] = []
    with contextlib.ExitStack() as stack:
        if "ray" in backends:
            try:
                from l3mvn.run.eval.ray_backend import private_ray

                stack.enter_context(private_ray(max(args.workers)))
            except L3MVNError as exc:
                print(f"{exc}: benchmarking local processes only", file=sys.stderr)
                backends.remove("ray")
        for policy in args.policy or ["oracle"]:
            job = EvalJob.create(
                args.dataset,
                args.split,
                houses=args.houses,
                episodes_per_house=args.episodes_per_house,
                seed=args.seed,
                config=config,
                policy=policy,
            )
            keys = job.keys()[: args.episodes] if args.episodes else job.keys()
            for backend in backends:
                for n in args.workers:
                    runs.append(measure(job, keys, backend, n))
                    print(f"{policy} {backend} x{n}: {runs[-1].wall_s:.1f} s", file=sys.stderr)
    source = args.dataset or f"procedural {args.houses} houses x {args.episodes_per_house}"
    title = f"{source}, {h}x{w}, {os.cpu_count()} CPUs"
    print(f"## Throughput: {title}\n")
    print(table(runs))
    plot(runs, args.plot, title)
    print(f"\nscaling plot: {args.plot}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

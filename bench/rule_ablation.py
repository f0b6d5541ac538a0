"""Which of the agent's special rules earn their place: each turned off alone, paired with the default.

    python bench/rule_ablation.py --dataset DEV --split train --policy cost-utility --out runs/rules
    python bench/rule_ablation.py ... --rules keep_heading,clearance   # a subset
    python bench/rule_ablation.py ... --table-only                     # the table from the files there
    python bench/rule_ablation.py ... --policy l3mvn-ff --set policy.head=map --out runs/rules-map

Runs ``l3mvn eval --resume`` once with the default config (``base``) and once per rule with that rule's
``--set`` values, each into ``OUT/<policy>_<rule>.jsonl`` (rerunning resumes a cut-off run and skips a
finished one; ``--set`` settings apply to every configuration, before the rule's own, so give each
``--set`` its own ``--out``), then prints one markdown row per rule: what the rule gains (default minus
rule off, paired per episode, with a 95% bootstrap interval) in SR and SPL on the houses changes are
decided on and on the held-out houses, the episodes walked differently, and the mean steps with the
rule off. A positive gain is what the rule is worth; an interval across zero says the episodes cannot
tell.

Held-out houses: those ``house_split`` puts on its test side (docs/benchmarks.md, "Held-out houses"),
or ``--held-out NAME,NAME``.
"""

from __future__ import annotations

import argparse
import math
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from l3mvn.agent.language.frontier_head import house_split  # noqa: E402
from l3mvn.core.config import Config, override  # noqa: E402
from l3mvn.core.errors import L3MVNError  # noqa: E402
from l3mvn.run.eval.paired import pair_rows  # noqa: E402
from l3mvn.run.eval.results import episode_lines  # noqa: E402


@dataclass(frozen=True)
class Rule:
    """A rule of the agent or planner, and the settings that switch it off (or back to the plain
    mechanism it refines)."""

    name: str
    what: str
    off: tuple[str, ...]


RULES = (
    Rule("keep_heading", "keep stepping while the path stays within 30 deg", ("planner.keep_heading_deg=15",)),
    Rule("clearance", "keep one cell more from walls where the goal allows", ("planner.clearance_cells=0",)),
    Rule(
        "target_marks",
        "clear or side-step collision marks that lengthen the way to the target",
        ("planner.target_mark_detour_m=1000",),
    ),
    Rule(
        "narrow_target_marks",
        "1-5 cell collision marks near the target (wide ones elsewhere)",
        ("planner.collision_mark_target_width_cells=5", "planner.collision_mark_target_max_width_cells=9"),
    ),
    Rule("look_tolerance", "a goal counts as looked at only once faced", ("agent.look_tolerance_deg=89.9",)),
    Rule("press", "walk a faced frontier that still borders unknown to 0.3 m", ("agent.frontier_press_m=0.74",)),
    Rule("candidate_views", "look at a glimpsed target from other poses", ("agent.candidate_views=0",)),
    Rule(
        "glimpse",
        "walk towards a far target seen without depth",
        ("agent.glimpse_min_fraction=0.999", "agent.glimpse_max_fraction=1.0"),
    ),
    Rule("far_areas", "visit areas seen only from afar before wandering", ("agent.look_min_area_m2=1e9",)),
    Rule(
        "patience",
        "give up a goal not come closer to, nor mapped 2 m2 of new floor, in 40 steps",
        ("agent.goal_patience_steps=100000",),
    ),
    Rule(
        "done_frontier_only",
        "a done frontier goal blocks only what is left of that frontier, not other openings within 1 m",
        ("agent.blocked_frontier_gap_m=1000",),
    ),
    Rule("commitment", "keep the current frontier unless another scores 0.15 more", ("agent.commitment_margin=0",)),
    Rule("blocked_stop", "stop at 0.95 m when no path leads closer", ("agent.blocked_stop_distance_m=0.9",)),
    Rule(
        "escape",
        "clear marks and wiggle out after 3 unreachable steps (stuck-signal escapes stay)",
        ("agent.escape_after_unreachable=100000",),
    ),
    Rule(
        "small_explore_goal",
        "approach exploration goals with a 0.1 m disk, not 0.5 m",
        ("agent.explore_goal_dilation_m=0.5",),
    ),
)
BASE = "base"


@dataclass(frozen=True)
class Row:
    """One rule's line of the table: ``decide`` / ``held_out`` hold the SR gain, its interval, the SPL
    gain and its interval (default minus rule off)."""

    rule: Rule
    decide: tuple[float, tuple[float, float], float, tuple[float, float]]
    held_out: tuple[float, tuple[float, float], float, tuple[float, float]]
    changed: int
    steps: float


def run_eval(args: argparse.Namespace, rule: str, settings: tuple[str, ...], out: Path) -> None:
    """``l3mvn eval --resume`` of one configuration into its own file ``out``."""
    cmd = [sys.executable, "-m", "l3mvn.run.cli", "eval", "--dataset", args.dataset, "--split", args.split]
    cmd += ["--policy", args.policy, "--frame", args.frame, "--workers", str(args.workers), "--seed", str(args.seed)]
    cmd += ["--out", str(out), "--resume"]
    for s in (*args.set, *settings):
        cmd += ["--set", s]
    print(f"{rule}: {' '.join(settings) or 'defaults'} -> {out}", file=sys.stderr, flush=True)
    done = subprocess.run(cmd, stdout=subprocess.DEVNULL, check=False)
    if done.returncode != 0:
        raise SystemExit(f"error: the eval of {rule} exited with status {done.returncode}")


def rows_of(path: Path) -> dict[str, dict]:
    """A result file's finished-episode rows by key (a resumed run's later line wins)."""
    if not path.is_file():
        raise SystemExit(f"error: {path} does not exist: run it first (without --table-only)")
    rows = {row["key"]: row for _, row in episode_lines(path).rows}
    if not rows:
        raise SystemExit(f"error: {path} holds no finished episode: run it first (without --table-only)")
    return rows


def gains(
    base: dict[str, dict], off: dict[str, dict], keys: list[str], seed: int
) -> tuple[float, tuple[float, float], float, tuple[float, float]]:
    """SR and SPL gain (base - off) over ``keys`` with their intervals; nan where no key is given."""
    if not keys:
        nan = float("nan")
        return nan, (nan, nan), nan, (nan, nan)
    pairing = pair_rows({k: off[k] for k in keys}, {k: base[k] for k in keys}, "rule off", "default", seed=seed)
    sr, spl = pairing.rows["all"]
    return sr.mean, (sr.low, sr.high), spl.mean, (spl.low, spl.high)


def table_row(rule: Rule, base: dict[str, dict], off: dict[str, dict], held_out: set[str], seed: int) -> Row:
    keys = sorted(set(base) & set(off))
    decide = [k for k in keys if base[k]["scene"] not in held_out]
    unseen = [k for k in keys if base[k]["scene"] in held_out]
    changed = sum(
        1 for k in keys if (base[k]["steps"], base[k]["path_length_m"]) != (off[k]["steps"], off[k]["path_length_m"])
    )
    steps = sum(off[k]["steps"] for k in keys) / len(keys)
    return Row(rule, gains(base, off, decide, seed), gains(base, off, unseen, seed), changed, steps)


def _cell(mean: float, interval: tuple[float, float]) -> str:
    low, high = interval
    if math.isnan(mean):
        return "-"
    mark = "**" if low > 0 or high < 0 else ""
    return f"{mark}{mean:+.3f}{mark} [{low:+.3f}, {high:+.3f}]"


def format_table(rows: list[Row], base: dict[str, dict], held_out: set[str]) -> str:
    n_decide = sum(1 for r in base.values() if r["scene"] not in held_out)
    n_held = len(base) - n_decide

    def sr_spl(rows: list[dict]) -> str:
        if not rows:
            return "-"
        return f"{sum(r['success'] for r in rows) / len(rows):.3f} / {sum(r['spl'] or 0 for r in rows) / len(rows):.3f}"

    lines = [
        f"default: decide houses ({n_decide} eps) SR / SPL "
        f"{sr_spl([r for r in base.values() if r['scene'] not in held_out])}; held-out ({n_held} eps) "
        f"{sr_spl([r for r in base.values() if r['scene'] in held_out])}; mean steps "
        f"{sum(r['steps'] for r in base.values()) / len(base):.0f}",
        "",
        "| rule | what it does | SR gain, decide | SPL gain, decide | SR gain, held-out | SPL gain, held-out | "
        "episodes walked differently | mean steps without it |",
        "|---|---|---|---|---|---|---:|---:|",
    ]
    for r in rows:
        cells = [_cell(r.decide[0], r.decide[1]), _cell(r.decide[2], r.decide[3])]
        cells += [_cell(r.held_out[0], r.held_out[1]), _cell(r.held_out[2], r.held_out[3])]
        lines.append(f"| {r.rule.name} | {r.rule.what} | {' | '.join(cells)} | {r.changed} | {r.steps:.0f} |")
    return "\n".join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dataset", required=True)
    ap.add_argument("--split", default="train")
    ap.add_argument("--policy", required=True)
    ap.add_argument("--frame", default="480x640")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", required=True, help="folder for the result files, one per configuration")
    ap.add_argument("--rules", help=f"comma-separated subset of: {', '.join(r.name for r in RULES)}")
    ap.add_argument("--held-out", help="comma-separated houses (default: house_split's test side)")
    ap.add_argument("--table-only", action="store_true", help="print the table from the files in --out")
    ap.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="SECTION.FIELD=VALUE",
        help="a setting for every configuration, the default's included (e.g. policy.head=map)",
    )
    args = ap.parse_args()
    try:
        override(Config(), args.set)
    except L3MVNError as exc:
        raise SystemExit(f"error: {exc}") from None

    known = {r.name: r for r in RULES}
    chosen = list(RULES)
    if args.rules:
        names = [n.strip() for n in args.rules.split(",") if n.strip()]
        unknown = [n for n in names if n not in known]
        if unknown or not names:
            what = f"unknown rule(s) {', '.join(unknown)}" if unknown else "--rules names no rule"
            raise SystemExit(f"error: {what}; choose from {', '.join(known)}")
        chosen = [known[n] for n in names]
    if not args.table_only:
        Path(args.out).mkdir(parents=True, exist_ok=True)

    paths = {}
    for name, settings in [(BASE, ())] + [(r.name, r.off) for r in chosen]:
        paths[name] = Path(args.out) / f"{args.policy}_{name}.jsonl"
        if not args.table_only:
            run_eval(args, name, settings, paths[name])
    try:
        base = rows_of(paths[BASE])
        held_out = (
            {h.strip() for h in args.held_out.split(",")}
            if args.held_out
            else {r["scene"] for r in base.values() if house_split(r["scene"]) == "test"}
        )
        rows = [table_row(r, base, rows_of(paths[r.name]), held_out, args.seed) for r in chosen]
    except L3MVNError as exc:
        raise SystemExit(f"error: {exc}") from None
    print(f"{args.policy}, held-out houses: {', '.join(sorted(held_out)) or 'none'}")
    print(format_table(rows, base, held_out))
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""How good is each global policy's frontier choice, judged by the ground truth, on the same maps?

    python bench/bench_frontier_regret.py --dataset DIR [--split train] [--workers 2] [--limit N]
        [--houses held-out | --houses A B ...] [--only LABEL ...] [--poni CHECKPOINT.pt ...]
        [--heads HEAD.pt ...]

``--houses held-out`` keeps the houses ``house_split`` puts on the test side: the frontier-trained
head never saw them (neither in training nor in choosing its checkpoint).

One behaviour policy (cost-utility by default) walks every episode. At each re-selection, every
policy under test chooses among the *same* frontiers on the *same* map, and the choice is scored by
the frontier oracle's criterion: travel cost to the frontier plus the ground-truth geodesic from it to
the goal. Regret = that total minus the best frontier's. It isolates the choice from everything that
follows it (commitment, planning, luck of the walk), so a language prior's information shows at once
instead of through whole-episode SPL runs, whose seed spread hides small differences. The oracle
scores 0 by construction.

Reported per policy: mean regret in metres overall and per goal, and how often its choice differs from
cost-utility's. ``--only`` runs some candidates (cost-utility always, the reference of the last
column); ``--poni`` adds PONI with each checkpoint given, ``--heads`` l3mvn-ff with each feed-forward
head file given (from ``l3mvn train-head``; a frontier head both by the bound rule and ``expected``).
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import sys
from collections import defaultdict
from multiprocessing import get_context
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
os.environ.setdefault("HF_HUB_OFFLINE", "1")

from l3mvn.agent.language import GOALS  # noqa: E402
from l3mvn.agent.language.frontier_head import house_split  # noqa: E402
from l3mvn.agent.language.head import load_head  # noqa: E402
from l3mvn.agent.policies.oracle_frontier import frontier_goal_distances  # noqa: E402
from l3mvn.core.config import Config, PolicyConfig, PotentialConfig  # noqa: E402
from l3mvn.run.registry import make_policy  # noqa: E402
from l3mvn.run.runner import Runner  # noqa: E402
from l3mvn.world.datasets import load_episode_set  # noqa: E402

# (label, policy name, options): the paper's policies and its Table II ablations.
CANDIDATES = [
    ("cost-utility", "cost-utility", PolicyConfig()),
    ("frontier", "frontier", PolicyConfig()),
    ("l3mvn-ff", "l3mvn-ff", PolicyConfig()),
    ("l3mvn-ff official_code", "l3mvn-ff", PolicyConfig(selection="official_code")),
    ("l3mvn-ff rooms head", "l3mvn-ff", PolicyConfig(head="rooms")),
    ("l3mvn-ff frontiers head", "l3mvn-ff", PolicyConfig(head="frontiers")),
    ("l3mvn-ff frontiers expected", "l3mvn-ff", PolicyConfig(head="frontiers", selection="expected")),
    ("l3mvn-ff rooms-bag head", "l3mvn-ff", PolicyConfig(head="rooms-bag")),  # the ablations without the LM
    ("l3mvn-ff frontiers-bag head", "l3mvn-ff", PolicyConfig(head="frontiers-bag")),
    ("l3mvn-ff frontiers-bag expected", "l3mvn-ff", PolicyConfig(head="frontiers-bag", selection="expected")),
    ("l3mvn-zs", "l3mvn-zs", PolicyConfig()),
    ("l3mvn-zs embedding", "l3mvn-zs", PolicyConfig(scorer="embedding")),
    ("near+llm", "near+llm", PolicyConfig()),
    ("oracle-frontier", "oracle-frontier", PolicyConfig()),  # 0 by construction: checks the bench
    ("poni", "poni", PolicyConfig()),  # the shipped checkpoint
]

_STATE: dict = {}


def _candidates(
    only: list[str] | None, poni: list[str], heads: list[str]
) -> list[tuple[str, str, PolicyConfig, PotentialConfig]]:
    chosen = [
        (label, name, opts, PotentialConfig())
        for label, name, opts in CANDIDATES
        if only is None or label in only or label == "cost-utility"
    ]
    for head in heads:
        chosen.append((f"l3mvn-ff {Path(head).name}", "l3mvn-ff", PolicyConfig(head=head), PotentialConfig()))
        if load_head(head)[1].get("kind", "").startswith("frontiers"):
            options = PolicyConfig(head=head, selection="expected")
            chosen.append((f"l3mvn-ff {Path(head).name} expected", "l3mvn-ff", options, PotentialConfig()))
    return chosen + [(f"poni {Path(c).name}", "poni", PolicyConfig(), PotentialConfig(checkpoint=c)) for c in poni]


def _episode(args: tuple[str | None, str, int, str, list]) -> list[tuple[str, str, float, bool]]:
    dataset, split, index, behaviour, chosen = args
    if "eset" not in _STATE:
        _STATE["eset"] = load_episode_set(dataset, split, cfg=_STATE.setdefault("cfg", Config().with_frame(120, 160)))
    eset, cfg = _STATE["eset"], _STATE["cfg"]
    ep = eset.episodes[index]
    runner = Runner(cfg, config_hash="bench")
    floor = runner.floor(eset.scene_of(ep))
    candidates = [
        (label, make_policy(name, floor.env, floor.task, cfg.replace(policy=opts, poni=poni)).global_policy)
        for label, name, opts, poni in chosen
    ]
    session = runner.session(eset.scene_of(ep), behaviour)
    session.start(ep)
    region, rng = floor.task.region(ep.goal), np.random.default_rng(0)
    rows = []
    for _, decision in session.frontier_choices():
        frontiers = decision.frontiers
        if len(frontiers) < 2:
            continue
        total = np.array([f.cost for f in frontiers]) + frontier_goal_distances(
            frontiers, decision.map, region.distances_at
        )
        if not np.isfinite(total).any():
            continue
        best = total.min()
        # A frontier off the ground-truth floor (seen through a gap) counts as the worst reachable one.
        total = np.where(np.isfinite(total), total, total[np.isfinite(total)].max())
        choices = {}
        for label, policy in candidates:
            sel = policy.select(copy.deepcopy(frontiers), decision.map, ep.goal, rng)
            choices[label] = sel.frontier
        for label, i in choices.items():
            rows.append((label, ep.goal, float(total[i] - best), i != choices["cost-utility"]))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dataset", default=None, help="SemExp dataset dir (default: procedural houses)")
    parser.add_argument("--split", default="train")
    parser.add_argument("--behaviour", default="cost-utility", help="policy that walks the episodes")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--limit", type=int, default=None, help="first N episodes only")
    parser.add_argument(
        "--houses",
        nargs="+",
        default=None,
        help="only these houses; 'held-out': the test side of the frontier head's house split",
    )
    parser.add_argument("--json", action="store_true", help="print the table as one JSON line too")
    labels = [label for label, _, _ in CANDIDATES]
    parser.add_argument("--only", nargs="+", default=None, choices=labels, help="these candidates only")
    parser.add_argument("--poni", nargs="+", default=[], help="PONI checkpoints to add as candidates")
    parser.add_argument("--heads", nargs="+", default=[], help="feed-forward head files to add as l3mvn-ff candidates")
    args = parser.parse_args()
    chosen_candidates = _candidates(args.only, args.poni, args.heads)
    eset = load_episode_set(args.dataset, args.split, cfg=Config().with_frame(120, 160))
    chosen = list(range(len(eset.episodes)))
    if args.houses == ["held-out"]:
        chosen = [i for i in chosen if house_split(eset.episodes[i].scene) == "test"]
    elif args.houses:
        unknown = sorted(set(args.houses) - set(eset.scenes))
        if unknown:
            parser.error(f"unknown house(s) {', '.join(unknown)}; valid: held-out, {', '.join(sorted(eset.scenes))}")
        chosen = [i for i in chosen if eset.episodes[i].scene in args.houses]
    chosen = chosen[: args.limit]
    n = len(chosen)
    houses = sorted({eset.episodes[i].scene for i in chosen})
    jobs = [(args.dataset, args.split, i, args.behaviour, chosen_candidates) for i in chosen]
    regret: dict[str, dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
    changed: dict[str, list[bool]] = defaultdict(list)
    with get_context("forkserver").Pool(args.workers) as pool:
        for rows in pool.imap_unordered(_episode, jobs):
            for label, goal, r, differs in rows:
                regret[label][goal].append(r)
                regret[label]["all"].append(r)
                changed[label].append(differs)
    goals = ["all"] + [g for g in GOALS if regret["cost-utility"][g]]
    print(
        f"{n} episodes in {len(houses)} houses ({', '.join(houses)}), {len(regret['cost-utility']['all'])} "
        "re-selections; mean regret (m) of each choice"
    )
    print("| policy | " + " | ".join(goals) + " | differs from cost-utility |")
    print("|---" * (len(goals) + 2) + "|")
    table = {}
    for label, *_ in chosen_candidates:
        means = {g: float(np.mean(regret[label][g])) for g in goals}
        table[label] = {"regret_m": means, "differs": float(np.mean(changed[label]))}
        print(f"| {label} | " + " | ".join(f"{means[g]:.3f}" for g in goals) + f" | {np.mean(changed[label]):.3f} |")
    if args.json:
        print(json.dumps(table))


if __name__ == "__main__":
    main()

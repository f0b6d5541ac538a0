"""One policy's frontier choices in given episodes, with the ground truth beside every frontier.

    python bench/trace_choices.py --dataset DIR [--split train] --policy poni --episode HOUSE/FLOOR/ID
        [--episode KEY ...] [--frame 480x640] [--set SECTION.FIELD=VALUE ...]

Walks each episode as ``l3mvn eval`` does (same config, same seed) and prints every fresh choice
among frontiers: the frontier the agent took, the rule's own pick where the agent's commitment kept
another, and the frontier the oracle would take (least travel + true metres on to the goal). Per
frontier: travel cost, size in cells, what the rule compared (a language policy's fused score, PONI's
or the expected rule's total metres, else S_CU), the prior's expected metres on where it predicts
them, and the true geodesic metres on from the frontier to the goal (``inf``: off the true floor).
After each episode, one line on the goal's frontier (one within 1.5 m of the goal by the true floor):
at how many choices it was listed and taken, its median rank by what the rule compared (by S_CU for
the policies that leave no numbers of their own), and, for a prior that predicts metres, how much
nearer the goal it expected it than the frontier taken.

What the dashboard shows of one decision, for every decision of an episode, with what the agent cannot
know: whether a lost episode is the prior's error (it expected the goal beyond the wrong frontier),
the walk's (commitment kept a worse one), or a near tie.
"""

from __future__ import annotations

import argparse
import os
import sys
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
os.environ.setdefault("HF_HUB_OFFLINE", "1")

from l3mvn.agent.decision import Decision  # noqa: E402
from l3mvn.agent.policies.oracle_frontier import frontier_goal_distances  # noqa: E402
from l3mvn.core.config import Config, override  # noqa: E402
from l3mvn.core.errors import L3MVNError  # noqa: E402
from l3mvn.run.cli import frame_size  # noqa: E402
from l3mvn.run.registry import check_policy  # noqa: E402
from l3mvn.run.runner import Runner  # noqa: E402
from l3mvn.world.baselines import ObjectDistances  # noqa: E402
from l3mvn.world.datasets import load_episode_set  # noqa: E402


def choice_lines(step: int, decision: Decision, truth: np.ndarray) -> list[str]:
    """The lines of one choice: a header, then one row per frontier (``truth``: true metres on)."""
    frontiers = decision.frontiers
    fusion = frontiers[0].fusion
    cost = np.array([f.cost for f in frontiers], dtype=np.float64)
    compared = np.array(fusion.compared) if fusion is not None else np.array([f.s_cu for f in frontiers])
    expected = fusion.expected_m if fusion is not None and fusion.expected_m else None
    took, oracle = decision.chosen_frontier, int(np.argmin(cost + truth))
    header = f"step {step}: took F{frontiers[took].id}" if took is not None else f"step {step}: took none"
    if fusion is not None and took is not None and fusion.choice != took:
        header += f" (kept by commitment; the rule picked F{frontiers[fusion.choice].id})"
    header += f"; oracle F{frontiers[oracle].id}"
    lines = [header]
    for k, f in enumerate(frontiers):
        mark = ("*" if k == took else " ") + ("o" if k == oracle else " ")
        prior = f"  expected {expected[k]:5.1f} m" if expected is not None else ""
        lines.append(
            f"  {mark} F{f.id:<3d} cost {cost[k]:5.1f} m  size {f.size:4d}  compared {compared[k]:6.2f}{prior}"
            f"  true on {truth[k]:5.1f} m"
        )
    return lines


# A frontier this near the goal by the true floor counts as the goal's: its door, or the room's open side.
GOAL_FRONTIER_M = 1.5


def rank_order(decision: Decision) -> tuple[np.ndarray, str]:
    """A key per frontier, least first, and what it is: what a language policy or PONI compared
    (least first for the rules that compare metres), else S_CU, which only cost-utility ranks by (the
    other policies without a record leave no numbers of their own in the decision)."""
    fusion = decision.frontiers[0].fusion
    if fusion is None:
        return -np.array([f.s_cu for f in decision.frontiers]), "S_CU"
    label = "the rule's totals" if fusion.least_wins else "the rule's scores"
    return np.array(fusion.compared) * (1 if fusion.least_wins else -1), label


def goal_frontier(decision: Decision, truth: np.ndarray) -> tuple[int, int] | None:
    """The goal's frontier best ranked by ``rank_order``, as (index, rank from 1); None when no
    frontier lies within ``GOAL_FRONTIER_M``."""
    near = truth <= GOAL_FRONTIER_M
    if not near.any():
        return None
    key, _ = rank_order(decision)
    rank = np.argsort(np.argsort(key, kind="stable"), kind="stable") + 1
    best = int(np.flatnonzero(near)[np.argmin(rank[near])])
    return best, int(rank[best])


@dataclass
class GoalFrontierTally:
    """Over one episode's choices: how often the goal's frontier was listed and taken, its rank, and
    where the prior predicts metres, how much nearer to the goal it expected it than the frontier taken
    (negative: it rated the goal's frontier better, and travel or the bonuses outweighed that)."""

    choices: int = 0
    taken: int = 0
    ranks: list[int] = field(default_factory=list)
    listed: list[int] = field(default_factory=list)
    expected_gap_m: list[float] = field(default_factory=list)
    ranked_by: str = ""

    def add(self, decision: Decision, truth: np.ndarray) -> None:
        self.choices += 1
        found = goal_frontier(decision, truth)
        if found is None:
            return
        k, rank = found
        self.ranked_by = rank_order(decision)[1]
        self.ranks.append(rank)
        self.listed.append(len(decision.frontiers))
        took = decision.chosen_frontier
        if took is not None and truth[took] <= GOAL_FRONTIER_M:
            self.taken += 1
            return
        fusion = decision.frontiers[0].fusion
        if took is not None and fusion is not None and fusion.expected_m:
            self.expected_gap_m.append(fusion.expected_m[k] - fusion.expected_m[took])

    def line(self) -> str:
        listed = f"{len(self.ranks)} of {self.choices} choices"
        head = f"goal's frontier (<= {GOAL_FRONTIER_M:g} m from the goal) listed at {listed}"
        if not self.ranks:
            return head
        line = f"{head}, taken at {self.taken}; its median rank {np.median(self.ranks):g} of {np.median(self.listed):g}"
        line += f" by {self.ranked_by}"
        if self.expected_gap_m:
            line += f"; expected metres on, against the frontier taken: median {np.median(self.expected_gap_m):+.1f} m"
        return line


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dataset", required=True)
    ap.add_argument("--split", default="train")
    ap.add_argument("--policy", required=True)
    ap.add_argument(
        "--episode", action="append", required=True, metavar="HOUSE/FLOOR/ID", help="as in the result lines"
    )
    ap.add_argument("--frame", default="480x640", metavar="HxW")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--set", action="append", default=[], metavar="SECTION.FIELD=VALUE")
    args = ap.parse_args()
    try:
        height, width = frame_size(args.frame)
    except argparse.ArgumentTypeError as exc:
        raise SystemExit(f"error: --frame: {exc}") from None
    try:
        check_policy(args.policy)
        cfg = override(Config().with_frame(height, width), args.set)
        episodes = load_episode_set(args.dataset, args.split, seed=args.seed, cfg=cfg)
    except L3MVNError as exc:
        raise SystemExit(f"error: {exc}") from None
    by_key = {ep.key: ep for ep in episodes.episodes}
    missing = [k for k in args.episode if k not in by_key]
    if missing:
        example = next(iter(by_key), "none there")
        raise SystemExit(f"error: no episode {', '.join(missing)} in {args.dataset} ({args.split}); e.g. {example}")
    runner = Runner(cfg, seed=args.seed)
    try:  # a habitat floor is a server process: closed however the walk ends
        for key in args.episode:
            ep = by_key[key]
            scene = episodes.scene_of(ep)
            distances = partial(ObjectDistances(runner.floor(scene).task), ep.goal)
            session = runner.session(scene, args.policy)
            session.start(ep)
            print(f"# {key}: {ep.goal}, {args.policy}")
            tally = GoalFrontierTally()
            for step, decision in session.frontier_choices():
                truth = frontier_goal_distances(decision.frontiers, decision.map, distances)
                print("\n".join(choice_lines(step, decision, truth)))
                tally.add(decision, truth)
            result = session.result
            outcome = "success" if result.success else result.failure
            print(f"# {key}: {outcome} in {result.steps} steps, SPL {result.spl:.3f}")
            print(f"# {key}: {tally.line()}")
    finally:
        runner.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())

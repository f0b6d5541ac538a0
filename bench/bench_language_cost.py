"""What language scoring adds to an agent step, and how often its cache answers.

    python bench/bench_language_cost.py [--dataset DIR --split S] [--episodes 6] [--policies ...]

Runs the same episodes with each policy (cost-utility first, as the reference without language) and
reports the agent's per-step time (Decision.timings_ms: mapping, frontiers, policy = language scoring
and fusion, planning), the simulator's, and the scorer's cache hit rate. Model loading happens once
before timing (it is a per-process cost, not a per-step one).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from l3mvn.agent.policies.language_policy import shared_scorer
from l3mvn.core.config import Config
from l3mvn.run.events import EventBus
from l3mvn.run.runner import Runner
from l3mvn.world.datasets import load_episode_set


def run(policy: str, eset, cfg: Config, episodes) -> dict:
    stages: dict[str, list[float]] = {}
    sim_s = steps = 0
    runner = Runner(cfg, config_hash="bench")
    for ep in episodes:
        bus = EventBus()
        bus.subscribe(
            lambda ev: (
                [stages.setdefault(k, []).append(v) for k, v in ev.decision.timings_ms.items()]
                if ev.decision is not None
                else None
            )
        )
        session = runner.session(eset.scene_of(ep), policy, bus)
        session.start(ep)
        while not session.done:
            t = time.perf_counter()
            session.step()
            sim_s += time.perf_counter() - t
        steps += session.env.steps
    agent_ms = {k: float(np.sum(v)) / steps for k, v in stages.items()}
    return {"steps": steps, "step_ms": sim_s * 1e3 / steps, "agent_ms": agent_ms}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dataset", default=None)
    parser.add_argument("--split", default="train")
    parser.add_argument("--episodes", type=int, default=6)
    parser.add_argument("--policies", nargs="*", default=["cost-utility", "l3mvn-ff", "l3mvn-zs"])
    parser.add_argument("--threads", type=int, default=1, help="torch threads (1 per worker is the eval setting)")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    cfg = Config().with_frame(120, 160)
    eset = load_episode_set(args.dataset, args.split, houses=3, episodes_per_house=2, seed=0, cfg=cfg)
    episodes = eset.episodes[: args.episodes]
    for name in ("feedforward", "roomtype"):
        shared_scorer(name)  # load once, outside the timing
    rows = {}
    for policy in args.policies:
        for name in ("feedforward", "roomtype"):
            shared_scorer(name).clear_cache()
        rows[policy] = run(policy, eset, cfg, episodes)
        if policy != "cost-utility":
            scorer = {"l3mvn-ff": "feedforward", "near+llm": "feedforward"}.get(policy, "roomtype")
            info = shared_scorer(scorer).cache_info()
            rows[policy]["cache"] = info
    print("| policy | steps | ms per step (all) | language ms per step | language adds | cache hits |")
    print("|---|---:|---:|---:|---:|---:|")
    for policy, r in rows.items():
        lang = r["agent_ms"].get("policy", 0.0)
        adds = lang / max(r["step_ms"] - lang, 1e-9)
        cache = r.get("cache")
        hits = (
            f"{cache.hits / max(cache.hits + cache.misses, 1):.1%} ({cache.hits}/{cache.hits + cache.misses})"
            if cache
            else "-"
        )
        print(f"| {policy} | {r['steps']} | {r['step_ms']:.1f} | {lang:.2f} | {adds:+.1%} | {hits} |")


if __name__ == "__main__":
    main()

"""Offline ranking benchmark of the language scorers on real rooms held out by building.

For each goal: AUC of "rooms that contain the goal score above rooms that do not", each room scored
from its OTHER objects only (the goal itself removed), on the ``test`` buildings (never used to
train the head or choose its checkpoint). tv is only labelled in the AI2-THOR rooms, so its AUC rests
on few rooms. Reference line: a Bernoulli naive Bayes fitted on the ``train`` buildings' counts.

    python bench/bench_language_auc.py                       # offline scorers, both object filters
    python bench/bench_language_auc.py --scorers mlm causal --mlm-model /path/roberta-large
    python bench/bench_language_auc.py --scorers llm --filters entropy --llm-models smollm2-135m gemma3-270m \
        --llm-prompts paper contrastive
    python bench/bench_language_auc.py --scorers feedforward --embedders minilm smollm2-135m   # Emb(W)
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np
from scipy.stats import rankdata

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
os.environ.setdefault("HF_HUB_OFFLINE", "1")

from l3mvn.agent.language import GOALS, Room, load_rooms, load_stats, make_scorer, rooms_in  # noqa: E402
from l3mvn.core.errors import L3MVNError  # noqa: E402


def auc(scores: np.ndarray, positive: np.ndarray) -> float:
    """Mann-Whitney AUC with ties counted half."""
    n_pos, n_neg = int(positive.sum()), int((~positive).sum())
    if not n_pos or not n_neg:
        return float("nan")
    ranks = rankdata(scores)
    return float((ranks[positive].sum() - n_pos * (n_pos + 1) / 2) / (n_pos * n_neg))


def goal_cases(rooms: list[Room], goal: str) -> tuple[list[frozenset[str]], np.ndarray]:
    """Non-empty rooms that label ``goal``: their objects minus the goal, and whether it was there."""
    cases = [r for r in rooms if goal in r.labelled_goals and r.objects - {goal}]
    return [r.objects - {goal} for r in cases], np.array([goal in r.objects for r in cases])


def naive_bayes_scores(train: list[Room], vocab: tuple[str, ...], goal: str, sets: list[frozenset[str]]) -> np.ndarray:
    """Bernoulli naive-Bayes log-odds of ``goal`` from presence/absence of ``vocab`` objects."""
    rooms = [r for r in train if goal in r.labelled_goals and r.objects - {goal}]
    y = np.array([goal in r.objects for r in rooms])
    x = np.array([[o in r.objects for o in vocab] for r in rooms], dtype=float)
    p1 = (x[y].sum(0) + 1) / (y.sum() + 2)
    p0 = (x[~y].sum(0) + 1) / ((~y).sum() + 2)
    q = np.array([[o in s for o in vocab] for s in sets], dtype=float)
    return q @ np.log(p1 / p0) + (1 - q) @ np.log((1 - p1) / (1 - p0))


def table(rows: dict[str, list[float]], counts: list[str]) -> str:
    head = "| scorer | " + " | ".join(GOALS) + " | mean |"
    lines = [head, "|---" * (len(GOALS) + 2) + "|", "| positives / rooms | " + " | ".join(counts) + " | |"]
    for name, aucs in rows.items():
        lines.append(f"| {name} | " + " | ".join(f"{a:.2f}" for a in aucs) + f" | {np.nanmean(aucs):.3f} |")
    return "\n".join(lines)


def timing(scorer, sets: list[frozenset[str]], batch: int = 8, repeats: int = 5) -> tuple[float, float]:
    """ms per call of ``batch`` frontiers x 6 goals: cold (empty cache) and cached (same sets again)."""
    cold, warm = [], []
    for r in range(repeats):
        chunk = sets[r * batch : (r + 1) * batch]
        scorer.clear_cache()
        t = time.perf_counter()
        scorer.score(chunk)
        cold.append(time.perf_counter() - t)
        t = time.perf_counter()
        scorer.score(chunk)
        warm.append(time.perf_counter() - t)
    return 1000 * float(np.median(cold)), 1000 * float(np.median(warm))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scorers", nargs="+", default=["embedding", "roomtype", "feedforward"])
    ap.add_argument("--filters", nargs="+", default=["entropy", "all"], choices=["entropy", "all"])
    ap.add_argument("--mlm-model", default="roberta-large")
    ap.add_argument("--causal-model", default="gpt2-large")
    ap.add_argument("--llm-models", nargs="+", default=["smollm2-135m"], help="llm scorer: models to compare")
    ap.add_argument("--llm-prompts", nargs="+", default=["paper"], help="llm scorer: prompts to compare")
    ap.add_argument(
        "--embedders", nargs="+", default=["minilm"], help="feedforward scorer: the room heads' embedders to compare"
    )
    ap.add_argument("--split", default="test", choices=["val", "test"])
    args = ap.parse_args(argv)

    rooms = load_rooms()
    held_out, train = rooms_in(rooms, args.split), rooms_in(rooms, "train")
    stats = load_stats()
    print(
        f"{len(held_out)} rooms of {len({r.building for r in held_out})} held-out buildings ({args.split}); "
        f"naive Bayes fitted on {len(train)} train rooms; informative list: {', '.join(stats.informative)}\n"
    )
    cases = {g: goal_cases(held_out, g) for g in GOALS}
    counts = [f"{int(y.sum())}/{len(y)}" for _, y in cases.values()]
    rows: dict[str, list[float]] = {}
    all_vocab = tuple(sorted({o for r in train for o in r.objects}))
    for filt, vocab in (("entropy", stats.informative), ("all", all_vocab)):
        if filt in args.filters:
            rows[f"naive Bayes prior ({filt})"] = [
                auc(naive_bayes_scores(train, vocab, g, s), y) for g, (s, y) in cases.items()
            ]
    timings = {}
    variants = []
    for name in args.scorers:
        if name == "llm":
            variants += [
                (f"llm {m} {p}", name, {"model": m, "prompt": p}) for m in args.llm_models for p in args.llm_prompts
            ]
        elif name == "feedforward":
            variants += [(f"{name} {e}", name, {"model": e}) for e in args.embedders]
        else:
            variants.append((name, name, {}))
    for label, name, extra in variants:
        for filt in args.filters:
            options = {"object_filter": filt, **extra}
            if name == "mlm":
                options["model"] = args.mlm_model
            if name == "causal":
                options["model"] = args.causal_model
            if name == "feedforward":  # room membership is what the room-list head predicts
                options["head"] = "rooms"
            try:
                scorer = make_scorer(name, **options)
            except L3MVNError as exc:
                print(f"skipped {label}: {exc}")
                break
            rows[f"{label} ({filt})"] = [auc(scorer.score_goal(s, g), y) for g, (s, y) in cases.items()]
            if filt == "entropy":
                sets = [s for s in cases["chair"][0] if scorer.query_objects(s)]
                timings[label] = timing(scorer, sets)
    print(table(rows, counts))
    if timings:
        print("\n| scorer | ms / 8 frontiers x 6 goals, cold | cached |\n|---|---|---|")
        for name, (cold, warm) in timings.items():
            print(f"| {name} | {cold:.1f} | {warm:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())

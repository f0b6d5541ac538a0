"""Training the feed-forward head on frontiers of real house maps (``l3mvn train-head --data F``).

The paper's architecture stays: a frontier's objects -> "This frontier contains o1, ..., and ok." ->
MiniLM embedding -> 3-layer head -> one number per goal. What changes is what the number means and
what teaches it. The room-list head predicts p(goal | objects share a room), which says little about
which *frontier* leads to a toilet; this head predicts the expected geodesic metres from the frontier
to the nearest instance of each goal, learned from frontier data (``l3mvn language frontier-data``):
frontiers an agent really chose among, labelled by where the goals really are.

Loss, per (choice, goal) = the frontiers of one re-selection and one goal the agent's map did not yet
hold (a goal on the map is walked to, never searched for):

- listwise: cross-entropy between softmax_i(-(c_i + d_i) / tau), the frontier oracle's criterion
  (c_i the agent's travel cost to frontier i, d_i the ground-truth metres on from it), and
  softmax_i(-(c_i - U_i / lambda + d^_i) / tau), the ``expected`` selection's (cost-utility's criterion
  in metres plus the head's d^_i): the head learns what cost-utility misses, and a head that knows
  nothing leaves cost-utility's choice as it is;
- calibration: ``calibration`` x Huber(d^_i - d_i), because the ranking alone is blind to a shift
  shared by all frontiers and the selection adds d^ to metres of travel.

A frontier with no path to the goal counts as the farthest reachable one (as the regret bench does).
Split by house (``house_split``: a hash of the name, so a house's side never depends on which others
are in the file); the checkpoint is the epoch with the lowest mean regret per choice on the
validation houses, the regret bench's measure; the test houses are never read.

``bag=True`` (``--head frontiers-bag``) is the ablation without the language model: the same lists,
loss and checkpoint rule, but each frontier's input is the multi-hot vector of its window's objects
over every category the training and validation frontiers hold, instead of its sentence's embedding.
"""

from __future__ import annotations

import hashlib
import random
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from l3mvn.agent.language.frontier_file import Choice, frontier_query, load_choices
from l3mvn.agent.language.head import (
    BAG,
    BAG_FEATURES,
    SHIPPED_HEADS,
    GoalHead,
    bag_features,
    save_head,
)
from l3mvn.agent.language.models import MINILM, load_sentence_encoder
from l3mvn.agent.language.vocabulary import GOALS
from l3mvn.core.config import FrontierConfig
from l3mvn.core.errors import L3MVNError

HOUSE_SPLITS = ("train", "val", "test")
# Of 100 hash buckets: test first, then val, the rest train (a small set of houses meets these shares roughly).
_TEST_BUCKETS, _VAL_BUCKETS = 20, 10
FRONTIER_HEAD_KIND = "frontiers"


def house_split(house: str) -> str:
    """``"train"``, ``"val"`` or ``"test"`` for a house, from the first bytes of the SHA-1 of its name."""
    bucket = int.from_bytes(hashlib.sha1(house.encode()).digest()[:4], "big") % 100
    if bucket < _TEST_BUCKETS:
        return "test"
    return "val" if bucket < _TEST_BUCKETS + _VAL_BUCKETS else "train"


@dataclass(frozen=True)
class RankingLists:
    """Padded (choice, goal) lists: ``sentence`` indexes the unique sentences, ``mask`` marks real
    frontiers; ``cost``, ``base`` and ``dist`` are metres; ``goal`` indexes ``GOALS``; ``s_cu`` for
    the baseline. ``base`` = cost - U / lambda: cost-utility's own criterion in metres (argmax S_CU =
    argmin base), which the head's metres are added to."""

    sentence: torch.Tensor  # (L, F) long
    mask: torch.Tensor  # (L, F) bool
    cost: torch.Tensor  # (L, F) float
    base: torch.Tensor  # (L, F) float
    dist: torch.Tensor  # (L, F) float
    s_cu: torch.Tensor  # (L, F) float
    goal: torch.Tensor  # (L,) long

    def __len__(self) -> int:
        return len(self.goal)

    def take(self, idx: torch.Tensor) -> RankingLists:
        return RankingLists(
            *(t[idx] for t in (self.sentence, self.mask, self.cost, self.base, self.dist, self.s_cu, self.goal))
        )


def ranking_lists(choices: Sequence[Choice], sentences: dict[str, int], cu_lambda: float) -> RankingLists:
    """Every (choice, goal) with two or more frontiers, a goal the house holds and the map did not."""
    rows = []
    for ch in choices:
        if len(ch.frontiers) < 2:
            continue
        for g, goal in enumerate(GOALS):
            if goal in ch.mapped:
                continue
            d = np.array([f.goal_m[goal] for f in ch.frontiers])
            finite = np.isfinite(d)
            if not finite.any():
                continue
            rows.append((ch, g, np.where(finite, d, d[finite].max())))
    if not rows:
        raise L3MVNError("no (choice, goal) with two frontiers and a reachable goal in the data")
    width = max(len(ch.frontiers) for ch, _, _ in rows)
    n = len(rows)
    sentence = torch.zeros((n, width), dtype=torch.long)
    mask = torch.zeros((n, width), dtype=torch.bool)
    cost, base, dist, s_cu = (torch.zeros((n, width)) for _ in range(4))
    for r, (ch, _, d) in enumerate(rows):
        k = len(ch.frontiers)
        sentence[r, :k] = torch.tensor([sentences[frontier_query(f.objects)] for f in ch.frontiers])
        mask[r, :k] = True
        cost[r, :k] = torch.tensor([f.cost for f in ch.frontiers])
        base[r, :k] = torch.tensor([f.cost - f.utility / cu_lambda for f in ch.frontiers])
        dist[r, :k] = torch.from_numpy(d.astype(np.float32))
        s_cu[r, :k] = torch.tensor([f.s_cu for f in ch.frontiers])
    return RankingLists(sentence, mask, cost, base, dist, s_cu, torch.tensor([g for _, g, _ in rows]))


def regret(choice: torch.Tensor, lists: RankingLists) -> torch.Tensor:
    """Per list: travel + ground-truth metres of the chosen frontier minus the best one's."""
    total = torch.where(lists.mask, lists.cost + lists.dist, torch.inf)
    return total.gather(1, choice[:, None])[:, 0] - total.min(1).values


def expected_choice(pred: torch.Tensor, lists: RankingLists) -> torch.Tensor:
    """The ``expected`` selection: argmin of cost-utility's metres + predicted metres on."""
    return torch.where(lists.mask, lists.base + pred, torch.inf).argmin(1)


def _predict(head: GoalHead, table: torch.Tensor, lists: RankingLists) -> torch.Tensor:
    """(L, F) predicted metres to each list's goal."""
    # Each sentence the lists hold, once: BatchNorm sees the batch's vocabulary, and the cost of a step
    # grows with the batch, not with every sentence of thousands of houses.
    used, inverse = torch.unique(lists.sentence, return_inverse=True)
    if head.training and len(used) < 2:  # BatchNorm needs two rows to train on
        used, inverse = torch.arange(len(table)), lists.sentence
    out: torch.Tensor = head(table[used])
    per = out[inverse]  # (L, F, G)
    return per.gather(2, lists.goal[:, None, None].expand(-1, per.shape[1], 1))[..., 0]


def _loss(pred: torch.Tensor, lists: RankingLists, tau: float, calibration: float) -> torch.Tensor:
    neg = torch.finfo(pred.dtype).min
    target = torch.softmax(torch.where(lists.mask, -(lists.cost + lists.dist) / tau, neg), 1)
    logp = torch.log_softmax(torch.where(lists.mask, -(lists.base + pred) / tau, neg), 1)
    listwise = -(target * torch.where(lists.mask, logp, 0.0)).sum(1).mean()
    huber = nn.functional.huber_loss(pred[lists.mask], lists.dist[lists.mask], delta=1.0)
    return listwise + calibration * huber


@torch.inference_mode()
def _scores(head: GoalHead, table: torch.Tensor, lists: RankingLists) -> dict[str, float]:
    head.eval()
    pred = _predict(head, table, lists)
    mae = (pred - lists.dist).abs()[lists.mask].mean()
    return {
        "regret_m": float(regret(expected_choice(pred, lists), lists).mean()),
        "cost_utility_regret_m": float(regret(torch.where(lists.mask, lists.s_cu, -torch.inf).argmax(1), lists).mean()),
        "nearest_regret_m": float(regret(torch.where(lists.mask, lists.cost, torch.inf).argmin(1), lists).mean()),
        "distance_mae_m": float(mae),
        "lists": len(lists),
    }


def train_frontier_head(
    data: Sequence[str | Path],
    model: str = MINILM,
    out: str | Path | None = None,
    epochs: int = 80,
    lr: float = 1e-3,
    weight_decay: float = 1e-4,
    batch_size: int = 128,
    tau: float = 1.0,
    calibration: float = 0.2,
    cu_lambda: float = FrontierConfig.cu_lambda,
    seed: int = 0,
    command: str = "",
    bag: bool = False,
) -> dict[str, Any]:
    """Train on the frontier files ``data``, keep the best-validation epoch, save to ``out`` (default:
    the shipped frontier head for ``model``, or for ``bag``) and return the metrics written into its
    meta. ``bag``: the input is the bag of window objects and ``model`` is not read."""
    if epochs < 1 or batch_size < 2 or not tau > 0 or calibration < 0 or not cu_lambda > 0:
        raise L3MVNError(
            f"need epochs >= 1, batch_size >= 2, tau > 0, calibration >= 0, cu_lambda > 0; got "
            f"{epochs}, {batch_size}, {tau}, {calibration}, {cu_lambda}"
        )
    if not data:
        raise L3MVNError("no frontier data: pass --data FILE (made by `l3mvn language frontier-data`)")
    key = FRONTIER_HEAD_KIND + BAG if bag else f"{model.lower()}-{FRONTIER_HEAD_KIND}"
    if out is None:
        if key not in SHIPPED_HEADS:
            raise L3MVNError(f"pass --out for embedder {model!r} (shipped heads: {', '.join(SHIPPED_HEADS)})")
        out = SHIPPED_HEADS[key]
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # tiny matrices: a second thread only waits for a shared CPU
    try:
        return _train(
            data, model, out, epochs, lr, weight_decay, batch_size, tau, calibration, cu_lambda, seed, command, bag
        )
    finally:
        torch.set_num_threads(threads)


def _train(
    data: Sequence[str | Path],
    model: str,
    out: str | Path,
    epochs: int,
    lr: float,
    weight_decay: float,
    batch_size: int,
    tau: float,
    calibration: float,
    cu_lambda: float,
    seed: int,
    command: str,
    bag: bool,
) -> dict[str, Any]:
    torch.manual_seed(seed)
    random.seed(seed)
    np.random.seed(seed)
    choices = [c for path in data for c in load_choices(path)]
    by_split = {s: [c for c in choices if house_split(c.house) == s] for s in HOUSE_SPLITS}
    houses = {s: sorted({c.house for c in by_split[s]}) for s in HOUSE_SPLITS}
    if not by_split["train"] or not by_split["val"]:
        raise L3MVNError(f"need choices on train and validation houses; got houses {houses}")
    objects = {
        frontier_query(f.objects): f.objects for c in choices if house_split(c.house) != "test" for f in c.frontiers
    }
    texts = sorted(objects)
    sentences = {t: i for i, t in enumerate(texts)}
    vocabulary = sorted({o for objs in objects.values() for o in objs})
    if bag:
        table = torch.from_numpy(bag_features([objects[t] for t in texts], vocabulary))
    else:
        table = torch.from_numpy(np.asarray(load_sentence_encoder(model).encode(texts), dtype=np.float32))
    train = ranking_lists(by_split["train"], sentences, cu_lambda)
    val = ranking_lists(by_split["val"], sentences, cu_lambda)

    head = GoalHead(table.shape[1], len(GOALS))
    with torch.no_grad():  # start at the mean distance per goal: the listwise term then only ranks
        mean = [
            float(train.dist[train.mask & (train.goal[:, None] == g)].mean()) if (train.goal == g).any() else 0.0
            for g in range(len(GOALS))
        ]
        last = head.net[-1]
        assert isinstance(last, nn.Linear)  # GoalHead ends in its output layer
        last.bias.copy_(torch.tensor(mean))
    opt = torch.optim.Adam(head.parameters(), lr=lr, weight_decay=weight_decay)
    gen = torch.Generator().manual_seed(seed)
    best: tuple[float, int, dict[str, torch.Tensor] | None] = (float("inf"), -1, None)
    for epoch in range(epochs):
        head.train()
        order = torch.randperm(len(train), generator=gen)
        for start in range(0, len(order), batch_size):
            batch = train.take(order[start : start + batch_size])
            opt.zero_grad()
            # torch leaves Tensor.backward unannotated.
            _loss(_predict(head, table, batch), batch, tau, calibration).backward()  # type: ignore[no-untyped-call]
            opt.step()
        score = _scores(head, table, val)["regret_m"]
        if score < best[0]:
            best = (score, epoch, {k: v.clone() for k, v in head.state_dict().items()})
    if best[2] is None:  # every epoch's validation regret was NaN or infinite: the training diverged
        raise L3MVNError(
            f"training diverged: no epoch of {epochs} gave a finite validation regret; lower the "
            "learning rate or check the data for non-finite values"
        )
    head.load_state_dict(best[2])
    metrics = {
        "best_epoch": best[1] + 1,
        "epochs": epochs,
        "train": _scores(head, table, train),
        "val": _scores(head, table, val),
        "choices": {s: len(by_split[s]) for s in HOUSE_SPLITS},
        "sentences": len(texts),
    }
    settings = {
        "epochs": epochs,
        "lr": lr,
        "weight_decay": weight_decay,
        "batch_size": batch_size,
        "tau": tau,
        "calibration": calibration,
        "cu_lambda": cu_lambda,
        "seed": seed,
    }
    meta = {
        "kind": FRONTIER_HEAD_KIND,
        "output": "metres",
        "object_filter": "all",
        "encoder": model,
        "goals": list(GOALS),
        "houses": houses,
        "data": [str(p) for p in data],
        "command": command or f"l3mvn train-head --data {' '.join(map(str, data))}",
        "metrics": metrics,
        "settings": settings,
    }
    if bag:
        del meta["encoder"]
        meta |= {
            "kind": FRONTIER_HEAD_KIND + BAG,
            "features": BAG_FEATURES,
            "vocabulary": vocabulary,
            "command": command
            or f"l3mvn train-head --head {FRONTIER_HEAD_KIND + BAG} --data {' '.join(map(str, data))}",
        }
    save_head(head, meta, out)
    return {**metrics, "houses": houses, "path": str(out)}


__all__ = [
    "FRONTIER_HEAD_KIND",
    "HOUSE_SPLITS",
    "RankingLists",
    "expected_choice",
    "house_split",
    "ranking_lists",
    "regret",
    "train_frontier_head",
]

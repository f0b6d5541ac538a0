"""Training the feed-forward head (``l3mvn train-head``): on frontiers of house maps (``--head
frontiers --data F``, ``frontier_head``) or, the paper's recipe, on real rooms (``--head rooms``, here).

Samples: per room, each labelled goal present becomes a label and the room's other *informative*
objects the sample (the runtime query only ever names those). A frontier window sees part of a room,
so every subset of up to ``max_objects`` of them is a sample, plus the whole set; each (room, goal)
weighs 1 in total so object-rich rooms do not dominate. Permutations (the code's augmentation) are
not needed: our query order is fixed by the informative list. Rooms with no other informative
object give no sample (the scorer answers uniform for them).

Split by building (``rooms.split_of``): train on ``train``, choose the epoch with the lowest
validation loss on ``val``; ``test`` buildings stay unseen for the ranking benchmark.

``--head rooms-bag`` is the ablation without the language model: the same samples, split, loss,
epochs and checkpoint rule, but each sample is the multi-hot vector of its objects over the
informative list (the only objects the sentence could name) instead of the sentence's embedding.
"""

from __future__ import annotations

import itertools
import random
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from l3mvn.agent.language.cooccurrence import CooccurrenceStats, load_stats
from l3mvn.agent.language.head import (
    BAG,
    BAG_FEATURES,
    SHIPPED_HEADS,
    GoalHead,
    bag_features,
    base_kind,
    is_bag,
    save_head,
)
from l3mvn.agent.language.models import MINILM, SentenceEncoder, load_sentence_encoder
from l3mvn.agent.language.queries import feedforward_query
from l3mvn.agent.language.rooms import Room, load_rooms, rooms_in
from l3mvn.agent.language.vocabulary import GOALS
from l3mvn.core.errors import L3MVNError

TRAIN_COMMAND = "l3mvn train-head"
ROOMS_BAG = "rooms" + BAG


@dataclass(frozen=True)
class Sample:
    objects: tuple[str, ...]
    goal: str
    weight: float


def room_samples(rooms: list[Room], stats: CooccurrenceStats, max_objects: int = 3) -> list[Sample]:
    out: list[Sample] = []
    for room in rooms:
        for goal in sorted(room.goals, key=GOALS.index):
            others = stats.informative_in(room.objects - {goal})
            if not others:
                continue
            subsets = {
                c for n in range(1, min(max_objects, len(others)) + 1) for c in itertools.combinations(others, n)
            }
            subsets.add(others)
            out += [Sample(s, goal, 1.0 / len(subsets)) for s in sorted(subsets)]
    return out


def train_head(
    model: str = MINILM,
    out: str | Path | None = None,
    gibson_rooms: str | Path | None = None,
    thor_metadata: str | Path | None = None,
    stats_path: str | Path | None = None,
    epochs: int = 60,
    lr: float = 1e-3,
    weight_decay: float = 1e-4,
    batch_size: int = 256,
    max_objects: int = 3,
    seed: int = 0,
    bag: bool = False,
) -> dict[str, Any]:
    """Train, keep the best-validation epoch, save to ``out`` (default: the shipped head for
    ``model``, or for ``bag``) and return the metrics written into the file's meta. ``bag``: the
    input is the bag of objects over the informative list and ``model`` is not read."""
    if epochs < 1 or batch_size < 2 or max_objects < 1:
        raise L3MVNError(
            f"need epochs >= 1, batch_size >= 2, max_objects >= 1; got {epochs}, {batch_size}, {max_objects}"
        )
    key = ROOMS_BAG if bag else model.lower()
    if out is None:
        if key not in SHIPPED_HEADS:
            raise L3MVNError(f"pass --out for embedder {model!r} (shipped heads: {', '.join(SHIPPED_HEADS)})")
        out = SHIPPED_HEADS[key]
    torch.manual_seed(seed)
    random.seed(seed)
    np.random.seed(seed)
    stats = load_stats(stats_path)
    rooms = load_rooms(gibson_rooms, thor_metadata)
    train = room_samples(rooms_in(rooms, "train"), stats, max_objects)
    val = room_samples(rooms_in(rooms, "val"), stats, max_objects)
    if not train or not val:
        raise L3MVNError(f"too little data: {len(train)} train and {len(val)} validation samples")
    encoder = None if bag else load_sentence_encoder(model)

    def featurise(sets: list[tuple[str, ...]]) -> np.ndarray:
        if encoder is None:
            return bag_features(sets, stats.informative)
        return _embed(encoder, [feedforward_query(o) for o in sets])

    xt, yt, wt = _tensors(train, featurise)
    xv, yv, wv = _tensors(val, featurise)

    head = GoalHead(xt.shape[1], len(GOALS))
    opt = torch.optim.Adam(head.parameters(), lr=lr, weight_decay=weight_decay)
    loss_fn = nn.CrossEntropyLoss(reduction="none")
    best: tuple[float, int, dict[str, torch.Tensor] | None] = (float("inf"), -1, None)
    gen = torch.Generator().manual_seed(seed)
    for epoch in range(epochs):
        head.train()
        order = torch.randperm(len(xt), generator=gen)
        for start in range(0, len(order) - 1, batch_size):
            idx = order[start : start + batch_size]
            if len(idx) < 2:  # BatchNorm needs two samples
                continue
            opt.zero_grad()
            loss = (loss_fn(head(xt[idx]), yt[idx]) * wt[idx]).sum() / wt[idx].sum()
            loss.backward()
            opt.step()
        val_loss, _ = _evaluate(head, xv, yv, wv)
        if val_loss < best[0]:
            best = (val_loss, epoch, {k: v.clone() for k, v in head.state_dict().items()})
    if best[2] is None:  # every epoch's validation loss was NaN or infinite: the training diverged
        raise L3MVNError(
            f"training diverged: no epoch of {epochs} gave a finite validation loss; lower the "
            "learning rate or check the data for non-finite values"
        )
    head.load_state_dict(best[2])
    train_loss, train_acc = _evaluate(head, xt, yt, wt)
    val_loss, val_acc = _evaluate(head, xv, yv, wv)
    metrics = {
        "best_epoch": best[1] + 1,
        "epochs": epochs,
        "train_loss": round(train_loss, 4),
        "train_accuracy": round(train_acc, 4),
        "val_loss": round(val_loss, 4),
        "val_accuracy": round(val_acc, 4),
        "val_majority_accuracy": round(_majority(yt, yv, wv), 4),
        "train_samples": len(train),
        "val_samples": len(val),
        "train_rooms": len(rooms_in(rooms, "train")),
        "val_rooms": len(rooms_in(rooms, "val")),
    }
    settings = {
        "epochs": epochs,
        "lr": lr,
        "weight_decay": weight_decay,
        "batch_size": batch_size,
        "max_objects": max_objects,
        "seed": seed,
    }
    meta = {"goals": list(GOALS), "informative": list(stats.informative), "metrics": metrics, "settings": settings}
    if bag:
        meta |= {
            "kind": ROOMS_BAG,
            "features": BAG_FEATURES,
            "vocabulary": list(stats.informative),
            "command": f"{TRAIN_COMMAND} --head {ROOMS_BAG} --seed {seed}",
        }
    else:
        meta |= {"encoder": model, "command": f"{TRAIN_COMMAND} --model {model}"}
    save_head(head, meta, out)
    return {**metrics, "path": str(out)}


def _tensors(
    samples: list[Sample], featurise: Callable[[list[tuple[str, ...]]], np.ndarray]
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """``featurise`` maps object tuples to one input row each; it runs once per distinct tuple."""
    sets = sorted({s.objects for s in samples})
    rows = dict(zip(sets, np.asarray(featurise(sets), dtype=np.float32)))
    x = torch.from_numpy(np.stack([rows[s.objects] for s in samples]))
    y = torch.tensor([GOALS.index(s.goal) for s in samples])
    w = torch.tensor([s.weight for s in samples], dtype=torch.float32)
    return x, y, w


def _embed(encoder: SentenceEncoder, texts: list[str]) -> np.ndarray:
    """One embedding per text, each distinct text encoded once, in sorted order (batches, and so the
    padding each text is encoded with, do not depend on the sample order)."""
    unique = sorted(set(texts))
    emb = dict(zip(unique, encoder.encode(unique)))
    return np.stack([emb[t] for t in texts])


@torch.inference_mode()
def _evaluate(head: GoalHead, x: torch.Tensor, y: torch.Tensor, w: torch.Tensor) -> tuple[float, float]:
    """Weighted cross-entropy and weighted top-1 accuracy (the label among six goals)."""
    head.eval()
    logits = head(x)
    loss = float((nn.functional.cross_entropy(logits, y, reduction="none") * w).sum() / w.sum())
    acc = float(((logits.argmax(1) == y).float() * w).sum() / w.sum())
    return loss, acc


def _majority(yt: torch.Tensor, yv: torch.Tensor, wv: torch.Tensor) -> float:
    """Accuracy of always answering the most frequent training label: the floor to beat."""
    top = int(torch.bincount(yt, minlength=len(GOALS)).argmax())
    return float(((yv == top).float() * wv).sum() / wv.sum())


def train_any_head(
    head: str,
    data: list[str] | None = None,
    model: str = MINILM,
    out: str | Path | None = None,
    gibson_rooms: str | Path | None = None,
    epochs: int | None = None,
    seed: int = 0,
) -> dict[str, Any]:
    """``l3mvn train-head``: a frontier head from ``data`` or a room-list head from room data, on
    sentence embeddings or (``*-bag``) bags of objects, each with its own default epochs; flags that
    do not apply to ``head`` are refused."""
    from l3mvn.agent.language.frontier_head import train_frontier_head
    from l3mvn.core.config.policy import HEAD_KINDS

    if head not in HEAD_KINDS:
        raise L3MVNError(f"unknown head {head!r}; valid: {', '.join(HEAD_KINDS)}")
    bag = is_bag(head)
    if bag and model.lower() != MINILM:
        raise L3MVNError(f"--model names a sentence embedder; the {head} head reads no sentence (drop --model)")
    extra: dict[str, Any] = {} if epochs is None else {"epochs": epochs}
    if base_kind(head) == "rooms":
        if data:
            raise L3MVNError(f"--data is frontier data, for --head frontiers; the {head} head reads --gibson-rooms")
        return train_head(model=model, out=out, gibson_rooms=gibson_rooms, seed=seed, bag=bag, **extra)
    if gibson_rooms:
        raise L3MVNError(f"--gibson-rooms is room data, for --head rooms; the {head} head reads --data")
    command = (
        f"{TRAIN_COMMAND} --head {head} --data {' '.join(map(str, data or []))}"
        + ("" if bag else f" --model {model}")
        + (f" --epochs {epochs}" if epochs is not None else "")
        + f" --seed {seed}"
    )
    return train_frontier_head(data or [], model=model, out=out, seed=seed, command=command, bag=bag, **extra)


__all__ = ["ROOMS_BAG", "TRAIN_COMMAND", "Sample", "room_samples", "train_any_head", "train_head"]

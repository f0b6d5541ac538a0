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
"""

from __future__ import annotations

import itertools
import random
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn

from l3mvn.errors import L3MVNError
from l3mvn.language.cooccurrence import CooccurrenceStats, load_stats
from l3mvn.language.head import SHIPPED_HEADS, GoalHead, save_head
from l3mvn.language.models import MINILM, load_sentence_encoder
from l3mvn.language.queries import feedforward_query
from l3mvn.language.rooms import Room, load_rooms, rooms_in
from l3mvn.language.vocabulary import GOALS

TRAIN_COMMAND = "l3mvn train-head"


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
            subsets = {c for n in range(1, min(max_objects, len(others)) + 1) for c in itertools.combinations(others, n)}
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
) -> dict:
    """Train, keep the best-validation epoch, save to ``out`` (default: the shipped head for
    ``model``) and return the metrics written into the file's meta."""
    if epochs < 1 or batch_size < 2 or max_objects < 1:
        raise L3MVNError(f"need epochs >= 1, batch_size >= 2, max_objects >= 1; got {epochs}, {batch_size}, {max_objects}")
    if out is None:
        if model.lower() not in SHIPPED_HEADS:
            raise L3MVNError(f"pass --out for embedder {model!r} (only {', '.join(SHIPPED_HEADS)} has a shipped path)")
        out = SHIPPED_HEADS[model.lower()]
    torch.manual_seed(seed)
    random.seed(seed)
    np.random.seed(seed)
    stats = load_stats(stats_path)
    rooms = load_rooms(gibson_rooms, thor_metadata)
    train = room_samples(rooms_in(rooms, "train"), stats, max_objects)
    val = room_samples(rooms_in(rooms, "val"), stats, max_objects)
    if not train or not val:
        raise L3MVNError(f"too little data: {len(train)} train and {len(val)} validation samples")
    encoder = load_sentence_encoder(model)
    xt, yt, wt = _tensors(train, encoder)
    xv, yv, wv = _tensors(val, encoder)

    head = GoalHead(encoder.dim, len(GOALS))
    opt = torch.optim.Adam(head.parameters(), lr=lr, weight_decay=weight_decay)
    loss_fn = nn.CrossEntropyLoss(reduction="none")
    best = (float("inf"), -1, None)
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
    head.load_state_dict(best[2])
    train_loss, train_acc = _evaluate(head, xt, yt, wt)
    val_loss, val_acc = _evaluate(head, xv, yv, wv)
    metrics = {
        "best_epoch": best[1] + 1, "epochs": epochs, "train_loss": round(train_loss, 4),
        "train_accuracy": round(train_acc, 4), "val_loss": round(val_loss, 4), "val_accuracy": round(val_acc, 4),
        "val_majority_accuracy": round(_majority(yt, yv, wv), 4),
        "train_samples": len(train), "val_samples": len(val),
        "train_rooms": len(rooms_in(rooms, "train")), "val_rooms": len(rooms_in(rooms, "val")),
    }
    meta = {
        "encoder": model, "goals": list(GOALS), "informative": list(stats.informative),
        "command": f"{TRAIN_COMMAND} --model {model}", "metrics": metrics,
        "settings": {"epochs": epochs, "lr": lr, "weight_decay": weight_decay, "batch_size": batch_size,
                     "max_objects": max_objects, "seed": seed},
    }
    save_head(head, meta, out)
    return {**metrics, "path": str(out)}


def _tensors(samples: list[Sample], encoder) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    texts = sorted({feedforward_query(s.objects) for s in samples})
    emb = dict(zip(texts, encoder.encode(texts)))
    x = torch.from_numpy(np.stack([emb[feedforward_query(s.objects)] for s in samples]))
    y = torch.tensor([GOALS.index(s.goal) for s in samples])
    w = torch.tensor([s.weight for s in samples], dtype=torch.float32)
    return x, y, w


@torch.inference_mode()
def _evaluate(head: GoalHead, x, y, w) -> tuple[float, float]:
    """Weighted cross-entropy and weighted top-1 accuracy (the label among six goals)."""
    head.eval()
    logits = head(x)
    loss = float((nn.functional.cross_entropy(logits, y, reduction="none") * w).sum() / w.sum())
    acc = float(((logits.argmax(1) == y).float() * w).sum() / w.sum())
    return loss, acc


def _majority(yt, yv, wv) -> float:
    """Accuracy of always answering the most frequent training label: the floor to beat."""
    top = int(torch.bincount(yt, minlength=len(GOALS)).argmax())
    return float(((yv == top).float() * wv).sum() / wv.sum())


def train_any_head(head: str, data: list[str] | None = None, model: str = MINILM, out: str | Path | None = None,
                   gibson_rooms: str | Path | None = None, epochs: int | None = None, seed: int = 0) -> dict:
    """``l3mvn train-head``: the frontier head from ``data`` or the room-list head from room data,
    each with its own default epochs; flags that do not apply to ``head`` are refused."""
    from l3mvn.config.policy import HEAD_KINDS
    from l3mvn.language.frontier_head import train_frontier_head

    if head not in HEAD_KINDS:
        raise L3MVNError(f"unknown head {head!r}; valid: {', '.join(HEAD_KINDS)}")
    if head == "rooms":
        if data:
            raise L3MVNError("--data is frontier data, for --head frontiers; the rooms head reads --gibson-rooms")
        return train_head(model=model, out=out, gibson_rooms=gibson_rooms, seed=seed,
                          **({} if epochs is None else {"epochs": epochs}))
    if gibson_rooms:
        raise L3MVNError("--gibson-rooms is room data, for --head rooms; the frontiers head reads --data")
    command = f"{TRAIN_COMMAND} --head frontiers --data {' '.join(map(str, data or []))} --model {model}" + (
        f" --epochs {epochs}" if epochs is not None else "") + f" --seed {seed}"
    return train_frontier_head(data or [], model=model, out=out, seed=seed, command=command,
                               **({} if epochs is None else {"epochs": epochs}))


__all__ = ["Sample", "room_samples", "train_head", "train_any_head", "TRAIN_COMMAND"]

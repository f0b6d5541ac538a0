"""``l3mvn poni train``: the PONI network from full house maps, with no interaction, then fine-tuned on
the choices of an agent's own walks.

First stage, drawn windows (``samples.HouseTruth``): partial maps drawn from the Gibson houses of a
SemExp split, split by house (the same hash split as the feed-forward head's: train houses teach, val
houses pick the epoch, test houses are reported and never used), and from procedural houses
furnished from real rooms (all train). Loss: binary cross-entropy of each potential against its soft
label, at labelled cells only. Every epoch is scored on the val houses; the best epoch's weights are
kept.

Second stage, walks (``walks``): a prior-free agent walks generated episodes on the same houses and
procedural ones; at each of its choices the net is taught the true metres on from every frontier it
chose among (pointwise) and their order by travel plus metres on (listwise), which is what the policy
acts on. The epoch (the first stage's weights included) whose choices on the val houses' walks
regret least is kept. The checkpoint is saved with what it was trained on and how it scored.

Scores on drawn windows: ``metres_mae``, the mean error of the expected metres on to each goal at
labelled cells within range; ``regret_m``, per (window, goal), the true metres on from the labelled
cell the network rates best, less the best cell's (0 = it picks the cell nearest the goal);
``chance_regret_m``, the same for a cell picked at random (what a prior that knows nothing loses). On
walks: ``choice_regret``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from collections.abc import Callable, Iterator
from contextlib import ExitStack
from dataclasses import asdict, dataclass, replace
from multiprocessing import get_context
from pathlib import Path
from typing import Generic, TypeVar

import numpy as np
import torch
from torch import nn

from l3mvn.agent.language.frontier_head import HOUSE_SPLITS, house_split
from l3mvn.agent.potentials import CHANNELS, OUTPUTS, PotentialModel, PotentialNet, expected_totals, shipped_checkpoint
from l3mvn.agent.potentials.model import GEOMETRY
from l3mvn.core.config import PotentialConfig
from l3mvn.core.errors import L3MVNError
from l3mvn.run.potentials.samples import NO_LABEL, HouseTruth, RevealOptions, Source, source_scene
from l3mvn.run.potentials.walks import WALKERS, WalkJob, WalkSet, walk_floors
from l3mvn.world.scenes.semexp import load_split

Net = TypeVar("Net", bound=nn.Module)


@dataclass(frozen=True)
class TrainOptions:
    samples_per_floor: int = 160  # windows drawn per Gibson floor
    procedural_houses: int = 800
    samples_per_procedural: int = 2
    epochs: int = 5
    batch: int = 16
    learning_rate: float = 2e-3
    width: int = 16  # the U-Net's first layer; each halving doubles it
    seed: int = 0
    workers: int = 2  # processes drawing windows and walking
    # The second stage: the agent's own choices (``walks``), fine-tuning the first stage's net.
    walk_episodes: int = 12  # episodes walked per Gibson floor (train, val and test houses)
    walk_procedural_houses: int = 1000
    walk_procedural_first: int = 0  # the first procedural house walked (a later one is one never walked before)
    walk_episodes_per_procedural: int = 2
    walk_epochs: int = 3
    walk_learning_rate: float = 1e-3
    walk_tau_m: float = 1.0  # the listwise loss's temperature over total metres
    walk_height: int = 120  # the walks' frame: the map, not the pixels, is what the network reads
    walk_width: int = 160
    walker: str = WALKERS[0]  # who walks (walks.WALKERS): poni walks with the --init checkpoint


@dataclass
class SampleSet:
    features: np.ndarray  # (N, len(CHANNELS), n, n) uint8
    labels: np.ndarray  # (N, len(OUTPUTS), n, n) uint8
    houses: list[str]

    def __len__(self) -> int:
        return len(self.houses)

    @classmethod
    def join(cls, parts: list[SampleSet], cells: int) -> SampleSet:
        if not parts:
            return cls(
                np.zeros((0, len(CHANNELS), cells, cells), np.uint8),
                np.zeros((0, len(OUTPUTS), cells, cells), np.uint8),
                [],
            )
        return cls(
            np.concatenate([p.features for p in parts]),
            np.concatenate([p.labels for p in parts]),
            [h for p in parts for h in p.houses],
        )


def _draw(job: tuple[Source, int, int, PotentialConfig, RevealOptions]) -> SampleSet:
    source, n, seed, cfg, reveal = job
    truth = HouseTruth(source_scene(source), cfg, reveal)
    rng = np.random.default_rng(seed)
    got = [s for s in (truth.sample(rng) for _ in range(n)) if s is not None]
    if not got:
        return SampleSet.join([], cfg.window_cells)
    return SampleSet(np.stack([s.features for s in got]), np.stack([s.labels for s in got]), [s.house for s in got])


def draw_samples(
    sources: list[tuple[Source, int]],
    cfg: PotentialConfig,
    reveal: RevealOptions,
    seed: int,
    workers: int,
    progress: Callable[[int, int], None] | None = None,
) -> SampleSet:
    """Samples of every (source, count): each floor seeded by its place in the list, so a seed gives
    the same set whatever the worker count."""
    jobs = [(src, n, seed * 1_000_003 + k, cfg, reveal) for k, (src, n) in enumerate(sources)]
    parts: list[SampleSet] = []
    with ExitStack() as stack:
        results: Iterator[SampleSet] = map(_draw, jobs)
        if workers > 1:
            results = stack.enter_context(get_context("spawn").Pool(workers)).imap(_draw, jobs, chunksize=4)
        for part in results:
            parts.append(part)
            if progress:
                progress(len(parts), len(jobs))
    return SampleSet.join(parts, cfg.window_cells)


def _augment(x: torch.Tensor, y: torch.Tensor, rng: np.random.Generator) -> tuple[torch.Tensor, torch.Tensor]:
    """A random quarter turn and flip: a map's orientation carries no meaning."""
    k = int(rng.integers(4))
    x, y = torch.rot90(x, k, dims=(2, 3)), torch.rot90(y, k, dims=(2, 3))
    if rng.integers(2):
        x, y = torch.flip(x, dims=(3,)), torch.flip(y, dims=(3,))
    return x, y


def _batch(data: SampleSet, idx: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
    x = torch.from_numpy(data.features[idx].astype(np.float32) / 255.0)
    y = torch.from_numpy(data.labels[idx].astype(np.float32))
    return x, y


def _loss(logits: torch.Tensor, coded: torch.Tensor) -> torch.Tensor:
    mask = coded != NO_LABEL
    target = torch.where(mask, coded / 254.0, torch.zeros_like(coded))
    per_cell = torch.nn.functional.binary_cross_entropy_with_logits(logits, target, reduction="none")
    return (per_cell * mask).sum() / mask.sum().clamp(min=1)


@torch.inference_mode()
def evaluate(net: PotentialNet, data: SampleSet, cfg: PotentialConfig, batch: int = 32) -> dict[str, float]:
    """Loss, ``metres_mae`` and ``regret_m`` (see the module) over ``data``."""
    net.eval()
    losses, errors, regrets, chance = [], [], [], []
    for start in range(0, len(data), batch):
        idx = np.arange(start, min(start + batch, len(data)))
        x, y = _batch(data, idx)
        logits = net(x)
        losses.append(float(_loss(logits, y)) * len(idx))
        p = torch.sigmoid(logits)[:, 1:].numpy()
        coded = y[:, 1:].numpy()
        for i in range(len(idx)):
            for g in range(coded.shape[1]):
                mask = coded[i, g] != NO_LABEL
                if not mask.any():
                    continue
                true_m = cfg.range_m * (1.0 - coded[i, g][mask] / 254.0)
                pred_m = cfg.range_m * (1.0 - p[i, g][mask])
                near = true_m < cfg.range_m
                if near.any():
                    errors.append(float(np.abs(pred_m[near] - true_m[near]).mean()))
                regrets.append(float(true_m[int(np.argmin(pred_m))] - true_m.min()))
                chance.append(float(true_m.mean() - true_m.min()))
    n = max(len(data), 1)
    return {
        "loss": sum(losses) / n,
        "metres_mae": float(np.mean(errors)) if errors else float("nan"),
        "regret_m": float(np.mean(regrets)) if regrets else float("nan"),
        "chance_regret_m": float(np.mean(chance)) if chance else float("nan"),
        "windows": len(data),
    }


def shuffled_batches(rng: np.random.Generator, n: int, batch: int, batches: int) -> Iterator[np.ndarray]:
    """An epoch's ``batches`` batches of up to ``batch`` indices into ``n`` choices, drawn in a fresh
    order, each sorted (the walks' choices are read in index order)."""
    order = rng.permutation(n)
    for b in range(batches):
        yield np.sort(order[b * batch : (b + 1) * batch])


class Epochs(Generic[Net]):
    """A training stage's epochs: each row reported as it comes, with the val scores when there are
    any, and the weights of the epoch whose val ``regret_m`` is least kept to restore."""

    def __init__(self, progress: Callable[[str], None] | None) -> None:
        self.progress = progress
        self.history: list[dict[str, float]] = []
        self.best: tuple[float, dict[str, torch.Tensor]] | None = None

    def add(self, net: Net, row: dict[str, float], val: dict[str, float] | None) -> None:
        if val is not None:
            row.update({f"val_{k}": v for k, v in val.items() if k not in ("windows", "choices")})
            if self.best is None or row["val_regret_m"] < self.best[0]:
                self.best = (row["val_regret_m"], {k: v.detach().clone() for k, v in net.state_dict().items()})
        self.history.append(row)
        if self.progress:
            self.progress(json.dumps({k: round(v, 4) if isinstance(v, float) else v for k, v in row.items()}))

    def best_net(self, net: Net) -> tuple[Net, list[dict[str, float]]]:
        if self.best is not None:
            net.load_state_dict(self.best[1])
        net.eval()
        return net, self.history


def fit(
    train: SampleSet,
    val: SampleSet,
    cfg: PotentialConfig,
    options: TrainOptions,
    progress: Callable[[str], None] | None = None,
    net: PotentialNet | None = None,
) -> tuple[PotentialNet, list[dict[str, float]]]:
    """``net`` (a new one if None) after ``options.epochs`` epochs, with the weights of its best val
    epoch (by regret)."""
    if not len(train):
        raise L3MVNError("no training windows: the houses gave no frontier to label")
    torch.manual_seed(options.seed)
    rng = np.random.default_rng(options.seed)
    net = net if net is not None else PotentialNet(width=options.width)
    opt = torch.optim.AdamW(net.parameters(), lr=options.learning_rate, weight_decay=1e-4)
    steps = options.epochs * max(1, len(train) // options.batch)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=options.learning_rate, total_steps=steps)
    epochs = Epochs[PotentialNet](progress)
    for epoch in range(options.epochs):
        net.train()
        order = rng.permutation(len(train))
        started, total = time.monotonic(), 0.0
        batches = max(1, len(train) // options.batch)
        for b in range(batches):
            x, y = _augment(*_batch(train, order[b * options.batch : (b + 1) * options.batch]), rng)
            loss = _loss(net(x), y)
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            total += loss.item()
        row = {"epoch": epoch + 1, "train_loss": total / batches, "seconds": time.monotonic() - started}
        epochs.add(net, row, evaluate(net, val, cfg) if len(val) else None)
    return epochs.best_net(net)


# --- the second stage: the choices of the agent's own walks ------------------------------------------------
def frontier_logits(logits: torch.Tensor, cells: list[np.ndarray]) -> tuple[torch.Tensor, np.ndarray]:
    """(F, len(OUTPUTS)) logits of each frontier's best cell out of one window's (len(OUTPUTS), n*n),
    and which frontiers have a cell in the window (the others read potential 0, as in the policy)."""
    inside = np.array([len(c) > 0 for c in cells])
    rows = [logits[:, c].amax(dim=1) if len(c) else torch.full((logits.shape[0],), -30.0) for c in cells]
    return torch.stack(rows), inside


def _walk_loss(
    logits: torch.Tensor, walks: WalkSet, idx: np.ndarray, cfg: PotentialConfig, tau_m: float
) -> torch.Tensor:
    """Per frontier, binary cross-entropy of each goal's potential against ``1 - metres / range_m``;
    per (choice, goal), the listwise cross-entropy between the softmax of the true totals (travel +
    metres on) and of the totals the policy would compare: the order of frontiers is what it acts on."""
    point, lists = logits.new_zeros(()), logits.new_zeros(())
    n_point = n_lists = 0
    for s, i in enumerate(idx):
        cost, metres, cells = walks.frontiers(int(i))
        per_frontier, inside = frontier_logits(logits[s].reshape(len(OUTPUTS), -1), cells)
        known = np.isfinite(metres) & inside[:, None]
        mask = torch.from_numpy(known)
        target = torch.from_numpy(np.clip(1.0 - np.nan_to_num(metres) / cfg.range_m, 0.0, 1.0).astype(np.float32))
        bce = torch.nn.functional.binary_cross_entropy_with_logits(per_frontier[:, 1:], target, reduction="none")
        point = point + (bce * mask).sum()
        n_point += int(known.sum())
        totals = expected_totals(
            torch.from_numpy(cost), torch.sigmoid(per_frontier), cfg, torch.from_numpy(walks.size_m(int(i)))
        )
        true = torch.from_numpy(cost[:, None] + np.nan_to_num(metres))
        for g in range(metres.shape[1]):
            ok = torch.from_numpy(np.isfinite(metres[:, g]))
            if int(ok.sum()) < 2:
                continue
            wanted = torch.softmax(-true[ok, g] / tau_m, dim=0)
            lists = lists - (wanted * torch.log_softmax(-totals[ok, g] / tau_m, dim=0)).sum()
            n_lists += 1
    return point / max(n_point, 1) + lists / max(n_lists, 1)


@torch.inference_mode()
def choice_regret(net: PotentialNet, walks: WalkSet, cfg: PotentialConfig, batch: int = 32) -> dict[str, float]:
    """Mean regret in metres of the policy's choice at the walks' choices: the true total (travel +
    metres on) of the frontier it would take, less the least (a frontier off the true floor counts as
    the worst known one). ``regret_m`` over every goal the house holds, ``goal_regret_m`` for the
    episode's goal only; ``walker_*`` the same for the walking policy's own choice, ``nearest_*`` for
    the nearest frontier."""
    net.eval()
    found: dict[str, list[float]] = {
        k: [] for k in ("regret_m", "goal_regret_m", "walker_regret_m", "walker_goal_regret_m", "nearest_goal_regret_m")
    }
    for start in range(0, len(walks), batch):
        idx = np.arange(start, min(start + batch, len(walks)))
        logits = net(torch.from_numpy(walks.features[idx].astype(np.float32) / 255.0))
        for s, i in enumerate(idx):
            cost, metres, cells = walks.frontiers(int(i))
            per_frontier, _ = frontier_logits(logits[s].reshape(len(OUTPUTS), -1), cells)
            size = walks.size_m(int(i)).astype(np.float64)
            totals = expected_totals(cost.astype(np.float64), torch.sigmoid(per_frontier).numpy(), cfg, size)
            for g in range(metres.shape[1]):
                known = np.isfinite(metres[:, g])
                if not known.any():
                    continue
                true = cost + np.where(known, metres[:, g], metres[known, g].max())
                regret = true - true.min()
                found["regret_m"].append(float(regret[int(np.argmin(totals[:, g]))]))
                if walks.choice[i] >= 0:
                    found["walker_regret_m"].append(float(regret[walks.choice[i]]))
                if g == walks.goal[i]:
                    found["goal_regret_m"].append(found["regret_m"][-1])
                    found["nearest_goal_regret_m"].append(float(regret[int(np.argmin(cost))]))
                    if walks.choice[i] >= 0:
                        found["walker_goal_regret_m"].append(float(regret[walks.choice[i]]))
    out = {k: float(np.mean(v)) if v else float("nan") for k, v in found.items()}
    return out | {"choices": len(walks)}


def fit_walks(
    net: PotentialNet,
    train: WalkSet,
    val: WalkSet,
    cfg: PotentialConfig,
    options: TrainOptions,
    progress: Callable[[str], None] | None = None,
) -> tuple[PotentialNet, list[dict[str, float]]]:
    """``net`` fine-tuned on the walks' choices for ``options.walk_epochs`` epochs, keeping the
    weights (the starting ones included) whose choices on the val houses' walks regret least."""
    torch.manual_seed(options.seed)
    rng = np.random.default_rng(options.seed)
    opt = torch.optim.AdamW(net.parameters(), lr=options.walk_learning_rate, weight_decay=1e-4)
    batches = max(1, len(train) // options.batch)
    sched = torch.optim.lr_scheduler.OneCycleLR(
        opt, max_lr=options.walk_learning_rate, total_steps=options.walk_epochs * batches
    )
    epochs = Epochs[PotentialNet](progress)
    for epoch in range(options.walk_epochs + 1):
        started, total = time.monotonic(), 0.0
        if epoch:
            net.train()
            for idx in shuffled_batches(rng, len(train), options.batch, batches):
                x = torch.from_numpy(train.features[idx].astype(np.float32) / 255.0)
                loss = _walk_loss(_turned(net, x, rng), train, idx, cfg, options.walk_tau_m)
                opt.zero_grad()
                loss.backward()
                opt.step()
                sched.step()
                total += loss.item()
        row: dict[str, float] = {"walk_epoch": epoch, "seconds": time.monotonic() - started}
        if epoch:
            row["train_loss"] = total / batches
        epochs.add(net, row, choice_regret(net, val, cfg) if len(val) else None)
    return epochs.best_net(net)


def _turned(net: PotentialNet, x: torch.Tensor, rng: np.random.Generator) -> torch.Tensor:
    """The net's logits for ``x`` seen turned a random quarter and flipped, turned back: the labels
    stay at their cells, and a map's orientation carries no meaning."""
    k, flip = int(rng.integers(4)), bool(rng.integers(2))
    x = torch.rot90(x, k, dims=(2, 3))
    out = net(torch.flip(x, dims=(3,)) if flip else x)
    out = torch.flip(out, dims=(3,)) if flip else out
    return torch.rot90(out, -k, dims=(2, 3))


def gibson_sources(dataset: str, split: str, per_floor: int) -> dict[str, list[tuple[Source, int]]]:
    """The floors of a SemExp split by house split (train / val / test), each with ``per_floor``."""
    out: dict[str, list[tuple[Source, int]]] = {s: [] for s in HOUSE_SPLITS}
    for house, floors in load_split(dataset, split).items():
        for scene in floors.values():
            out[house_split(house)].append((scene, per_floor))
    return out


def train_potentials(
    dataset: str | None,
    split: str,
    out: str | Path,
    cfg: PotentialConfig = PotentialConfig(),
    options: TrainOptions = TrainOptions(),
    reveal: RevealOptions = RevealOptions(),
    init: str | Path | None = None,
    log: Callable[[str], None] = print,
) -> dict:
    """Draw windows and train on them (first stage), walk and fine-tune on the walks' choices (second
    stage), score on the held-out houses and save; returns the summary. ``init``: a checkpoint to
    start from instead of random weights (a stage with no data is skipped)."""
    out = Path(out)
    if out.suffix != ".pt":
        raise L3MVNError(f"--out must be a .pt file, got {out}")
    if not out.parent.is_dir():
        raise L3MVNError(f"--out: folder {out.parent} does not exist")
    if not os.access(out.parent, os.W_OK | os.X_OK):  # found now, not after the training
        raise L3MVNError(f"--out: no permission to write in {out.parent}")
    if options.walker not in WALKERS:
        raise L3MVNError(f"unknown walker {options.walker!r}; valid: {', '.join(WALKERS)}")
    if options.walker == "poni" and init is None:
        raise L3MVNError("--walker poni walks with the checkpoint it fine-tunes: give --init CHECKPOINT")
    start = PotentialModel.load(init, cfg, to_fine_tune=True) if init is not None else None
    net = start.net if start is not None else PotentialNet(width=options.width)
    options = replace(options, width=net.width)

    def floors(per_floor: int) -> dict[str, list[tuple[Source, int]]]:
        return gibson_sources(dataset, split, per_floor) if dataset else {s: [] for s in HOUSE_SPLITS}

    drawn = floors(options.samples_per_floor)
    drawn["train"] += [
        (_procedural_seed(options, k), options.samples_per_procedural) for k in range(options.procedural_houses)
    ]
    walked = walk_sources(dataset, split, options)
    drawn = {k: [(src, n) for src, n in v if n > 0] for k, v in drawn.items()}
    if not drawn["train"] and not walked["train"]:
        raise L3MVNError("nothing to train on: give --dataset with train houses, or procedural houses to draw or walk")
    sets: dict[str, SampleSet] = {}
    walks: dict[str, WalkSet] = {}
    history: list[dict[str, float]] = []
    walk_history: list[dict[str, float]] = []
    if drawn["train"]:
        for name in HOUSE_SPLITS:
            started = time.monotonic()

            def tick(done: int, total: int, name: str = name) -> None:
                if done == total or done % 100 == 0:
                    log(f"drawing {name} windows: {done}/{total} floors")

            seed = options.seed + HOUSE_SPLITS.index(name)
            sets[name] = draw_samples(drawn[name], cfg, reveal, seed, options.workers, tick)
            took = time.monotonic() - started
            log(f"{name}: {len(sets[name])} windows from {len(drawn[name])} floors in {took:.0f} s")
        net, history = fit(sets["train"], sets["val"], cfg, options, log, net=net)
    if walked["train"] and options.walk_epochs:
        walking = cfg
        if options.walker == "poni":  # PONI walks as its checkpoint was trained to
            assert start is not None  # refused above without --init
            walking = replace(cfg, checkpoint=str(init), size_bonus=bool(start.geometry["size_bonus"]))
        walks = walk_splits(walked, walking, options, log)
        net, walk_history = fit_walks(net, walks["train"], walks["val"], cfg, options, log)
    scores: dict[str, dict[str, float]] = {
        name: evaluate(net, sets[name], cfg) for name in ("val", "test") if name in sets and len(sets[name])
    }
    scores |= {
        f"walks_{name}": choice_regret(net, walks[name], cfg)
        for name in ("val", "test")
        if name in walks and len(walks[name])
    }
    houses = {
        name: sorted(set(sets[name].houses if name in sets else []) | set(walks[name].houses if name in walks else []))
        for name in HOUSE_SPLITS
    }
    training = {
        "dataset": str(dataset) if dataset else None,
        "split": split,
        "init": str(init) if init is not None else None,
        "houses": {name: h for name, h in houses.items() if name != "train"},
        "gibson_train_floors": len(gibson_sources(dataset, split, 1)["train"]) if dataset else 0,
        "options": asdict(options),
        "reveal": asdict(reveal),
        "history": history,
        "walk_history": walk_history,
        "scores": scores,
    }
    model = PotentialModel(net, {k: float(getattr(cfg, k)) for k in GEOMETRY}, training, str(out))
    model.save(out)
    counts = {k: len(v) for k, v in sets.items()} | {f"walks_{k}": len(v) for k, v in walks.items()}
    return {"out": str(out), "scores": scores, "windows": counts}


def _procedural_seed(options: TrainOptions, k: int) -> int:
    return options.seed * 100_000 + k


def walk_sources(dataset: str | None, split: str, options: TrainOptions) -> dict[str, list[tuple[Source, int]]]:
    """The floors walked on each side of the house split, with their episode counts: the SemExp
    split's houses and, on the train side, ``options.walk_procedural_houses`` procedural ones."""
    walked = gibson_sources(dataset, split, options.walk_episodes) if dataset else {s: [] for s in HOUSE_SPLITS}
    walked["train"] += [
        (_procedural_seed(options, k), options.walk_episodes_per_procedural)
        for k in range(options.walk_procedural_first, options.walk_procedural_first + options.walk_procedural_houses)
    ]
    return {k: [(src, n) for src, n in v if n > 0] for k, v in walked.items()}


def walk_splits(
    walked: dict[str, list[tuple[Source, int]]],
    walking: PotentialConfig,
    options: TrainOptions,
    log: Callable[[str], None],
) -> dict[str, WalkSet]:
    """``options.walker`` walks every side's floors (PONI with ``walking``'s checkpoint); refused in
    one line when the train side gives no choice among two or more frontiers."""
    frame = (options.walk_height, options.walk_width)
    walks: dict[str, WalkSet] = {}
    for name in HOUSE_SPLITS:
        started = time.monotonic()

        def step(done: int, total: int, name: str = name) -> None:
            if done == total or done % 100 == 0:
                log(f"walking {name} floors: {done}/{total}")

        jobs = [WalkJob(src, n, options.seed + 1, frame, walking, options.walker) for src, n in walked[name]]
        walks[name] = walk_floors(jobs, options.workers, step)
        log(f"{name}: {len(walks[name])} choices from {len(jobs)} floors in {time.monotonic() - started:.0f} s")
    if not len(walks["train"]):
        raise L3MVNError("the walks gave no choice among two or more frontiers to learn from")
    return walks


# --- the command (registered by l3mvn.run.cli as `l3mvn poni`) ------------------------------------------
def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="poni_command", required=True)
    tr = sub.add_parser(
        "train", help="train the potential network from full house maps, then on a prior-free agent's choices"
    )
    tr.add_argument("--dataset", default=None, help="SemExp dataset dir (its houses split train / val / test)")
    tr.add_argument("--split", default="train")
    tr.add_argument("--out", default=None, help="the .pt to write (default: the shipped checkpoint)")
    defaults = TrainOptions()
    counts = ("samples_per_floor", "procedural_houses", "samples_per_procedural", "epochs", "batch", "width")
    walk_counts = ("walk_episodes", "walk_procedural_houses", "walk_episodes_per_procedural", "walk_epochs")
    for name in counts + walk_counts:
        tr.add_argument(f"--{name.replace('_', '-')}", type=_count, default=getattr(defaults, name))
    for name in ("learning_rate", "walk_learning_rate", "walk_tau_m"):
        tr.add_argument(f"--{name.replace('_', '-')}", type=float, default=getattr(defaults, name))
    tr.add_argument(
        "--init", default=None, help="start from this checkpoint's weights (e.g. to run the walks' stage alone)"
    )
    tr.add_argument(
        "--walker",
        choices=WALKERS,
        default=defaults.walker,
        help="who walks the second stage's episodes: cost-utility (no prior), or poni with the --init checkpoint",
    )
    tr.add_argument(
        "--no-size-bonus",
        action="store_true",
        help="the walks' totals leave out cost-utility's size bonus (for poni.size_bonus=false)",
    )
    tr.add_argument("--seed", type=int, default=defaults.seed)
    tr.add_argument("--workers", type=_count, default=defaults.workers)
    words = sub.add_parser(
        "train-language",
        help="train l3mvn-ff's map head: the words of a frontier's window added to a PONI checkpoint's metres",
    )
    from l3mvn.run.potentials import language_map

    language_map.add_arguments(words, _count)
    show = sub.add_parser("show", help="what a checkpoint or a map head was trained on and how it scored")
    show.add_argument(
        "checkpoint", nargs="?", default=None, help="a PONI checkpoint or a map head .pt (default: the shipped PONI)"
    )


def _count(raw: str) -> int:
    if not raw.isascii() or not raw.strip().lstrip("+").isdigit():
        raise argparse.ArgumentTypeError(f"expected a whole number >= 0, got {raw!r}")
    return int(raw)


def run(args: argparse.Namespace) -> int:
    if args.poni_command == "train-language":
        from l3mvn.run.potentials import language_map

        return language_map.run(args)
    if args.poni_command == "show":
        from l3mvn.agent.potentials.language_map import LanguageMapHead, is_language_map

        if args.checkpoint is not None and is_language_map(args.checkpoint):
            print(json.dumps(LanguageMapHead.record(args.checkpoint), indent=2))
            return 0
        model = PotentialModel.load(args.checkpoint, PotentialConfig(), to_fine_tune=True)
        print(json.dumps({"checkpoint": model.source, "geometry": model.geometry, **model.training}, indent=2))
        return 0
    options = replace(
        TrainOptions(),
        **{k: getattr(args, k) for k in asdict(TrainOptions()) if hasattr(args, k) and getattr(args, k) is not None},
    )
    if options.epochs < 1 or options.batch < 1 or options.width < 8 or options.width % 8:
        raise L3MVNError("--epochs and --batch must be >= 1, --width a multiple of 8 (its group norm)")
    for name in ("learning_rate", "walk_learning_rate", "walk_tau_m"):
        value = getattr(options, name)
        if not (math.isfinite(value) and value > 0):
            raise L3MVNError(f"--{name.replace('_', '-')} must be a positive number, got {value}")
    summary = train_potentials(
        args.dataset,
        args.split,
        args.out or shipped_checkpoint(),
        cfg=PotentialConfig(size_bonus=not args.no_size_bonus),
        options=options,
        init=args.init,
        log=lambda line: print(line, flush=True),
    )
    print(json.dumps(summary))
    return 0

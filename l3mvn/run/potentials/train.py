"""``l3mvn poni train``: the PONI network from full house maps, with no interaction.

Samples (``samples.HouseTruth``) come from the Gibson houses of a SemExp split, split by house (the
same hash split as the feed-forward head's: train houses teach, val houses pick the epoch, test
houses are reported and never used), and from procedural houses furnished from real rooms (all
train). Loss: binary cross-entropy of each potential against its soft label, at labelled cells only.
Every epoch is scored on the val houses; the best epoch's weights are kept and saved with what they
were trained on and how they scored.

Scores: ``metres_mae``, the mean error of the expected metres on to each goal at labelled cells
within range; ``regret_m``, per (window, goal), the true metres on from the labelled cell the network
rates best, less the best cell's (0 = it picks the cell nearest the goal); ``chance_regret_m``, the
same for a cell picked at random (what a prior that knows nothing loses).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from collections.abc import Callable, Iterator
from contextlib import ExitStack
from dataclasses import asdict, dataclass, replace
from multiprocessing import get_context
from pathlib import Path

import numpy as np
import torch

from l3mvn.agent.language.frontier_head import HOUSE_SPLITS, house_split
from l3mvn.agent.potentials import CHANNELS, OUTPUTS, PotentialModel, PotentialNet, shipped_checkpoint
from l3mvn.agent.potentials.model import GEOMETRY
from l3mvn.core.config import PotentialConfig
from l3mvn.core.errors import L3MVNError
from l3mvn.run.potentials.samples import NO_LABEL, HouseTruth, RevealOptions
from l3mvn.world.scenes.procedural import generate_house
from l3mvn.world.scenes.scene import SceneMap
from l3mvn.world.scenes.semexp import load_split


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
    workers: int = 2  # processes drawing samples


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


# A floor to draw from: a scene, or the seed of a procedural house (built in the worker).
Source = SceneMap | int


def _draw(job: tuple[Source, int, int, PotentialConfig, RevealOptions]) -> SampleSet:
    source, n, seed, cfg, reveal = job
    scene = generate_house(source) if isinstance(source, int) else source
    truth = HouseTruth(scene, cfg, reveal)
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


def fit(
    train: SampleSet,
    val: SampleSet,
    cfg: PotentialConfig,
    options: TrainOptions,
    progress: Callable[[str], None] | None = None,
) -> tuple[PotentialNet, list[dict[str, float]]]:
    """The net after ``options.epochs`` epochs, with the weights of its best val epoch (by regret)."""
    if not len(train):
        raise L3MVNError("no training windows: the houses gave no frontier to label")
    torch.manual_seed(options.seed)
    rng = np.random.default_rng(options.seed)
    net = PotentialNet(width=options.width)
    opt = torch.optim.AdamW(net.parameters(), lr=options.learning_rate, weight_decay=1e-4)
    steps = options.epochs * max(1, len(train) // options.batch)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=options.learning_rate, total_steps=steps)
    history: list[dict[str, float]] = []
    best: tuple[float, dict[str, torch.Tensor]] | None = None
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
        if len(val):
            row.update({f"val_{k}": v for k, v in evaluate(net, val, cfg).items() if k != "windows"})
            score = row["val_regret_m"]
            if best is None or score < best[0]:
                best = (score, {k: v.detach().clone() for k, v in net.state_dict().items()})
        history.append(row)
        if progress:
            progress(json.dumps({k: round(v, 4) if isinstance(v, float) else v for k, v in row.items()}))
    if best is not None:
        net.load_state_dict(best[1])
    net.eval()
    return net, history


def gibson_sources(dataset: str, split: str, per_floor: int) -> dict[str, list[tuple[Source, int]]]:
    """The floors of a SemExp split by house split (train / val / test)."""
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
    log: Callable[[str], None] = print,
) -> dict:
    """Draw, train, score on the held-out houses and save; returns the training record."""
    out = Path(out)
    if out.suffix != ".pt":
        raise L3MVNError(f"--out must be a .pt file, got {out}")
    if not out.parent.is_dir():
        raise L3MVNError(f"--out: folder {out.parent} does not exist")
    sources = gibson_sources(dataset, split, options.samples_per_floor) if dataset else {s: [] for s in HOUSE_SPLITS}
    procedural: list[tuple[Source, int]] = [
        (options.seed * 100_000 + k, options.samples_per_procedural) for k in range(options.procedural_houses)
    ]
    if not sources["train"] and not procedural:
        raise L3MVNError("nothing to train on: give --dataset with train houses, or --procedural N > 0")
    sets: dict[str, SampleSet] = {}
    for name, floors in (("train", sources["train"] + procedural), ("val", sources["val"]), ("test", sources["test"])):
        started = time.monotonic()

        def tick(done: int, total: int, name: str = name) -> None:
            if done == total or done % 100 == 0:
                log(f"drawing {name} windows: {done}/{total} floors")

        sets[name] = draw_samples(floors, cfg, reveal, options.seed + HOUSE_SPLITS.index(name), options.workers, tick)
        log(f"{name}: {len(sets[name])} windows from {len(floors)} floors in {time.monotonic() - started:.0f} s")
    net, history = fit(sets["train"], sets["val"], cfg, options, log)
    scores = {name: evaluate(net, sets[name], cfg) for name in ("val", "test") if len(sets[name])}
    training = {
        "dataset": str(dataset) if dataset else None,
        "split": split,
        "houses": {name: sorted({h for h in sets[name].houses}) for name in sets if name != "train"},
        "gibson_train_floors": len(sources["train"]),
        "options": asdict(options),
        "reveal": asdict(reveal),
        "history": history,
        "scores": scores,
    }
    model = PotentialModel(net, {k: float(getattr(cfg, k)) for k in GEOMETRY}, training, str(out))
    model.save(out)
    return {"out": str(out), "scores": scores, "windows": {k: len(v) for k, v in sets.items()}}


# --- the command (registered by l3mvn.run.cli as `l3mvn poni`) ------------------------------------------
def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="poni_command", required=True)
    tr = sub.add_parser("train", help="train the potential network from full house maps (no interaction)")
    tr.add_argument("--dataset", default=None, help="SemExp dataset dir (its houses split train / val / test)")
    tr.add_argument("--split", default="train")
    tr.add_argument("--out", default=None, help="the .pt to write (default: the shipped checkpoint)")
    defaults = TrainOptions()
    for name in ("samples_per_floor", "procedural_houses", "samples_per_procedural", "epochs", "batch", "width"):
        tr.add_argument(f"--{name.replace('_', '-')}", type=_count, default=getattr(defaults, name))
    tr.add_argument("--learning-rate", type=float, default=defaults.learning_rate)
    tr.add_argument("--seed", type=int, default=defaults.seed)
    tr.add_argument("--workers", type=_count, default=defaults.workers)
    show = sub.add_parser("show", help="what a checkpoint was trained on and how it scored")
    show.add_argument("checkpoint", nargs="?", default=None, help="a .pt (default: the shipped one)")


def _count(raw: str) -> int:
    if not raw.isascii() or not raw.strip().lstrip("+").isdigit():
        raise argparse.ArgumentTypeError(f"expected a whole number >= 0, got {raw!r}")
    return int(raw)


def run(args: argparse.Namespace) -> int:
    if args.poni_command == "show":
        model = PotentialModel.load(args.checkpoint, PotentialConfig())
        print(json.dumps({"checkpoint": model.source, "geometry": model.geometry, **model.training}, indent=2))
        return 0
    options = replace(
        TrainOptions(),
        **{k: getattr(args, k) for k in asdict(TrainOptions()) if hasattr(args, k) and getattr(args, k) is not None},
    )
    if options.epochs < 1 or options.batch < 1 or options.width < 8 or options.width % 8:
        raise L3MVNError("--epochs and --batch must be >= 1, --width a multiple of 8 (its group norm)")
    if not (math.isfinite(options.learning_rate) and options.learning_rate > 0):
        raise L3MVNError(f"--learning-rate must be a positive number, got {options.learning_rate}")
    summary = train_potentials(
        args.dataset,
        args.split,
        args.out or shipped_checkpoint(),
        options=options,
        log=lambda line: print(line, flush=True),
    )
    print(json.dumps(summary))
    return 0

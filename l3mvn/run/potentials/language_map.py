"""``l3mvn poni train-language``: the map head of l3mvn-ff (``l3mvn.agent.potentials.language_map``),
the words of each frontier's window added to a fixed PONI checkpoint's expected metres on.

PONI walks generated episodes (the states the combined policy meets, since an untrained head is
PONI), by default on procedural houses the shipped checkpoint never walked, so the head learns what
PONI gets wrong where it did not learn, beside the SemExp split's train houses. At each choice the
frozen network's totals per frontier and goal are computed once; the head is then taught, per
(choice, goal), the listwise cross-entropy between the softmax of the true totals (travel + metres
on) and of PONI's totals plus the head's metres, the loss PONI's own walks' stage uses. The epoch
(epoch 0: the head at zero, PONI itself) whose choices on the val houses' walks regret least is kept.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import cast

import numpy as np
import numpy.typing as npt
import torch

from l3mvn.agent.potentials import OUTPUTS, PotentialModel, expected_totals, shipped_checkpoint
from l3mvn.agent.potentials.language_map import (
    LanguageMapHead,
    LanguageResidual,
    shipped_language_map,
    window_sentences,
)
from l3mvn.core.config import PotentialConfig
from l3mvn.core.errors import L3MVNError
from l3mvn.core.paths import file_sha256
from l3mvn.run.potentials.train import (
    Epochs,
    TrainOptions,
    frontier_logits,
    shuffled_batches,
    walk_sources,
    walk_splits,
)
from l3mvn.run.potentials.walks import WalkSet

# The shipped PONI checkpoint walked the default procedural houses: the head learns on houses after them.
FIRST_UNWALKED_PROCEDURAL = TrainOptions.walk_procedural_first + TrainOptions.walk_procedural_houses


@dataclass(frozen=True)
class LanguageMapOptions:
    encoder: str = "minilm"  # the sentence embedder the head reads
    hidden: int = 128
    epochs: int = 30
    batch: int = 256  # choices per step
    learning_rate: float = 1e-3
    weight_decay: float = 1e-3
    tau_m: float = TrainOptions.walk_tau_m
    seed: int = 0


@dataclass
class Lists:
    """Every walk choice padded to its largest frontier count: PONI's ``totals`` (N, F, goals), the
    ``true`` totals (travel + metres on; NaN where unknown), ``frontier`` (N, F: a real frontier),
    each frontier's ``sentence`` (index into the embeddings) and the episode's ``goal`` (N,)."""

    totals: np.ndarray
    true: np.ndarray
    frontier: np.ndarray
    sentence: np.ndarray
    goal: np.ndarray

    def __len__(self) -> int:
        return len(self.goal)


@torch.inference_mode()
def prepare(walks: WalkSet, poni: PotentialModel, cfg: PotentialConfig, sentences: dict[str, int]) -> Lists:
    """The walks' choices as PONI reads them (``sentences`` grows with each new window sentence)."""
    goals = len(OUTPUTS) - 1
    width = max((len(walks.frontiers(i)[0]) for i in range(len(walks))), default=1)
    n = len(walks)
    out = Lists(
        np.zeros((n, width, goals)),
        np.full((n, width, goals), np.nan),
        np.zeros((n, width), bool),
        np.zeros((n, width), np.int64),
        walks.goal.astype(np.int64),
    )
    for start in range(0, n, 32):
        idx = np.arange(start, min(start + 32, n))
        logits = poni.net(torch.from_numpy(walks.features[idx].astype(np.float32) / 255.0))
        for s, i in enumerate(idx):
            cost, metres, cells = walks.frontiers(int(i))
            per_frontier, _ = frontier_logits(logits[s].reshape(len(OUTPUTS), -1), cells)
            potentials = torch.sigmoid(per_frontier).numpy().astype(np.float64)
            f = len(cost)
            out.totals[i, :f] = expected_totals(cost.astype(np.float64), potentials, cfg, walks.size_m(int(i)))
            out.true[i, :f] = cost[:, None] + metres
            out.frontier[i, :f] = True
            for k, text in enumerate(window_sentences(walks.objects(int(i)))):
                out.sentence[i, k] = sentences.setdefault(text, len(sentences))
    return out


def _known(lists: Lists, idx: np.ndarray) -> np.ndarray:
    return lists.frontier[idx][:, :, None] & np.isfinite(lists.true[idx])


def list_loss(
    net: LanguageResidual, embeddings: torch.Tensor, lists: Lists, idx: np.ndarray, tau_m: float
) -> torch.Tensor:
    """Mean listwise cross-entropy over the (choice, goal) lists of ``idx`` with two or more known
    frontiers."""
    known = torch.from_numpy(_known(lists, idx))
    lists_ok = known.sum(dim=1) >= 2  # (B, goals)
    words = net(embeddings[torch.from_numpy(lists.sentence[idx])])  # (B, F, goals)
    predicted = -(torch.from_numpy(lists.totals[idx]).float() + words) / tau_m
    true = -torch.from_numpy(np.nan_to_num(lists.true[idx])).float() / tau_m
    off = torch.tensor(-1e9)
    wanted = torch.softmax(torch.where(known, true, off), dim=1)
    log_p = torch.log_softmax(torch.where(known, predicted, off), dim=1)
    per_list = -(torch.where(known, wanted * log_p, torch.zeros(()))).sum(dim=1)
    return per_list[lists_ok].sum() / lists_ok.sum().clamp(min=1)


@torch.inference_mode()
def regret(net: LanguageResidual, embeddings: torch.Tensor, lists: Lists) -> dict[str, float]:
    """Mean regret in metres of the choice by PONI's totals plus the head's metres: the true total
    (travel + metres on) of the frontier taken, less the least; ``regret_m`` over every goal the house
    holds, ``goal_regret_m`` for the episode's goal. Where every frontier lies on the true floor this is
    ``train.choice_regret``; a frontier off it counts here as the worst known total (there: its own
    travel plus the worst known metres on)."""
    idx = np.arange(len(lists))
    words = net(embeddings[torch.from_numpy(lists.sentence)]).numpy().astype(np.float64)
    totals = np.where(lists.frontier[:, :, None], lists.totals + words, np.inf)
    known = _known(lists, idx)
    worst = np.where(known, lists.true, -np.inf).max(axis=1, keepdims=True)
    true = np.where(known, lists.true, np.where(lists.frontier[:, :, None], worst, np.inf))
    # (choices, goals) the house holds; the others' regret is undefined. numpy types a reduction over
    # an axis as maybe a scalar; over axis 1 of a 3-D array it is 2-D.
    held = cast(npt.NDArray[np.bool_], known.any(axis=1))
    with np.errstate(invalid="ignore"):
        lost = np.take_along_axis(true, totals.argmin(axis=1)[:, None], axis=1)[:, 0] - true.min(axis=1)
    own = held[idx, lists.goal]
    return {
        "regret_m": float(lost[held].mean()) if held.any() else math.nan,
        "goal_regret_m": float(lost[idx, lists.goal][own].mean()) if own.any() else math.nan,
        "choices": len(lists),
    }


def fit_language_map(
    train: Lists,
    val: Lists,
    embeddings: torch.Tensor,
    options: LanguageMapOptions,
    log: Callable[[str], None] = print,
) -> tuple[LanguageResidual, list[dict[str, float]]]:
    """The head after ``options.epochs`` epochs, with the weights of the epoch (0: at zero, PONI's
    choices) whose val regret is least."""
    torch.manual_seed(options.seed)
    rng = np.random.default_rng(options.seed)
    net = LanguageResidual(embeddings.shape[1], options.hidden)
    opt = torch.optim.AdamW(net.parameters(), lr=options.learning_rate, weight_decay=options.weight_decay)
    epochs = Epochs[LanguageResidual](log)
    batches = max(1, math.ceil(len(train) / options.batch))
    for epoch in range(options.epochs + 1):
        started, total = time.monotonic(), 0.0
        if epoch:
            net.train()
            for idx in shuffled_batches(rng, len(train), options.batch, batches):
                loss = list_loss(net, embeddings, train, idx, options.tau_m)
                opt.zero_grad()
                loss.backward()
                opt.step()
                total += loss.item()
        net.eval()
        row: dict[str, float] = {"epoch": epoch, "seconds": time.monotonic() - started}
        if epoch:
            row["train_loss"] = total / batches
        row |= {f"train_{k}": v for k, v in regret(net, embeddings, train).items() if k != "choices"}
        epochs.add(net, row, regret(net, embeddings, val))
    return epochs.best_net(net)


def train_language_map(
    walks: dict[str, WalkSet],
    poni_checkpoint: str | Path,
    out: str | Path,
    options: LanguageMapOptions = LanguageMapOptions(),
    provenance: dict | None = None,
    log: Callable[[str], None] = print,
) -> dict:
    """Fit the head on ``walks`` (train / val / test, as ``walk_splits`` gives them) over the PONI
    checkpoint at ``poni_checkpoint``, save it to ``out`` and return the summary."""
    from l3mvn.agent.language.models import load_sentence_encoder

    poni_file = Path(poni_checkpoint)
    poni = PotentialModel.load(poni_file, PotentialConfig(), to_fine_tune=True)
    cfg = PotentialConfig(checkpoint=str(poni_file), size_bonus=bool(poni.geometry["size_bonus"]))
    sentences: dict[str, int] = {}
    lists = {name: prepare(w, poni, cfg, sentences) for name, w in walks.items()}
    started = time.monotonic()
    texts = list(sentences)
    embeddings = torch.from_numpy(load_sentence_encoder(options.encoder).encode(texts))
    log(f"{len(texts)} window sentences embedded with {options.encoder} in {time.monotonic() - started:.0f} s")
    net, history = fit_language_map(lists["train"], lists["val"], embeddings, options, log)
    start = LanguageResidual(embeddings.shape[1], options.hidden)  # zero words: PONI's own choices
    scores = {
        name: {"head": regret(net, embeddings, lists[name]), "poni": regret(start, embeddings, lists[name])}
        for name in ("val", "test")
        if len(lists[name])
    }
    training = {
        "poni_checkpoint": poni_file.name,
        "options": asdict(options),
        "walks": {name: len(w) for name, w in walks.items()},
        "houses": {name: sorted(set(w.houses)) for name, w in walks.items() if name != "train"},
        "sentences": len(texts),
        "history": history,
        "scores": scores,
    } | (provenance or {})
    LanguageMapHead(net, options.encoder, file_sha256(poni_file), training, str(out)).save(out)
    return {"out": str(out), "scores": scores, "choices": training["walks"]}


# --- the command (registered under `l3mvn poni` by l3mvn.run.potentials.train) ------------------------------
def add_arguments(parser: argparse.ArgumentParser, count: Callable[[str], int]) -> None:
    parser.add_argument("--dataset", default=None, help="SemExp dataset dir (its houses split train / val / test)")
    parser.add_argument("--split", default="train")
    parser.add_argument("--out", default=None, help="the .pt to write (default: the shipped map head)")
    parser.add_argument("--poni", default=None, help="the PONI checkpoint it corrects (default: the shipped one)")
    walking = TrainOptions()
    parser.add_argument("--walk-episodes", type=count, default=walking.walk_episodes)
    parser.add_argument("--walk-procedural-houses", type=count, default=walking.walk_procedural_houses)
    parser.add_argument("--walk-episodes-per-procedural", type=count, default=walking.walk_episodes_per_procedural)
    parser.add_argument(
        "--walk-procedural-first",
        type=count,
        default=FIRST_UNWALKED_PROCEDURAL,
        help="the first procedural house walked (default: the first the shipped PONI never walked)",
    )
    defaults = LanguageMapOptions()
    parser.add_argument("--encoder", default=defaults.encoder, help="the sentence embedder (minilm, smollm2-135m, ...)")
    for name in ("hidden", "epochs", "batch"):
        parser.add_argument(f"--{name}", type=count, default=getattr(defaults, name))
    for name in ("learning_rate", "weight_decay"):
        parser.add_argument(f"--{name.replace('_', '-')}", type=float, default=getattr(defaults, name))
    parser.add_argument("--seed", type=int, default=defaults.seed)
    parser.add_argument("--workers", type=count, default=walking.workers)


def run(args: argparse.Namespace) -> int:
    options = LanguageMapOptions(
        args.encoder, args.hidden, args.epochs, args.batch, args.learning_rate, args.weight_decay, seed=args.seed
    )
    if options.hidden < 1 or options.batch < 1:
        raise L3MVNError("--hidden and --batch must be >= 1")
    if not (math.isfinite(options.learning_rate) and options.learning_rate > 0):
        raise L3MVNError(f"--learning-rate must be a positive number, got {options.learning_rate}")
    if not (math.isfinite(options.weight_decay) and options.weight_decay >= 0):
        raise L3MVNError(f"--weight-decay must be a non-negative number, got {options.weight_decay}")
    out = Path(args.out) if args.out else shipped_language_map()
    if out.suffix != ".pt" or not out.parent.is_dir():
        raise L3MVNError(f"--out must be a .pt file in an existing folder, got {out}")
    poni_file = Path(args.poni) if args.poni else shipped_checkpoint()
    poni = PotentialModel.load(poni_file, PotentialConfig(), to_fine_tune=True)
    from l3mvn.agent.language.models import load_sentence_encoder

    load_sentence_encoder(options.encoder)  # an embedder that cannot load is refused before the walks
    walking = replace(
        TrainOptions(),
        walk_episodes=args.walk_episodes,
        walk_procedural_houses=args.walk_procedural_houses,
        walk_episodes_per_procedural=args.walk_episodes_per_procedural,
        walk_procedural_first=args.walk_procedural_first,
        walker="poni",
        seed=args.seed,
        workers=args.workers,
    )
    sources = walk_sources(args.dataset, args.split, walking)
    if not sources["train"]:
        raise L3MVNError("nothing to walk: give --dataset with train houses, or --walk-procedural-houses > 0")
    log = lambda line: print(line, flush=True)  # noqa: E731
    cfg = PotentialConfig(checkpoint=str(poni_file), size_bonus=bool(poni.geometry["size_bonus"]))
    walks = walk_splits(sources, cfg, walking, log)
    provenance = {"dataset": args.dataset, "split": args.split, "walking": asdict(walking)}
    print(json.dumps(train_language_map(walks, poni_file, out, options, provenance, log)))
    return 0

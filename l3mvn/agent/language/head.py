"""The feed-forward head: sentence embedding -> 3-layer MLP -> one number per goal (logits of p(goal)
for the room-list head, expected metres to the goal for the frontier head; ``meta["kind"]`` says which).

The bag-of-objects heads (kinds ``rooms-bag``, ``frontiers-bag``) are the ablation without the
language model: the same MLP, training data and recipe, but the input is the multi-hot vector of the
frontier's objects over the head's own vocabulary (``meta["vocabulary"]``, ``bag_features``), so no
sentence is written or embedded. What they lose against the sentence heads is what MiniLM adds.

Layout of the paper's code (1024-512-256-6 for RoBERTa-large; 384-512-256-6 for MiniLM), BatchNorm
and ReLU after each hidden layer. Saved as one torch file: ``{"state_dict", "meta"}``, where
``meta`` names the encoder, goals, sizes, training settings and metrics (see MODEL_CARD.md).
"""

from __future__ import annotations

import io
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from l3mvn.core.errors import L3MVNError
from l3mvn.core.paths import PACKAGE_DATA
from l3mvn.core.writing import write_file

DATA_DIR = PACKAGE_DATA / "language"
# "<embedder>" is the room-list head (the paper's recipe), "<embedder>-frontiers" the one trained on
# frontiers of house maps (``frontier_head``); "<kind>-bag" the same heads on bags of objects (no embedder).
SHIPPED_HEADS = {
    "minilm": DATA_DIR / "head_minilm.pt",
    "smollm2-135m": DATA_DIR / "head_smollm2_135m.pt",  # the room head on the LLM's own embedding
    "minilm-frontiers": DATA_DIR / "head_minilm_frontiers.pt",
    "rooms-bag": DATA_DIR / "head_rooms_bag.pt",
    "frontiers-bag": DATA_DIR / "head_frontiers_bag.pt",
}
HIDDEN = (512, 256)
BAG = "-bag"  # suffix of a head kind whose input is a bag of objects instead of a sentence embedding
BAG_FEATURES = "bag"  # meta["features"] of such a head (a sentence head has no "features" entry)


def is_bag(kind: str) -> bool:
    return kind.endswith(BAG)


def base_kind(kind: str) -> str:
    """``"rooms"`` or ``"frontiers"``: what the head was trained to predict, whatever its input."""
    return kind[: -len(BAG)] if is_bag(kind) else kind


def bag_features(object_sets: Sequence[Iterable[str]], vocabulary: Sequence[str]) -> np.ndarray:
    """(sets, len(vocabulary)) float32 multi-hot: 1 where the set holds that (canonical) object. An
    object outside the vocabulary adds nothing, as an uninformative object adds no word to a room
    head's sentence; an empty set is the zero vector."""
    column = {o: i for i, o in enumerate(vocabulary)}
    out = np.zeros((len(object_sets), len(vocabulary)), dtype=np.float32)
    for row, objects in enumerate(object_sets):
        out[row, [column[o] for o in set(objects) if o in column]] = 1.0
    return out


class GoalHead(nn.Module):
    def __init__(self, in_dim: int, n_goals: int, hidden: tuple[int, ...] = HIDDEN):
        super().__init__()
        layers: list[nn.Module] = []
        width = in_dim
        for h in hidden:
            layers += [nn.Linear(width, h), nn.BatchNorm1d(h), nn.ReLU()]
            width = h
        layers.append(nn.Linear(width, n_goals))
        self.net = nn.Sequential(*layers)
        self.in_dim, self.n_goals, self.hidden = in_dim, n_goals, tuple(hidden)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        out: torch.Tensor = self.net(x)  # torch types a module call as Any
        return out


def save_head(head: GoalHead, meta: dict[str, Any], path: str | Path) -> Path:
    meta = {**meta, "in_dim": head.in_dim, "n_goals": head.n_goals, "hidden": list(head.hidden)}
    encoded = io.BytesIO()
    torch.save({"state_dict": {k: v.detach().cpu() for k, v in head.state_dict().items()}, "meta": meta}, encoded)
    return write_file(path, encoded.getvalue(), "head weights")


def load_head(path: str | Path) -> tuple[GoalHead, dict[str, Any]]:
    """(head in eval mode, meta) from a file written by ``save_head``."""
    path = Path(path)
    if not path.exists():
        raise L3MVNError(f"feed-forward head {path} not found; train one with `l3mvn train-head`")
    try:
        blob = torch.load(path, map_location="cpu", weights_only=True)
        meta = blob["meta"]
        head = GoalHead(int(meta["in_dim"]), int(meta["n_goals"]), tuple(meta["hidden"]))
        head.load_state_dict(blob["state_dict"])
    except (KeyError, RuntimeError, TypeError, ValueError) as exc:
        raise L3MVNError(f"{path}: not a feed-forward head file ({str(exc).splitlines()[0][:120]})") from None
    return head.eval(), meta


__all__ = [
    "BAG",
    "BAG_FEATURES",
    "HIDDEN",
    "SHIPPED_HEADS",
    "GoalHead",
    "bag_features",
    "base_kind",
    "is_bag",
    "load_head",
    "save_head",
]

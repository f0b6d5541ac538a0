"""The feed-forward head on the partial map (``l3mvn-ff --head map``): PONI's expected metres on to
each goal, corrected by what a sentence embedder reads in the frontier's window objects.

The paper's head reads "This frontier contains o1, ..., and ok." alone, and a window's objects say
little about which frontier leads to a goal in a house the head never saw; PONI reads the partial
map, which does. Here the two meet: the sentence's embedding feeds a small network whose output, in
metres per goal, is added to PONI's expected metres on. Its last layer starts at zero, so an untrained
head chooses exactly as PONI does, and training (``l3mvn poni train-language``, on the agent's own
walks, through the totals the policy minimises) keeps the epoch whose choices on validation houses
regret least: the words move PONI's choice only as far as that moved it well on houses not learned.

A head file is a ``torch.save`` dict of plain tensors, strings and numbers, read with
``weights_only=True``: ``kind`` ("language-map"), ``state``, ``hidden``, ``encoder`` (the sentence
embedder, by name), ``goals``, ``poni_sha256`` (the PONI checkpoint whose metres it corrects: read with
another, it is refused) and ``training``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from l3mvn.core.categories import GIBSON_CATEGORIES, GOAL_CATEGORIES
from l3mvn.core.config.policy import HEAD_FILE_SUFFIX, MAP_HEAD
from l3mvn.core.errors import L3MVNError, first_line
from l3mvn.core.paths import PACKAGE_DATA, file_sha256
from l3mvn.core.writing import replacing

KIND = "language-map"
_KEYS = {"kind", "state", "hidden", "encoder", "goals", "poni_sha256"}


def shipped_language_map() -> Path:
    return PACKAGE_DATA / "potentials" / "language_map.pt"


def is_language_map(path: str | Path) -> bool:
    """Whether ``path`` is a head file of this kind (a feed-forward head file of another kind is not).
    Asked at every policy build, so a file is read once until it changes."""
    try:
        stat = Path(path).stat()
    except OSError:
        return False
    return _is_language_map(str(Path(path).resolve()), stat.st_mtime_ns, stat.st_size)


@lru_cache(maxsize=64)
def _is_language_map(path: str, mtime_ns: int, size: int) -> bool:
    try:
        blob = torch.load(path, map_location="cpu", weights_only=True)
    except Exception:  # torch raises many kinds for a foreign file; the head loader names the problem
        return False
    return isinstance(blob, dict) and blob.get("kind") == KIND


def map_head_file(head: str | None) -> Path | None:
    """The map head file a ``policy.head`` names (``map``: the shipped one; a .pt file of this kind),
    or None where it names an object-list head."""
    if head == MAP_HEAD:
        return shipped_language_map()
    if head is not None and head.endswith(HEAD_FILE_SUFFIX) and Path(head).is_file() and is_language_map(head):
        return Path(head)
    return None


def window_sentences(hot: np.ndarray) -> list[str]:
    """The feed-forward sentence of each frontier's window categories (rows of ``objects_hot``): the
    one text the walks' training and the running agent both embed."""
    from l3mvn.agent.language.frontier_file import frontier_query

    return [frontier_query([GIBSON_CATEGORIES[k] for k in np.flatnonzero(row)]) for row in hot]


def _read(path: str | Path | None) -> tuple[Path, dict[str, Any]]:
    """The file a map head ``path`` names (None: the shipped one) and its dict, refused in one line
    when missing, unreadable or of another kind."""
    file = Path(path) if path is not None else shipped_language_map()
    if not file.is_file():
        raise L3MVNError(f"map head {file} does not exist; train one with `l3mvn poni train-language --out FILE.pt`")
    try:
        blob = torch.load(file, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises many kinds for a damaged or foreign file
        raise L3MVNError(f"cannot read map head {file}: {first_line(exc)}") from None
    if not isinstance(blob, dict) or blob.get("kind") != KIND or not _KEYS <= set(blob):
        raise L3MVNError(f"{file} is not a map head from `l3mvn poni train-language` (kind or keys missing)")
    return file, blob


class LanguageResidual(nn.Module):
    """Embedding -> hidden -> metres per goal, the last layer zero at the start (PONI unchanged)."""

    def __init__(self, dim: int, hidden: int = 128) -> None:
        super().__init__()
        self.net = nn.Sequential(nn.Linear(dim, hidden), nn.ReLU(), nn.Linear(hidden, len(GOAL_CATEGORIES)))
        last = self.net[-1]
        assert isinstance(last, nn.Linear)
        nn.init.zeros_(last.weight)
        nn.init.zeros_(last.bias)
        self.dim, self.hidden = dim, hidden

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        out: torch.Tensor = self.net(x)
        return out


@dataclass
class LanguageMapHead:
    """A trained residual, the embedder it reads and the PONI checkpoint it corrects."""

    net: LanguageResidual
    encoder: str
    poni_sha256: str
    training: dict[str, Any] = field(default_factory=dict)
    source: str = ""
    _cache: dict[str, np.ndarray] = field(default_factory=dict, repr=False)

    @classmethod
    def load(cls, path: str | Path | None, poni_checkpoint: str | Path) -> LanguageMapHead:
        """The head at ``path`` (None: the shipped one), refused in one line when missing, unreadable,
        of another kind, or trained over another PONI checkpoint than ``poni_checkpoint``."""
        file, blob = _read(path)
        if tuple(blob["goals"]) != GOAL_CATEGORIES:
            raise L3MVNError(f"{file} predicts {list(blob['goals'])}; this version's goals are {list(GOAL_CATEGORIES)}")
        poni_sha = file_sha256(poni_checkpoint)
        if blob["poni_sha256"] != poni_sha:
            raise L3MVNError(
                f"{file} corrects another PONI checkpoint than {poni_checkpoint}: set poni.checkpoint to the "
                f"one it was trained over, or retrain it with `l3mvn poni train-language`"
            )
        weight = blob["state"].get("net.0.weight")
        if not isinstance(weight, torch.Tensor) or weight.ndim != 2:
            raise L3MVNError(f"{file}: weights do not fit the map head (net.0.weight missing)")
        net = LanguageResidual(int(weight.shape[1]), int(blob["hidden"]))
        try:
            net.load_state_dict(blob["state"])
        except (RuntimeError, KeyError, TypeError) as exc:
            raise L3MVNError(f"{file}: weights do not fit the map head: {first_line(exc)}") from None
        net.eval()
        return cls(net, str(blob["encoder"]), poni_sha, dict(blob.get("training", {})), str(file))

    @staticmethod
    def record(path: str | Path | None) -> dict[str, Any]:
        """What the head at ``path`` (None: the shipped one) reads, corrects and was trained on, without
        its weights: ``l3mvn poni show`` prints it."""
        file, blob = _read(path)
        keys = ("encoder", "hidden", "goals", "poni_sha256", "training")
        return {"map_head": str(file), "kind": KIND} | {k: blob[k] for k in keys if k in blob}

    def save(self, path: str | Path) -> None:
        blob = {
            "kind": KIND,
            "state": self.net.state_dict(),
            "hidden": self.net.hidden,
            "encoder": self.encoder,
            "goals": list(GOAL_CATEGORIES),
            "poni_sha256": self.poni_sha256,
            "training": self.training,
        }
        with replacing(path, "map head") as fh:  # whole or not at all: a full disk is one error
            torch.save(blob, fh)

    @property
    def label(self) -> str:
        return f"{self.encoder} words ({Path(self.source).name or 'untrained'})"

    def embed(self, sentences: list[str]) -> np.ndarray:
        """(len(sentences), dim) embeddings; each distinct sentence is embedded once per process."""
        new = sorted({s for s in sentences if s not in self._cache})
        if new:
            from l3mvn.agent.language.models import load_sentence_encoder

            for s, v in zip(new, load_sentence_encoder(self.encoder).encode(new)):
                self._cache[s] = v
        return np.stack([self._cache[s] for s in sentences]) if sentences else np.zeros((0, self.net.dim), np.float32)

    @torch.inference_mode()
    def metres(self, sentences: list[str]) -> np.ndarray:
        """(len(sentences), goals) metres added to PONI's expected metres on."""
        x = torch.from_numpy(self.embed(sentences))
        out: np.ndarray = self.net(x).numpy().astype(np.float64)
        return out

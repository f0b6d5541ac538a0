"""The potential network (a small U-Net, as PONI's) and its checkpoint.

A checkpoint is a ``torch.save`` dict of plain tensors and numbers, read with ``weights_only=True`` so
loading one runs nothing from the file: ``state`` (the weights), ``width``, ``channels`` and
``outputs`` (the layout it was trained on), ``geometry`` (the ``PotentialConfig`` numbers its outputs
are scaled by) and ``training`` (what it was trained on and how it scored, for the model card).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from l3mvn.agent.potentials.features import CHANNELS, OUTPUTS
from l3mvn.core.config import PotentialConfig
from l3mvn.core.errors import L3MVNError, first_line
from l3mvn.core.paths import PACKAGE_DATA
from l3mvn.core.writing import replacing

# The PotentialConfig fields a checkpoint fixes (size_bonus as 0 / 1); a checkpoint saved before
# size_bonus existed was trained without it.
GEOMETRY = ("cell_m", "input_window_m", "range_m", "area_scale_m2", "size_bonus")
_SAVED_BEFORE = {"size_bonus": 0.0}


def _shown(name: str, value: float | None) -> str:
    """A geometry value as ``--set`` takes it (the size bonus as true / false)."""
    if name == "size_bonus" and value is not None:
        return "true" if value else "false"
    return str(value)


def shipped_checkpoint() -> Path:
    return PACKAGE_DATA / "potentials" / "poni.pt"


def _block(cin: int, cout: int) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv2d(cin, cout, 3, padding=1, bias=False),
        nn.GroupNorm(8, cout),
        nn.ReLU(inplace=True),
        nn.Conv2d(cout, cout, 3, padding=1, bias=False),
        nn.GroupNorm(8, cout),
        nn.ReLU(inplace=True),
    )


class PotentialNet(nn.Module):
    """U-Net with three halvings: a 128-cell window sees the whole 25.6 m at its 16-cell bottom, wide
    enough to tell a corridor that leads on from a room that ends. Outputs are logits."""

    def __init__(self, channels: int = len(CHANNELS), outputs: int = len(OUTPUTS), width: int = 24) -> None:
        super().__init__()
        w = width
        self.down = nn.ModuleList([_block(channels, w), _block(w, 2 * w), _block(2 * w, 4 * w)])
        self.bottom = _block(4 * w, 4 * w)
        self.up = nn.ModuleList([_block(8 * w, 2 * w), _block(4 * w, w), _block(2 * w, w)])
        self.head = nn.Conv2d(w, outputs, 1)
        self.width = width

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        skips = []
        for block in self.down:
            x = block(x)
            skips.append(x)
            x = nn.functional.max_pool2d(x, 2)
        x = self.bottom(x)
        for block, skip in zip(self.up, reversed(skips)):
            x = nn.functional.interpolate(x, scale_factor=2.0, mode="nearest")
            x = block(torch.cat([x, skip], dim=1))
        out: torch.Tensor = self.head(x)
        return out


@dataclass
class PotentialModel:
    """A trained network with the geometry its outputs are scaled by."""

    net: PotentialNet
    geometry: dict[str, float]
    training: dict[str, Any] = field(default_factory=dict)
    source: str = ""

    @classmethod
    def load(cls, path: str | Path | None, cfg: PotentialConfig, to_fine_tune: bool = False) -> PotentialModel:
        """The checkpoint at ``path`` (None: the shipped one), refused in one line when missing,
        unreadable, of another layout, or trained with other geometry than ``cfg``'s; ``to_fine_tune``:
        its size bonus may differ from ``cfg``'s (training changes the criterion it learned through)."""
        file = Path(path) if path is not None else shipped_checkpoint()
        if not file.is_file():
            where = "the shipped checkpoint" if path is None else "poni.checkpoint"
            raise L3MVNError(f"{where} {file} does not exist; train one with `l3mvn poni train --out FILE.pt`")
        try:
            blob = torch.load(file, map_location="cpu", weights_only=True)
        except Exception as exc:  # torch raises many kinds for a damaged or foreign file
            raise L3MVNError(f"cannot read PONI checkpoint {file}: {first_line(exc)}") from None
        if not isinstance(blob, dict) or not {"state", "width", "channels", "outputs", "geometry"} <= set(blob):
            raise L3MVNError(f"{file} is not a PONI checkpoint from `l3mvn poni train` (keys missing)")
        if tuple(blob["channels"]) != CHANNELS or tuple(blob["outputs"]) != OUTPUTS:
            raise L3MVNError(
                f"{file} was trained on channels {list(blob['channels'])} -> {list(blob['outputs'])}; this "
                f"version reads {list(CHANNELS)} -> {list(OUTPUTS)}: retrain it with `l3mvn poni train`"
            )
        geometry = _SAVED_BEFORE | {k: float(v) for k, v in dict(blob["geometry"]).items()}
        wanted = {k: float(getattr(cfg, k)) for k in GEOMETRY}
        fixed = [k for k in GEOMETRY if not (to_fine_tune and k == "size_bonus")]
        wrong = [k for k in fixed if not math.isclose(geometry.get(k, math.nan), wanted[k], rel_tol=1e-6)]
        if wrong:
            said = ", ".join(f"poni.{k}={_shown(k, geometry.get(k))} (config {_shown(k, wanted[k])})" for k in wrong)
            raise L3MVNError(f"{file} was trained with {said}: set those, or retrain with the config's")
        net = PotentialNet(width=int(blob["width"]))
        try:
            net.load_state_dict(blob["state"])
        except (RuntimeError, KeyError, TypeError) as exc:
            raise L3MVNError(f"{file}: weights do not fit the network: {first_line(exc)}") from None
        net.eval()
        return cls(net, geometry, dict(blob.get("training", {})), str(file))

    def save(self, path: str | Path) -> None:
        blob = {
            "state": self.net.state_dict(),
            "width": self.net.width,
            "channels": list(CHANNELS),
            "outputs": list(OUTPUTS),
            "geometry": dict(self.geometry),
            "training": self.training,
        }
        with replacing(path, "PONI checkpoint") as fh:  # whole or not at all: a full disk is one error
            torch.save(blob, fh)

    @property
    def label(self) -> str:
        return f"poni ({Path(self.source).name or 'untrained'})"

    @torch.inference_mode()
    def predict(self, features: np.ndarray) -> np.ndarray:
        """(len(OUTPUTS), n, n) potentials in [0, 1] for one window's features."""
        x = torch.from_numpy(np.ascontiguousarray(features, dtype=np.float32))[None]
        out: np.ndarray = torch.sigmoid(self.net(x))[0].numpy()
        return out

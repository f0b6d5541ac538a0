"""Settings that change what a named policy does (``--scorer``, ``--selection``, ``--seg-noise``)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from l3mvn.errors import L3MVNError

# Language policies: the paper's bound rule, or the thresholds of the authors' code.
SELECTIONS = ("paper", "official_code")


@dataclass(frozen=True)
class PolicyConfig:
    scorer: str | None = None  # language policies: a scorer instead of the policy's default
    selection: str = "paper"
    seg_noise: float = 0.0  # map-based policies: perception errors (see l3mvn.perception)

    def __post_init__(self) -> None:
        if self.selection not in SELECTIONS:
            raise L3MVNError(f"unknown selection {self.selection!r}; valid: {', '.join(SELECTIONS)}")
        if not (math.isfinite(self.seg_noise) and 0.0 <= self.seg_noise <= 1.0):
            raise L3MVNError(f"seg_noise must lie in [0, 1], got {self.seg_noise}")

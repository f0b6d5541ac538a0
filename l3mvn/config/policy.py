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
    # The paper's bound B: language alone decides above bound_high, exploration alone below
    # bound_low, and in between the two are fused (see l3mvn.policies.language_policy).
    bound_low: float = 0.15
    bound_high: float = 0.30
    seg_noise: float = 0.0  # map-based policies: perception errors (see l3mvn.perception)

    def __post_init__(self) -> None:
        if self.selection not in SELECTIONS:
            raise L3MVNError(f"unknown selection {self.selection!r}; valid: {', '.join(SELECTIONS)}")
        if not 0.0 <= self.bound_low < self.bound_high <= 1.0:
            raise L3MVNError(f"the bound must satisfy 0 <= bound_low < bound_high <= 1, got {self.bound_low}, "
                             f"{self.bound_high}")
        if not (math.isfinite(self.seg_noise) and 0.0 <= self.seg_noise <= 1.0):
            raise L3MVNError(f"seg_noise must lie in [0, 1], got {self.seg_noise}")

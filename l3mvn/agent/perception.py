"""Semantic perception errors on demand (``--seg-noise P``).

The paper names segmentation errors as its main failure cause; with ground-truth labels every
map-based policy saturates. Per frame and per category in view, with probability ``p`` the detector
misses it (pixels become background) and, independently, with probability ``p`` it is mislabelled
as another category of the vocabulary (a false positive: the kind that causes false stops).
"""

from __future__ import annotations

import numpy as np

from l3mvn.core.errors import L3MVNError


class SegmentationNoise:
    def __init__(self, p: float, num_categories: int, seed: int = 0) -> None:
        if not 0.0 <= p <= 1.0:
            raise L3MVNError(f"--seg-noise must lie in [0, 1], got {p}")
        self.p, self.k, self.seed = p, num_categories, seed
        self._rng = np.random.default_rng(seed)

    def reset(self, episode_seed: int) -> None:
        self._rng = np.random.default_rng([self.seed, episode_seed])

    def __call__(self, semantic: np.ndarray) -> np.ndarray:
        if self.p == 0.0:
            return semantic
        ids = np.unique(semantic)
        ids = ids[ids > 0]
        if len(ids) == 0:
            return semantic
        drop = self._rng.random(len(ids)) < self.p
        swap = self._rng.random(len(ids)) < self.p
        if not (drop | swap).any():
            return semantic
        lut = np.arange(self.k + 1, dtype=semantic.dtype)
        others = self._rng.integers(1, self.k + 1, size=len(ids))
        lut[ids[swap]] = others[swap]
        lut[ids[drop & ~swap]] = 0
        return lut[semantic]

"""How the agent perceives: camera frames, with segmentation errors on demand, into its semantic map.

``SegmentationNoise`` (``--seg-noise P``): the paper names segmentation errors as its main failure
cause; with ground-truth labels every map-based policy saturates. Per frame and per category in
view, with probability ``p`` the detector misses it (pixels become background) and, independently,
with probability ``p`` it is mislabelled as another category of the vocabulary (a false positive:
the kind that causes false stops). ``Perception`` puts the frame, the noise and the mapper together.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from l3mvn.agent.mapping import SemanticMap, SemanticMapper
from l3mvn.core.camera import CameraIntrinsics
from l3mvn.core.config import Config
from l3mvn.core.errors import L3MVNError
from l3mvn.core.frames import CameraFrame
from l3mvn.core.types import Pose


class SegmentationNoise:
    """Per-frame detector misses and mislabels with probability ``p`` each (see the module docstring)."""

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
        relabelled: np.ndarray = lut[semantic]  # numpy types fancy indexing as Any
        return relabelled


@dataclass(frozen=True, eq=False)
class MappedFrame:
    """A frame as the mapper took it: depth (metres) and labels at the mapper's input size, after
    the segmentation noise, with the intrinsics of that size."""

    depth: np.ndarray
    semantic: np.ndarray
    intrinsics: CameraIntrinsics


class Perception:
    """Camera frames -> the agent's semantic map, the one way the agent perceives.

    Frames are strided to the mapper's input size (``AgentConfig.downsample_factor``: SemExp's
    480x640 -> 120x160), their labels degraded by ``SegmentationNoise`` when the policy asks for it,
    and projected by a ``SemanticMapper`` sized on the first frame and centred on the start pose.
    ``MapAgent`` perceives through it, and so does the scene audit, which must map exactly what the
    agent would from a pose."""

    def __init__(self, config: Config, categories: tuple[str, ...], seed: int = 0) -> None:
        self.config = config
        self.categories = categories
        self.noise = SegmentationNoise(config.policy.seg_noise, len(categories), seed)
        self._mapper: SemanticMapper | None = None
        self._start: Pose | None = None
        self._fresh = True  # the mapper still holds the previous episode's map
        self.frame: MappedFrame | None = None  # the last frame mapped

    def reset(self, start: Pose, episode_seed: int) -> None:
        """A new map centred on ``start`` from the next frame on; noise seeded by the episode."""
        self.noise.reset(episode_seed)
        self._start = start
        self._fresh = True
        self.frame = None

    @property
    def map(self) -> SemanticMap:
        """The map so far (live arrays: the next ``update`` changes them)."""
        if self._mapper is None or self._fresh:
            raise L3MVNError("perception has mapped no frame of this episode yet")
        return self._mapper.map

    def update(self, frame: CameraFrame, pose: Pose, tilt: float) -> SemanticMap:
        """Map one camera frame seen from ``pose`` at ``tilt`` (only its strided pixels are read)."""
        if self._start is None:
            raise L3MVNError("perception has no start pose: call reset(start, seed) first")
        depth, semantic = frame.strided(self.config.agent.downsample_factor(*frame.shape))
        semantic = self.noise(semantic)
        mapper = self._mapper
        if mapper is None or (mapper.intrinsics.height, mapper.intrinsics.width) != depth.shape:
            mapper = self._mapper = SemanticMapper.for_sim(
                self.config.map, self.config.sim, depth.shape[0], depth.shape[1], self.categories
            )
            self._fresh = True
        if self._fresh:
            mapper.reset(self._start)
            self._fresh = False
        self.frame = MappedFrame(depth, semantic, mapper.intrinsics)
        return mapper.update(depth, semantic, pose, tilt)

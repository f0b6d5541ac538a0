import numpy as np
import pytest

from l3mvn.agent.perception import SegmentationNoise
from l3mvn.core.errors import L3MVNError

FRAME = np.zeros((20, 30), np.int32)
FRAME[2:8, 2:8] = 3
FRAME[10:15, 10:20] = 5


def test_zero_noise_returns_the_frame_untouched():
    noise = SegmentationNoise(0.0, num_categories=6)
    assert noise(FRAME) is FRAME


def test_full_noise_changes_every_category_in_view_and_keeps_background():
    noise = SegmentationNoise(1.0, num_categories=6, seed=1)
    noise.reset(7)
    out = noise(FRAME)
    assert (out[FRAME == 0] == 0).all()
    # Each object keeps one label per frame (a detector mistake, not pixel noise), within the vocabulary.
    for cid in (3, 5):
        labels = np.unique(out[FRAME == cid])
        assert len(labels) == 1 and 1 <= labels[0] <= 6


def test_noise_is_seeded_by_episode_not_by_call_order():
    a, b = SegmentationNoise(0.5, 6, seed=2), SegmentationNoise(0.5, 6, seed=2)
    a.reset(11)
    b.reset(99)
    b.reset(11)
    assert all((a(FRAME) == b(FRAME)).all() for _ in range(5))


def test_some_frames_drop_or_swap_at_moderate_noise():
    noise = SegmentationNoise(0.3, 6, seed=0)
    noise.reset(0)
    changed = sum(not (noise(FRAME) == FRAME).all() for _ in range(50))
    assert 10 < changed < 50


def test_noise_probability_outside_zero_one_is_refused():
    with pytest.raises(L3MVNError, match=r"--seg-noise must lie in \[0, 1\]"):
        SegmentationNoise(1.5, 6)

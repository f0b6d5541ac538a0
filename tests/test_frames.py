"""Camera frames made as far as they are read: arrays handed over, lazily made images, strides,
category counts and the render time a step claims."""

from __future__ import annotations

import numpy as np
import pytest

from l3mvn.core.errors import L3MVNError
from l3mvn.core.frames import CameraFrame, centre_pixels


def arrays(h: int = 8, w: int = 12) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(0)
    depth = rng.uniform(0.0, 5.0, (h, w)).astype(np.float32)
    depth[0, :4] = 0.0  # invalid depth: never counted
    semantic = rng.integers(0, 4, (h, w)).astype(np.int32)
    return np.zeros((h, w, 3), np.uint8), depth, semantic


class Counting(CameraFrame):
    """A frame that makes its arrays from ``arrays()`` and counts each making."""

    def __init__(self, strided_alone: bool) -> None:
        super().__init__((8, 12))
        self.made: list[str] = []
        self.strided_alone = strided_alone

    def _make_full(self):
        self.made.append("full")
        _, depth, semantic = arrays()
        return depth, semantic

    def _make_rgb(self):
        self.made.append("rgb")
        return arrays()[0]

    def _make_strided(self, step):
        if not self.strided_alone:
            return None
        self.made.append(f"strided {step}")
        _, depth, semantic = arrays()
        return centre_pixels(depth, step).copy(), centre_pixels(semantic, step).copy()


def test_centre_pixels_keep_the_middle_of_each_block():
    image = np.arange(64).reshape(8, 8)
    assert centre_pixels(image, 4).tolist() == [[18, 22], [50, 54]]
    assert centre_pixels(image, 1) is not image and np.array_equal(centre_pixels(image, 1), image)


def test_a_frame_of_arrays_serves_strides_and_counts_from_them():
    rgb, depth, semantic = arrays()
    frame = CameraFrame.of(rgb, depth, semantic)
    assert frame.shape == (8, 12) and frame.rgb is rgb and frame.depth is depth and frame.semantic is semantic
    d, s = frame.strided(2)
    assert np.array_equal(d, depth[1::2, 1::2]) and np.array_equal(s, semantic[1::2, 1::2])
    assert frame.strided(1) == (depth, semantic)
    for label in range(5):
        assert frame.count(label) == int(np.count_nonzero((semantic == label) & (depth > 0)))
    assert frame.take_render_seconds() == 0.0  # nothing was made


def test_mismatched_arrays_and_bad_strides_are_refused():
    rgb, depth, semantic = arrays()
    with pytest.raises(L3MVNError, match="disagree in size"):
        CameraFrame.of(rgb, depth, semantic[:, :-1])
    with pytest.raises(L3MVNError, match="stride must be >= 1"):
        CameraFrame.of(rgb, depth, semantic).strided(0)


def test_a_lazy_frame_makes_each_image_once_and_only_when_read():
    frame = Counting(strided_alone=True)
    frame.strided(4)
    frame.strided(4)
    assert frame.made == ["strided 4"]
    assert frame.rgb.shape == (8, 12, 3)
    assert frame.made == ["strided 4", "rgb"]  # the subclass's colours need no depth here
    assert frame.depth.shape == frame.semantic.shape == (8, 12)
    assert frame.made == ["strided 4", "rgb", "full"]
    frame.strided(2)  # cut from the whole frame now that it exists
    assert frame.made == ["strided 4", "rgb", "full"]
    assert frame.take_render_seconds() > 0.0 and frame.take_render_seconds() == 0.0


def test_a_frame_that_cannot_make_strides_alone_cuts_them_from_the_whole():
    frame = Counting(strided_alone=False)
    d, _ = frame.strided(3)
    assert frame.made == ["full"] and np.array_equal(d, centre_pixels(arrays()[1], 3))
    _, depth, semantic = arrays()
    assert frame.count(2) == int(np.count_nonzero((semantic == 2) & (depth > 0)))  # counted in the whole frame
    assert frame.made == ["full"]

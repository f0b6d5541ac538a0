"""Depth image + pose -> world point cloud, with the pinhole camera every backend renders with.

Camera frame (shared with the renderer): the camera sits at ``(x, y, camera_height)``; its optical
axis points along the heading on the floor plane, pitched by ``tilt`` (radians, positive looks up);
image rows grow downwards and columns to the right; depth is z-depth along the optical axis in metres
and 0 where invalid. Square pixels, focal length from the horizontal field of view, pixel centres at
``(col + 0.5, row + 0.5)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import overload

import numpy as np

from l3mvn.core.config import SimConfig
from l3mvn.core.errors import L3MVNError
from l3mvn.core.frames import centre_pixels
from l3mvn.core.types import Pose


@dataclass(frozen=True)
class CameraIntrinsics:
    """A pinhole depth camera: image size in pixels, horizontal FOV in degrees, height in metres."""

    height: int
    width: int
    hfov_deg: float
    camera_height_m: float

    def __post_init__(self) -> None:
        if self.height <= 0 or self.width <= 0:
            raise L3MVNError(f"camera image size must be positive, got {self.height}x{self.width}")
        if not 0 < self.hfov_deg < 180:
            raise L3MVNError(f"hfov_deg must lie in (0, 180), got {self.hfov_deg}")
        if not (math.isfinite(self.camera_height_m) and self.camera_height_m > 0):
            raise L3MVNError(f"camera_height_m must be positive, got {self.camera_height_m}")

    @classmethod
    def from_sim(cls, cfg: SimConfig, height: int, width: int) -> CameraIntrinsics:
        """The task camera at the resolution the mapper is fed (e.g. 120x160 after downsampling)."""
        return cls(height=height, width=width, hfov_deg=cfg.hfov_deg, camera_height_m=cfg.camera_height_m)

    @property
    def focal_px(self) -> float:
        return (self.width / 2.0) / math.tan(math.radians(self.hfov_deg) / 2.0)


@dataclass(frozen=True)
class PointCloud:
    """Valid depth pixels in the world frame: ``points`` (N, 3) float32 metres (x, y, z up, z = 0
    on the floor); ``labels`` (N,) int32 semantic ids (0 = background, k = categories[k - 1])."""

    points: np.ndarray
    labels: np.ndarray

    def __len__(self) -> int:
        return len(self.points)


def depth_to_points(
    depth: np.ndarray,
    intrinsics: CameraIntrinsics,
    pose: Pose,
    tilt: float,
    semantic: np.ndarray | None = None,
    max_depth_m: float = math.inf,
) -> PointCloud:
    """Back-project every valid depth pixel (finite, > 0 and < ``max_depth_m``) to the world frame.

    Readings at or beyond ``max_depth_m`` are dropped: sensors report saturation there, not a surface.
    Without ``semantic`` every label is 0.
    """
    _check_frame(depth, semantic, intrinsics)
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(depth) & (depth > 0) & (depth < max_depth_m)
    points = _back_project(depth[valid].astype(np.float32, copy=False), valid, intrinsics, pose, tilt)
    if semantic is None:
        labels = np.zeros(len(points), dtype=np.int32)
    else:
        labels = semantic[valid].astype(np.int32, copy=False)
    return PointCloud(points=points, labels=labels)


def too_near_points(
    depth: np.ndarray, intrinsics: CameraIntrinsics, pose: Pose, tilt: float, min_depth_m: float, max_depth_m: float
) -> np.ndarray:
    """(N, 3) points at ``min_depth_m`` along every invalid ray that must have met something nearer.

    A sensor reads 0 both below its minimum range and beyond its maximum, but a downward ray that
    would meet the floor within range cannot have seen nothing: the floor is there, so something
    nearer than ``min_depth_m`` stopped it. Dropped with the rest, such readings would hide every wall
    within 0.5 m that the agent had not mapped from farther (turned towards it, come round a corner),
    and it would walk into it. The point is placed at the farthest the obstacle can be, so it
    never lies in front of it; the floor in between stays as it was, unknown or seen.
    """
    _check_frame(depth, None, intrinsics)
    _, _, rise_per_m = ray_factors(intrinsics, tilt)
    with np.errstate(divide="ignore"):
        floor_depth = np.where(rise_per_m < 0, intrinsics.camera_height_m / -rise_per_m, np.inf)
    floor_in_range = (floor_depth >= min_depth_m) & (floor_depth < max_depth_m)
    if not floor_in_range.any():
        return np.empty((0, 3), dtype=np.float32)
    with np.errstate(invalid="ignore"):
        invalid = ~(np.isfinite(depth) & (depth > 0)) & floor_in_range[:, None]
    return _back_project(np.full(int(invalid.sum()), min_depth_m, np.float32), invalid, intrinsics, pose, tilt)


def ray_factors(intrinsics: CameraIntrinsics, tilt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per column: rightward offset per metre of depth; per row: forward reach and height gain per
    metre of depth once pitched by ``tilt``."""
    f = intrinsics.focal_px
    # Image-plane offsets of pixel centres, in units of depth: right and up.
    right = (np.arange(intrinsics.width, dtype=np.float32) + 0.5 - intrinsics.width / 2.0) / f
    up = (intrinsics.height / 2.0 - 0.5 - np.arange(intrinsics.height, dtype=np.float32)) / f
    ct, st = math.cos(tilt), math.sin(tilt)
    return right, (ct - up * st).astype(np.float32), (st + up * ct).astype(np.float32)


def _back_project(d: np.ndarray, mask: np.ndarray, intrinsics: CameraIntrinsics, pose: Pose, tilt: float) -> np.ndarray:
    """World points of the pixels in ``mask`` (row-major order) at depths ``d``."""
    right, forward_per_m, rise_per_m = ray_factors(intrinsics, tilt)
    # Boolean selection of broadcast row/column factors: cheaper than gathering by pixel index.
    ahead = d * np.broadcast_to(forward_per_m[:, None], mask.shape)[mask]
    rightward = d * np.broadcast_to(right[None, :], mask.shape)[mask]
    ch, sh = math.cos(pose.heading), math.sin(pose.heading)
    points = np.empty((len(d), 3), dtype=np.float32)
    # Right of a heading h (counter-clockwise from +x) is (sin h, -cos h).
    points[:, 0] = pose.x + ahead * ch + rightward * sh
    points[:, 1] = pose.y + ahead * sh - rightward * ch
    points[:, 2] = intrinsics.camera_height_m + d * np.broadcast_to(rise_per_m[:, None], mask.shape)[mask]
    return points


@overload
def downsample_frame(depth: np.ndarray, semantic: np.ndarray, factor: int) -> tuple[np.ndarray, np.ndarray]: ...


@overload
def downsample_frame(depth: np.ndarray, semantic: None, factor: int) -> tuple[np.ndarray, None]: ...


def downsample_frame(
    depth: np.ndarray, semantic: np.ndarray | None, factor: int
) -> tuple[np.ndarray, np.ndarray | None]:
    """Keep the centre pixel of every ``factor`` x ``factor`` block, as SemExp does (480x640 -> 120x160
    with 4): striding never mixes depths across an edge or averages label ids."""
    if factor < 1:
        raise L3MVNError(f"downsample factor must be >= 1, got {factor}")
    h, w = depth.shape[:2]
    if h % factor or w % factor:
        raise L3MVNError(f"frame {h}x{w} is not divisible by the downsample factor {factor}")
    return centre_pixels(depth, factor), None if semantic is None else centre_pixels(semantic, factor)


def _check_frame(depth: np.ndarray, semantic: np.ndarray | None, intrinsics: CameraIntrinsics) -> None:
    expected = (intrinsics.height, intrinsics.width)
    if depth.ndim != 2 or depth.shape != expected:
        raise L3MVNError(
            f"depth image has shape {depth.shape}, the camera intrinsics expect {expected}; "
            "build CameraIntrinsics for the fed resolution or use downsample_frame"
        )
    if not np.issubdtype(depth.dtype, np.floating):
        raise L3MVNError(f"depth must be float metres, got dtype {depth.dtype}")
    if semantic is not None:
        if semantic.shape != expected:
            raise L3MVNError(f"semantic image has shape {semantic.shape}, expected {expected} like depth")
        if not np.issubdtype(semantic.dtype, np.integer):
            raise L3MVNError(f"semantic must hold integer ids, got dtype {semantic.dtype}")

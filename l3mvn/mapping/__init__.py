"""Semantic mapping: depth + semantic ids + pose -> top-down obstacle / explored / object grids."""

from l3mvn.mapping.projection import CameraIntrinsics, PointCloud, depth_to_points, downsample_frame
from l3mvn.mapping.semantic_map import LocalWindow, SemanticMap, SemanticMapper

__all__ = [
    "CameraIntrinsics",
    "LocalWindow",
    "PointCloud",
    "SemanticMap",
    "SemanticMapper",
    "depth_to_points",
    "downsample_frame",
]

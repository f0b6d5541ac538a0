"""Semantic mapping: depth + semantic ids + pose -> top-down obstacle / explored / object grids
(the camera model it projects with is ``l3mvn.core.camera``)."""

from l3mvn.agent.mapping.semantic_map import LocalWindow, SemanticMap, SemanticMapper

__all__ = ["LocalWindow", "SemanticMap", "SemanticMapper"]

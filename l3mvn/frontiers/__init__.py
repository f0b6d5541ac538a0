"""Frontier extraction and cost-utility scoring on plain map arrays."""

from l3mvn.frontiers.extract import extract_frontiers
from l3mvn.frontiers.types import EDGE_MODES, UTILITY_MODES, Frontier, FrontierConfig

__all__ = ["EDGE_MODES", "UTILITY_MODES", "Frontier", "FrontierConfig", "extract_frontiers"]

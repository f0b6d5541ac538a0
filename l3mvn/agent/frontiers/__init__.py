"""Frontier extraction and cost-utility scoring on plain map arrays."""

from l3mvn.agent.frontiers.extract import extract_frontiers
from l3mvn.agent.frontiers.types import Frontier, Fusion

__all__ = ["Frontier", "Fusion", "extract_frontiers"]

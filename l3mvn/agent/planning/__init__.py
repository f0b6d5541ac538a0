"""Local policy: Fast Marching on the agent's own map, short-term goals, collisions, stuck."""

from l3mvn.agent.planning.fmm import GeodesicField, Window, distance_field
from l3mvn.agent.planning.local_policy import LocalPlanner, Plan

__all__ = ["GeodesicField", "LocalPlanner", "Plan", "Window", "distance_field"]

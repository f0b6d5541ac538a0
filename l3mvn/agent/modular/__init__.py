"""The modular L3MVN agent: ``MapAgent`` runs the step; the target search and the exploration goals
each keep their own state in their own module."""

from l3mvn.agent.modular.map_agent import MapAgent

__all__ = ["MapAgent"]

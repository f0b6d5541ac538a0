"""The task: what counts as success and how an episode is scored, judged beside the simulator.

``regions`` (success regions and geodesic distances per rule), ``objectnav`` (the judge of one
floor), ``measures`` (per-step measures of an episode), ``scoring`` (Success, SPL, DTG, failure
cause) and ``failures`` (failures split into what the world allowed and what the agent did).
"""

from l3mvn.world.task.measures import EpisodeMeasures, target_visible
from l3mvn.world.task.objectnav import ObjectNavTask
from l3mvn.world.task.regions import GoalRegion, footprint_region, geodesic_field, goal_region
from l3mvn.world.task.scoring import FAILURE_CAUSES, EpisodeOutcome, EpisodeResult, score_episode

__all__ = [
    "FAILURE_CAUSES",
    "EpisodeMeasures",
    "EpisodeOutcome",
    "EpisodeResult",
    "GoalRegion",
    "ObjectNavTask",
    "footprint_region",
    "geodesic_field",
    "goal_region",
    "score_episode",
    "target_visible",
]

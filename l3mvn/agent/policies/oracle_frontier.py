"""The frontier oracle: a global policy that is told the true distance from any point to the goal.

Not a method but a ceiling: the map-based agent with the same frontiers and a perfect prior, which
bounds what any language prior choosing among frontiers can reach. It knows the world only through
the reader it is handed (``GoalDistances``; the run side wires in the world's ground-truth reader),
so the agent side still never imports the world.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial

import numpy as np

from l3mvn.agent.frontiers import Frontier
from l3mvn.agent.mapping import SemanticMap
from l3mvn.agent.policies.global_policies import Selection

# (goal, world xs, world ys) -> metres from each point to the goal (inf off the floor).
GoalDistances = Callable[[str, np.ndarray, np.ndarray], np.ndarray]
PointDistances = Callable[[np.ndarray, np.ndarray], np.ndarray]


def frontier_goal_distances(frontiers: list[Frontier], sem_map: SemanticMap, distances: PointDistances) -> np.ndarray:
    """The distance from each frontier (its nearest cell) to the goal, in metres: ``distances`` read at
    the world points of the frontier's cells; inf where none of them lies on the floor it knows."""
    return np.array(
        [distances(*sem_map.cell_to_world(f.cells[:, 0], f.cells[:, 1])).min() for f in frontiers], dtype=np.float64
    )


class FrontierOracle:
    """Global policy: the frontier that minimises (travel cost to it + true distance from it to the
    goal object). Same agent, same frontiers, perfect prior.

    The distance is to the object, not to its success region: under the SemExp rule that region
    reaches through walls, and ranking by it leads to the far side of a room's wall, where the agent
    can never see the object it must confirm before stopping."""

    name = "oracle-frontier"

    def __init__(self, distances: GoalDistances) -> None:
        self.distances = distances

    def select(
        self, frontiers: list[Frontier], sem_map: SemanticMap, goal: str, rng: np.random.Generator
    ) -> Selection | None:
        if not frontiers:
            return None
        cost = np.array([f.cost for f in frontiers], dtype=np.float64)
        to_goal = frontier_goal_distances(frontiers, sem_map, partial(self.distances, goal))
        if not np.isfinite(to_goal).any():
            # Frontier cells off the ground-truth floor everywhere (early, in a narrow spot): say so.
            i = int(np.argmin(cost))
            return Selection(
                i,
                frontiers[i].center,
                1.0 - cost / max(float(cost.max()), 1e-9),
                f"oracle: no frontier on the ground-truth floor, nearest one ({cost[i]:.1f} m)",
            )
        total = cost + to_goal
        i = int(np.argmin(total))
        finite = np.where(np.isfinite(total), total, total[np.isfinite(total)].max())
        scores = 1.0 - (finite - finite.min()) / max(float(np.ptp(finite)), 1e-9)
        return Selection(
            i,
            frontiers[i].center,
            scores,
            f"oracle: frontier {frontiers[i].id}, {cost[i]:.1f} m away, {to_goal[i]:.1f} m on to the "
            f"{goal} (ground truth)",
        )

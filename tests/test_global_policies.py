import numpy as np
import pytest

from l3mvn.agent.frontiers import Frontier
from l3mvn.agent.mapping import SemanticMap
from l3mvn.agent.policies.global_policies import CostUtility, NearestFrontier, RandomSample
from l3mvn.core.config import PolicyConfig
from l3mvn.core.errors import L3MVNError
from l3mvn.run.registry import check_options


def _map(explored: np.ndarray, obstacle: np.ndarray) -> SemanticMap:
    n = explored.shape[0]
    return SemanticMap(
        obstacle=obstacle,
        explored=explored,
        visited=np.zeros_like(explored),
        categories=np.zeros((0, n, n), bool),
        category_names=(),
        looked=explored,
        resolution_m=0.05,
        start_xy=(0.0, 0.0),
        agent_cell=(n // 2, n // 2),
        agent_heading=0.0,
        local_cells=n,
        footprint_radius_cells=3,
    )


def _frontier(i, distance, cost, s_cu):
    return Frontier(
        id=i, cells=np.array([[i, i]]), center=(i, i), size=10, distance_m=distance, utility=10.0, cost=cost, s_cu=s_cu
    )


def test_nearest_frontier_ranks_by_travel_cost_and_cost_utility_by_s_cu():
    frontiers = [_frontier(0, 2.0, 2.0, 0.2), _frontier(1, 1.5, 3.0, 0.9)]
    rng = np.random.default_rng(0)
    assert NearestFrontier().select(frontiers, None, "bed", rng).frontier == 0
    assert CostUtility().select(frontiers, None, "bed", rng).frontier == 1


def test_random_sample_draws_unexplored_free_cells_of_the_local_window():
    explored = np.zeros((40, 40), bool)
    explored[:, :30] = True
    obstacle = np.zeros_like(explored)
    obstacle[:, 35:] = True
    sem_map, rng = _map(explored, obstacle), np.random.default_rng(3)
    cells = [RandomSample(1).select([], sem_map, "bed", rng).cell for _ in range(50)]
    assert all(30 <= c < 35 for _, c in cells)


def test_random_sample_skips_unexplored_cells_the_map_walls_off_from_the_agent():
    # The agent's room (rows 5..34, cols 5..24) is mapped closed; beyond its walls lies unexplored space.
    explored = np.zeros((40, 40), bool)
    explored[5:35, 5:25] = True
    explored[18:22, 18:25] = False  # an unexplored alcove inside the room
    obstacle = np.zeros_like(explored)
    obstacle[4, 4:26] = obstacle[35, 4:26] = True
    obstacle[4:36, 4] = obstacle[4:36, 25] = True
    sem_map, rng = _map(explored, obstacle), np.random.default_rng(5)
    cells = {RandomSample(1).select([], sem_map, "bed", rng).cell for _ in range(50)}
    assert cells and all(18 <= r < 22 and 18 <= c < 25 for r, c in cells)


def test_random_sample_prefers_unknown_cells_next_to_explored_floor():
    # Explored floor in the west columns 0..9; unknown beyond. Cells more than 1.5 m (30 cells) from
    # the floor are drawn only once none nearer is left.
    explored = np.zeros((80, 80), bool)
    explored[:, :10] = True
    obstacle = np.zeros_like(explored)
    sem_map, rng = _map(explored, obstacle), np.random.default_rng(7)
    policy = RandomSample(1)
    cells = [policy.select([], sem_map, "bed", rng).cell for _ in range(100)]
    assert all(10 <= c <= 9 + policy.band_m / 0.05 for _, c in cells)
    assert max(c for _, c in cells) > 30  # the whole band is drawn, not only its edge


def test_random_sample_does_not_reach_through_gaps_in_a_mapped_wall():
    # The agent's room (columns 20..59) is mapped; its east wall (column 60) has one-cell gaps, as a
    # wall mapped from 120x160 frames does, too narrow for the planner's dilated map; the room opens
    # west onto unknown floor. Samples come from the west only.
    explored = np.zeros((80, 80), bool)
    explored[:, 20:60] = True
    obstacle = np.zeros_like(explored)
    obstacle[:, 60] = True
    obstacle[5::10, 60] = False
    sem_map, rng = _map(explored, obstacle), np.random.default_rng(11)
    cells = [RandomSample(1).select([], sem_map, "bed", rng).cell for _ in range(100)]
    assert all(c < 20 for _, c in cells)
    # Without dilation the gaps are passages, and the unknown behind the wall is drawn too.
    undilated = [RandomSample(0).select([], sem_map, "bed", rng).cell for _ in range(100)]
    assert any(c > 60 for _, c in undilated)


def test_random_sample_draws_next_to_an_agent_standing_by_a_wall():
    # The agent (cell 20, 20) stands beside a wall (column 21) that closes its room; west of it the
    # floor goes on (unknown columns 0..4), east of the wall lies unknown space it cannot reach.
    # Dilation must not swallow the agent's own cell, or the walled-off east counts as reachable.
    explored = np.zeros((40, 40), bool)
    explored[:, 5:30] = True
    obstacle = np.zeros_like(explored)
    obstacle[:, 21] = True
    sem_map, rng = _map(explored, obstacle), np.random.default_rng(13)
    cells = [RandomSample(1).select([], sem_map, "bed", rng).cell for _ in range(50)]
    assert all(c < 5 for _, c in cells)


def test_options_a_policy_would_ignore_are_refused():
    with pytest.raises(L3MVNError, match="apply to language policies only"):
        check_options("frontier", PolicyConfig(scorer="roomtype"))
    with pytest.raises(L3MVNError, match="does not read the semantic frames"):
        check_options("oracle", PolicyConfig(seg_noise=0.1))
    check_options("exp+llm", PolicyConfig(selection="official_code"))

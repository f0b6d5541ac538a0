"""Frontier extraction and cost-utility scoring, specified on small hand-made maps.

Maps use 5 cm cells. A "room" is an explored rectangle whose border cells are walls; an "opening"
removes wall cells, so the explored edge there borders unknown space. With the default 1-cell obstacle
dilation an opening of g cells yields a frontier of g - 2 cells (the cells touching the wall ends go).
Distances are straight-line fields: extraction only reads the planner's field, it never computes one.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from l3mvn.agent.frontiers import Frontier, extract_frontiers
from l3mvn.core.config import FrontierConfig
from l3mvn.core.errors import L3MVNError

RES = 0.05


def room(shape: tuple[int, int], top: int, left: int, bottom: int, right: int) -> tuple[np.ndarray, ...]:
    """Explored rows top..bottom x cols left..right (inclusive), walls on the rectangle's border."""
    explored = np.zeros(shape, dtype=bool)
    explored[top : bottom + 1, left : right + 1] = True
    obstacle = np.zeros(shape, dtype=bool)
    obstacle[top, left : right + 1] = obstacle[bottom, left : right + 1] = True
    obstacle[top : bottom + 1, left] = obstacle[top : bottom + 1, right] = True
    return explored, obstacle


def straight_line(shape: tuple[int, int], agent: tuple[int, int]) -> np.ndarray:
    rows, cols = np.indices(shape)
    return (np.hypot(rows - agent[0], cols - agent[1]) * RES).astype(np.float32)


def extract(
    explored: np.ndarray,
    obstacle: np.ndarray,
    agent: tuple[int, int],
    cfg: FrontierConfig = FrontierConfig(),
    distance: np.ndarray | None = None,
    categories: dict[str, np.ndarray] | None = None,
) -> list[Frontier]:
    shape = explored.shape
    categories = categories or {}
    maps = np.stack(list(categories.values())) if categories else np.zeros((0, *shape), dtype=bool)
    distance = straight_line(shape, agent) if distance is None else distance
    return extract_frontiers(explored, obstacle, agent, distance, maps, tuple(categories), cfg, resolution_m=RES)


def corridor_open_at_right() -> tuple[np.ndarray, np.ndarray, tuple[int, int]]:
    """Rows 20..30, cols 10..60; walls on top, bottom and left; the right end (col 60) is open."""
    explored, obstacle = room((60, 80), 20, 10, 30, 60)
    obstacle[21:30, 60] = False
    return explored, obstacle, (25, 15)


def two_door_room() -> tuple[np.ndarray, np.ndarray, tuple[int, int]]:
    """Rows 10..50, cols 10..90; 11-cell doors in the left (near the agent) and right walls."""
    explored, obstacle = room((60, 100), 10, 10, 50, 90)
    obstacle[25:36, 10] = False
    obstacle[25:36, 90] = False
    return explored, obstacle, (30, 30)


def five_door_hall(widths: dict[int, int]) -> tuple[np.ndarray, np.ndarray, tuple[int, int]]:
    """Rows 10..40, cols 5..120 with doors in the top wall: {centre column: door width}."""
    explored, obstacle = room((50, 130), 10, 5, 40, 120)
    for col, width in widths.items():
        obstacle[10, col - width // 2 : col - width // 2 + width] = False
    return explored, obstacle, (25, 10)


def test_corridor_with_one_open_end_has_exactly_one_frontier_at_that_end():
    explored, obstacle, agent = corridor_open_at_right()
    frontiers = extract(explored, obstacle, agent)
    assert len(frontiers) == 1
    f = frontiers[0]
    assert f.id == 0
    assert f.center == (25, 60)
    assert f.size == 7 and set(map(tuple, f.cells)) == {(r, 60) for r in range(22, 29)}
    assert f.cells.dtype == np.int32 and f.cells.shape == (7, 2)
    assert f.distance_m == pytest.approx(45 * RES, abs=RES)


def test_first_connected_component_is_not_skipped():
    # The authors' code looped over regionprops from index 1, losing the first cluster found.
    explored, obstacle, agent = corridor_open_at_right()
    assert len(extract(explored, obstacle, agent)) == 1
    explored, obstacle, agent = two_door_room()
    frontiers = extract(explored, obstacle, agent)
    assert sorted(f.center[1] for f in frontiers) == [10, 90]


def test_frontier_clusters_smaller_than_min_size_are_dropped():
    explored, obstacle, agent = corridor_open_at_right()
    obstacle[21:30, 60] = True
    obstacle[23:29, 60] = False  # a 6-cell gap leaves a 4-cell frontier
    assert extract(explored, obstacle, agent) == []
    kept = extract(explored, obstacle, agent, FrontierConfig(min_cluster_cells=4))
    assert [f.size for f in kept] == [4]


def test_frontier_cells_next_to_dilated_obstacles_are_removed():
    explored, obstacle, agent = corridor_open_at_right()
    wall = np.argwhere(obstacle)
    for cells, expected in ((0, 9), (1, 7), (2, 5)):
        frontiers = extract(explored, obstacle, agent, FrontierConfig(obstacle_dilation_cells=cells))
        assert [f.size for f in frontiers] == [expected]
        gap = np.abs(frontiers[0].cells[:, None, :] - wall[None, :, :]).max(axis=2).min()
        assert gap > cells


def test_walls_of_a_closed_room_are_not_frontiers():
    explored, obstacle = room((40, 40), 5, 5, 30, 30)
    assert extract(explored, obstacle, (15, 15)) == []


def test_two_openings_give_two_clusters_and_the_nearer_has_the_smaller_distance():
    explored, obstacle, agent = two_door_room()
    frontiers = extract(explored, obstacle, agent)
    assert len(frontiers) == 2
    by_side = {f.center[1]: f for f in frontiers}
    assert by_side[10].distance_m < by_side[90].distance_m
    # A cell's distance is the smallest in its 3x3 neighbourhood: one cell less than the door's own.
    assert by_side[10].distance_m == pytest.approx(19 * RES)
    assert by_side[90].distance_m == pytest.approx(59 * RES)
    assert [f.id for f in frontiers] == [0, 1]


def test_frontiers_nearer_than_min_distance_are_dropped():
    explored, obstacle, _ = two_door_room()
    frontiers = extract(explored, obstacle, (30, 15))  # 0.25 m from the left door
    assert [f.center[1] for f in frontiers] == [90]


def test_frontiers_beyond_max_distance_are_dropped_while_a_near_one_exists():
    explored, obstacle, agent = two_door_room()
    frontiers = extract(explored, obstacle, agent, FrontierConfig(max_distance_m=2.0))
    assert [f.center[1] for f in frontiers] == [10]


def test_far_frontiers_are_kept_when_none_lies_within_max_distance():
    # Otherwise an agent in a big open area would have nowhere to go.
    explored, obstacle, agent = two_door_room()
    frontiers = extract(explored, obstacle, agent, FrontierConfig(max_distance_m=0.8))
    assert sorted(f.center[1] for f in frontiers) == [10, 90]


def test_blocked_frontiers_are_dropped_before_the_far_limit_so_far_ones_return():
    # The near door was reached and blocked: the far one must come back even though it lies
    # beyond max_distance_m (the limit only applies while an eligible frontier lies within it).
    explored, obstacle, agent = two_door_room()
    (near,) = extract(explored, obstacle, agent, FrontierConfig(max_distance_m=2.0))
    maps = np.zeros((0, *explored.shape), dtype=bool)
    distance = straight_line(explored.shape, agent)
    frontiers = extract_frontiers(
        explored,
        obstacle,
        agent,
        distance,
        maps,
        (),
        FrontierConfig(max_distance_m=2.0),
        blocked=np.array([near.center]),
        blocked_radius_cells=20,
        resolution_m=RES,
    )
    assert [f.center[1] for f in frontiers] == [90]
    with pytest.raises(L3MVNError, match="blocked"):
        extract_frontiers(explored, obstacle, agent, distance, maps, (), blocked=np.array([1, 2, 3]), resolution_m=RES)


def test_a_done_frontier_blocks_what_is_left_of_itself_not_another_opening_beside_it():
    # Two doors 0.75 m apart in one wall: the agent went to the left one and is done with it. The
    # right one lies within the done goal's 1 m radius, but it borders other unknown space.
    explored, obstacle, agent = five_door_hall({30: 9, 45: 9})
    maps = np.zeros((0, *explored.shape), dtype=bool)
    distance = straight_line(explored.shape, agent)
    left = next(f for f in extract(explored, obstacle, agent) if f.center[1] == 30)

    def centres(own, door_width=9):
        hall, walls, _ = five_door_hall({30: door_width, 45: 9})
        frontiers = extract_frontiers(
            hall,
            walls,
            agent,
            distance,
            maps,
            (),
            blocked=np.array([left.center]),
            blocked_radius_cells=20,
            blocked_frontiers=[own],
            blocked_gap_cells=5,
            resolution_m=RES,
        )
        return sorted(f.center[1] for f in frontiers)

    assert centres(None) == []  # a done goal that was no frontier: the whole radius, as before
    assert centres(left.cells) == [45]  # the door beside it stays
    assert centres(left.cells, door_width=7) == [45]  # what is left of the done door is still done
    with pytest.raises(L3MVNError, match="one entry per blocked cell"):
        extract_frontiers(
            explored,
            obstacle,
            agent,
            distance,
            maps,
            (),
            blocked=np.array([left.center]),
            blocked_radius_cells=20,
            blocked_frontiers=[None, None],
            resolution_m=RES,
        )


def test_each_blocked_cell_can_have_its_own_radius():
    explored, obstacle, agent = two_door_room()
    maps = np.zeros((0, *explored.shape), dtype=bool)
    distance = straight_line(explored.shape, agent)
    near = extract(explored, obstacle, agent)[0].center  # the left door, at column 10
    beside = np.array([[near[0] + 8, near[1]]])  # a done goal 8 cells along the door

    def centres(radii):
        return [
            f.center[1]
            for f in extract_frontiers(
                explored,
                obstacle,
                agent,
                distance,
                maps,
                (),
                blocked=beside,
                blocked_radius_cells=radii,
                resolution_m=RES,
            )
        ]

    assert centres(np.array([10.0])) == [90]  # the door lies within 10 cells: dropped
    assert centres(np.array([5.0])) == [10, 90]  # within a 5-cell radius only the done spot: kept
    with pytest.raises(L3MVNError, match="one radius per blocked cell"):
        centres(np.array([5.0, 5.0]))


@pytest.mark.parametrize("unreachable", [np.inf, np.nan])
def test_frontier_cells_marked_unreachable_take_the_distance_of_a_reachable_neighbour(unreachable):
    explored, obstacle, agent = corridor_open_at_right()
    distance = straight_line(explored.shape, agent)
    distance[:, 60:] = unreachable  # the planner blocked the frontier column itself
    (f,) = extract(explored, obstacle, agent, distance=distance)
    assert f.distance_m == pytest.approx(float(distance[25, 59]))


def test_frontiers_with_no_reachable_neighbour_are_dropped():
    explored, obstacle, agent = two_door_room()
    distance = straight_line(explored.shape, agent)
    distance[:, 85:] = np.inf
    assert [f.center[1] for f in extract(explored, obstacle, agent, distance=distance)] == [10]


def test_cluster_center_is_a_cell_of_the_cluster_even_when_the_centroid_is_not():
    # Open on the right and at the bottom: one L-shaped frontier whose centroid lies inside the room.
    explored, obstacle = room((50, 50), 10, 10, 40, 40)
    obstacle[11:, 40] = False
    obstacle[40, 11:] = False
    (f,) = extract(explored, obstacle, (15, 15))
    cells = set(map(tuple, f.cells))
    centroid = f.cells.mean(axis=0)
    assert tuple(np.round(centroid).astype(int)) not in cells
    assert f.center in cells
    gap = np.hypot(*(f.cells - centroid).T)
    assert np.hypot(*(np.array(f.center) - centroid)) == pytest.approx(gap.min())


DOORS = {20: 7, 40: 8, 60: 9, 80: 14, 100: 12}  # frontier sizes 5, 6, 7, 12, 10 (unique: they name doors)


def test_s_cu_is_normalised_to_unit_range_and_orders_by_utility_minus_lambda_cost():
    explored, obstacle, agent = five_door_hall(DOORS)
    cfg = FrontierConfig(cu_lambda=3.0)
    frontiers = extract(explored, obstacle, agent, cfg)
    assert sorted(f.size for f in frontiers) == [5, 6, 7, 10, 12]
    raw = np.array([f.size - cfg.cu_lambda * f.distance_m for f in frontiers])
    s_cu = np.array([f.s_cu for f in frontiers])
    assert np.all(np.diff(raw) <= 0), "frontiers come best S_CU first"
    assert s_cu.min() == 0.0 and s_cu.max() == 1.0
    np.testing.assert_allclose(s_cu, (raw - raw.min()) / (raw.max() - raw.min()), atol=1e-12)
    assert all(f.utility == f.size and f.cost == f.distance_m for f in frontiers)


def test_lambda_trades_cluster_size_against_distance():
    explored, obstacle, agent = five_door_hall(DOORS)
    biggest = extract(explored, obstacle, agent, FrontierConfig(cu_lambda=0.0))[0]
    nearest = extract(explored, obstacle, agent, FrontierConfig(cu_lambda=1000.0))[0]
    assert biggest.size == 12 and nearest.size == 5


def test_single_frontier_gets_s_cu_one():
    explored, obstacle, agent = corridor_open_at_right()
    assert [f.s_cu for f in extract(explored, obstacle, agent)] == [1.0]


def test_official_code_utility_adds_8_within_3_m_ignores_cost_and_keeps_top_4():
    explored, obstacle, agent = five_door_hall(DOORS)
    cfg = FrontierConfig.official_code()
    assert cfg.utility == "official_code" and cfg.top_k == 4
    frontiers = extract(explored, obstacle, agent, cfg)
    # The 7-cell door at ~2.6 m scores 15 and beats the 12-cell door at ~3.6 m (12, no bonus); the
    # 10-cell door at ~4.5 m (10) is the fifth and goes.
    assert [f.size for f in frontiers] == [7, 6, 5, 12]
    assert [f.utility for f in frontiers] == [15.0, 14.0, 13.0, 12.0]
    assert all((f.utility - f.size == 8.0) == (f.distance_m < 3.0) for f in frontiers)
    assert [f.s_cu for f in frontiers] == pytest.approx([1.0, 2 / 3, 1 / 3, 0.0])


def test_top_k_keeps_the_best_frontiers_in_paper_mode_too():
    explored, obstacle, agent = five_door_hall(DOORS)
    frontiers = extract(explored, obstacle, agent, FrontierConfig(cu_lambda=0.0, top_k=2))
    assert [f.size for f in frontiers] == [12, 10] and [f.id for f in frontiers] == [0, 1]


def test_objects_inside_the_window_are_listed_sorted_and_those_outside_are_not():
    explored, obstacle, agent = two_door_room()  # left frontier centre (30, 10)
    shape = explored.shape
    categories = {name: np.zeros(shape, dtype=bool) for name in ("sink", "chair", "bed", "tv")}
    categories["chair"][30, 30] = True  # 20 cells right of the left centre: inside a 1 m window
    categories["bed"][50, 25] = True  # 20 rows down, 15 cols right: inside (square, not round)
    categories["sink"][30, 31] = True  # 21 cells: just outside
    categories["tv"][35, 89] = True  # next to the right door only
    cfg = FrontierConfig(window_m=1.0)
    by_side = {f.center[1]: f for f in extract(explored, obstacle, agent, cfg, categories=categories)}
    assert by_side[10].objects == ("bed", "chair")
    assert by_side[90].objects == ("tv",)


def test_largest_edge_ignores_a_disconnected_explored_blob_and_all_keeps_it():
    explored, obstacle, agent = corridor_open_at_right()
    explored[40:50, 20:30] = True  # a small blob seen elsewhere, open on every side
    largest = extract(explored, obstacle, agent)
    both = extract(explored, obstacle, agent, FrontierConfig(edge="all"))
    assert [f.center for f in largest] == [(25, 60)]
    assert len(both) == 2 and (25, 60) in [f.center for f in both]


def test_explored_space_reaching_the_map_border_is_not_a_frontier():
    explored, obstacle = room((40, 61), 20, 10, 30, 60)
    obstacle[21:30, 60] = False  # the open end lies on the last column of the map
    assert extract(explored, obstacle, (25, 15)) == []


def test_nothing_explored_gives_no_frontier():
    shape = (30, 30)
    assert extract(np.zeros(shape, bool), np.zeros(shape, bool), (15, 15)) == []


def test_to_dict_is_json_ready_and_summarises_cells():
    explored, obstacle, agent = corridor_open_at_right()
    (f,) = extract(explored, obstacle, agent)
    f.llm_scores["bed"] = np.float32(0.25)
    summary = json.loads(json.dumps(f.to_dict()))
    assert "cells" not in summary
    assert summary["bbox"] == [22, 60, 28, 60] and summary["center"] == [25, 60] and summary["size"] == 7
    assert summary["s_llm"] is None and summary["llm_scores"] == {"bed": 0.25}
    assert len(json.loads(json.dumps(f.to_dict(cells=True)))["cells"]) == 7


@pytest.mark.parametrize(
    "change, message",
    [
        ({"utility": "greedy"}, "unknown frontier utility"),
        ({"edge": "biggest"}, "unknown frontier edge"),
        ({"min_distance_m": 6.0}, "min_distance_m < max_distance_m"),
        ({"top_k": 0}, "top_k"),
        ({"cu_lambda": -1.0}, "cu_lambda"),
        ({"window_m": -1.0}, "window_m"),
    ],
)
def test_bad_config_values_raise_a_clear_error(change, message):
    with pytest.raises(L3MVNError, match=message):
        FrontierConfig(**change)


def test_bad_inputs_raise_a_clear_error():
    explored, obstacle, agent = corridor_open_at_right()
    distance = straight_line(explored.shape, agent)
    none = np.zeros((0, *explored.shape), dtype=bool)
    with pytest.raises(L3MVNError, match="explored must be a 2-D bool array"):
        extract_frontiers(explored.astype(np.float32), obstacle, agent, distance, none, (), resolution_m=RES)
    with pytest.raises(L3MVNError, match="does not match"):
        extract_frontiers(explored, obstacle[:-1], agent, distance, none, (), resolution_m=RES)
    with pytest.raises(L3MVNError, match="distance_m must be a float array"):
        extract_frontiers(explored, obstacle, agent, distance[:, :-1], none, (), resolution_m=RES)
    with pytest.raises(L3MVNError, match="1 category names for 0"):
        extract_frontiers(explored, obstacle, agent, distance, none, ("bed",), resolution_m=RES)
    with pytest.raises(L3MVNError, match="outside"):
        extract_frontiers(explored, obstacle, (60, 0), distance, none, (), resolution_m=RES)
    with pytest.raises(L3MVNError, match="at the agent cell"):
        extract_frontiers(explored, obstacle, agent, straight_line(explored.shape, (0, 0)), none, (), resolution_m=RES)


def test_turn_cost_makes_the_frontier_ahead_cheaper_than_an_equally_near_one_behind():
    explored, obstacle, _ = two_door_room()
    agent = (30, 50)  # halfway between the two doors: both frontiers 40 cells away
    plain = extract(explored, obstacle, agent)
    assert plain[0].cost == pytest.approx(plain[1].cost)
    cfg = FrontierConfig(turn_cost_m_per_rad=0.5)
    shape = explored.shape
    facing_right = extract_frontiers(
        explored,
        obstacle,
        agent,
        straight_line(shape, agent),
        np.zeros((0, *shape), bool),
        (),
        cfg,
        agent_heading=0.0,
        resolution_m=RES,
    )
    by_side = {f.center[1]: f for f in facing_right}
    assert by_side[90].cost == pytest.approx(by_side[90].distance_m)
    assert by_side[10].cost == pytest.approx(by_side[10].distance_m + 0.5 * np.pi, abs=0.05)
    assert facing_right[0].center[1] == 90

"""Specifications of the local policy (Fast Marching on the agent's map) on hand-made maps."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage

from l3mvn.agent.planning import GeodesicField, LocalPlanner, Window, distance_field
from l3mvn.agent.planning.steering import Steering
from l3mvn.core.config import PlannerConfig, SimConfig
from l3mvn.core.errors import L3MVNError
from l3mvn.core.types import Action

RES = 0.05
SIM = SimConfig()


def _planner() -> LocalPlanner:
    """SemExp's planner: obstacles grown by disk(3), on 5 cm cells."""
    return LocalPlanner.for_sim(PlannerConfig(obstacle_dilation_cells=3), RES, SIM)


def _room(size: int = 120) -> np.ndarray:
    """An empty square room: a one-cell wall all around."""
    obstacle = np.zeros((size, size), dtype=bool)
    obstacle[[0, -1], :] = True
    obstacle[:, [0, -1]] = True
    return obstacle


def _reference_field(
    planner: LocalPlanner, obstacle: np.ndarray, goal: tuple[int, int], agent: tuple[int, int]
) -> np.ndarray:
    """Whole-map FMM to the dilated goal, built independently of the planner's windows and cache:
    obstacles grown by the body's cells plus the clearance, or by the body's alone when the agent
    cannot reach the goal so, or only by a detour longer than ``clearance_detour_m``."""
    cfg = planner.cfg
    g = planner.goal_dilation_cells
    goal_mask = np.zeros_like(obstacle)
    goal_mask[goal] = True
    sources = ndimage.binary_dilation(goal_mask, np.hypot(*np.mgrid[-g : g + 1, -g : g + 1]) <= g)
    fields = []
    for r in (cfg.obstacle_dilation_cells + cfg.clearance_cells, cfg.obstacle_dilation_cells):
        disk = np.hypot(*np.mgrid[-r : r + 1, -r : r + 1]) <= r
        trav = ~ndimage.binary_dilation(obstacle, disk)
        if planner.collision_map is not None:
            trav &= ~planner.collision_map
        fields.append(distance_field(trav, sources, resolution_m=planner.resolution_m))
    wide, narrow = fields
    return wide if np.isfinite(wide[agent]) and not narrow[agent] + cfg.clearance_detour_m < wide[agent] else narrow


def test_fmm_distance_through_a_door_equals_the_detour_length():
    trav = np.ones((100, 100), dtype=bool)
    trav[50, :] = False
    trav[50, 80] = True  # the door
    field = distance_field(trav, np.array([[20, 20]]), resolution_m=RES)
    detour = (math.hypot(50 - 20, 80 - 20) + math.hypot(80 - 50, 80 - 80)) * RES
    assert field[80, 80] == pytest.approx(detour, abs=RES)
    assert field[50, 79] == np.inf


def test_fmm_limit_stops_the_march_without_changing_nearer_distances():
    rng = np.random.default_rng(0)
    trav = rng.random((80, 80)) > 0.2
    trav[40, 40] = True
    full = distance_field(trav, np.array([[40, 40]]), resolution_m=RES)
    limited = distance_field(trav, np.array([[40, 40]]), resolution_m=RES, limit_m=1.0)
    near = full <= 1.0
    np.testing.assert_allclose(limited[near], full[near], atol=1e-6)
    assert np.isinf(limited[~near]).all()


def test_fmm_rejects_sources_outside_the_array():
    with pytest.raises(L3MVNError, match="inside"):
        distance_field(np.ones((5, 5), dtype=bool), np.array([[9, 0]]), resolution_m=RES)


def test_planned_distance_around_a_wall_matches_the_whole_map_field():
    obstacle = _room(200)
    obstacle[100, 20:180] = True
    planner = _planner()
    plan = planner.plan(obstacle, (50, 100), 0.0, (150, 100))
    reference = _reference_field(planner, obstacle, (150, 100), (50, 100))
    assert plan.reachable
    assert plan.distance_to_goal_m == pytest.approx(reference[50, 100] + 0.5, abs=1e-4)


@pytest.mark.parametrize("seed", range(6))
def test_windowed_field_equals_the_whole_map_field_on_random_maps(seed):
    rng = np.random.default_rng(seed)
    obstacle = _room(160)
    obstacle |= ndimage.binary_dilation(rng.random((160, 160)) < 0.004, iterations=3)
    free = np.argwhere(~ndimage.binary_dilation(obstacle, iterations=6))
    agent, goal = (tuple(int(v) for v in free[i]) for i in rng.choice(len(free), 2, replace=False))
    planner = _planner()
    plan = planner.plan(obstacle, agent, 0.0, goal)
    reference = _reference_field(planner, obstacle, goal, agent)
    window = plan.field.window
    local = reference[window.slices]
    values = plan.field.values
    both = np.isfinite(local) & np.isfinite(values)
    # A window only removes paths, so it never claims a shorter distance (up to the FMM stencil at
    # its edge, a few mm); around the agent (all the short-term goal looks at) it is exact, and with
    # every obstacle inside it (limit inf) exact everywhere.
    assert (values[both] >= local[both] - 0.1 * RES).all()
    rows, cols = np.nonzero(both)
    near = np.hypot(rows + window.r0 - agent[0], cols + window.c0 - agent[1]) <= 20
    np.testing.assert_allclose(values[rows[near], cols[near]], local[rows[near], cols[near]], atol=1e-4)
    assert plan.field.at(*agent) == pytest.approx(reference[agent], abs=1e-4)
    if plan.field.limit_m == math.inf:
        np.testing.assert_allclose(values[both], local[both], atol=1e-4)


@pytest.mark.parametrize("seed", range(3))
def test_distance_from_agent_equals_the_whole_map_field_within_its_limit(seed):
    rng = np.random.default_rng(10 + seed)
    obstacle = _room(160)
    obstacle |= ndimage.binary_dilation(rng.random((160, 160)) < 0.004, iterations=3)
    free = np.argwhere(~ndimage.binary_dilation(obstacle, iterations=6))
    agent = tuple(int(v) for v in free[rng.integers(len(free))])
    planner = _planner()
    near = planner.distance_from_agent(obstacle, agent, max_distance_m=2.0)
    everywhere = planner.distance_from_agent(obstacle, agent)
    full = everywhere.full()
    assert everywhere.window == Window.full(obstacle.shape)
    rows, cols = np.nonzero(np.isfinite(full) & (full <= 2.0))
    np.testing.assert_allclose(near.at(rows, cols), full[rows, cols], atol=1e-4)
    rows, cols = np.nonzero(full > 2.0)
    assert np.isinf(near.at(rows, cols)).all()


def test_distance_from_agent_covers_the_targets_beyond_the_obstacles():
    obstacle = np.zeros((300, 300), dtype=bool)
    obstacle[100:110, 100:110] = True
    explored = np.zeros_like(obstacle)
    explored[90:250, 90:120] = True  # explored open floor reaching far below the only obstacle
    planner = _planner()
    field = planner.distance_from_agent(obstacle, (95, 95), targets=explored)
    assert field.at(240, 110) == pytest.approx(math.hypot(145, 15) * RES, rel=0.02)
    assert field.at(299, 299) == np.inf  # outside the window: not computed


@pytest.mark.parametrize("seed", range(3))
def test_reused_field_gives_the_agent_the_same_distance_as_a_fresh_plan(seed):
    rng = np.random.default_rng(100 + seed)
    obstacle = _room(200)
    agent, goal = (20, 20), (180, 170)
    cached = _planner()
    reused = 0
    for _ in range(40):
        # New obstacles appear, some near the agent's path, most far from it.
        r, c = rng.integers(5, 195, size=2)
        obstacle[max(r - 2, 1) : r + 3, max(c - 2, 1) : c + 3] = True
        obstacle[agent[0] - 4 : agent[0] + 5, agent[1] - 4 : agent[1] + 5] = False
        plan = cached.plan(obstacle, agent, 0.0, goal)
        fresh = _planner().plan(obstacle, agent, 0.0, goal)
        reused += not plan.replanned
        assert plan.distance_to_goal_m == pytest.approx(fresh.distance_to_goal_m, abs=2 * RES)
        step = np.subtract(plan.short_term_goal, agent)
        agent = tuple(int(v) for v in np.add(agent, np.rint(step * 5 / max(np.hypot(*step), 1))))
    assert reused > 10


def test_short_term_goal_stays_on_the_free_side_of_a_wall():
    obstacle = _room(160)
    obstacle[80, :] = True
    obstacle[80, 130:140] = False  # a door far to the right
    planner = _planner()
    plan = planner.plan(obstacle, (72, 40), 0.0, (90, 40))
    assert plan.reachable
    assert plan.short_term_goal[0] < 80 - planner.cfg.obstacle_dilation_cells
    assert plan.short_term_goal[1] > 40  # toward the door
    assert plan.distance_to_goal_m > (140 - 40) * RES


@pytest.mark.parametrize(
    ("heading_deg", "goal", "expected"),
    [
        (0.0, (70, 30), Action.TURN_LEFT),  # goal behind, on the +row (left) side
        (0.0, (50, 30), Action.TURN_RIGHT),  # goal behind, on the -row (right) side
        (90.0, (60, 20), Action.TURN_LEFT),  # facing +row; goal toward -col is to the left
        (90.0, (60, 100), Action.TURN_RIGHT),
        (0.0, (60 + 7, 100), Action.MOVE_FORWARD),  # 10 deg off: within the threshold
        (0.0, (60 + 15, 100), Action.TURN_LEFT),  # 20 deg off
        (0.0, (60 - 15, 100), Action.TURN_RIGHT),
        (350.0, (60, 100), Action.MOVE_FORWARD),
    ],
)
def test_action_turns_toward_the_goal_and_goes_forward_when_aligned(heading_deg, goal, expected):
    plan = _planner().plan(_room(), (60, 60), math.radians(heading_deg), goal)
    assert plan.action == expected


def test_a_goal_that_moves_with_the_heading_does_not_turn_the_agent_back_and_forth():
    """A sighting's bearing that shifts with the view (here 96 degrees seen at heading 77 and 90 degrees
    at 107) must not make each heading turn to the other for ever."""
    planner = _planner()
    heading, actions = 77.0, []
    for _ in range(4):
        goal = (80, 58) if heading < 92 else (80, 60)
        action = planner.plan(_room(), (60, 60), math.radians(heading), goal).action
        actions.append(action)
        if action == Action.MOVE_FORWARD:
            break
        heading += 30 if action == Action.TURN_LEFT else -30
    assert actions == [Action.TURN_LEFT, Action.MOVE_FORWARD]


def test_a_goal_far_to_the_other_side_still_turns_the_agent_back():
    planner = _planner()
    assert planner.plan(_room(), (60, 60), 0.0, (75, 100)).action == Action.TURN_LEFT
    assert planner.plan(_room(), (60, 60), math.radians(30), (40, 60)).action == Action.TURN_RIGHT
    planner.reset()  # a new episode forgets the last turn
    first = planner.plan(_room(), (60, 60), math.radians(77), (80, 58)).action
    assert first == Action.TURN_LEFT
    planner.reset()
    assert planner.plan(_room(), (60, 60), math.radians(107), (80, 60)).action == Action.TURN_RIGHT


@pytest.mark.parametrize("goal", [(60, 67), (60, 71), (50, 60)])
def test_short_term_goal_inside_the_dilated_goal_heads_for_the_goal_itself(goal):
    plan = _planner().plan(_room(), (60, 60), 0.0, goal)
    before = math.dist((60, 60), goal)
    assert math.dist(plan.short_term_goal, goal) < before - 1


def test_planner_never_stops_even_on_the_goal():
    plan = _planner().plan(_room(), (60, 60), 0.0, (60, 60), goal_reached_radius_m=0.5)
    assert plan.reached
    assert plan.action != Action.STOP


def test_failed_forward_step_blocks_cells_ahead_and_the_next_plan_goes_around():
    obstacle = _room()
    planner = _planner()
    first = planner.plan(obstacle, (60, 30), 0.0, (60, 100))
    assert first.action == Action.MOVE_FORWARD and not first.collided
    second = planner.plan(obstacle, (60, 30), 0.0, (60, 100), last_move_m=0.02)
    assert second.collided
    assert planner.collision_map[60, 32:35].all()
    assert not planner.collision_map[60, 30]
    assert second.action in (Action.TURN_LEFT, Action.TURN_RIGHT)
    assert abs(second.short_term_goal[0] - 60) > 2  # the stg sidesteps the marked cells
    assert second.distance_to_goal_m > first.distance_to_goal_m


def test_a_failed_step_towards_the_target_leaves_the_passage_beside_it_open():
    """Bumping into floor the navmesh lost, right beside the only passage to the toilet: an exploring
    mark (5 cells wide) closes the passage; the target's (1, then 3 wide) does not."""
    obstacle = _room()
    obstacle[:, 33] = True
    obstacle[57:64, 33] = False  # passable rows 58-62 once the wall grows by a cell
    for target, widths_open in ((False, [False, False]), (True, [True, True])):
        planner = LocalPlanner.for_sim(PlannerConfig(), RES, SIM)
        planner.plan(obstacle, (60, 30), 0.0, (60, 100), target=target)
        for still_open in widths_open:
            plan = planner.plan(obstacle, (60, 30), 0.0, (60, 100), last_move_m=0.0, target=target)
            assert plan.collided and plan.reachable == still_open, target
    assert planner.collision_map[59:62, 33].all() and not planner.collision_map[[58, 62], 33].any()


def test_marks_that_force_a_detour_to_the_target_are_cleared_a_few_times_an_episode():
    """Beside the toilet the floor is a passage as wide as the agent, which marks thickening its
    sides close from the second collision on; the way round is 5 m longer.
    Approaching the target the marks are cleared (``target_mark_clears`` times), exploring they stay;
    cleared collisions still count as collisions for the stuck signal."""
    obstacle = _room()
    obstacle[:, 33] = True
    obstacle[59:62, 33] = False  # one traversable row (60) once the wall grows by a cell
    obstacle[105:112, 33] = False  # the way round
    collisions = 12
    cfg = PlannerConfig(stuck_collisions=collisions)
    straight = LocalPlanner.for_sim(cfg, RES, SIM).plan(obstacle, (60, 30), 0.0, (60, 100), target=True)
    straight = straight.distance_to_goal_m
    for target in (False, True):
        planner = LocalPlanner.for_sim(cfg, RES, SIM)
        planner.plan(obstacle, (60, 30), 0.0, (60, 100), target=target)
        cleared = []
        for _ in range(collisions):
            plan = planner.plan(obstacle, (60, 30), 0.0, (60, 100), last_move_m=0.0, target=target)
            assert plan.collided
            cleared.append(plan.marks_cleared)
            if plan.marks_cleared:
                assert not planner.collision_map.any() and plan.distance_to_goal_m == pytest.approx(straight)
        assert sum(cleared) == (cfg.target_mark_clears if target else 0)
        assert planner.collision_map[60, 33] and plan.distance_to_goal_m > straight + cfg.target_mark_detour_m
    assert plan.stuck


def _passage(below: int, above: int) -> np.ndarray:
    """A room split by two blocks (columns 40-80) with a passage between rows ``below`` and ``above``."""
    obstacle = _room()
    obstacle[20:below, 40:81] = True
    obstacle[above:101, 40:81] = True
    return obstacle


def test_a_step_into_a_mapped_corner_marks_beside_it_when_a_mark_across_would_shut_the_way():
    """Grazing the mapped corner of a 0.4 m passage, the rectangle laid straight ahead would shut it
    and the room behind it would never be reached. When the rectangle lengthens the way by over
    ``target_mark_detour_m``, the step swept nearer a mapped obstacle and, with the cells beside that
    obstacle marked instead, the plan turns off the failed heading, those are marked; a second
    failed step in a row still blocks the way ahead."""
    obstacle = _passage(57, 62)  # rows 57-61 free
    agent, into_corner, goal = (59, 84), math.pi + 0.3, (60, 20)  # 17 degrees towards the lower block
    open_way = LocalPlanner.for_sim(PlannerConfig(), RES, SIM).plan(obstacle, agent, into_corner, goal)
    open_way = open_way.distance_to_goal_m
    planner = LocalPlanner.for_sim(PlannerConfig(), RES, SIM)
    plan = planner.plan(obstacle, agent, into_corner, goal, last_move_m=0.0)
    marks = planner.collision_cells
    assert plan.collided and plan.marked_beside and len(marks) and plan.action != Action.MOVE_FORWARD
    grown = ndimage.binary_dilation(obstacle, structure=np.ones((3, 3), bool))
    assert grown[marks[:, 0], marks[:, 1]].all() and not obstacle[marks[:, 0], marks[:, 1]].any()
    assert plan.reachable and plan.distance_to_goal_m == pytest.approx(open_way, abs=0.3)
    again = planner.plan(obstacle, agent, into_corner, goal, last_move_m=0.0)  # the map was wrong
    added = planner.collision_cells[len(marks) :]
    assert again.collided and not again.marked_beside and len(added) >= 9 and (added[:, 1] < agent[1]).all()


def test_marks_beside_that_leave_the_failed_step_the_way_on_are_not_laid():
    """Marked beside the obstacle, a plan that steps the same way again fails again: a step straight
    along the passage's axis, whose mapped corner the marks beside do not move the way off, keeps
    the rectangle."""
    obstacle = _passage(57, 62)
    planner = LocalPlanner.for_sim(PlannerConfig(), RES, SIM)
    plan = planner.plan(obstacle, (58, 84), math.pi, (58, 20), last_move_m=0.0)
    marks = planner.collision_cells
    assert plan.collided and not plan.marked_beside
    assert (marks[:, 1] < 84).all() and planner.collision_map[58, 80:83].all()
    # The trial leaves nothing behind: the same plans as a planner that never tries marks beside.
    tried = LocalPlanner.for_sim(PlannerConfig(), RES, SIM)
    never = LocalPlanner.for_sim(PlannerConfig(target_mark_detour_m=1e9), RES, SIM)
    for last_move, heading in ((0.0, math.pi), (None, math.pi / 2), (0.25, math.pi / 2), (0.0, math.pi / 2)):
        a, b = (p.plan(obstacle, (58, 84), heading, (58, 20), last_move_m=last_move) for p in (tried, never))
        assert (a.action, a.short_term_goal, a.distance_to_goal_m, a.replanned) == (
            b.action,
            b.short_term_goal,
            b.distance_to_goal_m,
            b.replanned,
        )
        assert np.array_equal(tried.collision_map, never.collision_map)


@pytest.mark.parametrize(
    "walls, start",
    [
        (_room(), (58, 84)),  # nothing mapped in the way
        (_passage(57, 62), (59, 60)),  # along the passage: no nearer its walls a step on
        (_passage(55, 64), (58, 84)),  # a wide passage the rectangle leaves open
    ],
)
def test_a_step_the_map_cannot_explain_or_whose_mark_leaves_the_way_open_blocks_the_way_ahead(walls, start):
    planner = LocalPlanner.for_sim(PlannerConfig(), RES, SIM)
    plan = planner.plan(walls, start, math.pi, (60, 20), last_move_m=0.0)
    ahead = planner.collision_cells
    assert plan.collided and not plan.marked_beside
    assert len(ahead) and (ahead[:, 1] < start[1]).all() and (np.abs(ahead[:, 0] - start[0]) <= 2).all()


def test_the_way_keeps_a_cell_more_off_walls_where_the_floor_allows():
    """Along a wall the body's 1-cell growth lets the centre graze it (and forward steps fail): the
    short-term goal keeps the clearance; without it, it runs along the wall."""
    obstacle = _room()
    cfg = PlannerConfig()
    edge = 1 + cfg.obstacle_dilation_cells  # the first row the body's growth leaves free below the wall
    agent, goal = (edge, 10), (edge, 110)
    hugging = LocalPlanner.for_sim(PlannerConfig(clearance_cells=0), RES, SIM).plan(obstacle, agent, 0.0, goal)
    clear = LocalPlanner.for_sim(cfg, RES, SIM).plan(obstacle, agent, 0.0, goal)
    assert hugging.short_term_goal[0] == edge
    assert clear.short_term_goal[0] >= edge + cfg.clearance_cells
    assert clear.reachable and clear.distance_to_goal_m == pytest.approx(hugging.distance_to_goal_m, abs=0.15)


@pytest.mark.parametrize("round_rows, narrow", [((100, 111), True), ((66, 77), False)])
def test_a_passage_only_the_body_fits_is_taken_unless_the_clear_way_is_barely_longer(round_rows, narrow):
    """A gap one agent wide (open with the body's growth, shut with the clearance) beside a wide one:
    the plan takes the gap when the wide way round is over ``clearance_detour_m`` longer."""
    obstacle = _room()
    obstacle[:, 60] = True
    obstacle[59:62, 60] = False  # row 60 passes the body's growth only
    obstacle[round_rows[0] : round_rows[1], 60] = False
    cfg = PlannerConfig()
    body_only = LocalPlanner.for_sim(PlannerConfig(clearance_cells=0), RES, SIM)
    body_only = body_only.plan(obstacle, (60, 30), 0.0, (60, 100))
    plan = LocalPlanner.for_sim(cfg, RES, SIM).plan(obstacle, (60, 30), 0.0, (60, 100))
    if narrow:
        assert plan.distance_to_goal_m == pytest.approx(body_only.distance_to_goal_m, abs=1e-4)
    else:
        assert body_only.distance_to_goal_m < plan.distance_to_goal_m and plan.short_term_goal[0] > 62
        assert plan.distance_to_goal_m <= body_only.distance_to_goal_m + cfg.clearance_detour_m


def test_the_marked_cells_are_listed_for_views_as_arrays_that_never_change_under_a_reader():
    planner = _planner()
    planner.plan(_room(), (60, 30), 0.0, (60, 100))
    assert len(planner.collision_cells) == 0
    planner.plan(_room(), (60, 30), 0.0, (60, 100), last_move_m=0.0)
    first = planner.collision_cells
    assert sorted(map(tuple, first.tolist())) == sorted(map(tuple, np.argwhere(planner.collision_map).tolist()))
    kept = first.copy()
    planner.plan(_room(), (60, 30), math.pi / 2, (60, 100), last_move_m=0.0)  # a second, wider mark
    assert len(planner.collision_cells) > len(first) and np.array_equal(first, kept)
    assert len(np.unique(planner.collision_cells, axis=0)) == len(planner.collision_cells)
    planner.clear_collisions()
    assert len(planner.collision_cells) == 0 and np.array_equal(first, kept)


def test_forward_step_that_moved_enough_is_not_a_collision():
    planner = _planner()
    plan = planner.plan(_room(), (60, 30), 0.0, (60, 100), last_move_m=0.12)
    assert not plan.collided
    assert not planner.collision_map.any()


def test_repeated_collisions_raise_stuck():
    cfg = PlannerConfig(stuck_collisions=5, stuck_window_steps=50)
    planner = LocalPlanner.for_sim(cfg, RES, SIM)
    flags = [planner.plan(_room(), (60, 30), 0.0, (60, 100), last_move_m=0.0).stuck for _ in range(5)]
    assert flags == [False, False, False, False, True]


def test_no_progress_over_the_window_raises_stuck():
    cfg = PlannerConfig(stuck_window_steps=10, stuck_collisions=10, stuck_min_displacement_m=0.5)
    planner = LocalPlanner.for_sim(cfg, RES, SIM)
    flags = [planner.plan(_room(), (60, 30 + i % 2), 0.0, (60, 100)).stuck for i in range(10)]
    assert flags == [False] * 9 + [True]
    planner.reset()
    assert not planner.plan(_room(), (60, 30), 0.0, (60, 100)).stuck


def test_unreachable_goal_is_reported_and_the_agent_heads_to_the_nearest_reachable_cell():
    obstacle = _room()
    obstacle[40:81, 80] = True
    obstacle[40:81, 110] = True
    obstacle[40, 80:111] = True
    obstacle[80, 80:111] = True  # a closed box around the goal
    planner = _planner()
    plan = planner.plan(obstacle, (60, 30), 0.0, (60, 95))
    assert not plan.reachable and not plan.reached
    assert plan.distance_to_goal_m == math.inf
    assert plan.action == Action.MOVE_FORWARD
    assert plan.short_term_goal[1] > 30


def test_agent_inside_dilated_obstacles_can_still_move_out():
    obstacle = _room()
    obstacle[:, 58] = True  # a wall 2 cells to the agent's right (-col side)
    planner = _planner()
    plan = planner.plan(obstacle, (60, 60), math.pi / 2, (60, 100))
    assert plan.reachable
    assert plan.short_term_goal[1] > 60
    assert plan.action == Action.TURN_RIGHT  # facing +row, the goal lies toward +col


def test_reached_is_true_only_within_the_radius():
    planner = _planner()
    assert planner.plan(_room(), (60, 60), 0.0, (60, 66), goal_reached_radius_m=0.5).reached
    assert not planner.plan(_room(), (60, 60), 0.0, (60, 76), goal_reached_radius_m=0.5).reached
    assert planner.plan(_room(), (60, 60), 0.0, (60, 76), goal_reached_radius_m=1.0).reached


def test_small_goal_dilation_keeps_a_goal_behind_a_thin_wall_from_reading_as_reached():
    obstacle = _room()
    obstacle[:100, 64] = True  # a one-cell wall, its door at the far end
    planner = LocalPlanner.for_sim(PlannerConfig(obstacle_dilation_cells=1), RES, SIM)
    through_wall = planner.plan(obstacle, (40, 58), 0.0, (40, 70), goal_reached_radius_m=0.75)
    assert through_wall.reached  # the 0.5 m object disk reaches across the wall
    planner.reset()
    frontier = planner.plan(obstacle, (40, 58), 0.0, (40, 70), goal_reached_radius_m=0.75, goal_dilation_m=0.1)
    assert frontier.reachable and not frontier.reached
    assert frontier.distance_to_goal_m > 3.0  # via the door
    with pytest.raises(L3MVNError, match="goal_dilation_m"):
        planner.plan(obstacle, (40, 58), 0.0, (40, 70), goal_dilation_m=0.8)


def test_bad_inputs_raise_clear_errors():
    planner = _planner()
    with pytest.raises(L3MVNError, match="bool"):
        planner.plan(_room().astype(np.uint8), (60, 60), 0.0, (60, 70))
    with pytest.raises(L3MVNError, match="outside"):
        planner.plan(_room(), (600, 60), 0.0, (60, 70))
    with pytest.raises(L3MVNError, match="empty"):
        planner.plan(_room(), (60, 60), 0.0, np.zeros((120, 120), dtype=bool))
    with pytest.raises(L3MVNError, match="reset"):
        planner.plan(_room(100), (60, 60), 0.0, (60, 70))
    with pytest.raises(L3MVNError, match="positive"):
        PlannerConfig(stg_lookahead_m=0.0)
    for keep in (10.0, 90.0, float("nan")):  # below the turn threshold, square to the goal, or no angle
        with pytest.raises(L3MVNError, match=r"keep_heading_deg must lie in \[turn_threshold_deg \(15\), 90\), got"):
            PlannerConfig(keep_heading_deg=keep)


def _drive(
    obstacle: np.ndarray,
    start: tuple[float, float, float],
    goal: tuple[int, int],
    steps: int,
    planner: LocalPlanner | None = None,
) -> tuple[int, LocalPlanner, list[Action]]:
    """A 2D kinematic agent (0.25 m steps, 30 deg turns, 0.18 m disk) driven by the planner: the
    steps it took to reach ``goal``, the planner, and its actions."""
    clearance = ndimage.distance_transform_edt(~obstacle) * RES
    x, y, heading = start
    planner = planner or _planner()
    last_move, actions = None, []
    for step in range(steps):
        cell = (int(y / RES), int(x / RES))
        plan = planner.plan(obstacle, cell, heading, goal, last_move_m=last_move)
        assert plan.action != Action.STOP
        if plan.reached:
            return step, planner, actions
        actions.append(plan.action)
        last_move = None
        if plan.action == Action.TURN_LEFT:
            heading += math.radians(30)
        elif plan.action == Action.TURN_RIGHT:
            heading -= math.radians(30)
        elif plan.action == Action.MOVE_FORWARD:
            x0, y0 = x, y
            for _ in range(5):
                nx, ny = x + 0.05 * math.cos(heading), y + 0.05 * math.sin(heading)
                if clearance[int(ny / RES), int(nx / RES)] < 0.18:
                    break
                x, y = nx, ny
            last_move = math.hypot(x - x0, y - y0)
    raise AssertionError(f"goal not reached in {steps} steps")


def test_closed_loop_agent_reaches_a_goal_through_a_door():
    obstacle = _room(160)
    obstacle[:, 80] = True
    obstacle[110:130, 80] = False  # the door
    obstacle[30:60, 40] = True  # a pillar on the way
    steps, planner, _ = _drive(obstacle, (1.0, 1.0, 0.0), (20, 140), steps=150)
    # The shortest path is ~10.8 m (43 forward steps) plus ~6 turns; the 30-degree headings still
    # cost some turns on its diagonals.
    assert steps < 70
    assert planner.fmm_runs < steps


@pytest.mark.parametrize("bearing_deg", [10, 15, 45, 75])
def test_a_path_between_two_headings_is_walked_without_turning_at_every_step(bearing_deg):
    """SemExp's rule turns whenever the short-term goal lies over 15 degrees off: on a path between
    two 30-degree headings the error crosses that at nearly every step, and the agent turns left,
    steps, turns right, steps, spending a large share of its steps on such turns."""
    goal_m = (1.0 + 8.0 * math.sin(math.radians(bearing_deg)), 1.0 + 8.0 * math.cos(math.radians(bearing_deg)))
    goal = (int(goal_m[0] / RES), int(goal_m[1] / RES))
    turns = {}
    for keep in (15.0, 30.0):
        planner = LocalPlanner.for_sim(PlannerConfig(obstacle_dilation_cells=3, keep_heading_deg=keep), RES, SIM)
        _, _, actions = _drive(_room(200), (1.0, 1.0, 0.0), goal, steps=200, planner=planner)
        turns[keep] = sum(a != Action.MOVE_FORWARD for a in actions)
    # 7.5 m is 30 steps: aligning takes up to 2 turns, and a heading 15 degrees off drifts enough
    # for one or two more on the way.
    assert turns[30.0] <= 4
    assert turns[15.0] >= 10  # the zig-zag the hysteresis removes


def test_a_step_that_moved_keeps_its_heading_while_the_goal_lies_within_keep_heading_deg():
    for keep, second in ((30.0, Action.MOVE_FORWARD), (15.0, Action.TURN_LEFT)):
        planner = LocalPlanner.for_sim(PlannerConfig(obstacle_dilation_cells=3, keep_heading_deg=keep), RES, SIM)
        heading = math.radians(-30)
        assert planner.plan(_room(), (50, 20), heading, (40, 37)).action == Action.MOVE_FORWARD
        # A step on, the goal lies 29 degrees off the heading.
        assert planner.plan(_room(), (49, 22), heading, (48, 100)).action == second
        # Where the last step failed (the same cell), the agent turns.
        assert planner.plan(_room(), (49, 22), heading, (48, 100)).action == Action.TURN_LEFT


def _kept(trav: np.ndarray, field_values: np.ndarray) -> Action:
    """The steering's second action: one forward step done at -30 degrees, the short-term goal now
    29 degrees off, on a given field and traversible window."""
    steering = Steering(PlannerConfig(), RES, SIM.forward_step_m)
    field = GeodesicField(field_values.astype(np.float32), Window(0, 0, 120, 120), (120, 120))
    heading = math.radians(-30)
    assert steering.action((50, 20), heading, (40, 37), field, trav) == Action.MOVE_FORWARD
    return steering.action((49, 22), heading, (48, 40), field, trav)


def test_a_kept_heading_only_sweeps_free_cells_and_ends_nearer_the_goal():
    rows, cols = np.mgrid[0:120, 0:120]
    to_goal = np.hypot(rows - 48, cols - 119) * RES
    free = np.ones((120, 120), dtype=bool)
    assert _kept(free, to_goal) == Action.MOVE_FORWARD
    corner = free.copy()
    corner[47, 25] = False  # halfway along the step, the way's end free
    assert _kept(corner, to_goal) == Action.TURN_LEFT
    away = np.hypot(rows - 60, cols - 22) * RES  # downhill lies behind the agent
    assert _kept(free, away) == Action.TURN_LEFT


def test_closed_loop_agent_gets_around_an_obstacle_missing_from_its_map():
    true_map = _room(120)
    true_map[50:70, 60:63] = True  # the planner never sees this wall
    clearance = ndimage.distance_transform_edt(~true_map) * RES
    x, y, heading = 1.5, 3.0, 0.0
    planner = _planner()
    last_move = None
    for _ in range(150):
        cell = (int(y / RES), int(x / RES))
        plan = planner.plan(_room(120), cell, heading, (60, 100), last_move_m=last_move)
        if plan.reached:
            break
        last_move = None
        if plan.action == Action.MOVE_FORWARD:
            x0, y0 = x, y
            for _ in range(5):
                nx, ny = x + 0.05 * math.cos(heading), y + 0.05 * math.sin(heading)
                if clearance[int(ny / RES), int(nx / RES)] < 0.18:
                    break
                x, y = nx, ny
            last_move = math.hypot(x - x0, y - y0)
        else:
            heading += math.radians(30 if plan.action == Action.TURN_LEFT else -30)
    assert plan.reached
    assert planner.collision_map.any()


@pytest.mark.parametrize("body, step", [(-0.1, 0.25), (0.18, 0.0), (float("nan"), 0.25)])
def test_a_body_no_step_can_sweep_is_refused_in_one_line(body, step):
    with pytest.raises(L3MVNError, match=r"need body_radius_m >= 0 and forward_step_m > 0, got"):
        LocalPlanner(PlannerConfig(), RES, body_radius_m=body, forward_step_m=step)


def test_the_narrow_field_is_marched_only_where_it_could_win():
    """A clear way as short as the straight line leaves the narrow way nothing to win: one march.
    Where the clear way goes round, the narrow field is marched and compared (the gap above)."""
    straight = LocalPlanner.for_sim(PlannerConfig(), RES, SIM)
    plan = straight.plan(_room(), (60, 30), 0.0, (60, 100))
    assert plan.reachable and straight.fmm_runs == 1
    obstacle = _room()
    obstacle[:, 60] = True
    obstacle[59:62, 60] = False  # only the body fits: the clear way goes round through rows 100-110
    obstacle[100:111, 60] = False
    round_about = LocalPlanner.for_sim(PlannerConfig(), RES, SIM)
    round_about.plan(obstacle, (60, 30), 0.0, (60, 100))
    assert round_about.fmm_runs >= 2

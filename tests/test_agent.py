"""The map-based agent on the tiny two-room house, with ground-truth semantics.

The house (tests/conftest.py::draw_two_room_house): two 4.5 m rooms joined by a 1.2 m door; the
toilet stands in the north-east corner of the east room, the agent starts in the west room.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from l3mvn.agent.mapping import SemanticMap
from l3mvn.agent.modular import MapAgent
from l3mvn.agent.policies.global_policies import NearestFrontier
from l3mvn.core.config import AgentConfig, Config, SimConfig, TaskConfig
from l3mvn.core.errors import L3MVNError
from l3mvn.core.frames import CameraFrame
from l3mvn.core.types import Action, Pose
from l3mvn.run.session import EpisodeSession
from l3mvn.world.episode import Episode
from l3mvn.world.sim.simulator import BuiltinSimulator
from l3mvn.world.task import ObjectNavTask

MAX_STEPS = 300
START = Pose(x=2.5, y=2.0, heading=math.pi)  # west room, facing away from the door


@pytest.fixture
def env(tiny_scene):
    cfg = dataclasses.replace(SimConfig().with_frame(60, 80), max_steps=MAX_STEPS)
    return BuiltinSimulator(tiny_scene, cfg)


def _agent(env, **overrides) -> MapAgent:
    return MapAgent(NearestFrontier(), env.categories, _tree(env, agent=AgentConfig(**overrides)))


def _tree(env, **sections) -> Config:
    """The config tree of ``env``'s simulator with the given sections."""
    return Config(sim=env.cfg, **sections)


def _episode(goal: str = "toilet", start: Pose = START) -> Episode:
    return Episode(episode_id=0, scene="Tiny", floor=0, start=start, goal=goal)


def _run(env, agent, episode):
    session = EpisodeSession(env, ObjectNavTask(env.scene, _tree(env)), agent, policy_name="frontier", config_hash="t")
    session.start(episode)
    events = []
    while not session.done:
        blocked_before = list(agent.explore.blocked)
        events.append((session.step(), blocked_before))
    return session.result, events


def test_agent_finds_the_toilet_in_the_other_room_with_ground_truth_semantics(env):
    result, events = _run(env, _agent(env), _episode())
    assert result.success, result.failure
    assert result.steps < 200
    assert events[-1][0].decision.action == Action.STOP
    # Coverage: the share of the reachable floor the agent's own map explored (for failure analysis).
    assert 0.0 < result.extra["coverage"] <= 1.0


def test_agent_never_stops_before_its_map_shows_the_target(env):
    agent = _agent(env)
    _, events = _run(env, agent, _episode())
    min_cells = agent.cfg.target_min_cells
    for event, _ in events:
        d = event.decision
        if d.action == Action.STOP:
            assert d.goal_kind == "target" and d.target_seen
            assert d.map.category("toilet").sum() >= min_cells


def test_look_around_comes_first_when_the_target_is_not_in_view(env):
    agent = _agent(env)
    _, events = _run(env, agent, _episode())
    first = [e.decision for e, _ in events[: agent.cfg.look_around_steps]]
    assert all(d.goal_kind == "look-around" and d.action == Action.TURN_LEFT for d in first)
    assert events[agent.cfg.look_around_steps][0].decision.goal_kind != "look-around"


def _until_set_aside(env, agent, offset_cells: int, max_steps: int):
    """Inject one toilet cell ``offset_cells`` east of the agent (the toilet itself is in the other
    room, out of sight) and run until the agent sets goal cells aside; the agent never stops."""
    episode = _episode("toilet")
    obs = env.reset(episode)
    agent.reset(episode)
    agent.act(obs)
    row, col = agent.perception.map.agent_cell
    noise = agent.perception.map.category("toilet")
    assert not noise.any()
    noise[row, col + offset_cells] = True
    decisions = []
    for _ in range(max_steps):
        d = agent.act(obs)
        assert d.action != Action.STOP
        decisions.append(d)
        if "set aside" in d.reason:
            break
        obs = env.step(d.action)
    assert decisions[0].goal_kind == "candidate" and "set aside" in decisions[-1].reason
    return decisions, obs


def test_a_single_noisy_goal_cell_is_looked_at_from_other_sides_then_set_aside(env):
    agent = _agent(env, look_around_steps=0)
    decisions, obs = _until_set_aside(env, agent, 3, 120)  # 15 cm away: well inside the stop distance
    assert "viewpoint" in [d.goal_kind for d in decisions]  # looked at from another side before it was dropped
    assert agent.act(env.step(decisions[-1].action)).goal_kind not in ("candidate", "viewpoint")


def test_a_candidate_the_agent_comes_no_nearer_to_is_looked_at_from_elsewhere_then_set_aside(env):
    """A few goal cells seen in a room the agent cannot get nearer to (a bathroom the navmesh cut
    short) must not hold it for hundreds of steps. Here no step can bring the agent the (impossible)
    required progress closer: after its patience it tries another side, then sets the cells aside,
    instead of approaching for ever."""
    agent = _agent(env, look_around_steps=0, goal_patience_steps=3, goal_progress_m=50.0, goal_progress_area_m2=1e9)
    decisions, _ = _until_set_aside(env, agent, 60, 60)  # 3 m east, in the unknown
    assert any("no nearer in 3 steps" in d.reason for d in decisions)
    assert len(decisions) < 30


def test_manual_goal_is_followed_recorded_and_cleared_once_reached(env):
    agent = _agent(env, look_around_steps=0)
    episode = _episode("toilet")
    session = EpisodeSession(env, ObjectNavTask(env.scene, _tree(env)), agent, policy_name="frontier", config_hash="t")
    session.start(episode)
    session.step()
    row, col = agent.perception.map.agent_cell
    cell = (row + 20, col + 10)  # 1.1 m away in the open west room
    agent.set_manual_goal(cell)
    seen = []
    for _ in range(40):
        d = session.step().decision
        seen.append(d)
        if d.goal_kind != "manual":
            break
    manual = [d for d in seen if d.goal_kind == "manual"]
    assert manual and all(d.override == f"manual:{cell[0]},{cell[1]}" and d.long_term_goal == cell for d in manual)
    assert seen[-1].goal_kind != "manual" and seen[-1].override is None  # reached: back to exploring
    with pytest.raises(L3MVNError, match="outside"):
        agent.set_manual_goal((-1, 5))


def test_reached_frontiers_are_not_chosen_again(env):
    agent = _agent(env)
    episode = _episode()
    obs = env.reset(episode)
    agent.reset(episode)
    agent.change_target("couch")  # no couch in this house: the agent explores all the way
    radius = agent.cfg.blocked_radius_m / 0.05
    gap = agent.cfg.blocked_frontier_gap_m / 0.05
    chosen = 0
    for _ in range(200):
        blocked, own = list(agent.explore.blocked), dict(agent.explore.done_frontiers)
        d = agent.act(obs)
        obs = env.step(d.action)
        fresh = d.timings_ms.get("frontiers", 0.0) > 0.0
        if d.goal_kind != "frontier" or not blocked or not fresh or len(agent.explore.blocked) < len(blocked):
            continue  # (a shorter list: the fallback forgot them all, as nothing else was left)
        gaps = np.hypot(*(np.array(blocked) - np.array(d.long_term_goal)).T)
        # A frontier stood on and looked beyond blocks only half the radius: the explorer's own radii
        # (new done goals are appended after the ones this choice saw).
        radii = agent.explore.blocked_radii(0.05)[: len(blocked)]
        assert (radii >= radius / 2).all()
        cells = d.frontiers[d.chosen_frontier].cells
        for cell in np.array(blocked)[gaps <= radii]:
            # Within a done goal's radius only a frontier other than the done one may be taken.
            done = own[tuple(int(v) for v in cell)]
            assert np.hypot(*(cells[:, None, :] - done[None, :, :]).transpose(2, 0, 1)).min() > gap
        chosen += 1
    assert chosen > 0


def test_frontier_choices_step_to_the_end_and_yield_each_fresh_frontier_list_once(env):
    task = ObjectNavTask(env.scene, _tree(env))
    session = EpisodeSession(env, task, _agent(env), policy_name="frontier", config_hash="t")
    session.start(_episode(goal="toilet"))  # in the other room: found after a few choices
    choices = list(session.frontier_choices())
    assert session.done and len(choices) >= 2
    steps = [step for step, _ in choices]
    assert steps == sorted(set(steps)) and steps[-1] <= session.env.steps
    assert len({id(d.frontiers) for _, d in choices}) == len(choices)  # each list once
    for _, decision in choices:
        assert decision.goal_kind == "frontier" and decision.frontiers and decision.chosen_frontier is not None


def test_random_sample_keeps_its_goal_until_reached_while_frontier_policies_reselect(env):
    from l3mvn.agent.policies.global_policies import RandomSample

    tree = _tree(env)
    agent = MapAgent(RandomSample(tree.planner.obstacle_dilation_cells), env.categories, tree)
    episode = _episode()
    obs = env.reset(episode)
    agent.reset(episode)
    agent.change_target("couch")  # absent: the agent only explores
    goals, legs = [], []
    for _ in range(150):
        d = agent.act(obs)
        obs = env.step(d.action)
        if d.goal_kind != "random":
            continue
        if goals and d.long_term_goal == goals[-1]:
            legs[-1] += 1
        else:
            goals.append(d.long_term_goal)
            legs.append(1)
    assert len(goals) >= 2 and max(legs) > agent.cfg.replan_every


def test_an_exploration_goal_that_gets_no_nearer_is_given_up_after_the_patience(env):
    agent = _agent(env, goal_patience_steps=5)
    agent.reset(_episode())
    progress = agent.wayfinder.progress
    goal, mapped = (10, 10), 1000
    # Circling: the path keeps changing and the distance wanders without a 0.5 m gain, and the map
    # grows by less than goal_progress_area_m2 (2 m2 = 800 cells) all the while.
    wander = [8.0, 8.3, 7.8, 8.1, 7.9]
    assert not any(progress.stalled(goal, d, mapped + 100 * k) for k, d in enumerate(wander))
    assert progress.stalled(goal, 8.0, mapped + 700)
    # Real progress restarts the count, and so does a new goal.
    assert not progress.stalled(goal, 7.0, mapped + 700)
    assert not progress.stalled((20, 20), 9.0, mapped + 700)
    with pytest.raises(L3MVNError, match="goal_patience_steps"):
        AgentConfig(goal_patience_steps=0)


def test_a_detour_that_keeps_mapping_new_floor_is_not_given_up(env):
    # Round walls it could not see, the planned way grows for a while: not circling, as each step
    # the walk maps another 2 m2 (800 cells) of floor.
    agent = _agent(env, goal_patience_steps=5)
    agent.reset(_episode())
    progress, goal = agent.wayfinder.progress, (10, 10)
    detour = [8.0 + 0.2 * k for k in range(20)]
    assert not any(progress.stalled(goal, d, 1000 + 800 * k) for k, d in enumerate(detour))
    # Once the map stops growing, the patience runs out as before.
    assert [progress.stalled(goal, 12.0, 1000 + 800 * 19) for _ in range(5)] == [False] * 4 + [True]


def _walled_target_map(agent_cell):
    """Floor on both sides of a wall (cols 100-101) whose only door is 6 m south; a toilet 0.6 m
    beyond the wall, level with the agent."""
    n = 200
    obstacle = np.zeros((n, n), bool)
    obstacle[:170, 100:102] = True
    target = np.zeros((n, n), bool)
    target[48:53, 114:119] = True
    explored = np.ones((n, n), bool)
    sem_map = SemanticMap(
        obstacle=obstacle,
        explored=explored,
        visited=np.zeros_like(explored),
        categories=target[None],
        category_names=("toilet",),
        looked=explored,
        resolution_m=0.05,
        start_xy=(0.0, 0.0),
        agent_cell=agent_cell,
        agent_heading=0.0,
        local_cells=n,
        footprint_radius_cells=3,
    )
    return sem_map, target


@pytest.mark.parametrize("rule", ["semexp", "geodesic"])
def test_a_target_behind_a_wall_is_approached_as_the_success_rule_measures(rule):
    agent = MapAgent(NearestFrontier(), ("toilet",), Config(task=TaskConfig(success_rule=rule)))
    far = agent.wayfinder.plan(*_walled_target_map((50, 60)), "target", None)
    beside_wall = agent.wayfinder.plan(*_walled_target_map((50, 97)), "target", None)
    if rule == "semexp":
        # Straight-line success: the floor on this side of the wall, within 0.9 m of the toilet.
        assert far.reachable and far.distance_to_goal_m < 2.0 and far.short_term_goal[1] > 60
        assert beside_wall.reached
    else:
        # Geodesic success: round through the door.
        assert far.distance_to_goal_m > 10.0 and far.short_term_goal[0] > 50
        assert not beside_wall.reached


@pytest.mark.parametrize(
    ("offset", "stuck", "stops"),
    [
        ((5, 18), True, True),  # 0.93 m, no way closer: stop
        ((5, 18), False, False),  # 0.93 m, a path closer: walk on
        ((0, 19), True, True),  # 19 cells: exactly the 0.95 m bound (19 * 0.05 is 0.9500000000000001 in floats)
        ((6, 19), True, False),  # 1.00 m: too far to count, stuck or not
    ],
)
def test_a_target_the_agent_cannot_get_closer_to_is_stopped_at_within_the_success_distance(env, offset, stuck, stops):
    agent = _agent(env, look_around_steps=0)
    episode = _episode("toilet")
    obs = env.reset(episode)
    agent.reset(episode)
    agent.act(obs)
    row, col = agent.perception.map.agent_cell
    toilet = agent.perception.map.category("toilet")
    toilet[row + offset[0] : row + offset[0] + 2, col + offset[1] : col + offset[1] + 2] = True
    plan = agent.planner.plan
    agent.planner.plan = lambda *a, **k: dataclasses.replace(plan(*a, **k), stuck=stuck)
    d = agent.act(obs)
    assert d.goal_kind == "target"
    assert (d.action == Action.STOP) == stops, d.reason
    if stops:
        assert "no path closer" in d.reason


def test_a_stuck_agent_escapes_under_its_own_goal_kind(env):
    """Stuck while exploring: the marks go, a random turn then two steps forward, each decision
    labelled ``GoalKind.ESCAPE`` (consumers read the kind's name, which a plain string lacks)."""
    from l3mvn.agent.decision import GoalKind

    agent = _agent(env, look_around_steps=0)
    episode = _episode("toilet")
    obs = env.reset(episode)
    agent.reset(episode)
    agent.act(obs)
    plan = agent.planner.plan
    agent.planner.plan = lambda *a, **k: dataclasses.replace(plan(*a, **k), stuck=True)
    first = agent.act(obs)
    assert "escaping" in first.reason and first.goal_kind in (GoalKind.FRONTIER, GoalKind.EXPLORE)
    agent.planner.plan = plan
    rest = []
    while agent.wayfinder.escape.active:
        rest.append(agent.act(obs))
    assert rest and all(d.goal_kind is GoalKind.ESCAPE and d.goal_kind.name == "ESCAPE" for d in rest)
    assert [d.action for d in rest][-2:] == [Action.MOVE_FORWARD] * 2


def test_stop_distances_are_checked_against_each_other_and_the_success_distance(env):
    with pytest.raises(L3MVNError, match="stop_distance_m <= blocked_stop_distance_m"):
        AgentConfig(stop_distance_m=0.95, blocked_stop_distance_m=0.9)
    with pytest.raises(L3MVNError, match="must be below task.success_distance_m"):
        _tree(env, agent=AgentConfig(blocked_stop_distance_m=1.0))


def test_frontier_oracle_heads_for_the_frontier_nearest_the_goal_and_succeeds(env):
    from l3mvn.agent.policies.oracle_frontier import FrontierOracle
    from l3mvn.world.baselines import ObjectDistances, object_distances

    task = ObjectNavTask(env.scene, _tree(env))
    oracle = FrontierOracle(ObjectDistances(task))
    result, events = _run(env, MapAgent(oracle, env.categories, _tree(env)), _episode())
    assert result.success, result.failure
    region = object_distances(task, "toilet")
    checked = 0
    for event, _ in events:
        d = event.decision
        if d.goal_kind != "frontier" or len(d.frontiers) < 2 or not (d.reason or "").startswith("oracle"):
            continue

        def to_goal(f, m=d.map):
            return min(region.distance_at(*m.cell_to_world(int(r), int(c))) for r, c in f.cells)

        totals = [f.cost + to_goal(f) for f in d.frontiers]
        assert d.frontiers[d.chosen_frontier].cost + to_goal(d.frontiers[d.chosen_frontier]) == min(totals)
        checked += 1
    assert checked > 0


def test_the_frontier_oracle_measures_to_the_object_not_through_the_wall_to_its_success_region():
    # The side room's toilet against its south wall: its SemExp success region reaches through the
    # wall into the corridor, but from there the toilet is farther round by the door.
    from l3mvn.world.baselines import object_distances

    scene = _corridor_with_side_room(toilet=(slice(28, 36), slice(112, 119)))
    task = ObjectNavTask(scene, Config(sim=SimConfig().with_frame(60, 80)))
    below = scene.cell_center(53, 116)  # corridor, under the toilet
    assert task.region("toilet").distance_at(*below) == 0.0
    assert object_distances(task, "toilet").distance_at(*below) > 1.0


def _corridor_with_side_room(toilet=(slice(10, 20), slice(82, 92))):
    """A 10 m corridor and, off its north wall through a 0.8 m door, a 2 x 1.5 m side room whose
    toilet stands in the corner beside the door: seen from the corridor only through the doorway."""
    from scipy import ndimage as ndi

    from l3mvn.core.grid import disk
    from l3mvn.world.scenes.scene import SceneMap

    h, w = 80, 200
    nav = np.zeros((h, w), bool)
    nav[52:68, 8:192] = True  # corridor
    nav[12:38, 80:120] = True  # side room
    nav[36:54, 94:106] = True  # its door
    objects = np.zeros((1, h, w), bool)
    objects[0][toilet] = True  # north-west corner by default
    nav &= ~ndi.binary_dilation(objects[0], disk(4))
    return SceneMap(name="Corridor", floor=0, categories=("toilet",), navigable=nav, objects=objects)


@pytest.mark.parametrize("start", [Pose(x=1.0, y=3.0, heading=0.0), Pose(x=9.0, y=3.0, heading=math.pi)])
def test_an_agent_in_a_corridor_looks_into_the_side_room_as_it_passes_and_confirms_its_toilet(start):
    # The door spans x = 4.7..5.3 m. Marking the door's frontier reached from beside it without
    # looking in would send the agent on to the corridor's end and back later; looking into the
    # unknown beyond a reached frontier finds the toilet on the way.
    scene = _corridor_with_side_room()
    env = BuiltinSimulator(scene, dataclasses.replace(SimConfig().with_frame(60, 80), max_steps=400))
    agent = _agent(env)
    episode = Episode(episode_id=0, scene="Corridor", floor=0, start=start, goal="toilet")
    result, events = _run(env, agent, episode)
    assert result.success, result.failure
    first = next(i for i, (e, _) in enumerate(events) if e.decision is not None and e.decision.goal_kind == "target")
    xs = [e.pose.x for e, _ in events[: first + 1]]
    past = max(xs) - 5.3 if start.x < 5.0 else 4.7 - min(xs)
    assert past <= 1.0, f"walked {past:.2f} m past the door before looking in"


def test_with_no_frontier_left_the_agent_goes_to_look_at_floor_it_only_saw_from_afar(env):
    # A closed, fully explored 10 x 10 m room: no frontier. Its east end (x > 7 m) was explored from
    # afar only (a room seen through its door), so that is where the agent goes next.
    n = 240
    obstacle = np.zeros((n, n), bool)
    obstacle[20, 20:221] = obstacle[220, 20:221] = obstacle[20:221, 20] = obstacle[20:221, 220] = True
    explored = np.zeros((n, n), bool)
    explored[20:221, 20:221] = True
    looked = explored.copy()
    looked[21:220, 160:220] = False
    sem_map = SemanticMap(
        obstacle=obstacle,
        explored=explored,
        visited=np.zeros_like(explored),
        categories=np.zeros((1, n, n), bool),
        category_names=("toilet",),
        looked=looked,
        resolution_m=0.05,
        start_xy=(0.0, 0.0),
        agent_cell=(120, 60),
        agent_heading=0.0,
        local_cells=n,
        footprint_radius_cells=3,
    )
    agent = _agent(env)
    agent.reset(_episode())
    agent.explore.reselect(sem_map, agent.goal, agent.rng)
    assert agent.explore.frontiers == []
    assert agent.explore.kind == "look" and 155 <= agent.explore.cell[1] <= 165 and 100 <= agent.explore.cell[0] <= 140
    agent.explore.blocked.append(agent.explore.cell)  # looked at: the next look goal is elsewhere in that area
    agent.explore.reselect(sem_map, agent.goal, agent.rng)
    assert agent.explore.kind == "look" and np.hypot(*np.subtract(agent.explore.cell, agent.explore.blocked[0])) > 20


def test_a_target_seen_beyond_the_depth_range_is_walked_towards_until_it_maps(env):
    agent = _agent(env, look_around_steps=0)
    episode = _episode("toilet")
    obs = env.reset(episode)
    agent.reset(episode)
    h, w = obs.depth.shape
    semantic, depth = obs.semantic.copy(), obs.depth.copy()
    goal_id = env.categories.index("toilet") + 1
    semantic[h // 2 - 2 : h // 2 + 2, w - 12 : w - 4] = goal_id  # right edge of the view, no depth
    depth[h // 2 - 2 : h // 2 + 2, w - 12 : w - 4] = 0.0
    d = agent.act(dataclasses.replace(obs, frame=CameraFrame.of(obs.rgb, depth, semantic)))
    assert d.goal_kind == "glimpse"
    r, c = d.map.agent_cell
    gr, gc = d.long_term_goal
    bearing = math.atan2(gr - r, gc - c) - d.map.agent_heading
    bearing = (bearing + math.pi) % (2 * math.pi) - math.pi
    half_fov = math.radians(env.cfg.hfov_deg) / 2
    assert -half_fov < bearing < -0.6 * half_fov  # to the right (clockwise), near the view's edge
    assert math.hypot(gr - r, gc - c) * d.map.resolution_m == pytest.approx(agent.sim.max_depth_m, abs=0.1)
    # The same pixels with depth are an ordinary candidate: nothing to walk towards blindly.
    agent.reset(episode)
    assert (
        agent.act(dataclasses.replace(obs, frame=CameraFrame.of(obs.rgb, obs.depth, semantic))).goal_kind != "glimpse"
    )


def test_looking_settings_are_checked_with_one_line_errors(env):
    with pytest.raises(L3MVNError, match="must be >= half of sim.turn_angle_deg"):
        _tree(env, agent=AgentConfig(look_tolerance_deg=10.0))
    with pytest.raises(L3MVNError, match="frontier_press_m"):
        AgentConfig(frontier_press_m=0.8)
    with pytest.raises(L3MVNError, match="viewpoint distances"):
        AgentConfig(viewpoint_min_m=2.0, viewpoint_max_m=1.5)
    with pytest.raises(L3MVNError, match="glimpse fractions"):
        AgentConfig(glimpse_min_fraction=0.1, glimpse_max_fraction=0.05)


def test_a_kept_frontier_names_why_it_was_chosen_once_not_once_per_keep():
    """Kept again and again, a frontier's reason must not quote the previous kept reason (the dashboard
    would show "kept frontier 1 (commitment): kept frontier 1 (commitment): ..." after two re-selections)."""
    from l3mvn.agent.frontiers import Frontier
    from l3mvn.agent.modular.exploration import ExplorationGoals
    from l3mvn.agent.planning import LocalPlanner
    from l3mvn.agent.policies.global_policies import Selection

    config = Config()
    goals = ExplorationGoals(
        NearestFrontier(), config, LocalPlanner.for_sim(config.planner, config.map.resolution_m, config.sim)
    )
    cells = np.zeros((1, 2), np.int64)
    goals.frontiers = [Frontier(k, cells, (100, 100 + 40 * k), 5, 1.0, 1.0, 1.0, 0.5) for k in range(2)]
    goals.cell, goals.frontier = (100, 100), 0
    goals.reason = goals.chosen_reason = "nearest frontier (1.0 m)"
    for _ in range(3):
        sel = goals.commit(Selection(1, (100, 140), np.array([0.5, 0.6]), "nearest frontier (0.9 m)"))
        assert sel.frontier == 0
        goals.reason = sel.reason
    assert goals.reason == "kept frontier 0 (commitment): nearest frontier (1.0 m)"


def test_a_frontier_too_near_for_a_new_list_is_looked_beyond_before_the_timer_chooses_again():
    """If the re-selection timer fires on the step the agent comes within 0.5 m of its frontier, before
    the plan can read it as reached, the new list leaves that frontier out (nearer than
    ``min_distance_m``): the agent walks to another, finds the first one nearest again and goes back,
    back and forth for hundreds of steps."""
    from l3mvn.agent.decision import GoalKind
    from l3mvn.agent.modular.exploration import ExplorationGoals
    from l3mvn.agent.planning import LocalPlanner

    config = Config()
    n = 200
    explored = np.zeros((n, n), bool)
    explored[58:142, 38:180] = True  # a walled room, open to the east (unknown beyond x = 9 m) ...
    obstacle = np.zeros((n, n), bool)
    obstacle[58:61, 38:180] = obstacle[139:142, 38:180] = obstacle[58:142, 38:41] = True
    obstacle[58:61, 106:118] = False  # ... with a door to the north

    def at(agent_cell):
        return SemanticMap(
            obstacle=obstacle,
            explored=explored,
            visited=np.zeros_like(explored),
            categories=np.zeros((1, n, n), bool),
            category_names=("toilet",),
            looked=explored,
            resolution_m=0.05,
            start_xy=(0.0, 0.0),
            agent_cell=agent_cell,
            agent_heading=0.0,
            local_cells=n,
            footprint_radius_cells=3,
        )

    goals = ExplorationGoals(
        NearestFrontier(), config, LocalPlanner.for_sim(config.planner, config.map.resolution_m, config.sim)
    )
    goals.reselect(at((100, 80)), "toilet", np.random.default_rng(0))
    assert goals.kind == GoalKind.FRONTIER and goals.cell[0] < 62  # the door, 2.6 m away
    door = goals.cell
    for _ in range(config.agent.replan_every):
        goals.tick()
    assert goals.due(at((100, 80)))  # still on the way: the timer re-selects as usual
    near = at((door[0] + 7, door[1]))  # 0.35 m from the door
    assert all(f.center[0] > 62 for f in goals.extract(near))  # why it matters: the door is gone
    assert not goals.due(near)


def test_with_no_other_frontier_left_the_edge_beside_guessed_obstacles_is_one():
    """Depth too near to read at a door frame puts guessed obstacles just through the door; the
    frontier there can shrink below ``min_cluster_cells``, leaving the map no frontier, and the agent
    would draw unreachable random cells for many steps. Guesses are the weakest evidence on the map:
    once nothing else is left unknown, the edge beside them is a frontier (the planner still walks
    round them)."""
    from l3mvn.agent.decision import GoalKind
    from l3mvn.agent.modular.exploration import ExplorationGoals
    from l3mvn.agent.planning import LocalPlanner

    config = Config()
    n = 200
    explored = np.zeros((n, n), bool)
    explored[58:142, 38:142] = True  # a closed room ...
    obstacle = np.zeros((n, n), bool)
    obstacle[58:61, 38:142] = obstacle[139:142, 38:142] = obstacle[58:142, 38:41] = obstacle[58:142, 139:142] = True
    obstacle[58:61, 84:100] = False  # ... with a door to the north, 0.8 m wide
    inferred = np.zeros((n, n), bool)
    inferred[57, 83:101] = True  # guesses just beyond it, on unknown floor
    inferred[45:57, 90] = True  # and a ray of them
    obstacle |= inferred

    def goals_at(guesses, obstacle=obstacle):
        sem_map = SemanticMap(
            obstacle=obstacle,
            explored=explored,
            visited=np.zeros_like(explored),
            categories=np.zeros((1, n, n), bool),
            category_names=("toilet",),
            looked=explored,
            resolution_m=0.05,
            start_xy=(0.0, 0.0),
            agent_cell=(110, 90),
            agent_heading=0.0,
            local_cells=n,
            footprint_radius_cells=3,
            inferred=guesses,
        )
        goals = ExplorationGoals(
            NearestFrontier(), config, LocalPlanner.for_sim(config.planner, config.map.resolution_m, config.sim)
        )
        goals.reselect(sem_map, "toilet", np.random.default_rng(0))
        return goals

    goals = goals_at(inferred)
    assert goals.kind == GoalKind.FRONTIER and goals.cell[0] < 62  # the door
    assert abs(goals.cell[1] - 92) <= 8
    # The same cells seen by depth are a wall across the door: no frontier there.
    assert not any(f.center[0] < 62 for f in goals_at(None).frontiers)
    # While another way out is left, the guesses stand.
    south = obstacle.copy()
    south[139:142, 60:76] = False
    goals = goals_at(inferred, south)
    assert goals.frontiers and all(f.center[0] > 130 for f in goals.frontiers)


class _WholeFrames(BuiltinSimulator):
    """The built-in simulator handing over every frame whole, as a backend of arrays would."""

    def _observe(self, collided: bool):
        obs = super()._observe(collided)
        return dataclasses.replace(obs, frame=CameraFrame.of(obs.rgb, obs.depth, obs.semantic))


def test_an_episode_on_frames_made_as_read_equals_the_episode_on_whole_frames(tiny_scene):
    """At a size the mapper strides (240x320 -> 120x160) the agent and the task read only some pixels
    of each frame; the episode must be the one whole frames give, step for step."""
    cfg = dataclasses.replace(SimConfig().with_frame(240, 320), max_steps=120)
    runs = []
    for sim in (BuiltinSimulator(tiny_scene, cfg), _WholeFrames(tiny_scene, cfg)):
        result, events = _run(sim, _agent(sim), _episode())
        runs.append(
            ([(e.action, e.pose) for e, _ in events], {k: v for k, v in result.to_json().items() if k != "seconds"})
        )
    assert runs[0] == runs[1]

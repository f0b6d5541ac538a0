"""The task's measures read the simulator and the task, never the policy: two policies that walk the
same way get the same failure cause, coverage and confirmation, whatever they say of themselves.

The house is tests/conftest.py::draw_two_room_house: the toilet in the north-east corner of the east
room, the agent starting in the west room.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from l3mvn.agent.decision import Decision
from l3mvn.agent.mapping import SemanticMap
from l3mvn.agent.modular import MapAgent
from l3mvn.agent.policies.global_policies import CostUtility
from l3mvn.core.camera import CameraIntrinsics, depth_to_points
from l3mvn.core.config import Config, SimConfig, TaskConfig
from l3mvn.core.errors import L3MVNError
from l3mvn.core.frames import CameraFrame
from l3mvn.core.grid import disk
from l3mvn.core.types import Action, EpisodeBrief, Observation, Pose
from l3mvn.run.session import EpisodeSession
from l3mvn.world.episode import Episode
from l3mvn.world.sim.simulator import BuiltinSimulator
from l3mvn.world.task import ObjectNavTask
from l3mvn.world.task.views import ViewRecord

START = Pose(x=2.5, y=2.0, heading=math.pi)  # west room, facing away from the door
EPISODE = Episode(episode_id=0, scene="Tiny", floor=0, start=START, goal="toilet")


def _config(max_steps: int) -> Config:
    return Config(sim=dataclasses.replace(SimConfig().with_frame(60, 80), max_steps=max_steps))


def _run(scene, policy, config: Config):
    env = BuiltinSimulator(scene, config.sim)
    session = EpisodeSession(env, ObjectNavTask(scene, config), policy, policy_name="p", config_hash="t")
    session.start(EPISODE)
    return session.run()


class _Replay:
    """Takes the given actions in order; with ``claims`` it also says things about itself that are not
    true: the target confirmed, stuck, and a map explored everywhere."""

    def __init__(self, actions: list[Action], claims: bool) -> None:
        self.actions, self.claims = actions, claims

    def reset(self, episode: EpisodeBrief) -> None:
        assert type(episode) is EpisodeBrief  # never the world's Episode, with its ground truth
        self.i = 0

    def change_target(self, goal: str) -> None:
        pass

    def act(self, obs: Observation) -> Action | Decision:
        action = self.actions[self.i]
        self.i += 1
        if not self.claims:
            return action
        n = 64
        everything = np.ones((n, n), bool)
        boasted = SemanticMap(
            obstacle=~everything,
            explored=everything,
            visited=~everything,
            categories=everything[None],
            category_names=("toilet",),
            looked=everything,
            resolution_m=1.0,
            start_xy=(0.0, 0.0),
            agent_cell=(32, 32),
            agent_heading=0.0,
            local_cells=n,
            footprint_radius_cells=1,
        )
        return Decision(action=action, target_seen=True, stuck=True, map=boasted)


def test_two_policies_walking_the_same_way_get_the_same_measures_whatever_they_report(tiny_scene):
    config = _config(60)  # too few steps to reach the toilet: a failure with a cause
    agent_run = []
    agent = MapAgent(CostUtility(), tiny_scene.categories, config)
    env = BuiltinSimulator(tiny_scene, config.sim)
    obs = env.reset(EPISODE)
    agent.reset(EPISODE.brief)
    while not env.done:
        action = agent.act(obs).action
        agent_run.append(action)
        obs = env.step(action)
    honest = _run(tiny_scene, _Replay(agent_run, claims=False), config)
    boaster = _run(tiny_scene, _Replay(agent_run, claims=True), config)
    mapper = _run(tiny_scene, MapAgent(CostUtility(), tiny_scene.categories, config), config)
    assert honest.success == 0.0 and honest.steps == 60
    for other in (boaster, mapper):
        assert (other.failure, other.extra["coverage"], other.extra["confirmed"]) == (
            honest.failure,
            honest.extra["coverage"],
            honest.extra["confirmed"],
        )
    assert honest.failure != "stuck" and 0.2 < honest.extra["coverage"] < 0.9
    # What a policy says of itself is kept, apart, as its own diagnostics.
    assert "agent" not in honest.extra
    assert boaster.extra["agent"] == {"confirmed": True, "stuck": True, "coverage": 1.0}
    assert mapper.extra["agent"]["stuck"] is False and 0.2 < mapper.extra["agent"]["coverage"] < 0.9


def test_the_target_is_confirmed_by_the_frames_once_enough_of_it_was_seen_up_close(tiny_scene):
    config = _config(500)
    result = _run(tiny_scene, MapAgent(CostUtility(), tiny_scene.categories, config), config)
    assert result.success == 1.0 and result.extra["confirmed"] is True
    strict = dataclasses.replace(config, task=TaskConfig(confirm_min_cells=10_000))
    assert _run(tiny_scene, MapAgent(CostUtility(), tiny_scene.categories, strict), strict).extra["confirmed"] is False


def _frame(env: BuiltinSimulator, pose: Pose, tilt: float = 0.0) -> Observation:
    return Observation(
        frame=env.renderer.render(pose, tilt),
        pose=pose,
        tilt=tilt,
        goal="toilet",
        step=0,
        collided=False,
        categories=env.categories,
    )


def test_the_floor_seen_grows_with_each_view_and_stops_at_the_walls(tiny_scene):
    config = _config(500)
    env = BuiltinSimulator(tiny_scene, config.sim)
    record = ViewRecord(tiny_scene, config)
    task = ObjectNavTask(tiny_scene, config)
    rows, cols = task.reachable_cells(START)
    seen = []
    for k in range(12):  # a full turn in place, 30 degrees a view
        pose = Pose(START.x, START.y, START.heading + k * math.pi / 6)
        record.add(_frame(env, pose), pose)
        seen.append(record.coverage(rows, cols))
    assert all(b >= a for a, b in zip(seen, seen[1:])) and seen[-1] > seen[0] * 3
    west, behind_the_wall = np.zeros_like(tiny_scene.walkable), np.zeros_like(tiny_scene.walkable)
    west[10:100, 10:95] = True
    behind_the_wall[10:45, 110:190] = True  # the east room's north half: no ray through the door reaches it
    assert record.seen_floor[west & tiny_scene.walkable].mean() > 0.95
    assert not record.seen_floor[behind_the_wall].any()
    rooms = np.zeros_like(tiny_scene.walkable)  # as conftest draws them, a cell wider (an edge may floor outside)
    rooms[9:101, 9:96] = rooms[9:101, 104:191] = rooms[49:75, 94:106] = True
    assert not record.seen_floor[~rooms].any()  # never inside a wall


def test_the_goal_is_seen_only_in_view_and_within_the_sensors_range(tiny_scene):
    config = _config(500)
    env = BuiltinSimulator(tiny_scene, config.sim)
    record = ViewRecord(tiny_scene, config)
    toilet = Pose(8.9, 1.6, -math.pi / 4)  # east room, 1.2 m from the toilet, facing it
    record.add(_frame(env, Pose(toilet.x, toilet.y, toilet.heading + math.pi)), toilet)  # back to it
    assert not record.confirmed
    record.add(_frame(env, toilet), toilet)
    assert record.confirmed
    record.retarget()
    assert not record.confirmed and record.seen_floor.any()


def test_measure_settings_out_of_range_are_refused_in_one_line():
    for name in ("confirm_min_cells", "view_rows"):
        with pytest.raises(L3MVNError, match=f"{name} must be >= 1"):
            TaskConfig(**{name: 0})


def _reference_record(seen_floor, goal_seen, obs, pose, config, scene):
    """The task's record of one frame as whole-array numpy: the points of the camera's own
    back-projection, marked as the module docstring of ``views`` describes (the kernel's reference)."""
    depth, semantic, tilt, res = obs.frame.depth, obs.frame.semantic, obs.tilt, scene.resolution_m
    intrinsics = CameraIntrinsics.from_sim(config.sim, *depth.shape)
    valid = np.isfinite(depth) & (depth > 0) & (depth < config.sim.max_depth_m)
    cloud = depth_to_points(np.where(valid, depth, 0.0).astype(np.float32), intrinsics, pose, tilt)
    points = np.full((*depth.shape, 3), np.nan, dtype=np.float32)
    points[valid] = cloud.points
    floor = valid.copy()
    floor[valid] = cloud.points[:, 2] < config.sim.max_climb_m

    def mark(grid, xy):
        rows, cols = np.floor(xy[:, 1] / res).astype(np.int64), np.floor(xy[:, 0] / res).astype(np.int64)
        ok = (rows >= 0) & (rows < grid.shape[0]) & (cols >= 0) & (cols < grid.shape[1])
        grid[rows[ok], cols[ok]] = True

    def between(a, b):
        length = np.hypot(b[:, 0] - a[:, 0], b[:, 1] - a[:, 1])
        a, b, length = a[length > res / 2], b[length > res / 2], length[length > res / 2]
        count = np.ceil(length / (res / 2)).astype(np.int64)
        seg = np.repeat(np.arange(len(a)), count - 1)
        k = np.arange(len(seg)) - np.repeat(np.cumsum(count - 1) - (count - 1), count - 1) + 1
        t = (k / count[seg])[:, None].astype(np.float32)
        return a[seg] + t * (b[seg] - a[seg])

    mark(seen_floor, points[floor])
    reach = np.hypot(points[..., 0] - pose.x, points[..., 1] - pose.y)
    wall = np.where(valid & ~floor, reach, np.inf)
    has_wall = np.isfinite(wall).any(axis=0)
    row = np.where(has_wall, wall.argmin(axis=0), np.where(floor, reach, -1.0).argmax(axis=0))
    columns = np.flatnonzero(has_wall | floor.any(axis=0))
    end = points[row[columns], columns, :2]
    start = np.empty_like(end)
    start[:, 0], start[:, 1] = pose.x, pose.y
    mark(seen_floor, np.concatenate([start, between(start, end)]))
    pairs = floor[:-1] & floor[1:]
    mark(seen_floor, between(points[:-1, :, :2][pairs], points[1:, :, :2][pairs]))
    radius = int(math.floor(config.sim.agent_radius_m / res + 1e-9))
    body = np.argwhere(disk(radius)) - radius + scene.cell_of(pose.x, pose.y)
    seen_floor[body[:, 0], body[:, 1]] = True
    if obs.goal in obs.categories:
        mark(goal_seen, points[valid & (semantic == obs.goal_id)])


def test_the_compiled_record_marks_the_cells_of_the_cameras_own_back_projection(tiny_scene):
    """Frames from both rooms, level and tilted, one of them with depths a sensor reports as nothing
    (NaN, 0, beyond range): every frame marks exactly the cells the array reference marks."""
    config = Config(sim=SimConfig().with_frame(120, 160))
    env = BuiltinSimulator(tiny_scene, config.sim)
    record = ViewRecord(tiny_scene, config)
    floor, goal = np.zeros_like(record.seen_floor), np.zeros_like(record.goal_seen)
    rng = np.random.default_rng(0)
    walkable = np.argwhere(tiny_scene.walkable)
    for k in range(24):
        r, c = walkable[rng.integers(len(walkable))]
        x, y = tiny_scene.cell_center(r, c)
        pose = Pose(float(x), float(y), float(rng.uniform(-math.pi, math.pi)))  # as the simulator gives it
        tilt = (0.0, -math.pi / 6)[k % 2]
        obs = _frame(env, pose, tilt)
        if k == 5:
            depth = obs.frame.depth.copy()
            depth[rng.random(depth.shape) < 0.1] = np.nan
            depth[rng.random(depth.shape) < 0.1] = 0.0
            depth[rng.random(depth.shape) < 0.1] = config.sim.max_depth_m + 1.0
            obs = dataclasses.replace(obs, frame=CameraFrame.of(obs.frame.rgb, depth, obs.frame.semantic))
        before = record.seen_floor.sum()
        record.add(obs, pose)
        _reference_record(floor, goal, obs, pose, config, tiny_scene)
        assert np.array_equal(record.seen_floor, floor) and np.array_equal(record.goal_seen, goal), k
        assert record.seen_floor.sum() >= before
    assert goal.any() and floor.sum() > 1000  # the toilet was in view, and much floor

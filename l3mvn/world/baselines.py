"""Baselines on the world side: the shortest-path oracle, the frontier oracle's ground-truth reader
and the paper's random walk.

The oracle is a check of the simulator and the metrics, not a method: it reads the environment's
ground truth (a geodesic field over the cells where the agent's centre may stand) and walks downhill.
``ObjectDistances`` is what the frontier oracle (``l3mvn.agent.policies.oracle_frontier``) knows of
the world: the ceiling any language prior choosing among frontiers is measured against.
"""

from __future__ import annotations

import math
import zlib

import numpy as np
from scipy import ndimage as ndi

from l3mvn.core.types import Action, EpisodeBrief, Observation, Pose, wrap_angle
from l3mvn.world.sim.base import MotionModel
from l3mvn.world.task import GoalRegion, ObjectNavTask, geodesic_field

_NEIGHBOURS = np.array([(-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)])


class OraclePolicy:
    """Follows the ground-truth shortest path to the success region, then stops. It plans on the
    environment's motion model (``MotionModel.forward_result``)."""

    name = "oracle"
    lookahead_cells = 8
    # Where the greedy walk stalls this near the region, the way in is searched over the motion model
    # itself: a region a few cells wide (habitat's 0.1 m around a single view point) can lie between
    # the poses that 0.25 m steps and 30-degree turns reach greedily.
    search_radius_m = 1.5
    search_states = 30_000
    stuck = False  # it reads the true distance field: never stuck by its own account

    def __init__(self, env: MotionModel, task: ObjectNavTask) -> None:
        self.env, self.task = env, task
        self._goal = ""
        self._fields: dict[str, np.ndarray] = {}
        self._field: np.ndarray | None = None
        self._plan: list[Action] = []  # the searched way into the region, popped from the end

    def reset(self, episode: EpisodeBrief) -> None:
        self.change_target(episode.goal)

    def change_target(self, goal: str) -> None:
        """Walk to ``goal`` from here on (episode start, or the dashboard's mid-episode change)."""
        self._plan = []
        if goal not in self._fields:
            scene = self.env.scene
            region = self.task.region(goal).region & scene.walkable
            self._fields[goal] = geodesic_field(scene.walkable, region, scene.resolution_m)
        self._goal, self._field = goal, self._fields[goal]

    def act(self, obs: Observation) -> Action:
        """Greedy on the true dynamics: of the 360/turn headings, head for the one whose forward
        move lands lowest on the distance field; move when already facing it."""
        assert self._field is not None
        if self.task.in_success_region(obs.pose, self._goal):
            return Action.STOP
        scene, pose = self.env.scene, obs.pose
        here = self._value(pose.x, pose.y)
        turn = self.env.cfg.turn_angle_rad
        n = max(1, round(2 * math.pi / turn))
        best_k, best_v = 0, here
        for k in sorted(range(-(n // 2), n - n // 2), key=abs):
            end, _ = self.env.forward_result(Pose(pose.x, pose.y, pose.heading + k * turn))
            v = self._value(end.x, end.y)
            if v < best_v - 1e-6:
                best_k, best_v = k, v
        if not math.isfinite(here):
            return Action.STOP  # no path from here to the goal: walking cannot help
        if self._plan:
            return self._plan.pop()
        if best_v >= here and here <= self.search_radius_m:
            self._plan = self._search_into_region(pose)
            if self._plan:
                return self._plan.pop()
        if best_v >= here:
            # No single move helps (a corner tighter than one step): turn towards the path ahead.
            r, c = scene.cell_of(pose.x, pose.y)
            tx, ty = scene.cell_center(*self._descend(r, c))
            err = wrap_angle(math.atan2(ty - pose.y, tx - pose.x) - pose.heading)
            return Action.TURN_LEFT if err > 0 else Action.TURN_RIGHT
        if best_k == 0:
            return Action.MOVE_FORWARD
        return Action.TURN_LEFT if best_k > 0 else Action.TURN_RIGHT

    def _search_into_region(self, start: Pose) -> list[Action]:
        """The shortest action sequence (breadth first over the simulator's own forward move and
        turns) from ``start`` to a pose inside the success region, reversed for popping; [] when
        none lies within ``search_radius_m`` and ``search_states``. A state is a map cell and a
        heading: the region is judged by cell, so reaching a cell at all is reaching it."""
        scene, turn = self.env.scene, self.env.cfg.turn_angle_rad
        n = max(1, round(2 * math.pi / turn))
        origin = scene.cell_of(start.x, start.y)
        reach = self.search_radius_m / scene.resolution_m + 1

        def key(pose: Pose, k: int) -> tuple[int, int, int]:
            return (*scene.cell_of(pose.x, pose.y), k % n)

        came: dict[tuple[int, int, int], tuple[tuple[int, int, int] | None, Action | None]] = {
            key(start, 0): (None, None)
        }
        layer = [(start, 0)]
        while layer and len(came) < self.search_states:
            following = []
            for pose, k in layer:
                here = key(pose, k)
                moves = (
                    (Action.MOVE_FORWARD, self.env.forward_result(pose)[0], k),
                    (Action.TURN_LEFT, Pose(pose.x, pose.y, pose.heading + turn), k + 1),
                    (Action.TURN_RIGHT, Pose(pose.x, pose.y, pose.heading - turn), k - 1),
                )
                for action, nxt, j in moves:
                    state = key(nxt, j)
                    if state in came or math.dist(state[:2], origin) > reach:
                        continue
                    came[state] = (here, action)
                    if self.task.in_success_region(nxt, self._goal):
                        return self._actions_to(state, came)
                    following.append((nxt, j))
            layer = following
        return []

    @staticmethod
    def _actions_to(state, came) -> list[Action]:
        actions = []
        while came[state][0] is not None:
            state, action = came[state]
            actions.append(action)
        return actions  # last action first: popped from the end

    def _descend(self, r: int, c: int) -> tuple[int, int]:
        """The cell ``lookahead_cells`` steps down the distance field from (r, c), following the
        lowest neighbour (stops early at the region or a local minimum)."""
        field = self._field
        assert field is not None  # act() runs only after reset() set the goal's field
        h, w = field.shape
        for _ in range(self.lookahead_cells):
            around = np.array([r, c]) + _NEIGHBOURS
            around = around[(around[:, 0] >= 0) & (around[:, 0] < h) & (around[:, 1] >= 0) & (around[:, 1] < w)]
            values = field[around[:, 0], around[:, 1]]
            k = int(np.argmin(values))
            if not values[k] < field[r, c]:
                break
            r, c = int(around[k, 0]), int(around[k, 1])
        return r, c

    def _value(self, x: float, y: float) -> float:
        assert self._field is not None  # act() runs only after reset() set the goal's field
        r, c = self.env.scene.cell_of(x, y)
        return float(self._field[r, c]) if self.env.scene.in_bounds(r, c) else math.inf


def object_distances(task: ObjectNavTask, goal: str) -> GoalRegion:
    """Ground-truth geodesic distance over the floor to the floor beside each goal object: the
    traversible cells nearest to it (within the agent's radius and a cell, or the smallest distance
    up to the success distance at which the instance has floor), as a GoalRegion for its lookups."""
    scene, cfg = task.scene, task.cfg
    res = scene.resolution_m
    labels, _ = ndi.label(scene.category_mask(goal), structure=np.ones((3, 3), dtype=bool))
    trav = scene.traversible
    first = math.ceil(cfg.sim.agent_radius_m / res) + 1
    last = max(first, math.ceil(cfg.task.success_distance_m / res))
    sources = np.zeros_like(trav)
    for box_id, box in enumerate(ndi.find_objects(labels), start=1):
        pad = last + 1
        window = (
            slice(max(box[0].start - pad, 0), box[0].stop + pad),
            slice(max(box[1].start - pad, 0), box[1].stop + pad),
        )
        near = ndi.distance_transform_edt(labels[window] != box_id)
        floor = trav[window]
        reach = near[floor]
        if reach.size and reach.min() <= last:
            sources[window] |= floor & (near <= max(first, float(reach.min())))
    field = geodesic_field(trav, sources, res)
    return GoalRegion(goal=goal, rule="object", region=sources, distance_m=field, length_offset_m=0.0, resolution_m=res)


class ObjectDistances:
    """The ground-truth reader behind ``oracle-frontier``: geodesic metres over the true floor from
    world points to the floor beside the goal's objects (``object_distances``, built once per goal).
    The agent-side frontier oracle is handed this reader; it never sees the task."""

    def __init__(self, task: ObjectNavTask) -> None:
        self.task = task
        self._regions: dict[str, GoalRegion] = {}

    def __call__(self, goal: str, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
        if goal not in self._regions:
            self._regions[goal] = object_distances(self.task, goal)
        return self._regions[goal].distances_at(xs, ys)


class RandomWalkPolicy:
    """Uniformly random actions over the full action space (the paper's random-walk baseline)."""

    name = "random-walk"
    stuck = False

    def __init__(self, seed: int = 0) -> None:
        self.seed = seed
        self._rng = np.random.default_rng(seed)

    def reset(self, episode: EpisodeBrief) -> None:
        # Seeded by episode, not by order, so results do not depend on scheduling.
        self._rng = np.random.default_rng([self.seed, episode.episode_id, zlib.crc32(episode.scene.encode())])

    def change_target(self, goal: str) -> None:
        """Random actions whatever the target: nothing to change."""

    def act(self, obs: Observation) -> Action:
        return Action(int(self._rng.integers(len(Action))))

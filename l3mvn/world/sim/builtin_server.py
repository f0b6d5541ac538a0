"""Our own simulator behind the habitat bridge's protocol: ``python -m l3mvn.world.sim.builtin_server``.

The same ``serve`` loop and wire format as ``habitat_server``, with the ``BuiltinSimulator`` on a
procedural house as the backend, speaking Habitat's frame like habitat-sim does. It lets the bridge
(process start, framing, frame conversion, a server that dies or hangs) be tested as a real process
without habitat-sim, and checked against the in-process simulator observation for observation.
"""

from __future__ import annotations

import dataclasses
import math
import sys

import numpy as np
import skfmm
from scipy import ndimage as ndi

from l3mvn.core.config import SimConfig
from l3mvn.core.types import Action
from l3mvn.world.episode import Episode
from l3mvn.world.scenes.procedural import generate_house
from l3mvn.world.scenes.scene import SceneMap
from l3mvn.world.sim.habitat_server import ACTIONS, RequestError, read_point, read_rotation, run_server
from l3mvn.world.sim.simulator import BuiltinSimulator

SCENE_PREFIX = "procedural:"


def parse_scene(spec: object) -> SceneMap:
    """``procedural:SEED`` -> that procedural house (the builtin backend's only scene source)."""
    if not isinstance(spec, str) or not spec.startswith(SCENE_PREFIX):
        raise RequestError(f"scene {spec!r}: the builtin server loads '{SCENE_PREFIX}SEED' scenes only")
    seed = spec[len(SCENE_PREFIX) :]
    if not seed.isdigit():
        raise RequestError(f"scene {spec!r}: SEED must be a non-negative integer")
    return generate_house(int(seed))


class BuiltinBackend:
    name = "builtin"

    def __init__(self) -> None:
        self.sim: BuiltinSimulator | None = None

    def versions(self) -> dict[str, str]:
        return {"numpy": np.__version__}

    def op_load(self, request: dict) -> tuple[dict, None]:
        scene = parse_scene(request.get("scene"))
        fields = {f.name for f in dataclasses.fields(SimConfig)}
        cfg = SimConfig(**{k: v for k, v in dict(request.get("sim") or {}).items() if k in fields})
        categories = list(request.get("categories") or [])
        if categories != list(scene.categories):
            raise RequestError(f"categories {categories} differ from the house's {list(scene.categories)}")
        self.sim = BuiltinSimulator(scene, cfg)
        width, height = scene.extent_m
        area = float(scene.navigable.sum()) * scene.resolution_m**2
        return {
            "categories": categories,
            "objects_matched": int(scene.objects.any(axis=(1, 2)).sum()),
            "navigable_area_m2": area,
            "bounds": [[0.0, 0.0, 0.0], [height, cfg.wall_height_m, width]],
        }, None

    def _sim(self) -> BuiltinSimulator:
        if self.sim is None:
            raise RequestError("no scene: send load first")
        return self.sim

    def _reply(self, obs, moved: float) -> tuple[dict, dict]:
        scene = self._sim().scene
        position, rotation = scene.pose_to_habitat(obs.pose)
        return (
            {
                "position": position,
                "rotation": rotation,
                "tilt_deg": math.degrees(obs.tilt),
                "collided": bool(obs.collided),
                "moved_m": moved,
            },
            {"rgb": obs.rgb, "depth": obs.depth, "semantic": obs.semantic},
        )

    def op_reset(self, request: dict) -> tuple[dict, dict]:
        sim = self._sim()
        scene = sim.scene
        position = read_point(request.get("position"), "position")
        pose = scene.pose_from_habitat(list(position), list(read_rotation(request.get("rotation"))))
        goal = request.get("goal", scene.categories[0])
        episode = Episode(episode_id=0, scene=scene.name, floor=scene.floor, start=pose, goal=goal)
        return self._reply(sim.reset(episode), 0.0)

    def op_step(self, request: dict) -> tuple[dict, dict]:
        sim = self._sim()
        action = request.get("action")
        if action not in ACTIONS:
            raise RequestError(f"unknown action {action!r}; valid: {', '.join(ACTIONS)}")
        before = sim.path_length_m
        obs = sim.step(Action.parse(action))
        return self._reply(obs, sim.path_length_m - before)

    def op_geodesic(self, request: dict) -> tuple[dict, None]:
        """Fast Marching over the walkable grid (our navmesh), from the start's cell to the nearest
        goal's; points off the grid's walkable cells snap to the nearest one, as habitat's do."""
        scene = self._sim().scene
        start, goals = request.get("start"), request.get("goals")
        if not isinstance(goals, list) or not goals:
            raise RequestError("geodesic needs a non-empty 'goals' list of [p0, p1, p2] points")
        cells = [self._snap(scene, p) for p in [start] + goals]
        sources = np.zeros(scene.shape, bool)
        for r, c in cells[1:]:
            sources[r, c] = True
        passable = scene.walkable
        phi = np.ma.MaskedArray(np.where(sources, -1.0, 1.0), ~passable)
        try:
            field = np.ma.filled(skfmm.distance(phi, dx=scene.resolution_m).astype(np.float64), np.inf)
        except ValueError:  # every goal cell is walled in
            field = np.where(sources, 0.0, np.inf)
        r, c = cells[0]
        # skfmm measures from the zero level set, half a cell outside the sources.
        value = 0.0 if sources[r, c] else float(field[r, c]) + 0.5 * scene.resolution_m
        return {"distance_m": value if math.isfinite(value) else None}, None

    @staticmethod
    def _snap(scene: SceneMap, point: object) -> tuple[int, int]:
        p0, _, p2 = (float(v) for v in read_point(point, "a point"))
        ox, oy = scene.origin_cm
        h, w = scene.shape
        r = int(np.clip(np.floor((p0 - oy / 100.0) / scene.resolution_m), 0, h - 1))
        c = int(np.clip(np.floor((p2 - ox / 100.0) / scene.resolution_m), 0, w - 1))
        if not scene.walkable[r, c]:
            _, (rows, cols) = ndi.distance_transform_edt(~scene.walkable, return_indices=True)
            r, c = int(rows[r, c]), int(cols[r, c])
        return r, c

    def close(self) -> None:
        self.sim = None


def main() -> int:
    return run_server(BuiltinBackend)


if __name__ == "__main__":
    sys.exit(main())

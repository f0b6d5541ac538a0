"""Ground-truth success regions and geodesic distances, computed by Fast Marching on the grid.

Two rules (``TaskConfig.success_rule``), and every number says which one it used:

* ``semexp`` (default, behind the paper's Gibson table): success region = goal footprints dilated by a
  1.0 m disk (straight line, through walls), restricted to reachable traversible cells; the shortest
  length for SPL is the geodesic distance to that region + 1.0 m.
* ``geodesic``: success region = traversible cells whose geodesic distance to a goal footprint is
  <= 1.0 m (paths may cross the agent-radius margin around it); the shortest length is the geodesic
  distance to that region.
* ``hm3d`` / ``mp3d`` (habitat's ObjectNav rule, for scans read from an episode file): success region
  = traversible cells within 0.1 m (geodesic) of any view point of the goal category; the shortest
  length is the geodesic distance to the nearest view point (the region's distance + 0.1 m), which
  is what the file's ``info.geodesic_distance`` holds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import skfmm
from scipy import ndimage as ndi

from l3mvn.core.config import Config
from l3mvn.core.config.task import VIEW_POINT_RULES
from l3mvn.core.errors import L3MVNError
from l3mvn.world.scenes.scan import ScanFloor
from l3mvn.world.scenes.scene import SceneMap


def geodesic_field(passable: np.ndarray, sources: np.ndarray, resolution_m: float) -> np.ndarray:
    """Geodesic distance (metres) from ``sources`` through ``passable`` cells; inf where unreachable."""
    sources = sources & passable
    if not sources.any():
        return np.full(passable.shape, np.inf, dtype=np.float32)
    phi = np.where(sources, -1.0, 1.0)
    try:
        dist = skfmm.distance(np.ma.MaskedArray(phi, ~passable), dx=resolution_m)
    except ValueError:  # no passable cell borders a source: nothing else is reachable
        return np.where(sources, 0.0, np.inf).astype(np.float32)
    out = np.ma.filled(dist.astype(np.float64), np.inf)
    # skfmm measures from the zero level set, half a cell outside the sources: add it back so a
    # neighbour of a source is one cell away, as cell-centre distances are.
    out = np.where(sources, 0.0, np.maximum(out, 0.0) + 0.5 * resolution_m)
    return out.astype(np.float32)


@dataclass(frozen=True, eq=False)
class GoalRegion:
    """Where an episode for ``goal`` in ``scene`` succeeds, and distances to it."""

    goal: str
    rule: str
    region: np.ndarray
    distance_m: np.ndarray
    length_offset_m: float
    resolution_m: float

    def distance_at(self, x: float, y: float) -> float:
        r, c = int(math.floor(y / self.resolution_m)), int(math.floor(x / self.resolution_m))
        h, w = self.distance_m.shape
        if not (0 <= r < h and 0 <= c < w):
            return math.inf
        return float(self.distance_m[r, c])

    def distances_at(self, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
        """``distance_at`` for arrays of world points (points off the grid read inf)."""
        rows = np.floor(np.asarray(ys) / self.resolution_m).astype(np.int64)
        cols = np.floor(np.asarray(xs) / self.resolution_m).astype(np.int64)
        h, w = self.distance_m.shape
        ok = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
        out = np.full(rows.shape, np.inf)
        out[ok] = self.distance_m[rows[ok], cols[ok]]
        return out

    def contains(self, x: float, y: float) -> bool:
        return self.distance_at(x, y) == 0.0

    def shortest_path_length(self, x: float, y: float) -> float:
        """The ``l`` of SPL from a start point, per this region's rule."""
        return self.distance_at(x, y) + self.length_offset_m


def goal_region(scene: SceneMap, goal: str, cfg: Config) -> GoalRegion:
    if cfg.task.success_rule in VIEW_POINT_RULES:
        scene.category_mask(goal)  # an unknown category is an error naming the valid ones
        return view_point_region(scene, goal, cfg)
    footprint = scene.category_mask(goal)
    if not footprint.any():
        raise L3MVNError(
            f"goal {goal!r} is not present in scene {scene.key}; "
            f"present goals: {', '.join(scene.present_goals()) or 'none'}"
        )
    return footprint_region(scene, footprint, cfg, goal)


def view_point_region(scene: SceneMap, goal: str, cfg: Config) -> GoalRegion:
    """Habitat's rule: within ``view_point_distance_m`` of a view point of ``goal`` (see the module
    docstring). View points off the traversible grid are snapped to the nearest traversible cell
    within that distance (our grid and habitat's navmesh differ by a cell at walls); farther ones
    are dropped. No view point on this floor: an empty region (every episode for it is ``no_path``)."""
    rule, res = cfg.task.success_rule, scene.resolution_m
    if not isinstance(scene, ScanFloor):
        raise L3MVNError(
            f"success rule {rule!r} needs the view points of an ObjectNav episode file; scene "
            f"{scene.key} has none: use --rule semexp or geodesic, or a --dataset with --scenes"
        )
    trav = scene.traversible
    points = scene.view_points.get(goal, np.zeros((0, 2)))
    sources = np.zeros(trav.shape, bool)
    if len(points):
        rows = np.floor(points[:, 1] / res).astype(np.int64)
        cols = np.floor(points[:, 0] / res).astype(np.int64)
        ok = (rows >= 0) & (rows < trav.shape[0]) & (cols >= 0) & (cols < trav.shape[1])
        sources[rows[ok], cols[ok]] = True
        off = sources & ~trav
        if off.any():
            dist, (near_r, near_c) = ndi.distance_transform_edt(~trav, return_indices=True)
            snap = off & (dist * res <= cfg.task.view_point_distance_m)
            sources[near_r[snap], near_c[snap]] = True
            sources &= trav
    to_points = geodesic_field(trav, sources, res)
    region = trav & (to_points <= cfg.task.view_point_distance_m)
    dist = geodesic_field(trav, region, res)
    return GoalRegion(
        goal=goal,
        rule=rule,
        region=region & np.isfinite(dist),
        distance_m=dist,
        length_offset_m=cfg.task.view_point_distance_m if region.any() else 0.0,
        resolution_m=res,
    )


def footprint_region(scene: SceneMap, footprint: np.ndarray, cfg: Config, label: str) -> GoalRegion:
    """The success region of any footprint mask under ``cfg.task.success_rule`` (``goal_region`` passes a
    category's; the scene audit passes one instance's); ``label`` names it in the result."""
    res = scene.resolution_m
    trav = scene.traversible
    task = cfg.task
    if task.success_rule in VIEW_POINT_RULES:
        raise L3MVNError(
            f"success rule {task.success_rule!r} judges view points, not object footprints: "
            "audit with --rule semexp or geodesic"
        )
    radius = int(round(task.success_distance_m / res))
    if task.success_rule == "semexp":
        # Dilation by a disk = a Euclidean distance threshold (a 41x41 structuring element is slow).
        region = (ndi.distance_transform_edt(~footprint) <= radius) & trav
        dist = geodesic_field(trav, region, res)
        offset = task.success_distance_m
    else:
        # The navmesh keeps an agent radius away from objects: let paths cross that margin to touch it.
        margin = math.ceil(cfg.sim.agent_radius_m / res) + 1
        near = ndi.distance_transform_edt(~footprint) <= margin
        to_object = geodesic_field(trav | near, footprint, res)
        region = trav & (to_object <= task.success_distance_m)
        dist = geodesic_field(trav, region, res)
        offset = 0.0
    return GoalRegion(
        goal=label,
        rule=task.success_rule,
        region=region & np.isfinite(dist),
        distance_m=dist,
        length_offset_m=offset,
        resolution_m=res,
    )

"""Training samples for the PONI network, from full house maps and nothing else (no agent, no episode).

A sample is what an agent's map could look like part-way through a search, with the answers the
full house gives. From a random start, views follow each other towards the revealed map's
frontier (nearer frontier cells likelier, as a searching agent goes); each view reveals, all round
and out to the depth range, every floor or object cell a ray reaches before it meets a wall. An
object does not stop a ray: the camera sits above most furniture, and the agent's map records the
floor behind it. The revealed cells become the three layers the agent's map has: explored, obstacle
(revealed and not floor) and the categories.

Labels, at the revealed map's frontier cells only (explored floor next to unexplored cells, as the
agent's frontier is the explored edge less obstacles): the object potential of each goal present in
the house, ``1 - d / range_m`` with d the geodesic metres over the true floor to the goal's nearest
instance; the area potential, the unexplored floor of the connected region the cell opens onto,
over ``area_scale_m2``. A network cell's label is the best of its frontier cells' (the policy reads a
frontier as the best of its cells). A goal absent from the house, or with no floor within the
success distance, has no label (its potential cannot be told from the map).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy import ndimage as ndi

from l3mvn.agent.planning import distance_field
from l3mvn.agent.potentials import OUTPUTS, WindowGrid, window_features
from l3mvn.core.categories import GIBSON_CATEGORIES, GOAL_CATEGORIES
from l3mvn.core.config import PotentialConfig
from l3mvn.world.scenes.procedural import generate_house
from l3mvn.world.scenes.scene import SceneMap

NO_LABEL = 255  # labels are stored as uint8: 0..254 for [0, 1], this for "no label here"

# A floor to learn from: a scene, or the seed of a procedural house (built where it is used, so a
# worker process receives a number, not a map).
Source = SceneMap | int


def source_scene(source: Source) -> SceneMap:
    return generate_house(source) if isinstance(source, int) else source


@dataclass(frozen=True)
class RevealOptions:
    """How a partial map is drawn: up to ``max_views`` views (at least one), each seeing
    ``rays`` bearings out to ``range_m``; the next view is a frontier cell, likelier the nearer it
    is (weight exp(-d / ``step_m``))."""

    max_views: int = 24
    rays: int = 720
    range_m: float = 5.0  # the simulator's depth range
    step_m: float = 2.0
    goal_reach_m: float = 0.25  # floor this near a goal object counts as at the goal ...
    goal_far_m: float = 1.0  # ... else the floor nearest it, if within this (the success distance)


@dataclass(frozen=True)
class Sample:
    """One window: ``features`` (len(CHANNELS), n, n) uint8 (x 255) and ``labels`` (len(OUTPUTS), n, n)
    uint8 (x 254, NO_LABEL where unlabelled)."""

    house: str
    features: np.ndarray
    labels: np.ndarray


class HouseTruth:
    """What the full map of one floor says, computed once per floor: the floor, the walls, the
    categories in SemExp's order, and each goal's geodesic field."""

    def __init__(self, scene: SceneMap, cfg: PotentialConfig, options: RevealOptions) -> None:
        self.scene, self.cfg, self.options = scene, cfg, options
        self.floor = scene.free
        shape = scene.shape
        index = {name: k for k, name in enumerate(scene.categories)}
        self.categories = np.zeros((len(GIBSON_CATEGORIES),) + shape, dtype=bool)
        for k, name in enumerate(GIBSON_CATEGORIES):
            if name in index:
                self.categories[k] = scene.objects[index[name]]
        self.objects = scene.object_any
        self.see_through = self.floor | self.objects
        res = scene.resolution_m
        self.goal_m = np.full((len(GOAL_CATEGORIES),) + shape, np.inf, dtype=np.float32)
        self.present = np.zeros(len(GOAL_CATEGORIES), dtype=bool)
        for g, name in enumerate(GOAL_CATEGORIES):
            if name not in index or not scene.objects[index[name]].any():
                continue
            near = _goal_floor(scene.objects[index[name]], self.floor, res, options)
            if near.any():
                self.present[g] = True
                self.goal_m[g] = distance_field(self.floor, near, resolution_m=res, limit_m=cfg.range_m)
        # Starts in the largest floor region: small islands are rasterisation crumbs, not rooms.
        n, labels, stats, _ = cv2.connectedComponentsWithStats(self.floor.view(np.uint8), connectivity=8)
        main = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA])) if n > 1 else 0
        self.starts = np.argwhere(labels == main) if n > 1 else np.zeros((0, 2), dtype=np.int64)
        angles = np.linspace(0.0, 2 * np.pi, options.rays, endpoint=False)
        steps = np.arange(1, round(options.range_m / res) + 1)
        self._dr = np.rint(np.sin(angles)[:, None] * steps[None, :]).astype(np.int64)
        self._dc = np.rint(np.cos(angles)[:, None] * steps[None, :]).astype(np.int64)

    def reveal(self, cell: tuple[int, int], seen: np.ndarray) -> None:
        """Mark in ``seen`` what a view from ``cell`` reaches: along each ray, every cell up to and
        including the first wall (a cell neither floor nor object) or the map's edge."""
        h, w = seen.shape
        rr, cc = self._dr + cell[0], self._dc + cell[1]
        inside = (rr >= 0) & (rr < h) & (cc >= 0) & (cc < w)
        open_ = np.zeros(rr.shape, dtype=bool)
        open_[inside] = self.see_through[rr[inside], cc[inside]]
        # A ray stops at its first closed cell (a wall, or off the map) and sees that cell too.
        blocked_before = np.cumsum(~open_, axis=1) - ~open_
        visible = (blocked_before == 0) & inside
        seen[rr[visible], cc[visible]] = True
        seen[cell] = True

    def partial_map(self, rng: np.random.Generator) -> tuple[np.ndarray, tuple[int, int]] | tuple[None, None]:
        """What a search could have seen: the revealed cells and the last view's cell; (None, None)
        where the floor gives no frontier (or no goal to label)."""
        if not len(self.starts) or not self.present.any():
            return None, None
        seen = np.zeros(self.floor.shape, dtype=bool)
        r0, c0 = self.starts[rng.integers(len(self.starts))]
        view = (int(r0), int(c0))
        res = self.scene.resolution_m
        for _ in range(int(rng.integers(1, self.options.max_views + 1))):
            self.reveal(view, seen)
            cells = np.argwhere(self.frontier(seen))
            if not len(cells):
                break
            d = np.hypot(cells[:, 0] - view[0], cells[:, 1] - view[1]) * res
            weight = np.exp(-(d - d.min()) / self.options.step_m)
            r, c = cells[rng.choice(len(cells), p=weight / weight.sum())]
            view = (int(r), int(c))
        if not self.frontier(seen).any():
            return None, None
        return seen, view

    def sample(self, rng: np.random.Generator) -> Sample | None:
        """One partial map and its labels; None where the floor gives no frontier to label."""
        seen, view = self.partial_map(rng)
        if seen is None or view is None:
            return None
        grid = WindowGrid.around(view, self.scene.resolution_m, self.cfg)
        obstacle = seen & ~self.floor
        features = window_features(seen, obstacle, self.categories & seen, GIBSON_CATEGORIES, grid)
        labels = self._labels(seen, self.frontier(seen), grid)
        if (labels == NO_LABEL).all():
            return None
        return Sample(self.scene.key, np.rint(features * 255).astype(np.uint8), labels)

    def frontier(self, seen: np.ndarray) -> np.ndarray:
        """Explored floor with an unexplored 8-neighbour outside the explored blob: as for the agent,
        holes inside what was seen (between rays, behind an object's edge) are not frontiers."""
        outside = ~ndi.binary_fill_holes(seen)
        unseen_near = ndi.binary_dilation(outside, structure=np.ones((3, 3), dtype=bool), border_value=0)
        frontier: np.ndarray = seen & self.floor & unseen_near
        return frontier

    def _labels(self, seen: np.ndarray, frontier: np.ndarray, grid: WindowGrid) -> np.ndarray:
        cfg, res = self.cfg, self.scene.resolution_m
        unexplored = (self.floor & ~seen).view(np.uint8)
        _, regions, stats, _ = cv2.connectedComponentsWithStats(unexplored, connectivity=8)
        area = stats[:, cv2.CC_STAT_AREA].astype(np.float32) * res * res / cfg.area_scale_m2
        area[0] = 0.0  # label 0: not unexplored floor
        opens = ndi.maximum_filter(np.minimum(area, 1.0)[regions], size=3)
        values = np.concatenate([opens[None], np.clip(1.0 - self.goal_m / cfg.range_m, 0.0, 1.0)])
        rows, cols = np.nonzero(frontier)
        wr, wc, inside = grid.to_window(rows, cols)
        out = np.full((len(OUTPUTS), grid.cells, grid.cells), -1.0, dtype=np.float32)
        for k in range(len(OUTPUTS)):
            if k and not self.present[k - 1]:
                continue
            np.maximum.at(out[k], (wr[inside], wc[inside]), values[k][rows[inside], cols[inside]])
        labelled = out >= 0
        coded = np.full(out.shape, NO_LABEL, dtype=np.uint8)
        coded[labelled] = np.rint(out[labelled] * 254).astype(np.uint8)
        return coded


def _goal_floor(goal: np.ndarray, floor: np.ndarray, res: float, options: RevealOptions) -> np.ndarray:
    """The floor cells that count as at the goal: within ``goal_reach_m`` of it, or where the floor
    comes no nearer (an object in a corner, behind another), the nearest floor cells (one cell's
    slack) if within ``goal_far_m``; none beyond that (the goal cannot be reached)."""
    metres = ndi.distance_transform_edt(~goal) * res
    on_floor = metres[floor]
    if not on_floor.size or on_floor.min() > options.goal_far_m:
        return np.zeros_like(floor)
    reach = max(options.goal_reach_m, float(on_floor.min()) + res)
    near: np.ndarray = floor & (metres <= reach)
    return near


def decode_features(features: np.ndarray) -> np.ndarray:
    return features.astype(np.float32) / 255.0


def decode_labels(labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(values in [0, 1], mask of labelled cells)."""
    mask = labels != NO_LABEL
    return np.where(mask, labels.astype(np.float32) / 254.0, 0.0), mask

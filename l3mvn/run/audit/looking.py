"""Standing at one cell and looking around as the agent would: the renderer draws the views, the
agent's own ``Perception`` maps them and its own ``TargetSearch.mask`` judges the map."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from l3mvn.agent.mapping import SemanticMap
from l3mvn.agent.modular.target import TargetSearch
from l3mvn.agent.perception import Perception
from l3mvn.core.camera import CameraIntrinsics, depth_to_points
from l3mvn.core.config import Config
from l3mvn.core.types import Pose, wrap_angle
from l3mvn.run.audit.records import AuditConfig
from l3mvn.world.scenes.scene import SceneMap
from l3mvn.world.sim.render import Renderer


@dataclass(frozen=True, eq=False)
class Target:
    """The instance looked for: its category and the scene cells on and near its footprint."""

    category: str
    cat_id: int  # semantic id: category index + 1
    near: np.ndarray  # footprint dilated by near_cells
    cells: np.ndarray  # (N, 2) footprint cells
    near_box: tuple[int, int, int, int] = (0, 0, 0, 0)  # rows r0:r1, cols c0:c1 of ``near``

    def __post_init__(self) -> None:
        rows, cols = np.flatnonzero(self.near.any(axis=1)), np.flatnonzero(self.near.any(axis=0))
        object.__setattr__(self, "near_box", (int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1))


@dataclass
class Look:
    """The outcome of standing at one cell and looking around."""

    confirmed: bool = False
    pixels: int = 0
    mapped: int = 0
    view: tuple[float, float, float, float] | None = None  # x, y, heading_deg, tilt_deg
    rgb: np.ndarray | None = None


def better(best: Look, look: Look) -> Look:
    """Keep the look with more of the instance in view (mapped cells break ties)."""
    if best.view is None or (look.pixels, look.mapped) > (best.pixels, best.mapped):
        return dataclasses.replace(look, mapped=max(look.mapped, best.mapped))
    best.mapped = max(best.mapped, look.mapped)
    return best


class Looker:
    """Looks around from scene cells of one floor; perception and rule built once and reused."""

    def __init__(self, scene: SceneMap, renderer: Renderer, config: Config, audit: AuditConfig) -> None:
        self.scene, self.renderer, self.audit = scene, renderer, audit
        sim = config.sim
        self.intrinsics = CameraIntrinsics.from_sim(sim, sim.frame_height, sim.frame_width)
        # Ground-truth labels: the audit charges the world, and segmentation errors are the agent's.
        exact = config.replace(policy=dataclasses.replace(config.policy, seg_noise=0.0))
        self.perception = Perception(exact, scene.categories)
        self.judge = TargetSearch(config.agent)

    def look(self, target: Target, cell: np.ndarray) -> Look:
        """Stand at ``cell``, look around into a fresh map; stop at the first view that confirms."""
        scene, audit = self.scene, self.audit
        r, c = int(cell[0]), int(cell[1])
        x, y = scene.cell_center(r, c)
        fr, fc = target.cells[np.argmin(((target.cells - (r, c)) ** 2).sum(axis=1))]
        bearing = math.atan2(fr - r, fc - c) if (fr, fc) != (r, c) else 0.0
        step = 2.0 * math.pi / audit.headings
        # Facing the instance first, then turning away from it both ways.
        offsets = sorted(range(-((audit.headings - 1) // 2), audit.headings // 2 + 1), key=abs)
        # Anchored at the cell's corner, the map grid coincides with the scene grid (see _confirm);
        # with the noise off the episode seed draws nothing.
        self.perception.reset(Pose(x - 0.5 * scene.resolution_m, y - 0.5 * scene.resolution_m, bearing), 0)
        out = Look()
        for j in offsets:
            pose = Pose(x, y, wrap_angle(bearing + j * step))
            for tilt_deg in audit.tilts_deg:
                tilt = math.radians(tilt_deg)
                frame = self.renderer.render(pose, tilt)
                pixels = self._pixels(frame.depth, frame.semantic, target, pose, tilt)
                sem_map = self.perception.update(frame, pose, tilt)
                mapped, ok = self._confirm(sem_map, target, r, c)
                if out.view is None or pixels > out.pixels:
                    out.pixels, out.rgb = pixels, frame.rgb
                    out.view = (round(x, 3), round(y, 3), round(math.degrees(pose.heading), 1), tilt_deg)
                out.mapped = max(out.mapped, mapped)
                if ok:
                    out.confirmed = True
                    return out
        return out

    def _pixels(self, depth: np.ndarray, semantic: np.ndarray, target: Target, pose: Pose, tilt: float) -> int:
        """Pixels of the instance's category whose depth lands on or near its footprint, counted on
        the full rendered frame (pixels with no valid depth, nearer than min_depth_m or beyond
        max_depth_m, cannot be placed)."""
        mine = semantic == target.cat_id
        if not mine.any():
            return 0
        cloud = depth_to_points(np.where(mine, depth, 0.0).astype(np.float32), self.intrinsics, pose, tilt)
        res = self.scene.resolution_m
        rows = np.floor(cloud.points[:, 1] / res).astype(np.int64)
        cols = np.floor(cloud.points[:, 0] / res).astype(np.int64)
        h, w = self.scene.shape
        ok = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
        return int(target.near[rows[ok], cols[ok]].sum())

    def _confirm(self, sem_map: SemanticMap, target: Target, r: int, c: int) -> tuple[int, bool]:
        """The agent's rule on the goal channel restricted to cells on or near this instance.

        The map was reset at cell (r, c)'s corner, so map cell (i, j) is scene cell (i - M/2 + r, j - M/2 + c).
        """
        channel = sem_map.category(target.category)
        half, size = sem_map.size // 2, sem_map.size
        r0, r1, c0, c1 = target.near_box
        mr0, mr1, mc0, mc1 = r0 - r + half, r1 - r + half, c0 - c + half, c1 - c + half
        if mr0 < 0 or mc0 < 0 or mr1 > size or mc1 > size:
            return 0, False
        crop = channel[mr0:mr1, mc0:mc1] & target.near[r0:r1, c0:c1]
        if not crop.any():
            return 0, False
        restricted = np.zeros_like(channel)
        restricted[mr0:mr1, mc0:mc1] = crop
        view = dataclasses.replace(sem_map, categories=restricted[None], category_names=(target.category,))
        mask, ok = self.judge.mask(view, target.category)
        return (0 if mask is None else int(mask.sum())), ok

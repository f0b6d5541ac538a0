"""The audit of one floor: for each goal instance, which poses to try, and what to make of the
looks from them (``InstanceAudit`` and its reason); then each episode's verdict from its start."""

from __future__ import annotations

import time
import zlib
from collections.abc import Iterable
from pathlib import Path

import numpy as np
from scipy import ndimage as ndi

from l3mvn.core.categories import GOAL_CATEGORIES
from l3mvn.core.config import Config
from l3mvn.run.audit.looking import Look, Looker, Target, better
from l3mvn.run.audit.records import EIGHT, AuditConfig, EpisodeAudit, FloorAudit, InstanceAudit, instance_labels
from l3mvn.run.audit.report import write_diagnostic_png
from l3mvn.world.episode import Episode
from l3mvn.world.scenes.scene import SceneMap
from l3mvn.world.sim.render import Renderer
from l3mvn.world.sim.simulator import BuiltinSimulator
from l3mvn.world.sim.world import World
from l3mvn.world.task.regions import footprint_region


class FloorAuditor:
    """Audits the goal instances of one floor; renderer, perception and agent rule built once and reused."""

    def __init__(
        self, scene: SceneMap, cfg: Config | None = None, audit: AuditConfig | None = None, world: World | None = None
    ) -> None:
        """``world``: audit this mesh instead of the one the built-in simulator builds from ``scene``."""
        self.scene = scene
        self.config = cfg or Config()
        self.audit = audit or AuditConfig()
        sim = self.config.sim
        self.renderer = BuiltinSimulator(scene, sim).renderer if world is None else Renderer(world, sim)
        self.looker = Looker(scene, self.renderer, self.config, self.audit)
        self.walk_labels, _ = ndi.label(scene.walkable, structure=EIGHT)
        self._mesh_cells = self._mesh_object_cells()

    def reachable(self, episodes: Iterable[Episode] = ()) -> tuple[np.ndarray, str]:
        """Walkable cells an episode can reach: the components of its starts, else the largest."""
        starts = [self.scene.cell_of(e.start.x, e.start.y) for e in episodes]
        ids = {int(self.walk_labels[r, c]) for r, c in starts if self.scene.in_bounds(r, c)} - {0}
        if ids:
            return np.isin(self.walk_labels, sorted(ids)), "episode starts"
        sizes = np.bincount(self.walk_labels.ravel())
        sizes[0] = 0
        return self.walk_labels == int(np.argmax(sizes)), "largest walkable component"

    def run(
        self, episodes: list[Episode] | None = None, out_dir: Path | None = None, all_pngs: bool = False
    ) -> FloorAudit:
        """Every goal instance of the floor, then the given episodes of it; a diagnostic picture per
        instance that is not confirmable (every instance with ``all_pngs``) when ``out_dir`` is given."""
        t0 = time.perf_counter()
        episodes = [e for e in episodes or () if (e.scene, e.floor) == (self.scene.name, self.scene.floor)]
        reachable, source = self.reachable(episodes)
        result = FloorAudit(self.scene.name, self.scene.floor, source, 0.0)
        for category in self.scene.present_goals(GOAL_CATEGORIES):
            labels, n = instance_labels(self.scene, category)
            for k in range(1, n + 1):
                inst, draw = self.instance(category, labels == k, k, reachable)
                result.instances.append(inst)
                if out_dir is not None and (all_pngs or not inst.confirmable):
                    write_diagnostic_png(out_dir, self.scene, self.renderer.world.walls, inst, *draw)
        result.episodes = [self._episode(e, result.instances) for e in episodes]
        result.seconds = time.perf_counter() - t0
        return result

    def instance(self, category: str, footprint: np.ndarray, instance_id: int, reachable: np.ndarray):
        """Audit one instance; returns it and what its diagnostic picture needs (region, tested
        cells, best view's RGB)."""
        scene, audit, res = self.scene, self.audit, self.scene.resolution_m
        rows, cols = np.nonzero(footprint)
        centroid = (int(round(rows.mean())), int(round(cols.mean())))
        d_fp = ndi.distance_transform_edt(~footprint) * res
        walk = scene.walkable
        gap = float(d_fp[walk].min()) if walk.any() else None
        region = footprint_region(scene, footprint, self.config, f"{category}#{instance_id}").region
        region_walk = region & walk
        region_reach = region_walk & reachable
        near = ndi.binary_dilation(footprint, EIGHT, iterations=audit.near_cells) if audit.near_cells else footprint
        rng = np.random.default_rng([audit.seed, zlib.crc32(f"{scene.key}/{category}/{instance_id}".encode())])
        target = Target(category, scene.categories.index(category) + 1, near, np.argwhere(footprint))

        best, tested = Look(), []

        def first_confirming(cells: np.ndarray) -> np.ndarray | None:
            nonlocal best
            for cell in cells:
                look = self.looker.look(target, cell)
                tested.append(cell)
                best = better(best, look)
                if look.confirmed:
                    return cell
            return None

        def spread_in(mask: np.ndarray, comp: int, k: int) -> np.ndarray:
            return self._spread(np.argwhere(mask & (self.walk_labels == comp)), d_fp, k, rng)

        confirmed_in, nearest = set(), None
        for comp in _labels_in(self.walk_labels, region_reach):
            cell = first_confirming(spread_in(region_reach, comp, audit.region_poses))
            if cell is not None:
                confirmed_in.add(comp)
                d = float(d_fp[cell[0], cell[1]])
                nearest = d if nearest is None else min(nearest, d)
        confirmable = bool(confirmed_in)
        # A side the episodes cannot reach is tried too: "unreachable" beats "occluded" when it is why.
        elsewhere = region_walk & ~reachable
        confirmed_elsewhere = not confirmable and any(
            first_confirming(spread_in(elsewhere, comp, audit.region_poses)) is not None
            for comp in _labels_in(self.walk_labels, elsewhere)
        )
        if not confirmable and audit.outside_poses:
            ring = walk & reachable & ~region & (d_fp <= audit.search_radius_m)
            cell = first_confirming(self._spread(np.argwhere(ring), d_fp, audit.outside_poses, rng))
            if cell is not None:
                nearest = float(d_fp[cell[0], cell[1]])

        others = [c for k, c in enumerate(scene.categories) if c != category and (scene.objects[k][footprint]).any()]
        reason = None
        if not confirmable:
            ids, mr, mc = self._mesh_cells
            in_mesh = bool((ids == target.cat_id)[ndi.binary_dilation(footprint, EIGHT)[mr, mc]].any())
            if not in_mesh:
                reason = "erased"
            elif gap is None or gap > self.config.task.success_distance_m:
                reason = "no_floor"
            elif not region_walk.any():
                reason = "no_region"
            elif not region_reach.any() or confirmed_elsewhere:
                reason = "unreachable"
            elif best.pixels == 0:
                shared = np.zeros_like(footprint)
                for c in others:
                    shared |= scene.category_mask(c)
                reason = "buried" if (shared[footprint]).all() else "occluded"
            elif nearest is not None:
                reason = "outside_only"
            else:
                reason = "hidden"
        inst = InstanceAudit(
            scene=scene.name,
            floor=scene.floor,
            category=category,
            instance_id=instance_id,
            cells=int(footprint.sum()),
            centroid=centroid,
            gap_m=_metres(gap),
            region_cells=int(region_walk.sum()),
            reachable_region_cells=int(region_reach.sum()),
            confirmable=confirmable,
            reason=reason,
            nearest_confirmable_m=_metres(nearest),
            max_pixels=best.pixels,
            max_mapped_cells=best.mapped,
            shared_with=tuple(others),
            poses_tested=len(tested),
            best_pose=best.view,
            region_components=tuple(_labels_in(self.walk_labels, region_walk)),
            confirmed_components=tuple(sorted(confirmed_in)),
        )
        return inst, (region, np.array(tested, dtype=np.int64).reshape(-1, 2), best.rgb)

    def _mesh_object_cells(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(category id, row, col) of every labelled triangle's centroid: what the world builder kept."""
        world = self.renderer.world
        labelled = world.tri_category > 0
        centre = world.vertices[world.triangles[labelled]].mean(axis=1)
        res = self.scene.resolution_m
        rows = np.clip(np.floor(centre[:, 1] / res).astype(np.int64), 0, self.scene.shape[0] - 1)
        cols = np.clip(np.floor(centre[:, 0] / res).astype(np.int64), 0, self.scene.shape[1] - 1)
        return world.tri_category[labelled], rows, cols

    def _spread(self, cells: np.ndarray, d_fp: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
        """Up to ``k`` cells spread over ``cells`` (the nearest to the footprint, then farthest-point
        sampling), returned nearest first: the first confirming pose is then the nearest one tried."""
        if len(cells) == 0 or k == 0:
            return cells[:0]
        if len(cells) > self.audit.max_candidates:
            cells = cells[np.sort(rng.choice(len(cells), self.audit.max_candidates, replace=False))]
        dist = d_fp[cells[:, 0], cells[:, 1]]
        chosen = [int(np.argmin(dist))]
        gap = ((cells - cells[chosen[0]]) ** 2).sum(axis=1)
        while len(chosen) < min(k, len(cells)):
            j = int(np.argmax(gap))
            if gap[j] == 0:
                break
            chosen.append(j)
            gap = np.minimum(gap, ((cells - cells[j]) ** 2).sum(axis=1))
        picked = cells[chosen]
        return picked[np.argsort(dist[chosen], kind="stable")]

    def _episode(self, ep: Episode, instances: list[InstanceAudit]) -> EpisodeAudit:
        r, c = self.scene.cell_of(ep.start.x, ep.start.y)
        comp = int(self.walk_labels[r, c]) if self.scene.in_bounds(r, c) else 0
        goal = [i for i in instances if i.category == ep.goal]
        ok = tuple(i.instance_id for i in goal if comp and comp in i.confirmed_components)
        reason = None
        if not ok:
            side = [i for i in goal if comp and comp in i.region_components]
            # An instance confirmable from another side only is "unreachable" from this start.
            reason = ",".join(sorted({i.reason or "unreachable" for i in side})) if side else "unreachable"
        return EpisodeAudit(ep.key, ep.goal, ep.object_id, bool(ok), ok, reason)


def audit_floor(
    scene: SceneMap,
    cfg: Config | None = None,
    episodes: list[Episode] | None = None,
    audit: AuditConfig | None = None,
    out_dir: str | Path | None = None,
    all_pngs: bool = False,
) -> FloorAudit:
    """Audit every goal instance of one floor (and the episodes given for it)."""
    out = None if out_dir is None else Path(out_dir)
    return FloorAuditor(scene, cfg, audit).run(episodes, out, all_pngs)


def _labels_in(labels: np.ndarray, mask: np.ndarray) -> list[int]:
    """The nonzero labels present under ``mask``, ascending."""
    return [int(v) for v in np.unique(labels[mask]) if v]


def _metres(v: float | None) -> float | None:
    """A distance as recorded: to the millimetre."""
    return None if v is None else round(float(v), 3)

"""Scene audit: can an agent confirm every goal object the way the success rule needs it to?

An episode only succeeds if the agent, standing in the goal's success region, has *mapped* the goal
well enough for its own confirmation rule. Gaps in the simulated world (an object with no floor near
it, walled in, lost by the world builder, too thin to map) cap the success rate of every policy, so
they are measured here, per goal instance, with the agent's own pieces: the renderer, the
``SemanticMapper`` built as ``MapAgent._update_map`` builds it, and the agent's ``TargetSearch.mask``.

For each instance (8-connected component of a goal category's footprint) the audit stands the agent
on a bounded, deterministic sample of walkable cells in the instance's success region (the rule of
``TaskConfig.success_rule``), looks around (``AuditConfig.headings`` x ``tilts_deg``), maps those
views into a fresh map and asks the agent's rule whether the mapped cells on or near this instance
confirm it. Poses are tried nearest first and the first confirming one ends the search; failing
that, reachable poses outside the region (up to ``search_radius_m``) give the nearest distance from
which it can be confirmed at all. Every instance that is not confirmable gets one reason from
``REASONS``.
"""

from __future__ import annotations

import dataclasses
import math
import time
import zlib
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable

import cv2
import numpy as np
from scipy import ndimage as ndi

from l3mvn.agent.modular.target import TargetSearch
from l3mvn.core.config import Config
from l3mvn.core.errors import L3MVNError
from l3mvn.core.json_values import json_safe
from l3mvn.world.task.regions import footprint_region
from l3mvn.agent.mapping import SemanticMapper
from l3mvn.core.camera import CameraIntrinsics
from l3mvn.core.camera import depth_to_points, downsample_frame
from l3mvn.core.categories import GOAL_CATEGORIES
from l3mvn.world.scenes.scene import SceneMap
from l3mvn.world.sim.render import Renderer
from l3mvn.world.sim.simulator import BuiltinSimulator
from l3mvn.core.types import Pose, wrap_angle
from l3mvn.world.episode import Episode
from l3mvn.world.sim.world import World
from l3mvn.run.viz import category_color
from l3mvn.core.writing import make_folder, write_file

# Why an instance is not confirmable from inside its success region, most fundamental first: the
# first that applies is reported.
REASONS: dict[str, str] = {
    "erased": "the world mesh has no face of it (a taller object's footprint took its cells)",
    "no_floor": "no walkable cell within the success distance (gap_m: to the nearest walkable cell)",
    "no_region": "walkable cells lie within the success distance, none in the success region (geodesic rule)",
    "unreachable": "no reachable success-region pose confirms it (reachable: the walkable components of the "
                   "episode starts, else the largest), but an unreachable one does, or none is reachable",
    "buried": "0 pixels from every tested pose, and every footprint cell is also another category's "
              "(shared_with): the world builds that object on or around it",
    "occluded": "in the mesh, but 0 pixels of it from every tested standing pose (walled in)",
    "outside_only": "confirmable, but only from poses outside its success region",
    "hidden": "pixels seen, never enough mapped cells near it for the agent's confirmation rule",
}

_EIGHT = np.ones((3, 3), dtype=bool)


@dataclass(frozen=True)
class AuditConfig:
    """How hard the audit looks. What it judges by (success rule, mapper, confirmation threshold) is
    the simulator's and the agent's, never its own."""

    headings: int = 12
    tilts_deg: tuple[float, ...] = (-30.0, 0.0)
    region_poses: int = 8  # per reachable walkable component touching the region
    outside_poses: int = 8
    search_radius_m: float = 3.0
    # Pixels and mapped cells count for an instance when they land this close to its footprint:
    # faces sit on footprint edges, and a point on an edge may floor into the cell outside.
    near_cells: int = 2
    max_candidates: int = 3000  # candidate cells subsampled (seeded) before spreading poses
    seed: int = 0

    def __post_init__(self) -> None:
        if self.headings < 1 or self.region_poses < 1 or self.outside_poses < 0 or not self.tilts_deg:
            raise L3MVNError("audit needs >= 1 heading, >= 1 tilt, >= 1 region pose and >= 0 outside poses")
        if not self.search_radius_m > 0 or self.near_cells < 0:
            raise L3MVNError("search_radius_m must be positive and near_cells >= 0")


@dataclass
class InstanceAudit:
    """One goal instance. Distances in metres (straight line, footprint to cell centre); cells are
    (row, col) of the scene grid; ``max_pixels`` is per view at the rendered frame size."""

    scene: str
    floor: int
    category: str
    instance_id: int  # label of the 8-connected component (SemExp's object_id numbering)
    cells: int
    centroid: tuple[int, int]
    gap_m: float | None  # to the nearest walkable cell; None when the floor has none
    region_cells: int  # walkable cells in its success region
    reachable_region_cells: int
    confirmable: bool  # from a reachable standing pose inside its success region
    reason: str | None
    nearest_confirmable_m: float | None  # None: no tested reachable pose within search_radius_m confirms it
    max_pixels: int
    max_mapped_cells: int  # largest near-instance blob the agent's rule saw
    shared_with: tuple[str, ...]  # other categories whose footprints overlap it
    poses_tested: int
    best_pose: tuple[float, float, float, float] | None  # x, y, heading_deg, tilt_deg of the best view
    region_components: tuple[int, ...] = ()  # walkable components holding its region cells
    confirmed_components: tuple[int, ...] = ()  # ... and those from which it was confirmed there

    @property
    def key(self) -> str:
        return f"{self.scene}/{self.floor}/{self.category}#{self.instance_id}"


@dataclass
class EpisodeAudit:
    """Whether an episode's goal can be confirmed from its success region on its start's side."""

    key: str
    goal: str
    object_id: int
    confirmable: bool
    confirming_instances: tuple[int, ...]
    reason: str | None  # "unreachable", or the reasons of the goal's instances on its side


@dataclass
class FloorAudit:
    scene: str
    floor: int
    reachable_from: str  # "episode starts" or "largest walkable component"
    seconds: float
    instances: list[InstanceAudit] = field(default_factory=list)
    episodes: list[EpisodeAudit] = field(default_factory=list)

    @property
    def key(self) -> str:
        return f"{self.scene}/{self.floor}"


@dataclass
class AuditReport:
    source: str
    split: str
    rule: str
    frame: tuple[int, int]
    seconds: float
    floors: list[FloorAudit]

    @property
    def instances(self) -> list[InstanceAudit]:
        return [i for f in self.floors for i in f.instances]

    @property
    def episodes(self) -> list[EpisodeAudit]:
        return [e for f in self.floors for e in f.episodes]

    def reason_counts(self) -> dict[str, int]:
        counts = Counter(i.reason for i in self.instances if i.reason)
        return {r: counts[r] for r in REASONS}

    def to_json(self) -> dict:
        return json_safe({
            "source": self.source, "split": self.split, "rule": self.rule, "frame": list(self.frame),
            "seconds": round(self.seconds, 2), "reasons": REASONS,
            "counts": {"instances": len(self.instances),
                       "confirmable": sum(i.confirmable for i in self.instances),
                       **self.reason_counts(),
                       "episodes": len(self.episodes),
                       "episodes_confirmable": sum(e.confirmable for e in self.episodes)},
            "floors": [{"scene": f.scene, "floor": f.floor, "reachable_from": f.reachable_from,
                        "seconds": round(f.seconds, 2)} for f in self.floors],
            "instances": [dataclasses.asdict(i) for i in self.instances],
            "episodes": [dataclasses.asdict(e) for e in self.episodes],
        })


# --- one floor ---------------------------------------------------------------------------------

@dataclass
class _Look:
    """The outcome of standing at one cell and looking around."""

    confirmed: bool = False
    pixels: int = 0
    mapped: int = 0
    view: tuple[float, float, float, float] | None = None
    rgb: np.ndarray | None = None


class FloorAuditor:
    """Audits the goal instances of one floor; renderer, mapper and agent rule built once and reused."""

    def __init__(self, scene: SceneMap, cfg: Config | None = None, audit: AuditConfig | None = None,
                 world: World | None = None) -> None:
        """``world``: audit this mesh instead of the one the built-in simulator builds from ``scene``."""
        self.scene = scene
        self.config = cfg or Config()
        self.cfg = self.config.sim
        self.audit = audit or AuditConfig()
        self.renderer = BuiltinSimulator(scene, self.cfg).renderer if world is None else Renderer(world, self.cfg)
        h, w = self.cfg.frame_height, self.cfg.frame_width
        # Exactly MapAgent._update_map's mapper: same config, intrinsics of the downsampled frame.
        self.factor = self.config.agent.downsample_factor(h, w)
        self.full_intr = CameraIntrinsics.from_sim(self.cfg, h, w)
        self.mapper = SemanticMapper.for_sim(self.config.map, self.cfg, h // self.factor, w // self.factor,
                                             scene.categories)
        self.judge = TargetSearch(self.config.agent)
        self.walk_labels, _ = ndi.label(scene.walkable, structure=_EIGHT)
        self._mesh_cells = self._mesh_object_cells()

    def _mesh_object_cells(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(category id, row, col) of every labelled triangle's centroid: what the world builder kept."""
        world = self.renderer.world
        labelled = world.tri_category > 0
        centre = world.vertices[world.triangles[labelled]].mean(axis=1)
        res = self.scene.resolution_m
        rows = np.clip(np.floor(centre[:, 1] / res).astype(np.int64), 0, self.scene.shape[0] - 1)
        cols = np.clip(np.floor(centre[:, 0] / res).astype(np.int64), 0, self.scene.shape[1] - 1)
        return world.tri_category[labelled], rows, cols

    def reachable(self, episodes: Iterable[Episode] = ()) -> tuple[np.ndarray, str]:
        """Walkable cells an episode can reach: the components of its starts, else the largest."""
        starts = [self.scene.cell_of(e.start.x, e.start.y) for e in episodes]
        ids = {int(self.walk_labels[r, c]) for r, c in starts if self.scene.in_bounds(r, c)} - {0}
        if ids:
            return np.isin(self.walk_labels, sorted(ids)), "episode starts"
        sizes = np.bincount(self.walk_labels.ravel())
        sizes[0] = 0
        return self.walk_labels == int(np.argmax(sizes)), "largest walkable component"

    def run(self, episodes: list[Episode] | None = None, out_dir: Path | None = None,
            all_pngs: bool = False) -> FloorAudit:
        t0 = time.perf_counter()
        episodes = [e for e in episodes or () if (e.scene, e.floor) == (self.scene.name, self.scene.floor)]
        reachable, source = self.reachable(episodes)
        result = FloorAudit(self.scene.name, self.scene.floor, source, 0.0)
        for category in self.scene.present_goals(GOAL_CATEGORIES):
            labels, n = ndi.label(self.scene.category_mask(category), structure=_EIGHT)
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
        near = ndi.binary_dilation(footprint, _EIGHT, iterations=audit.near_cells) if audit.near_cells else footprint
        rng = np.random.default_rng([audit.seed, zlib.crc32(f"{scene.key}/{category}/{instance_id}".encode())])
        target = _Target(category, scene.categories.index(category) + 1, near, np.argwhere(footprint))

        best, tested = _Look(), []

        def first_confirming(cells: np.ndarray) -> np.ndarray | None:
            nonlocal best
            for cell in cells:
                look = self._look(target, cell)
                tested.append(cell)
                best = _better(best, look)
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
            for comp in _labels_in(self.walk_labels, elsewhere))
        if not confirmable and audit.outside_poses:
            ring = walk & reachable & ~region & (d_fp <= audit.search_radius_m)
            cell = first_confirming(self._spread(np.argwhere(ring), d_fp, audit.outside_poses, rng))
            if cell is not None:
                nearest = float(d_fp[cell[0], cell[1]])

        others = [c for k, c in enumerate(scene.categories)
                  if c != category and (scene.objects[k][footprint]).any()]
        reason = None
        if not confirmable:
            ids, mr, mc = self._mesh_cells
            in_mesh = bool((ids == target.cat_id)[ndi.binary_dilation(footprint, _EIGHT)[mr, mc]].any())
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
            scene=scene.name, floor=scene.floor, category=category, instance_id=instance_id,
            cells=int(footprint.sum()), centroid=centroid, gap_m=_r(gap), region_cells=int(region_walk.sum()),
            reachable_region_cells=int(region_reach.sum()), confirmable=confirmable, reason=reason,
            nearest_confirmable_m=_r(nearest), max_pixels=best.pixels, max_mapped_cells=best.mapped,
            shared_with=tuple(others),
            poses_tested=len(tested), best_pose=best.view,
            region_components=tuple(_labels_in(self.walk_labels, region_walk)),
            confirmed_components=tuple(sorted(confirmed_in)),
        )
        return inst, (region, np.array(tested, dtype=np.int64).reshape(-1, 2), best.rgb)

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

    def _look(self, target: "_Target", cell: np.ndarray) -> _Look:
        """Stand at ``cell``, look around into a fresh map; stop at the first view that confirms."""
        scene, audit = self.scene, self.audit
        r, c = int(cell[0]), int(cell[1])
        x, y = scene.cell_center(r, c)
        fr, fc = target.cells[np.argmin(((target.cells - (r, c)) ** 2).sum(axis=1))]
        bearing = math.atan2(fr - r, fc - c) if (fr, fc) != (r, c) else 0.0
        step = 2.0 * math.pi / audit.headings
        # Facing the instance first, then turning away from it both ways.
        offsets = sorted(range(-((audit.headings - 1) // 2), audit.headings // 2 + 1), key=abs)
        # Anchored at the cell's corner, the map grid coincides with the scene grid (see _confirm).
        self.mapper.reset(Pose(x - 0.5 * scene.resolution_m, y - 0.5 * scene.resolution_m, bearing))
        out = _Look()
        for j in offsets:
            pose = Pose(x, y, wrap_angle(bearing + j * step))
            for tilt_deg in audit.tilts_deg:
                tilt = math.radians(tilt_deg)
                frame = self.renderer.render(pose, tilt)
                pixels = self._pixels(frame.depth, frame.semantic, target, pose, tilt)
                depth, semantic = (frame.depth, frame.semantic) if self.factor == 1 else downsample_frame(
                    frame.depth, frame.semantic, self.factor)
                sem_map = self.mapper.update(depth, semantic, pose, tilt)
                mapped, ok = self._confirm(sem_map, target, r, c)
                if out.view is None or pixels > out.pixels:
                    out.pixels, out.rgb = pixels, frame.rgb
                    out.view = (round(x, 3), round(y, 3), round(math.degrees(pose.heading), 1), tilt_deg)
                out.mapped = max(out.mapped, mapped)
                if ok:
                    out.confirmed = True
                    return out
        return out

    def _pixels(self, depth: np.ndarray, semantic: np.ndarray, target: "_Target", pose: Pose, tilt: float) -> int:
        """Pixels of the instance's category whose depth lands on or near its footprint (pixels with
        no valid depth, nearer than min_depth_m or beyond max_depth_m, cannot be placed)."""
        mine = semantic == target.cat_id
        if not mine.any():
            return 0
        cloud = depth_to_points(np.where(mine, depth, 0.0).astype(np.float32), self.full_intr, pose, tilt)
        res = self.scene.resolution_m
        rows = np.floor(cloud.points[:, 1] / res).astype(np.int64)
        cols = np.floor(cloud.points[:, 0] / res).astype(np.int64)
        h, w = self.scene.shape
        ok = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
        return int(target.near[rows[ok], cols[ok]].sum())

    def _confirm(self, sem_map, target: "_Target", r: int, c: int) -> tuple[int, bool]:
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


@dataclass(frozen=True, eq=False)
class _Target:
    category: str
    cat_id: int  # semantic id: category index + 1
    near: np.ndarray  # footprint dilated by near_cells
    cells: np.ndarray  # (N, 2) footprint cells
    near_box: tuple[int, int, int, int] = (0, 0, 0, 0)  # rows r0:r1, cols c0:c1 of ``near``

    def __post_init__(self) -> None:
        rows, cols = np.flatnonzero(self.near.any(axis=1)), np.flatnonzero(self.near.any(axis=0))
        object.__setattr__(self, "near_box", (int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1))


def _better(best: _Look, look: _Look) -> _Look:
    """Keep the look with more of the instance in view (mapped cells break ties)."""
    if best.view is None or (look.pixels, look.mapped) > (best.pixels, best.mapped):
        return dataclasses.replace(look, mapped=max(look.mapped, best.mapped))
    best.mapped = max(best.mapped, look.mapped)
    return best


def audit_floor(scene: SceneMap, cfg: Config | None = None, episodes: list[Episode] | None = None,
                audit: AuditConfig | None = None, out_dir: str | Path | None = None,
                all_pngs: bool = False) -> FloorAudit:
    """Audit every goal instance of one floor (and the episodes given for it)."""
    out = None if out_dir is None else Path(out_dir)
    return FloorAuditor(scene, cfg, audit).run(episodes, out, all_pngs)


# --- a split -----------------------------------------------------------------------------------

def audit_scenes(scenes: dict[str, dict[int, SceneMap]], cfg: Config | None = None,
                 episodes: list[Episode] | None = None, audit: AuditConfig | None = None, workers: int = 2,
                 out_dir: str | Path | None = None, all_pngs: bool = False, source: str = "", split: str = "",
                 progress: Callable[[FloorAudit], None] | None = None) -> AuditReport:
    """Audit every floor of ``scenes``, ``workers`` floors at a time (largest first), in name order."""
    cfg = cfg or Config()
    if workers < 1:
        raise L3MVNError(f"workers must be >= 1, got {workers}")
    cfg.agent.downsample_factor(cfg.sim.frame_height, cfg.sim.frame_width)
    t0 = time.perf_counter()
    floors = sorted((s for fl in scenes.values() for s in fl.values()), key=lambda s: -s.navigable.size)
    jobs = [(s, cfg, [e for e in episodes or () if (e.scene, e.floor) == (s.name, s.floor)], audit,
             None if out_dir is None else str(out_dir), all_pngs) for s in floors]
    if out_dir is not None:
        make_folder(out_dir, "--out")
    done: list[FloorAudit] = []
    if workers == 1 or len(jobs) <= 1:
        for job in jobs:
            done.append(_run_job(job))
            if progress:
                progress(done[-1])
    else:
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor, as_completed

        # As the eval backend: workers fork from a server that has imported this module already (a
        # script calling this needs the usual ``if __name__ == "__main__":`` guard).
        if "forkserver" in mp.get_all_start_methods():
            ctx = mp.get_context("forkserver")
            ctx.set_forkserver_preload(["l3mvn.run.eval.audit"])
        else:
            ctx = mp.get_context("spawn")
        with ProcessPoolExecutor(min(workers, len(jobs)), mp_context=ctx) as pool:
            for fut in as_completed([pool.submit(_run_job, job) for job in jobs]):
                done.append(fut.result())
                if progress:
                    progress(done[-1])
    done.sort(key=lambda f: (f.scene, f.floor))
    return AuditReport(source, split, cfg.task.success_rule, (cfg.sim.frame_height, cfg.sim.frame_width),
                       time.perf_counter() - t0, done)


def _run_job(job) -> FloorAudit:
    scene, cfg, episodes, audit, out_dir, all_pngs = job
    return audit_floor(scene, cfg, episodes, audit, out_dir, all_pngs)


def load_split_for_audit(dataset: str | Path, split: str, scene: str | None = None
                         ) -> tuple[dict[str, dict[int, SceneMap]], list[Episode]]:
    """A SemExp split's floors and its episodes (none when it has no episode files); ``scene``
    keeps only that scene."""
    from l3mvn.world.episodes import read_episodes
    from l3mvn.world.scenes.semexp import load_split

    scenes = load_split(dataset, split)
    episodes: list[Episode] = []
    if any((Path(dataset) / split / "content").glob("*_episodes.json.gz")):
        episodes = read_episodes(dataset, split, scenes)
    if scene is not None:
        if scene not in scenes:
            raise L3MVNError(f"unknown scene {scene!r} in {dataset}/{split}; available: {', '.join(sorted(scenes))}")
        scenes = {scene: scenes[scene]}
        episodes = [e for e in episodes if e.scene == scene]
    return scenes, episodes


def audit_split(dataset: str | Path, split: str, cfg: Config | None = None, scene: str | None = None,
                audit: AuditConfig | None = None, workers: int = 2, out_dir: str | Path | None = None,
                all_pngs: bool = False, progress: Callable[[FloorAudit], None] | None = None) -> AuditReport:
    """``audit_scenes`` on a SemExp split and its episodes (``load_split_for_audit``)."""
    scenes, episodes = load_split_for_audit(dataset, split, scene)
    return audit_scenes(scenes, cfg, episodes, audit, workers, out_dir, all_pngs, str(dataset), split, progress)


# --- output ------------------------------------------------------------------------------------

def format_report(report: AuditReport) -> str:
    """Per floor: instances, confirmable and per-reason counts; then one line per instance that is
    not confirmable from inside its success region; then episodes."""
    insts = report.instances
    ok = sum(i.confirmable for i in insts)
    share = f" ({ok / len(insts):.1%})" if insts else ""
    h, w = report.frame
    lines = [f"{report.source or '-'} / {report.split or '-'}: rule {report.rule}, frame {h}x{w}: "
             f"{len(insts)} goal instances on {len(report.floors)} floors, {ok} confirmable from their "
             f"success region{share}; {report.seconds:.1f} s"]
    short = {"no_floor": "nofloor", "no_region": "noregn", "unreachable": "unreach", "occluded": "occlud",
             "outside_only": "outside"}
    heads = [short.get(r, r) for r in REASONS]
    lines.append(f"{'scene/floor':<18}{'inst':>5}{'conf':>5}" + "".join(f"{x:>8}" for x in heads) + f"{'s':>7}")
    for f in report.floors:
        c = Counter(i.reason for i in f.instances)
        lines.append(f"{f.key:<18}{len(f.instances):>5}{sum(i.confirmable for i in f.instances):>5}"
                     + "".join(f"{c[r]:>8}" for r in REASONS) + f"{f.seconds:>7.1f}")
    total = report.reason_counts()
    lines.append(f"{'total':<18}{len(insts):>5}{ok:>5}" + "".join(f"{total[r]:>8}" for r in REASONS))
    bad = [i for i in insts if not i.confirmable]
    if bad:
        lines.append("")
        lines.append("not confirmable from inside the success region (gap: to walkable floor; nearest: "
                     "nearest confirming pose within the search radius):")
        lines.append(f"{'scene/floor':<18}{'category':<14}{'id':>3} {'centroid':>11} {'reason':<13}"
                     f"{'gap_m':>6}{'nearest_m':>10}{'max_px':>8}")
        for i in bad:
            cen = f"{i.centroid[0]},{i.centroid[1]}"
            lines.append(f"{i.scene + '/' + str(i.floor):<18}{i.category:<14}{i.instance_id:>3} {cen:>11} "
                         f"{i.reason:<13}{_fmt(i.gap_m):>6}{_fmt(i.nearest_confirmable_m):>10}{i.max_pixels:>8}")
    eps = report.episodes
    if eps:
        why = Counter(e.reason for e in eps if not e.confirmable)
        lines.append("")
        lines.append(f"episodes: {len(eps)}, goal confirmable from the success region on the start's side: "
                     f"{sum(e.confirmable for e in eps)}"
                     + (f"; not: {', '.join(f'{k} {v}' for k, v in why.most_common())}" if why else ""))
        for e in eps:
            if not e.confirmable:
                lines.append(f"  {e.key} {e.goal}: {e.reason}")
    return "\n".join(lines)


def write_diagnostic_png(out_dir: str | Path, scene: SceneMap, walls: np.ndarray, inst: InstanceAudit,
                         region: np.ndarray, tested: np.ndarray, rgb: np.ndarray | None) -> Path:
    """Top-down crop (walls dark, walkable floor light, other free floor mid, success region green,
    the instance in its category colour, tested poses blue, the best pose red with its heading)
    beside the best view's RGB."""
    res, pad = scene.resolution_m, 40
    labels, _ = ndi.label(scene.category_mask(inst.category), structure=_EIGHT)
    fp = labels == inst.instance_id
    rows, cols = np.nonzero(fp | region)
    r0, r1 = max(rows.min() - pad, 0), min(rows.max() + pad + 1, scene.shape[0])
    c0, c1 = max(cols.min() - pad, 0), min(cols.max() + pad + 1, scene.shape[1])
    win = (slice(r0, r1), slice(c0, c1))
    img = np.full((r1 - r0, c1 - c0, 3), 20, np.uint8)
    img[scene.free[win]] = (110, 110, 110)
    img[scene.walkable[win]] = (190, 190, 190)
    img[region[win] & scene.walkable[win]] = (150, 215, 150)
    img[walls[win]] = (60, 50, 45)
    img[scene.object_any[win]] = (95, 80, 110)
    img[fp[win]] = category_color(inst.category)
    scale = max(1, min(6, 480 // max(img.shape[:2])))
    img = cv2.resize(img, (img.shape[1] * scale, img.shape[0] * scale), interpolation=cv2.INTER_NEAREST)
    for r, c in tested:
        if r0 <= r < r1 and c0 <= c < c1:
            centre = (int((c - c0 + 0.5) * scale), int((r - r0 + 0.5) * scale))
            cv2.circle(img, centre, max(2, scale), (40, 80, 230), -1)
    if inst.best_pose is not None:
        x, y, heading, _ = inst.best_pose
        px, py = (x / res - c0) * scale, (y / res - r0) * scale
        tip = (px + 12 * scale * math.cos(math.radians(heading)), py + 12 * scale * math.sin(math.radians(heading)))
        cv2.line(img, (int(px), int(py)), (int(tip[0]), int(tip[1])), (230, 30, 30), max(1, scale // 2))
        cv2.circle(img, (int(px), int(py)), max(3, scale + 1), (230, 30, 30), -1)
    view = np.zeros((img.shape[0], img.shape[0] * 4 // 3, 3), np.uint8) if rgb is None else cv2.resize(
        rgb, (rgb.shape[1] * img.shape[0] // rgb.shape[0], img.shape[0]), interpolation=cv2.INTER_AREA)
    panel = np.concatenate([img, np.zeros((img.shape[0], 4, 3), np.uint8), view], axis=1)
    text = (f"{inst.scene}/{inst.floor} {inst.category} #{inst.instance_id}: {inst.reason or 'confirmable'} "
            f"px {inst.max_pixels} mapped {inst.max_mapped_cells}")
    cv2.putText(panel, text, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    path = Path(out_dir) / f"{inst.scene}_{inst.floor}_{inst.category.replace(' ', '-')}_{inst.instance_id}.png"
    ok, png = cv2.imencode(".png", cv2.cvtColor(panel, cv2.COLOR_RGB2BGR))
    if not ok:
        raise L3MVNError(f"cannot encode the diagnostic picture {path.name}")
    return write_file(path, png.tobytes(), "diagnostic picture")


def _labels_in(labels: np.ndarray, mask: np.ndarray) -> list[int]:
    """The nonzero labels present under ``mask``, ascending."""
    return [int(v) for v in np.unique(labels[mask]) if v]



def _r(v: float | None) -> float | None:
    return None if v is None or not math.isfinite(v) else round(float(v), 3)


def _fmt(v: float | None) -> str:
    return "-" if v is None else f"{v:.2f}"


__all__ = [
    "REASONS", "AuditConfig", "InstanceAudit", "EpisodeAudit", "FloorAudit", "AuditReport", "FloorAuditor",
    "audit_floor", "audit_scenes", "audit_split", "load_split_for_audit", "format_report",
    "write_diagnostic_png",
]

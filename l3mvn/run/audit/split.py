"""Auditing a whole split: its floors over worker processes, largest first, into one ``AuditReport``."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

from l3mvn.core.config import Config
from l3mvn.core.errors import L3MVNError
from l3mvn.core.writing import make_folder
from l3mvn.run.audit.floor import audit_floor
from l3mvn.run.audit.records import AuditConfig, AuditReport, FloorAudit
from l3mvn.world.episode import Episode
from l3mvn.world.scenes.scene import SceneMap


def audit_scenes(
    scenes: dict[str, dict[int, SceneMap]],
    cfg: Config | None = None,
    episodes: list[Episode] | None = None,
    audit: AuditConfig | None = None,
    workers: int = 2,
    out_dir: str | Path | None = None,
    all_pngs: bool = False,
    source: str = "",
    split: str = "",
    progress: Callable[[FloorAudit], None] | None = None,
) -> AuditReport:
    """Audit every floor of ``scenes``, ``workers`` floors at a time (largest first), in name order."""
    cfg = cfg or Config()
    if workers < 1:
        raise L3MVNError(f"workers must be >= 1, got {workers}")
    cfg.agent.downsample_factor(cfg.sim.frame_height, cfg.sim.frame_width)
    t0 = time.perf_counter()
    floors = sorted((s for fl in scenes.values() for s in fl.values()), key=lambda s: -s.navigable.size)
    jobs = [
        (
            s,
            cfg,
            [e for e in episodes or () if (e.scene, e.floor) == (s.name, s.floor)],
            audit,
            None if out_dir is None else str(out_dir),
            all_pngs,
        )
        for s in floors
    ]
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
        from multiprocessing.context import BaseContext

        # As the eval backend: workers fork from a server that has imported this module already (a
        # script calling this needs the usual ``if __name__ == "__main__":`` guard).
        ctx: BaseContext
        if "forkserver" in mp.get_all_start_methods():
            ctx = mp.get_context("forkserver")
            ctx.set_forkserver_preload(["l3mvn.run.audit.split"])
        else:
            ctx = mp.get_context("spawn")
        with ProcessPoolExecutor(min(workers, len(jobs)), mp_context=ctx) as pool:
            for fut in as_completed([pool.submit(_run_job, job) for job in jobs]):
                done.append(fut.result())
                if progress:
                    progress(done[-1])
    done.sort(key=lambda f: (f.scene, f.floor))
    return AuditReport(
        source,
        split,
        cfg.task.success_rule,
        (cfg.sim.frame_height, cfg.sim.frame_width),
        time.perf_counter() - t0,
        done,
    )


def load_split_for_audit(
    dataset: str | Path, split: str, scene: str | None = None
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


def audit_split(
    dataset: str | Path,
    split: str,
    cfg: Config | None = None,
    scene: str | None = None,
    audit: AuditConfig | None = None,
    workers: int = 2,
    out_dir: str | Path | None = None,
    all_pngs: bool = False,
    progress: Callable[[FloorAudit], None] | None = None,
) -> AuditReport:
    """``audit_scenes`` on a SemExp split and its episodes (``load_split_for_audit``)."""
    scenes, episodes = load_split_for_audit(dataset, split, scene)
    return audit_scenes(scenes, cfg, episodes, audit, workers, out_dir, all_pngs, str(dataset), split, progress)


def _run_job(job) -> FloorAudit:
    scene, cfg, episodes, audit, out_dir, all_pngs = job
    return audit_floor(scene, cfg, episodes, audit, out_dir, all_pngs)

"""Frontier data from house maps (``l3mvn language frontier-data``): what a frontier prior must learn.

An agent (any map-based policy, cost-utility by default) walks episodes on real houses. At every
re-selection, each frontier it chose among is written with what the agent saw there (the objects in
its window and their distance to its centre, the paper's feed-forward sentence, its S_CU and
geometry) and, from the task layer, the ground-truth geodesic from the frontier to the nearest
instance of *every* goal category present in the house (the frontier oracle's criterion, so one
walk labels six choices). The ground truth only goes into the file; the agent never reads it.

The houses are a dataset's (real maps), procedural houses (``--procedural-houses``: unlimited
training houses furnished from real room contents), or both; a house's name decides its side of the
train / val / test split wherever the file is read, so the two kinds mix freely.

File: JSON lines. A choice line is ``{"house", "floor", "episode", "seed", "goal", "step", "mapped"
(every category on the agent's map), "frontiers": [...]}``; after each episode's choices one
``{"done": episode, "seed", "choices"}`` line, which for a procedural house also names the house's
seed and how many episodes it has (``"procedural", "of"``). A job (one dataset episode, or every
episode of one procedural house) is written in one ``write`` when it ends, so ``resume`` keeps every
finished job and drops a block cut off by a kill.
Episodes are seeded by id (``MapAgent.reset``), so a seed gives the same file whatever the worker
count or the order of runs.
"""

from __future__ import annotations

import argparse
import json
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from multiprocessing import get_context
from pathlib import Path

import numpy as np

from l3mvn.agent.frontiers import Frontier
from l3mvn.agent.language.frontier_file import frontier_query, load_choices
from l3mvn.agent.language.vocabulary import GOALS, canonical
from l3mvn.agent.mapping import SemanticMap
from l3mvn.agent.policies.oracle_frontier import frontier_goal_distances
from l3mvn.core.config import Config
from l3mvn.core.errors import L3MVNError
from l3mvn.core.writing import write_file
from l3mvn.run.registry import PolicySpec, policies
from l3mvn.run.runner import Runner
from l3mvn.world.baselines import object_distances
from l3mvn.world.datasets import EpisodeSet, load_episode_set
from l3mvn.world.episode import Episode
from l3mvn.world.episodes import generate_episodes
from l3mvn.world.scenes.procedural import generate_house
from l3mvn.world.scenes.scene import SceneMap
from l3mvn.world.scenes.semexp import load_split
from l3mvn.world.task.regions import GoalRegion

DEFAULT_FRAME = (120, 160)  # the regret bench's: the map, not the pixels, is what the prior sees


@dataclass(frozen=True)
class FrontierDataJob:
    """One job: one episode of a dataset (``index`` into its episode set), or (``house_seed`` given)
    every generated episode of one procedural house; walked with ``seed`` by ``policy``."""

    dataset: str | None
    split: str
    index: int
    seed: int
    policy: str
    frame: tuple[int, int]
    episodes_per_house: int | None
    house_seed: int | None = None


def window_object_distances(frontier: Frontier, sem_map: SemanticMap, half_cells: int) -> dict[str, float]:
    """Per category in the frontier's window (``FrontierConfig.window_m``, Chebyshev, the same square
    ``extract_frontiers`` fills ``Frontier.objects`` from): the straight-line metres from the
    frontier's centre to its nearest cell, canonical names, nearest first."""
    r, c = frontier.center
    size = sem_map.size
    r0, r1 = max(0, r - half_cells), min(size, r + half_cells + 1)
    c0, c1 = max(0, c - half_cells), min(size, c + half_cells + 1)
    window = sem_map.categories[:, r0:r1, c0:c1]
    out: dict[str, float] = {}
    for k in np.flatnonzero(window.reshape(len(window), -1).any(axis=1)):
        rows, cols = np.nonzero(window[k])
        d = np.hypot(rows + r0 - r, cols + c0 - c).min() * sem_map.resolution_m
        name = canonical(sem_map.category_names[k])
        out[name] = min(out.get(name, np.inf), float(d))
    return dict(sorted(out.items(), key=lambda kv: (kv[1], kv[0])))


def label_frontiers(
    frontiers: list[Frontier], sem_map: SemanticMap, goal_fields: dict[str, GoalRegion], half_cells: int
) -> list[dict]:
    """One record per frontier: the agent's view of it plus the ground-truth metres from it to every
    goal in ``goal_fields`` (``None`` for a goal whose instances it has no path to, or that the house
    lacks)."""
    truth = {g: frontier_goal_distances(frontiers, sem_map, region.distances_at) for g, region in goal_fields.items()}
    out = []
    for i, f in enumerate(frontiers):
        objects = window_object_distances(f, sem_map, half_cells)
        if set(objects) != {canonical(o) for o in f.objects}:
            raise L3MVNError(
                f"frontier {f.id}: window objects {sorted(objects)} differ from its "
                f"extracted objects {sorted(f.objects)}"
            )
        goal_m = {g: (round(float(truth[g][i]), 3) if g in truth and np.isfinite(truth[g][i]) else None) for g in GOALS}
        out.append(
            {
                "id": f.id,
                "center": [int(f.center[0]), int(f.center[1])],
                "size": int(f.size),
                "distance_m": round(f.distance_m, 3),
                "cost": round(f.cost, 3),
                "utility": round(f.utility, 3),
                "s_cu": round(f.s_cu, 4),
                "objects": {k: round(v, 2) for k, v in objects.items()},
                "query": frontier_query(tuple(objects)),
                "goal_m": goal_m,
            }
        )
    return out


_STATE: dict = {}


def _episode_set(dataset: str, split: str, cfg: Config, per_house: int | None):
    """The dataset's episodes, or (a map-only dataset, or ``per_house``) episodes generated per floor
    with seed 0, so every run over the same arguments walks the same episodes."""
    if per_house is None and (Path(dataset) / split / "content").is_dir():
        return load_episode_set(dataset, split, cfg=cfg)
    scenes = load_split(dataset, split)
    episodes: list[Episode] = []
    for name in sorted(scenes):
        for floor in sorted(scenes[name]):
            episodes += generate_episodes(scenes[name][floor], per_house or 8, seed=0, cfg=cfg)
    return EpisodeSet(Path(dataset).resolve().name, split, scenes, episodes)


def _walk(job: FrontierDataJob) -> list[tuple[str, int, list[dict]]]:
    """Walk the job's episodes; returns (episode key, seed, choice records) per episode."""
    if _STATE.get("frame") != job.frame:
        _STATE.update(frame=job.frame, cfg=Config().with_frame(*job.frame), runners={}, fields={}, dataset=None)
    cfg = _STATE["cfg"]
    if job.house_seed is not None:
        scene = generate_house(job.house_seed)
        try:
            episodes = generate_episodes(scene, job.episodes_per_house or 1, seed=0, cfg=cfg)
        except L3MVNError:  # a house whose goals no start reaches in range: nothing to walk there
            episodes = []
    else:
        key = (job.dataset, job.split, job.episodes_per_house)
        if _STATE.get("dataset") != key:
            assert job.dataset is not None  # a job without a house seed walks a dataset's episode
            _STATE.update(dataset=key, eset=_episode_set(job.dataset, job.split, cfg, job.episodes_per_house))
        episodes = [_STATE["eset"].episodes[job.index]]
        scene = _STATE["eset"].scene_of(episodes[0])
    runner = _STATE["runners"].setdefault(job.seed, Runner(cfg, seed=job.seed, config_hash="frontier-data"))
    floor = runner.floor(scene)
    if scene.key not in _STATE["fields"]:
        present = [g for g in GOALS if g in scene.categories and scene.category_mask(g).any()]
        _STATE["fields"] = {scene.key: {g: object_distances(floor.task, g) for g in present}}  # one house at a time
    return [(ep.key, job.seed, _walk_episode(runner, scene, ep, job.seed, job.policy)) for ep in episodes]


def _walk_episode(runner: Runner, scene: SceneMap, ep: Episode, seed: int, policy: str) -> list[dict]:
    session = runner.session(scene, policy)
    session.start(ep)
    fields = _STATE["fields"][scene.key]
    half = runner.config.frontiers.window_cells(runner.config.map.resolution_m)
    rows = []
    for step, decision in session.frontier_choices():
        frontiers, sem_map = decision.frontiers, decision.map
        mapped = sorted(
            {
                canonical(sem_map.category_names[k])
                for k in np.flatnonzero(sem_map.categories.reshape(len(sem_map.categories), -1).any(axis=1))
            }
        )
        rows.append(
            {
                "house": ep.scene,
                "floor": ep.floor,
                "episode": ep.key,
                "seed": seed,
                "goal": ep.goal,
                "step": step,
                "mapped": mapped,
                "frontiers": label_frontiers(frontiers, sem_map, fields, half),
            }
        )
    return rows


def read_done(path: Path) -> tuple[set[tuple[str, int | None]], set[tuple[int, int | None]], list[str]]:
    """(finished (episode, seed) pairs, finished (procedural house seed, seed) pairs, the lines to
    keep): the lines of an episode without its ``done`` line, of a procedural house with fewer
    ``done`` lines than its episodes, and a last line cut off mid-write, are dropped."""
    if not path.exists():
        return set(), set(), []
    lines = path.read_text().splitlines()
    rows = []
    for n, line in enumerate(lines):
        try:
            row = json.loads(line)
        except json.JSONDecodeError:
            if n != len(lines) - 1:
                raise L3MVNError(f"{path}:{n + 1}: not a JSON line; not a frontier-data file?") from None
            row = None
        rows.append(row if isinstance(row, dict) else {})
    finished = [r for r in rows if "done" in r]
    walked: dict[tuple[int, int | None], int] = {}
    for r in finished:
        if "procedural" in r:
            walked[(r["procedural"], r.get("seed"))] = walked.get((r["procedural"], r.get("seed")), 0) + 1
    houses = {
        (r["procedural"], r.get("seed"))
        for r in finished
        if "procedural" in r and walked[(r["procedural"], r.get("seed"))] == r.get("of")
    }
    done = {
        (r["done"], r.get("seed"))
        for r in finished
        if "procedural" not in r or (r["procedural"], r.get("seed")) in houses
    }
    keep = [line for line, r in zip(lines, rows) if (r.get("done", r.get("episode")), r.get("seed")) in done]
    return done, houses, keep


def generate_frontier_data(
    dataset: str | None,
    split: str,
    out: str | Path,
    *,
    seeds: Sequence[int] = (0,),
    houses: Sequence[str] | None = None,
    policy: str = "cost-utility",
    episodes_per_house: int | None = None,
    limit: int | None = None,
    procedural_houses: int = 0,
    procedural_seed: int = 0,
    episodes_per_procedural: int = 2,
    workers: int = 1,
    frame: tuple[int, int] = DEFAULT_FRAME,
    resume: bool = False,
    progress: Callable[[int, int], None] | None = None,
) -> dict:
    """Walk every (episode, seed) of the dataset's split (only ``houses`` if given, the first
    ``limit`` episodes per house if given), then ``episodes_per_procedural`` generated episodes on
    each of ``procedural_houses`` procedural houses (seeds from ``procedural_seed``), and append
    their choices to ``out``; returns counts of what the file holds."""

    def walks(spec: PolicySpec) -> bool:  # a map agent that reads no language model and no ground truth
        return spec.map_based and spec.language is None and not spec.ground_truth and not spec.driven

    specs = policies()
    if policy not in specs or not walks(specs[policy]):
        valid = [name for name, spec in specs.items() if walks(spec)]
        raise L3MVNError(
            f"policy {policy!r} cannot walk frontier data (it must read no language model and "
            f"no ground truth); valid: {', '.join(valid)}"
        )
    if not seeds or any(s < 0 for s in seeds):
        raise L3MVNError(f"seeds must be one or more integers >= 0, got {list(seeds)}")
    if workers < 1 or (limit is not None and limit < 1) or (episodes_per_house is not None and episodes_per_house < 1):
        raise L3MVNError("workers, --limit and --episodes-per-house must be >= 1")
    if procedural_houses < 0 or procedural_seed < 0 or episodes_per_procedural < 1:
        raise L3MVNError(
            "--procedural-houses and --procedural-seed must be >= 0 and --episodes-per-procedural >= 1, got "
            f"{procedural_houses}, {procedural_seed}, {episodes_per_procedural}"
        )
    if dataset is None and not procedural_houses:
        raise L3MVNError("nothing to walk: give --dataset, --procedural-houses N, or both")
    if dataset is None and houses:
        raise L3MVNError("--houses picks houses of --dataset; give --dataset too")
    cfg = Config().with_frame(*frame)
    indices: list[int] = []
    eset = None if dataset is None else _episode_set(str(dataset), split, cfg, episodes_per_house)
    if eset is not None:
        known = sorted(eset.scenes)
        unknown = sorted(set(houses or ()) - set(known))
        if unknown:
            raise L3MVNError(f"unknown house(s) {', '.join(unknown)}; valid: {', '.join(known)}")
        per_house: dict[str, int] = {}
        for i, ep in enumerate(eset.episodes):
            if houses and ep.scene not in houses:
                continue
            per_house[ep.scene] = per_house.get(ep.scene, 0) + 1
            if limit is None or per_house[ep.scene] <= limit:
                indices.append(i)
    out = Path(out)
    done, houses_done, keep = read_done(out) if resume else (set(), set(), [])
    if not resume and out.exists() and out.stat().st_size:
        raise L3MVNError(f"{out} exists; pass --resume to continue it or choose another --out")
    write_file(out, "".join(line + "\n" for line in keep), "--out")
    source = None if dataset is None else str(dataset)
    jobs = [
        FrontierDataJob(source, split, i, s, policy, frame, episodes_per_house)
        for s in seeds
        for i in indices
        if eset is not None and (eset.episodes[i].key, s) not in done
    ] + [
        FrontierDataJob(None, split, 0, s, policy, frame, episodes_per_procedural, house_seed=procedural_seed + k)
        for s in seeds
        for k in range(procedural_houses)
        if (procedural_seed + k, s) not in houses_done
    ]
    total, finished = len(jobs), 0
    if progress:
        progress(0, total)
    with out.open("a") as fh:
        pool = None if workers == 1 else get_context("forkserver").Pool(workers)
        try:
            results = map(_walk, jobs) if pool is None else pool.imap(_walk, jobs)
            for job, walked in zip(jobs, results):
                block = []
                for key, seed, rows in walked:
                    block += [json.dumps(r, separators=(",", ":")) for r in rows]
                    end = {"done": key, "seed": seed, "choices": len(rows)}
                    if job.house_seed is not None:  # a house counts as walked once all its episodes are
                        end |= {"procedural": job.house_seed, "of": len(walked)}
                    block.append(json.dumps(end))
                if block:
                    _append(fh, "\n".join(block) + "\n", out)
                finished += 1
                if progress:
                    progress(finished, total)
        finally:
            if pool is not None:
                pool.terminate()
    return summarise(out)


def _append(fh, text: str, out: Path) -> None:
    """One episode's block, on the disk before the next starts; a block cut short by a full disk
    has no ``done`` line, so ``--resume`` drops it and walks that episode again."""
    try:
        fh.write(text)
        fh.flush()
        os.fsync(fh.fileno())
    except OSError as exc:
        raise L3MVNError(
            f"cannot write {out}: {exc.strerror or exc}; the episodes finished before are kept (--resume continues)"
        ) from None


def summarise(path: str | Path) -> dict:
    choices = load_choices(path)
    return {
        "path": str(path),
        "choices": len(choices),
        "frontiers": sum(len(c.frontiers) for c in choices),
        "houses": len({c.house for c in choices}),
        "episodes": len({(c.episode, c.seed) for c in choices}),
    }


# --- the command (registered by l3mvn.run.cli under `l3mvn language frontier-data`) ----------------------
def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--dataset", default=None, help="SemExp dataset dir (episodes are generated if it has none)")
    parser.add_argument("--split", default="train")
    parser.add_argument("--out", required=True, help="JSON-lines file to write (or continue with --resume)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0], help="agent seeds; each walks every episode")
    parser.add_argument("--houses", nargs="+", default=None, help="only these houses (default: all of the split)")
    parser.add_argument("--policy", default="cost-utility", help="map-based policy that walks (default cost-utility)")
    parser.add_argument(
        "--episodes-per-house",
        type=int,
        default=None,
        help="generate N episodes per floor instead of reading the dataset's",
    )
    parser.add_argument("--limit", type=int, default=None, help="only the first N episodes of each house")
    parser.add_argument(
        "--procedural-houses", type=int, default=0, help="also walk N procedural houses (with or without --dataset)"
    )
    parser.add_argument("--procedural-seed", type=int, default=0, help="seed of the first procedural house")
    parser.add_argument(
        "--episodes-per-procedural", type=int, default=2, help="generated episodes per procedural house (default 2)"
    )
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--resume", action="store_true", help="skip (episode, seed) pairs already in --out")


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    bar = tqdm(unit="episode", disable=None, dynamic_ncols=True)

    def progress(done: int, total: int) -> None:
        bar.total = total
        bar.n = done
        bar.refresh()

    try:
        summary = generate_frontier_data(
            args.dataset,
            args.split,
            args.out,
            seeds=args.seeds,
            houses=args.houses,
            policy=args.policy,
            episodes_per_house=args.episodes_per_house,
            limit=args.limit,
            procedural_houses=args.procedural_houses,
            procedural_seed=args.procedural_seed,
            episodes_per_procedural=args.episodes_per_procedural,
            workers=args.workers,
            resume=args.resume,
            progress=progress,
        )
    finally:
        bar.close()
    print(json.dumps(summary))
    return 0


__all__ = [
    "FrontierDataJob",
    "add_arguments",
    "generate_frontier_data",
    "label_frontiers",
    "read_done",
    "run",
    "summarise",
    "window_object_distances",
]

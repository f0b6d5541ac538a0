"""Training samples for the PONI network from an agent's own walks: the choices the policy will face.

Windows drawn from full house maps (``samples``) teach the potentials everywhere on a revealed edge;
the policy, though, chooses among the few frontiers the agent's frontier extraction keeps, read on the
agent's own map. Here a map agent walks generated episodes on a floor: one that reads no prior
(cost-utility), or PONI itself with the checkpoint being fine-tuned, whose own choices lead it to maps
the prior-free walker never draws (the states a policy trained on another's walks meets and was never
taught: learning on its own visits is the remedy imitation learning calls DAgger). At each
re-selection the sample is its map's window around it, and every frontier it chose among, with its
travel cost and size bonus, the network cells it is read at, and the ground-truth geodesic metres
from it to the nearest instance of every goal the house holds (the frontier oracle's reading, so one
walk labels six choices). The ground truth only enters the labels; the agent never reads it.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import ExitStack
from dataclasses import dataclass
from multiprocessing import get_context

import numpy as np

from l3mvn.agent.policies.global_policies import size_bonus_m
from l3mvn.agent.policies.oracle_frontier import frontier_goal_distances
from l3mvn.agent.potentials import CHANNELS, WindowGrid, objects_hot, window_features
from l3mvn.core.categories import GIBSON_CATEGORIES, GOAL_CATEGORIES
from l3mvn.core.config import Config, PotentialConfig
from l3mvn.run.potentials.samples import Source, source_scene
from l3mvn.run.runner import Runner
from l3mvn.world.baselines import object_distances
from l3mvn.world.episodes import generate_episodes

WALKERS = ("cost-utility", "poni")  # read no ground truth: cost-utility no prior, poni its checkpoint


@dataclass
class WalkSet:
    """Choices from walks. Sample i: ``features[i]`` (uint8, x 255), the episode's ``goal[i]``
    (index into GOAL_CATEGORIES) and the walking policy's ``choice[i]`` (index among its
    frontiers). Frontier rows (all samples' frontiers in order): ``frontier_sample``, travel
    ``frontier_cost`` (m), ``frontier_metres`` (per goal, NaN where the house lacks the goal or
    the frontier lies off the true floor) and ``frontier_size_m`` (the size bonus, m); cell rows:
    ``cell_frontier`` and ``cell_index`` (flat network cell)."""

    features: np.ndarray
    goal: np.ndarray
    choice: np.ndarray
    houses: list[str]
    frontier_sample: np.ndarray
    frontier_cost: np.ndarray
    frontier_metres: np.ndarray
    cell_frontier: np.ndarray
    cell_index: np.ndarray
    frontier_size_m: np.ndarray
    frontier_objects: np.ndarray

    def __post_init__(self) -> None:
        self._frontiers = np.searchsorted(self.frontier_sample, np.arange(len(self.features) + 1))
        self._cells = np.searchsorted(self.cell_frontier, np.arange(len(self.frontier_cost) + 1))

    def __len__(self) -> int:
        return len(self.features)

    def frontiers(self, i: int) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
        """Sample i's frontiers: (cost (F,), metres (F, goals), each frontier's flat network cells)."""
        a, b = self._frontiers[i], self._frontiers[i + 1]
        cells = [self.cell_index[self._cells[j] : self._cells[j + 1]] for j in range(a, b)]
        return self.frontier_cost[a:b], self.frontier_metres[a:b], cells

    def size_m(self, i: int) -> np.ndarray:
        """Sample i's frontiers' size bonus (F,) in metres."""
        return self.frontier_size_m[self._frontiers[i] : self._frontiers[i + 1]]

    def objects(self, i: int) -> np.ndarray:
        """Sample i's frontiers' window categories (F, len(GIBSON_CATEGORIES)) bool."""
        return self.frontier_objects[self._frontiers[i] : self._frontiers[i + 1]]

    @classmethod
    def join(cls, parts: list[WalkSet], cells: int) -> WalkSet:
        samples = np.cumsum([0] + [len(p) for p in parts])
        frontiers = np.cumsum([0] + [len(p.frontier_cost) for p in parts])

        def cat(arrays: list[np.ndarray], empty: np.ndarray) -> np.ndarray:
            return np.concatenate(arrays) if arrays else empty

        return cls(
            cat([p.features for p in parts], np.zeros((0, len(CHANNELS), cells, cells), np.uint8)),
            cat([p.goal for p in parts], np.zeros(0, np.int8)),
            cat([p.choice for p in parts], np.zeros(0, np.int16)),
            [h for p in parts for h in p.houses],
            cat([p.frontier_sample + o for p, o in zip(parts, samples)], np.zeros(0, np.int32)),
            cat([p.frontier_cost for p in parts], np.zeros(0, np.float32)),
            cat([p.frontier_metres for p in parts], np.zeros((0, len(GOAL_CATEGORIES)), np.float32)),
            cat([p.cell_frontier + o for p, o in zip(parts, frontiers)], np.zeros(0, np.int32)),
            cat([p.cell_index for p in parts], np.zeros(0, np.int32)),
            cat([p.frontier_size_m for p in parts], np.zeros(0, np.float32)),
            cat([p.frontier_objects for p in parts], np.zeros((0, len(GIBSON_CATEGORIES)), bool)),
        )


@dataclass(frozen=True)
class WalkJob:
    """``walker`` (one of ``WALKERS``) walks ``episodes`` generated episodes of ``source``; PONI walks
    with ``potentials.checkpoint``."""

    source: Source
    episodes: int
    seed: int
    frame: tuple[int, int]
    potentials: PotentialConfig
    walker: str = WALKERS[0]


# One per worker process, frame, walker and its potentials (floors kept warm).
_RUNNERS: dict[tuple[tuple[int, int], str, PotentialConfig], Runner] = {}


def walk_floor(job: WalkJob) -> WalkSet:
    """Walk ``job.episodes`` generated episodes of one floor and keep every re-selection among two
    or more frontiers; an empty set where the floor gives no episode."""
    scene = source_scene(job.source)
    cfg = Config().with_frame(*job.frame).replace(poni=job.potentials)
    cells = job.potentials.window_cells
    episodes = generate_episodes(scene, job.episodes, seed=job.seed, cfg=cfg)
    if not episodes:
        return WalkSet.join([], cells)
    runner = _RUNNERS.setdefault((job.frame, job.walker, job.potentials), Runner(cfg, config_hash="poni-walks"))
    floor = runner.floor(scene)
    fields = {
        g: object_distances(floor.task, g)
        for g in GOAL_CATEGORIES
        if g in scene.categories and scene.category_mask(g).any()
    }
    features, goals, choices, costs, sizes, metres, cell_lists, objects = [], [], [], [], [], [], [], []
    for episode in episodes:
        session = runner.session(scene, job.walker)
        session.start(episode)
        for _, decision in session.frontier_choices():
            frontiers, sem_map = decision.frontiers, decision.map
            if len(frontiers) < 2:
                continue
            grid = WindowGrid.around(sem_map.agent_cell, sem_map.resolution_m, job.potentials)
            window = window_features(
                sem_map.explored, sem_map.obstacle, sem_map.categories, sem_map.category_names, grid
            )
            truth = np.full((len(frontiers), len(GOAL_CATEGORIES)), np.nan, dtype=np.float32)
            for g, region in fields.items():
                truth[:, GOAL_CATEGORIES.index(g)] = frontier_goal_distances(frontiers, sem_map, region.distances_at)
            features.append(np.rint(window * 255).astype(np.uint8))
            goals.append(GOAL_CATEGORIES.index(episode.goal))
            choices.append(-1 if decision.chosen_frontier is None else decision.chosen_frontier)
            costs.append(np.array([f.cost for f in frontiers], dtype=np.float32))
            sizes.append(size_bonus_m(frontiers, cfg.frontiers.cu_lambda).astype(np.float32))
            metres.append(np.where(np.isfinite(truth), truth, np.nan))
            cell_lists.append([grid.flat_cells(f.cells).astype(np.int32) for f in frontiers])
            objects.append(objects_hot([f.objects for f in frontiers]))
    if not features:
        return WalkSet.join([], cells)
    per_sample = [len(c) for c in costs]
    flat_cells = [c for sample in cell_lists for c in sample]
    return WalkSet(
        np.stack(features),
        np.array(goals, dtype=np.int8),
        np.array(choices, dtype=np.int16),
        [scene.key] * len(features),
        np.repeat(np.arange(len(features), dtype=np.int32), per_sample),
        np.concatenate(costs),
        np.concatenate(metres).astype(np.float32),
        np.repeat(np.arange(len(flat_cells), dtype=np.int32), [len(c) for c in flat_cells]),
        np.concatenate(flat_cells) if flat_cells else np.zeros(0, np.int32),
        np.concatenate(sizes),
        np.concatenate(objects),
    )


def walk_floors(
    jobs: list[WalkJob],
    workers: int,
    progress: Callable[[int, int], None] | None = None,
) -> WalkSet:
    """Every job's walks joined in job order (the same set whatever the worker count)."""
    parts: list[WalkSet] = []
    with ExitStack() as stack:
        results: Iterator[WalkSet] = map(walk_floor, jobs)
        if workers > 1:
            results = stack.enter_context(get_context("spawn").Pool(workers)).imap(walk_floor, jobs)
        for part in results:
            parts.append(part)
            if progress:
                progress(len(parts), len(jobs))
    cells = jobs[0].potentials.window_cells if jobs else PotentialConfig().window_cells
    return WalkSet.join(parts, cells)

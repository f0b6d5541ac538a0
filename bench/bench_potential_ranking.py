"""How well does a PONI checkpoint rank frontiers by their distance to the goal, and where?

    python bench/bench_potential_ranking.py --dataset DIR [--split train] [--checkpoint PT]
        [--houses held-out | --houses A B ...] [--limit N] [--windows 40] [--workers 2]

Three measures, each the mean Spearman rank correlation between the metres on to the goal the network
implies at each frontier (``range_m x (1 - object potential)``, best cell) and the true geodesic metres
from it to the goal object (capped at ``range_m``), over choices with at least three frontiers whose
true metres differ:

- ``agent``: cost-utility walks the episodes; at each re-selection, the frontiers it chooses among,
  read on its own map (what the policy faces);
- ``revealed``: the same frontiers, read on a map revealed by the training sampler's rays from the
  agent's visited cells (the mapper taken out of the difference);
- ``drawn``: the frontier clusters (8-connected, 5 cells or more) of windows the training sampler
  draws on the same houses (what the network was trained on).
"""

from __future__ import annotations

import argparse
import os
import sys
from functools import partial
from multiprocessing import get_context
from pathlib import Path

import cv2
import numpy as np
from scipy.stats import spearmanr

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
os.environ.setdefault("HF_HUB_OFFLINE", "1")

from l3mvn.agent.language.frontier_head import house_split  # noqa: E402
from l3mvn.agent.policies.oracle_frontier import frontier_goal_distances  # noqa: E402
from l3mvn.agent.potentials import OUTPUTS, PotentialModel, PotentialPolicy, WindowGrid, window_features  # noqa: E402
from l3mvn.core.categories import GIBSON_CATEGORIES  # noqa: E402
from l3mvn.core.config import Config, PotentialConfig  # noqa: E402
from l3mvn.run.potentials.samples import HouseTruth, RevealOptions  # noqa: E402
from l3mvn.run.runner import Runner  # noqa: E402
from l3mvn.world.baselines import ObjectDistances  # noqa: E402
from l3mvn.world.datasets import load_episode_set  # noqa: E402

CFG = Config().with_frame(120, 160)
VISITED_STRIDE = 8  # one view per this many visited map cells along the agent's path


def _rho(true: np.ndarray, pred: np.ndarray) -> float | None:
    ok = np.isfinite(true)
    if ok.sum() < 3 or np.ptp(true[ok]) == 0 or np.ptp(pred[ok]) == 0:
        return None
    return float(spearmanr(true[ok], pred[ok]).statistic)


def _read(model: PotentialModel, pc: PotentialConfig, grid: WindowGrid, features: np.ndarray, goal: int, cells):
    """Implied metres at each cell list's best cell (range_m where none lies in the window)."""
    p = model.predict(features)[goal]
    out = []
    for rows, cols in cells:
        wr, wc, inside = grid.to_window(rows, cols)
        out.append(pc.range_m * (1 - p[wr[inside], wc[inside]].max()) if inside.any() else pc.range_m)
    return np.array(out)


def _episode(job: tuple[str, str, int, PotentialConfig]) -> list[tuple[str, float]]:
    dataset, split, index, pc = job
    eset = load_episode_set(dataset, split, cfg=CFG)
    ep, scene = eset.episodes[index], eset.scene_of(eset.episodes[index])
    model = PotentialModel.load(pc.checkpoint, pc)
    policy, truth = PotentialPolicy(model, pc, CFG.frontiers.cu_lambda), HouseTruth(scene, pc, RevealOptions())
    runner = Runner(CFG, config_hash="bench")
    distances = partial(ObjectDistances(runner.floor(scene).task), ep.goal)
    session = runner.session(scene, "cost-utility")
    session.start(ep)
    goal, rows = OUTPUTS.index(ep.goal), []
    for _, decision in session.frontier_choices():
        frontiers, m = decision.frontiers, decision.map
        true = np.minimum(frontier_goal_distances(frontiers, m, distances), pc.range_m)
        agent = pc.range_m * (1 - policy.frontier_potentials(frontiers, m)[:, goal])
        rho = _rho(true, agent)
        if rho is None:
            continue
        rows.append(("agent", rho))
        seen = np.zeros(truth.floor.shape, dtype=bool)
        vr, vc = np.nonzero(m.visited)
        for x, y in zip(*m.cell_to_world(vr[::VISITED_STRIDE], vc[::VISITED_STRIDE])):
            cell = scene.cell_of(x, y)
            if 0 <= cell[0] < seen.shape[0] and 0 <= cell[1] < seen.shape[1]:
                truth.reveal(cell, seen)
        grid = WindowGrid.around(scene.cell_of(*m.cell_to_world(*m.agent_cell)), scene.resolution_m, pc)
        features = window_features(seen, seen & ~truth.floor, truth.categories & seen, GIBSON_CATEGORIES, grid)
        cells = []
        for f in frontiers:
            xs, ys = m.cell_to_world(f.cells[:, 0], f.cells[:, 1])
            scene_cells = np.array([scene.cell_of(x, y) for x, y in zip(xs, ys)])
            cells.append((scene_cells[:, 0], scene_cells[:, 1]))
        revealed = _rho(true, _read(model, pc, grid, features, goal, cells))
        if revealed is not None:
            rows.append(("revealed", revealed))
    return rows


def _drawn(job: tuple[str, str, str, int, PotentialConfig]) -> list[tuple[str, float]]:
    dataset, split, house, windows, pc = job
    eset = load_episode_set(dataset, split, cfg=CFG)
    model = PotentialModel.load(pc.checkpoint, pc)
    rows = []
    for scene in eset.scenes[house].values():
        truth, rng = HouseTruth(scene, pc, RevealOptions()), np.random.default_rng(0)
        for _ in range(windows):
            seen, view = truth.partial_map(rng)
            if seen is None:
                continue
            n, labels = cv2.connectedComponents(truth.frontier(seen).view(np.uint8), connectivity=8)
            clusters = [np.nonzero(labels == k) for k in range(1, n)]
            clusters = [c for c in clusters if len(c[0]) >= 5]
            grid = WindowGrid.around(view, scene.resolution_m, pc)
            features = window_features(seen, seen & ~truth.floor, truth.categories & seen, GIBSON_CATEGORIES, grid)
            for g in np.flatnonzero(truth.present):
                true = np.array([min(truth.goal_m[g][r, c].min(), pc.range_m) for r, c in clusters])
                rho = _rho(true, _read(model, pc, grid, features, 1 + g, clusters))
                if rho is not None:
                    rows.append(("drawn", rho))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dataset", required=True, help="SemExp dataset dir with episodes")
    parser.add_argument("--split", default="train")
    parser.add_argument("--checkpoint", default=None, help="a .pt (default: the shipped one)")
    parser.add_argument("--houses", nargs="+", default=["held-out"], help="houses, or 'held-out' (the default)")
    parser.add_argument("--limit", type=int, default=None, help="first N episodes only")
    parser.add_argument("--windows", type=int, default=40, help="drawn windows per floor")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    pc = PotentialConfig(checkpoint=args.checkpoint)
    eset = load_episode_set(args.dataset, args.split, cfg=CFG)
    houses = sorted(h for h in eset.scenes if house_split(h) == "test") if args.houses == ["held-out"] else args.houses
    unknown = sorted(set(houses) - set(eset.scenes))
    if unknown:
        parser.error(f"unknown house(s) {', '.join(unknown)}; valid: held-out, {', '.join(sorted(eset.scenes))}")
    chosen = [i for i, e in enumerate(eset.episodes) if e.scene in houses][: args.limit]
    jobs = [(args.dataset, args.split, i, pc) for i in chosen]
    drawn = [(args.dataset, args.split, h, args.windows, pc) for h in houses]
    rhos: dict[str, list[float]] = {"agent": [], "revealed": [], "drawn": []}
    with get_context("forkserver").Pool(args.workers) as pool:
        for rows in [*pool.imap_unordered(_episode, jobs), *pool.imap_unordered(_drawn, drawn)]:
            for kind, rho in rows:
                rhos[kind].append(rho)
    print(f"{len(chosen)} episodes, houses {', '.join(houses)}; mean Spearman (choices)")
    for kind, values in rhos.items():
        print(f"{kind}: {np.mean(values):.3f} ({len(values)})")


if __name__ == "__main__":
    main()

"""Render speed and mesh size of the built-in simulator, as a markdown table.

    python bench/bench_render.py [--dataset ../shared/data/gibson_semexp --split train] [--frames 50]

Per frame size: the whole frame (colour, depth and semantic images), and the pixels the mapper reads
(the centre of every k x k block, k = AgentConfig.downsample_factor), which is what an episode renders
unless something reads the whole frame. Env steps: BuiltinSimulator.step under random movement
actions, reading the mapper's pixels of every frame.

Without the dataset it benchmarks a synthetic six-room house drawn below, so it always runs.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import numpy as np
from scipy import ndimage as ndi

from l3mvn.core.categories import GIBSON_CATEGORIES
from l3mvn.core.config import AgentConfig, SimConfig
from l3mvn.core.grid import disk
from l3mvn.core.types import Action, Pose
from l3mvn.world.episode import Episode
from l3mvn.world.scenes.scene import SceneMap
from l3mvn.world.sim.render import Renderer
from l3mvn.world.sim.simulator import BuiltinSimulator
from l3mvn.world.sim.world import build_world

SIZES = ((120, 160), (480, 640))
DEFAULT_SCENES = ("Allensville", "Lakeville", "Lindenwood", "Wainscott")


def synthetic_house() -> SceneMap:
    """A 15 x 10 m house: a 3 x 2 grid of rooms with doors, furniture in each."""
    h, w = 200, 300
    free = np.zeros((h, w), bool)
    for r0 in (4, 102):
        for c0 in (4, 102, 200):
            free[r0 : r0 + 94, c0 : c0 + 96] = True
    free[40:60, 96:206] = True  # doors along the top row
    free[140:160, 96:206] = True
    free[94:106, 40:60] = True  # and between the rows
    objects = np.zeros((len(GIBSON_CATEGORIES), h, w), bool)
    layout = {
        "bed": (10, 50, 10, 50),
        "chair": (120, 130, 120, 130),
        "couch": (110, 125, 220, 280),
        "toilet": (10, 22, 280, 290),
        "dining-table": (150, 170, 130, 170),
        "refrigerator": (180, 195, 10, 25),
        "tv": (104, 108, 240, 270),
        "potted plant": (80, 86, 180, 186),
    }
    for name, (r0, r1, c0, c1) in layout.items():
        objects[GIBSON_CATEGORIES.index(name), r0:r1, c0:c1] = True
    free &= ~objects.any(0)
    return SceneMap(
        name="Synthetic",
        floor=0,
        categories=GIBSON_CATEGORIES,
        navigable=ndi.binary_erosion(free, disk(4)),
        objects=objects,
    )


def load_scenes(dataset: Path | None, split: str, names: tuple[str, ...]) -> list[SceneMap]:
    if dataset is None or not (dataset / split / f"{split}_info.pbz2").exists():
        return [synthetic_house()]
    from l3mvn.world.scenes.semexp import load_split

    scenes = load_split(dataset, split)
    chosen = [n for n in names if n in scenes] or sorted(scenes)[:4]
    return [scenes[n][min(scenes[n])] for n in chosen]


def bench_scene(scene: SceneMap, cfg: SimConfig, frames: int, rng: np.random.Generator) -> dict:
    t0 = time.perf_counter()
    world = build_world(scene, cfg)
    build_s = time.perf_counter() - t0
    renderer = Renderer(world, cfg)
    renderer.render(Pose(0.0, 0.0, 0.0), 0.0, 8, 8)  # compile / load the jitted kernels
    cells = np.argwhere(scene.walkable)
    row = {
        "scene": scene.key,
        "grid": f"{scene.shape[0]}x{scene.shape[1]}",
        "triangles": world.num_triangles,
        "build_s": build_s,
    }
    for h, w in SIZES:
        step = AgentConfig().downsample_factor(h, w)
        whole, read = [], []
        for _ in range(frames):
            r, c = cells[rng.integers(len(cells))]
            x, y = scene.cell_center(int(r), int(c))
            pose = Pose(x, y, float(rng.uniform(-math.pi, math.pi)))
            tilt = math.radians(float(rng.choice([-30.0, 0.0, 30.0])))
            t = time.perf_counter()
            renderer.render(pose, tilt, h, w)
            whole.append((time.perf_counter() - t) * 1e3)
            t = time.perf_counter()
            renderer.frame(pose, tilt, h, w).strided(step)
            read.append((time.perf_counter() - t) * 1e3)
        row[f"{h}x{w}"] = (float(np.median(whole)), float(np.percentile(whole, 90)))
        row[f"read {h}x{w}"] = (float(np.median(read)), float(np.percentile(read, 90)))
        row[f"steps {h}x{w}"] = env_steps_per_second(scene, cfg.with_frame(h, w), frames * 4, rng)
    return row


def env_steps_per_second(scene: SceneMap, cfg: SimConfig, steps: int, rng: np.random.Generator) -> float:
    """Simulator steps per second under uniformly random movement actions, the mapper's pixels of
    every frame rendered."""
    env = BuiltinSimulator(scene, cfg)
    factor = AgentConfig().downsample_factor(cfg.frame_height, cfg.frame_width)
    goal = scene.present_goals()[0]
    cells = np.argwhere(scene.navigable)
    r, c = cells[rng.integers(len(cells))]
    x, y = scene.cell_center(int(r), int(c))
    env.reset(Episode(0, scene.name, scene.floor, Pose(x, y, 0.0), goal))
    moves = [Action.MOVE_FORWARD, Action.TURN_LEFT, Action.TURN_RIGHT]
    t = time.perf_counter()
    for i in range(steps):
        if env.done:
            env.reset(Episode(i, scene.name, scene.floor, Pose(x, y, 0.0), goal))
        env.step(moves[int(rng.integers(len(moves)))]).frame.strided(factor)
    return steps / (time.perf_counter() - t)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--dataset", type=Path, default=Path(__file__).resolve().parents[2] / "shared/data/gibson_semexp"
    )
    parser.add_argument("--split", default="train")
    parser.add_argument("--scenes", nargs="*", default=list(DEFAULT_SCENES))
    parser.add_argument("--frames", type=int, default=50)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    cfg = SimConfig()
    rng = np.random.default_rng(args.seed)
    rows = [bench_scene(s, cfg, args.frames, rng) for s in load_scenes(args.dataset, args.split, tuple(args.scenes))]
    sizes = [f"{h}x{w}" for h, w in SIZES]
    print(
        "| scene | grid | triangles | build s | "
        + " | ".join(f"{s} whole median / p90 ms | {s} mapper's pixels median / p90 ms" for s in sizes)
        + " | "
        + " | ".join(f"env steps/s {s}" for s in sizes)
        + " |"
    )
    print("|---|---|---:|---:|" + "---:|" * (3 * len(sizes)))
    for row in rows:
        cells = " | ".join(
            f"{row[s][0]:.1f} / {row[s][1]:.1f} | {row['read ' + s][0]:.2f} / {row['read ' + s][1]:.2f}" for s in sizes
        )
        steps = " | ".join(f"{row['steps ' + s]:.0f}" for s in sizes)
        print(f"| {row['scene']} | {row['grid']} | {row['triangles']} | {row['build_s']:.2f} | {cells} | {steps} |")


if __name__ == "__main__":
    main()

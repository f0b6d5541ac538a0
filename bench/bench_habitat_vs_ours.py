"""The same ObjectNav episodes on habitat-sim (through the bridge) and on our renderer, oracle policy.

    python bench/bench_habitat_vs_ours.py EXPORT_DIR [--habitat-python PY] [--habitat-export DIR] [--frames DIR]

EXPORT_DIR is a scan dataset in HM3D's layout (``l3mvn.world.datasets.hm3d_export``). Per episode: success,
SPL and path length on both simulators, habitat's pathfinder geodesic against the episode file's,
and how the first frames agree (depth error, semantic labels). ``--habitat-export`` gives habitat a
copy of the export with other files (e.g. re-encoded semantic meshes); ``--frames`` writes the first
frames of three episodes side by side (habitat left, ours right: RGB, depth, semantic).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from l3mvn.core.config import Config, SimConfig, TaskConfig
from l3mvn.run.registry import make_policy
from l3mvn.run.runner import Runner
from l3mvn.run.session import EpisodeSession
from l3mvn.world.datasets import load_episode_set
from l3mvn.world.datasets.objectnav import dataset_rule
from l3mvn.world.scenes.categories import RAW_NAMES
from l3mvn.world.sim.habitat_bridge import habitat_environment
from l3mvn.world.task import ObjectNavTask

SPLIT = "val"


def _picture(obs) -> np.ndarray:
    palette = np.random.default_rng(0).integers(40, 255, (64, 3)).astype(np.uint8)
    palette[0] = 0
    depth = np.repeat((np.clip(obs.depth / 5.0, 0, 1) * 255).astype(np.uint8)[..., None], 3, axis=2)
    return np.concatenate([obs.rgb, depth, palette[obs.semantic % 64]], axis=0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("export", type=Path)
    parser.add_argument("--habitat-python", type=Path, default=Path.home() / ".cache/l3mvn/habitat/python")
    parser.add_argument("--habitat-export", type=Path, default=None)
    parser.add_argument("--frames", type=Path, default=None)
    parser.add_argument("--size", type=int, nargs=2, default=(240, 320), metavar=("H", "W"))
    args = parser.parse_args()
    ours_root, hab_root = args.export.resolve(), (args.habitat_export or args.export).resolve()
    dataset = ours_root / "objectnav_hm3d_v2"
    config = Config(
        sim=SimConfig(frame_height=args.size[0], frame_width=args.size[1]),
        task=TaskConfig(success_rule=dataset_rule(dataset, SPLIT)),
    )
    eset = load_episode_set(dataset, SPLIT, scenes_dir=ours_root / "scene_datasets", cfg=config)
    dataset_config = str(next((hab_root / "scene_datasets").rglob("*.scene_dataset_config.json")))
    runner, envs, rows = Runner(config), {}, []
    for i, episode in enumerate(eset.episodes):
        floor = eset.scene_of(episode)
        if floor.key not in envs:
            stage = str(floor.source).replace(str(ours_root), str(hab_root))
            envs[floor.key] = habitat_environment(
                args.habitat_python,
                floor,
                stage,
                config.sim,
                category_map=RAW_NAMES,
                scene_dataset_config=dataset_config,
            )
        env, ref, task = envs[floor.key], runner.floor(floor).env, ObjectNavTask(floor, config)
        first, mine = env.reset(episode), ref.reset(episode)
        both = (first.depth > 0) & (mine.depth > 0)
        labelled = (first.semantic > 0) | (mine.semantic > 0)
        if args.frames is not None and i < 3:
            from PIL import Image

            args.frames.mkdir(parents=True, exist_ok=True)
            Image.fromarray(np.concatenate([_picture(first), _picture(mine)], axis=1)).save(
                args.frames / f"episode{i}_habitat_vs_ours.png"
            )
        t0 = time.perf_counter()
        want = runner.run(floor, episode, "oracle")
        t1 = time.perf_counter()
        session = EpisodeSession(
            env, task, make_policy("oracle", env, task, config), policy_name="oracle", config_hash=""
        )
        session.start(episode)
        got = session.run()
        t2 = time.perf_counter()
        points = [tuple(p) for p in floor.view_points.get(episode.goal, [])]
        error = np.abs(first.depth - mine.depth)[both]
        row = {
            "episode": episode.key,
            "goal": episode.goal,
            "file_geodesic_m": episode.geodesic_distance_m,
            "habitat_geodesic_m": round(env.geodesic_distance(episode.start, points), 3) if points else None,
            "ours": {
                "success": want.success,
                "spl": round(want.spl, 3),
                "path_m": round(want.path_length_m, 3),
                "steps": want.steps,
                "failure": want.failure,
                "seconds": round(t1 - t0, 1),
            },
            "habitat": {
                "success": got.success,
                "spl": round(got.spl, 3),
                "path_m": round(got.path_length_m, 3),
                "steps": got.steps,
                "failure": got.failure,
                "seconds": round(t2 - t1, 1),
            },
            "first_frame": {
                "depth_median_abs_m": round(float(np.median(error)), 4),
                "depth_p90_abs_m": round(float(np.percentile(error, 90)), 4),
                "labels_agree": round(float((first.semantic == mine.semantic)[labelled].mean()), 3)
                if labelled.any()
                else None,
            },
        }
        rows.append(row)
        print(json.dumps(row))
    for env in envs.values():
        env.close()
    same = [r for r in rows if r["ours"]["success"] == r["habitat"]["success"]]
    ratios = [r["habitat"]["path_m"] / r["ours"]["path_m"] for r in same if r["ours"]["path_m"] > 0]
    print(
        json.dumps(
            {
                "episodes": len(rows),
                "format": eset.format,
                "rule": config.task.success_rule,
                "sr_ours": float(np.mean([r["ours"]["success"] for r in rows])),
                "sr_habitat": float(np.mean([r["habitat"]["success"] for r in rows])),
                "same_outcome": len(same),
                "path_ratio_same_outcome": [round(min(ratios), 3), round(max(ratios), 3)] if ratios else None,
            }
        )
    )


if __name__ == "__main__":
    main()

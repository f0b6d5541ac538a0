"""Where scenes and episodes come from: a SemExp-format directory, an official habitat ObjectNav
dataset (``objectnav_hm3d`` v1/v2, ``objectnav_mp3d``, Gibson) with its scans, or the built-in
procedural houses. The format is detected from the files and named in every summary."""

from __future__ import annotations

import numbers
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from l3mvn.core.config import Config
from l3mvn.core.errors import L3MVNError
from l3mvn.world.episode import Episode
from l3mvn.world.episodes import generate_episodes, read_episodes
from l3mvn.world.scenes.procedural import procedural_split
from l3mvn.world.scenes.scene import SceneMap
from l3mvn.world.scenes.semexp import load_split

PROCEDURAL = "procedural"
SEMEXP = "semexp"


@dataclass
class EpisodeSet:
    """Scenes of a split and the episodes to run on them, in a fixed order; ``format`` names where
    they came from (``procedural``, ``semexp``, ``objectnav_hm3d_v2``, ...)."""

    name: str
    split: str
    scenes: Mapping[str, Mapping[int, SceneMap]]
    episodes: list[Episode]
    format: str = SEMEXP

    def scene_of(self, episode: Episode) -> SceneMap:
        return self.scenes[episode.scene][episode.floor]


def load_episode_set(
    dataset: str | Path | None,
    split: str,
    *,
    houses: int = 5,
    episodes_per_house: int = 10,
    seed: int = 0,
    cfg: Config | None = None,
    scenes_dir: str | Path | None = None,
) -> EpisodeSet:
    """A dataset's split with its episodes: SemExp maps, or a habitat ObjectNav dataset whose scans
    lie under ``scenes_dir``; or (``dataset=None``) procedural houses with generated episodes, seeded
    so the same arguments always give the same set."""
    from l3mvn.world.datasets.objectnav import is_objectnav, load_objectnav

    _check_whole("seed", seed, 0)
    if dataset is None:
        if scenes_dir is not None:
            raise L3MVNError("--scenes is the scan root of an ObjectNav dataset: give --dataset too")
        _check_whole("--houses", houses, 1)
        _check_whole("--episodes-per-house", episodes_per_house, 1)
        scenes = procedural_split(houses, seed)
        episodes: list[Episode] = []
        for name in sorted(scenes):
            for floor in sorted(scenes[name]):
                episodes += generate_episodes(scenes[name][floor], episodes_per_house, seed=seed, cfg=cfg)
        return EpisodeSet(PROCEDURAL, split, scenes, episodes, PROCEDURAL)
    if is_objectnav(dataset, split):
        return load_objectnav(dataset, scenes_dir, split, cfg)
    if scenes_dir is not None:
        raise L3MVNError(
            f"--scenes is for habitat ObjectNav datasets (<split>/<split>.json.gz); {dataset} is "
            "in SemExp's format, whose maps need no scans"
        )
    scenes = load_split(dataset, split)
    return EpisodeSet(Path(dataset).resolve().name, split, scenes, read_episodes(dataset, split, scenes), SEMEXP)


def _check_whole(name: str, value: object, low: int) -> None:
    """Counts and seeds arrive from job files and the API as well as argparse: 2.5 houses or a
    ``True`` seed must be refused, not truncated."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < low:
        raise L3MVNError(f"{name} must be a whole number >= {low}, got {value!r}")

"""Where scenes and episodes come from: a SemExp-format directory, or the built-in procedural houses."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from l3mvn.config import Config
from l3mvn.episodes import generate_episodes, read_episodes
from l3mvn.errors import L3MVNError
from l3mvn.scenes.procedural import procedural_split
from l3mvn.scenes.scene import SceneMap
from l3mvn.scenes.semexp import load_split
from l3mvn.types import Episode

PROCEDURAL = "procedural"


@dataclass
class EpisodeSet:
    """Scenes of a split and the episodes to run on them, in a fixed order."""

    name: str
    split: str
    scenes: dict[str, dict[int, SceneMap]]
    episodes: list[Episode]

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
) -> EpisodeSet:
    """A SemExp dataset's split with its episode files, or (``dataset=None``) procedural houses with
    generated episodes, seeded so the same arguments always give the same set."""
    if dataset is None:
        if houses < 1 or episodes_per_house < 1:
            raise L3MVNError("procedural houses need --houses >= 1 and --episodes-per-house >= 1")
        scenes = procedural_split(houses, seed)
        episodes: list[Episode] = []
        for name in sorted(scenes):
            for floor in sorted(scenes[name]):
                episodes += generate_episodes(scenes[name][floor], episodes_per_house, seed=seed, cfg=cfg)
        return EpisodeSet(PROCEDURAL, split, scenes, episodes)
    scenes = load_split(dataset, split)
    return EpisodeSet(Path(dataset).resolve().name, split, scenes, read_episodes(dataset, split, scenes))

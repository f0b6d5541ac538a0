"""One ObjectNav episode as the world knows it: the agent's brief plus what only the task may read."""

from __future__ import annotations

from dataclasses import dataclass

from l3mvn.core.types import EpisodeBrief


@dataclass(frozen=True)
class Episode(EpisodeBrief):
    """An episode in our world frame, with the dataset fields it came from: the goal instance
    (``object_id``) and the file's shortest-path length (``geodesic_distance_m``), both ground truth."""

    object_id: int = -1
    geodesic_distance_m: float = float("nan")

    @property
    def brief(self) -> EpisodeBrief:
        """The episode as a policy is told it (``EpisodeBrief``): never this record itself."""
        return EpisodeBrief(self.episode_id, self.scene, self.floor, self.start, self.goal)

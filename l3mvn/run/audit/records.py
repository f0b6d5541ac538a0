"""What the scene audit settles on: its settings, the reasons it gives, and its records per goal
instance, episode, floor and split (``AuditReport.to_json`` is the audit's JSON report)."""

from __future__ import annotations

import dataclasses
from collections import Counter
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage as ndi

from l3mvn.core.errors import L3MVNError
from l3mvn.core.json_values import json_safe
from l3mvn.world.scenes.scene import SceneMap

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

EIGHT = np.ones((3, 3), dtype=bool)  # instances and walkable components are 8-connected


def instance_labels(scene: SceneMap, category: str) -> tuple[np.ndarray, int]:
    """The instances of ``category`` on ``scene``: labels 1..n of its footprint's 8-connected
    components (SemExp's object_id numbering), and n."""
    return ndi.label(scene.category_mask(category), structure=EIGHT)


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
    instance_id: int  # label of the 8-connected component (``instance_labels``)
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
        return json_safe(
            {
                "source": self.source,
                "split": self.split,
                "rule": self.rule,
                "frame": list(self.frame),
                "seconds": round(self.seconds, 2),
                "reasons": REASONS,
                "counts": {
                    "instances": len(self.instances),
                    "confirmable": sum(i.confirmable for i in self.instances),
                    **self.reason_counts(),
                    "episodes": len(self.episodes),
                    "episodes_confirmable": sum(e.confirmable for e in self.episodes),
                },
                "floors": [
                    {
                        "scene": f.scene,
                        "floor": f.floor,
                        "reachable_from": f.reachable_from,
                        "seconds": round(f.seconds, 2),
                    }
                    for f in self.floors
                ],
                "instances": [dataclasses.asdict(i) for i in self.instances],
                "episodes": [dataclasses.asdict(e) for e in self.episodes],
            }
        )

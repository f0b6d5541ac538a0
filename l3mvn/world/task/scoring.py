"""An episode's score: Success, SPL, DTG and a failure cause (Anderson et al. 2018).

SPL = S * l / max(l, p), with ``l`` the shortest path length under the task's success rule and
``p`` the path actually walked. DTG = geodesic distance to the success region at the end.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

from l3mvn.core.config import TaskConfig

FAILURE_CAUSES = (
    "success",
    "false_stop",  # called stop outside the success region
    "never_saw_target",  # ran out of steps without the target ever in view
    # ... although the frames showed most of the reachable floor: the target hides behind something
    # and shows only from a few places
    "unseen_in_explored",
    "saw_target_not_reached",  # saw it, never entered the success region
    "timeout",  # was in the success region at some point but never stopped there
    "stuck",  # ran out of steps while colliding most of the time
    # The start has no path to the success region on the ground-truth floor: no agent can succeed.
    # Scored as a failure (SR and SPL 0, DTG left out) and counted apart in the summary, so a
    # dataset's infeasible episodes neither vanish from the denominator nor pass for agent failures.
    "no_path",
)


@dataclass
class EpisodeOutcome:
    """What the task measured of one episode (``EpisodeMeasures``); turned into metrics by
    ``score_episode``."""

    stopped: bool
    in_success_region: bool
    steps: int
    path_length_m: float
    shortest_path_m: float
    final_distance_m: float
    saw_target: bool
    entered_region: bool
    recent_collision_rate: float
    # The share of the reachable floor the frames showed (``views.ViewRecord``).
    coverage: float


@dataclass
class EpisodeResult:
    """One line of results.jsonl."""

    key: str
    scene: str
    floor: int
    episode_id: int
    goal: str
    policy: str
    success: float
    spl: float
    dtg: float
    failure: str
    steps: int
    path_length_m: float
    shortest_path_m: float
    rule: str
    config_hash: str
    seconds: float = 0.0
    extra: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        d = asdict(self)
        for k in ("spl", "dtg", "path_length_m", "shortest_path_m", "seconds"):
            d[k] = _round(d[k])
        return d


def _round(v: float) -> float | None:
    return None if not math.isfinite(v) else round(float(v), 4)


def score_episode(o: EpisodeOutcome, cfg: TaskConfig) -> tuple[float, float, float, str]:
    """(success, spl, dtg, failure cause); ``cfg`` holds the thresholds behind the causes."""
    success = 1.0 if (o.stopped and o.in_success_region) else 0.0
    spl = o.shortest_path_m / max(o.shortest_path_m, o.path_length_m, 1e-9) if success else 0.0
    if success:
        cause = "success"
    elif not math.isfinite(o.shortest_path_m):
        cause = "no_path"
    elif o.stopped:
        cause = "false_stop"
    elif o.recent_collision_rate >= cfg.stuck_collision_rate:
        cause = "stuck"
    elif o.entered_region:
        cause = "timeout"
    elif o.saw_target:
        cause = "saw_target_not_reached"
    elif o.coverage >= cfg.explored_coverage:
        cause = "unseen_in_explored"
    else:
        cause = "never_saw_target"
    return success, spl, o.final_distance_m, cause

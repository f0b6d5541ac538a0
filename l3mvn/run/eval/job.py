"""An evaluation run as a small picklable value that any worker process (local or Ray) can execute.

Workers receive the job once and episode keys one at a time; each process loads the episode set once
and runs episodes through a ``Runner`` that keeps a few floors warm. Policies are reset per episode
and seed themselves from the episode, so a key gives the same metrics whichever process runs it and
in whatever order.
"""

from __future__ import annotations

import atexit
import os
import resource
import socket
import sys
import threading
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path

from l3mvn.core.config import Config, config_dict, config_hash
from l3mvn.core.errors import L3MVNError
from l3mvn.run.events import EventBus, StepEvent
from l3mvn.run.registry import check_options, check_policy, check_ready, with_scorer
from l3mvn.run.runner import Runner
from l3mvn.world.datasets import EpisodeSet, load_episode_set


@dataclass(frozen=True)
class EvalJob:
    """Everything a worker needs to run any episode of one evaluation."""

    dataset: str | None
    split: str
    houses: int
    episodes_per_house: int
    seed: int
    config: Config
    policy: str
    config_hash: str
    record_dir: str | None = None  # write a rerun recording per episode here
    scenes: str | None = None  # scan root of a habitat ObjectNav dataset (--scenes)

    @classmethod
    def create(
        cls,
        dataset: str | Path | None,
        split: str,
        *,
        houses: int = 5,
        episodes_per_house: int = 10,
        seed: int = 0,
        config: Config | None = None,
        policy: str,
        record_dir: str | Path | None = None,
        scenes: str | Path | None = None,
    ) -> EvalJob:
        """A job whose config hash covers the whole config tree, the policy and the seed (recording
        changes no result, so it is not hashed); a language policy's scorer is written into the tree
        first (``with_scorer``: its default may fall back where no LLM is installed), and a policy's
        checkpoint is loaded once here, so a broken one fails the job before its first episode."""
        config = config or Config()
        check_options(check_policy(policy), config.policy)
        config = with_scorer(policy, config)
        check_ready(policy, config)
        chash = config_hash(config, policy, seed)
        # Absolute paths, so workers started elsewhere (Ray) find the same files on a shared disk.
        source = None if dataset is None else str(Path(dataset).resolve())
        record = None if record_dir is None else str(Path(record_dir).resolve())
        scans = None if scenes is None else str(Path(scenes).resolve())
        return cls(source, split, houses, episodes_per_house, seed, config, policy, chash, record, scans)

    def load(self) -> EpisodeSet:
        """The job's episode set, loaded once per process."""
        return _state(self).episodes

    def keys(self) -> list[str]:
        return [ep.key for ep in self.load().episodes]

    def run_one(self, key: str, record_tag: str | None = None) -> dict:
        """Run one episode and return its result line; any exception becomes an error row.
        ``record_tag`` names the recording apart from the episode's others (``recording_path``).

        A process keeps one job's warm state, so episodes of this process run one at a time
        whichever thread asks (a dashboard's tabs re-running lines, a comparison)."""
        t0 = time.perf_counter()
        try:
            with _STATE_LOCK:
                return _state(self).run(key, record_tag)
        except Exception as exc:  # a broken episode must not take the run down: report it as a row
            return error_row(
                self,
                key,
                f"{type(exc).__name__}: {exc}",
                seconds=time.perf_counter() - t0,
                detail=traceback.format_exc(limit=8),
            )


def error_row(job: EvalJob, key: str, message: str, *, seconds: float = 0.0, detail: str = "") -> dict:
    """The line written for an episode that could not be run. It carries no metrics, is left out of
    summaries, and is retried by ``--resume`` (see ``is_error_row``)."""
    row = {
        "key": key,
        "policy": job.policy,
        "config_hash": job.config_hash,
        "error": message,
        "worker": worker_id(),
        "timing": {"total_s": round(seconds, 4)},
    }
    if detail:
        row["traceback"] = detail
    return row


def is_error_row(row: dict) -> bool:
    return "error" in row


def worker_id() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


def peak_rss_mb() -> float:
    """Peak resident memory of this process (ru_maxrss is KiB on Linux, bytes on macOS)."""
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return round(peak / (1024 * 1024 if sys.platform == "darwin" else 1024), 1)


# --- per-process state -------------------------------------------------------------------------


@dataclass
class _StageTotals:
    """Sums Decision.timings_ms over an episode (map-based agents report their stages there)."""

    ms: dict[str, float] = field(default_factory=dict)

    def __call__(self, event: StepEvent) -> None:
        if event.decision is not None:
            for stage, value in event.decision.timings_ms.items():
                self.ms[stage] = self.ms.get(stage, 0.0) + float(value)


class _JobState:
    def __init__(self, job: EvalJob) -> None:
        self.job = job
        check_policy(job.policy)
        self.episodes = load_episode_set(
            job.dataset,
            job.split,
            houses=job.houses,
            episodes_per_house=job.episodes_per_house,
            seed=job.seed,
            cfg=job.config,
            scenes_dir=job.scenes,
        )
        self.by_key = {ep.key: ep for ep in self.episodes.episodes}
        self.runner = Runner(job.config, seed=job.seed, config_hash=job.config_hash)

    def run(self, key: str, record_tag: str | None = None) -> dict:
        episode = self.by_key.get(key)
        if episode is None:
            raise L3MVNError(f"episode {key!r} is not in {self.episodes.name}/{self.episodes.split}")
        t0 = time.perf_counter()
        stages, bus = _StageTotals(), EventBus()
        bus.subscribe(stages)
        recorder, unrecorded = None, None
        if self.job.record_dir is not None:
            from l3mvn.run.recording import Recorder  # rerun loads in ~0.4 s: only for runs that record

            try:
                recorder = Recorder.for_episode(
                    self.job.record_dir, self.episodes.name, episode, self.job.policy, record_tag
                ).attach(bus)
            except L3MVNError as exc:  # the episode still runs: its result is worth more than its picture
                unrecorded = str(exc)
        session = self.runner.session(self.episodes.scene_of(episode), self.job.policy, bus)
        setup_s = time.perf_counter() - t0
        session.start(episode)
        result = session.run()
        run_s = time.perf_counter() - t0 - setup_s
        row = result.to_json()
        row["config"] = config_dict(self.job.config)
        row["worker"] = worker_id()
        row["timing"] = {
            "total_s": round(setup_s + run_s, 4),
            "setup_s": round(setup_s, 4),
            "sim_s": round(session.sim_seconds, 4),
            "policy_s": round(run_s - session.sim_seconds, 4),  # policy and loop bookkeeping
            "stages_ms": {k: round(v, 3) for k, v in sorted(stages.ms.items())},
        }
        row["peak_rss_mb"] = peak_rss_mb()
        if recorder is not None:
            recorder.close()  # already closed by the episode's last event; a no-op then
            unrecorded = recorder.failure
        if unrecorded:
            row["recording_error"] = unrecorded  # the metrics stand; the recording does not
        return row


_STATES: dict[EvalJob, _JobState] = {}
_STATE_LOCK = threading.RLock()


def _state(job: EvalJob) -> _JobState:
    with _STATE_LOCK:  # never while another thread runs an episode of the state it would drop
        if job not in _STATES:
            _close_states()  # one job at a time per process: drop the previous job's worlds
            _STATES[job] = _JobState(job)
        return _STATES[job]


@atexit.register
def _close_states() -> None:
    """Close the warm environments (a habitat bridge's server) with the job or the process."""
    while _STATES:
        _STATES.popitem()[1].runner.close()

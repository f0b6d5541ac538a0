"""Run an evaluation's episodes on a Ray cluster (``pip install 'l3mvn[distributed]'``).

Each episode is one task on a long-lived actor (one per CPU by default) that loads the episode set
once and keeps environments (and, for language policies, their models) warm across episodes. Each
actor holds one task at a time, so when an actor's process dies we know the one episode it took
down: that episode is retried on a fresh actor up to ``max_retries`` times and then yielded as an
error row, never dropped. Every node needs ``l3mvn`` importable (installed, or shipped with
``runtime_env``), as for any Ray job.
"""

from __future__ import annotations

import logging
import os
from collections import Counter, deque
from contextlib import suppress
from typing import Iterable, Iterator

from l3mvn.errors import L3MVNError
from l3mvn.eval.backends import interrupt_on_sigterm
from l3mvn.eval.job import EvalJob, error_row


def run_ray(job: EvalJob, keys: Iterable[str], address: str | None = None, num_workers: int | None = None,
            max_retries: int = 2) -> Iterator[dict]:
    """One result row per key, in completion order. Arguments are checked now (Ray missing raises
    L3MVNError), Ray is started or joined on the first ``next()``.

    Without ``address`` a private local Ray is started (``num_workers`` CPUs, default all) and shut
    down at the end; with one (``"auto"``, ``"ray://host:10001"``, ``"host:6379"``) the run joins
    that cluster and leaves it running.
    """
    ray = _import_ray()
    keys = list(keys)
    if num_workers is not None and num_workers < 1:
        raise L3MVNError(f"--workers must be >= 1, got {num_workers}")
    if max_retries < 0:
        raise L3MVNError(f"max_retries must be >= 0, got {max_retries}")
    return _run(ray, job, keys, address, num_workers, max_retries)


def _run(ray, job: EvalJob, keys: list[str], address: str | None, num_workers: int | None,
         max_retries: int) -> Iterator[dict]:
    if not keys:
        return
    started = _connect(ray, address, num_workers)
    actor_cls = ray.remote(num_cpus=1, max_restarts=0, max_task_retries=0)(EpisodeActor)
    actors: list = []
    try:
        cpus = int(ray.cluster_resources().get("CPU", 0))
        size = num_workers or cpus
        if size > cpus:
            raise L3MVNError(f"the Ray cluster has {cpus} CPUs; --workers must be <= {cpus}, got {size}")
        with interrupt_on_sigterm():
            actors = [actor_cls.remote(job) for _ in range(min(size, len(keys)))]
            yield from _schedule(ray, job, keys, actors, actor_cls, max_retries)
    finally:
        for actor in actors:
            with suppress(Exception):
                ray.kill(actor)
        if started:
            ray.shutdown()


class EpisodeActor:
    """One Ray worker process: the job's episode set and environments stay loaded between tasks."""

    def __init__(self, job: EvalJob) -> None:
        self.job = job
        with suppress(Exception):
            job.load()  # a load error is reported by run_one, once per episode, as an error row

    def run(self, key: str) -> dict:
        return self.job.run_one(key)


def _schedule(ray, job: EvalJob, keys: list[str], actors: list, actor_cls, max_retries: int) -> Iterator[dict]:
    from ray.exceptions import RayActorError, RayError

    pending, strikes = deque(keys), Counter()
    in_flight: dict = {}  # ObjectRef -> (actor, key)

    def submit(actor) -> None:
        if pending:
            key = pending.popleft()
            in_flight[actor.run.remote(key)] = (actor, key)

    for actor in actors:
        submit(actor)
    while in_flight:
        (ref,), _ = ray.wait(list(in_flight), num_returns=1)
        actor, key = in_flight.pop(ref)
        row: dict | None = None
        try:
            row = ray.get(ref)
        except RayActorError as exc:
            strikes[key] += 1
            actors.remove(actor)
            with suppress(Exception):
                ray.kill(actor)
            actor = actor_cls.remote(job)
            actors.append(actor)
            if strikes[key] <= max_retries:
                pending.appendleft(key)
            else:
                row = error_row(job, key, f"Ray worker died {strikes[key]} times running this episode: "
                                f"{_first_line(exc)}")
        except RayError as exc:
            row = error_row(job, key, f"Ray task failed: {_first_line(exc)}")
        submit(actor)  # keep the actor busy while the caller handles the row
        if row is not None:
            yield row


def _connect(ray, address: str | None, num_workers: int | None) -> bool:
    """Join ``address`` or start a private local Ray; True when this call started it."""
    quiet = {"include_dashboard": False, "logging_level": logging.ERROR, "log_to_driver": False,
             "configure_logging": True}
    if ray.is_initialized():
        return False
    try:
        if address is None:
            os.environ.setdefault("RAY_ACCEL_ENV_VAR_OVERRIDE_ON_ZERO", "0")
            # A private instance serves only this process: keep it off the network.
            ray.init(num_cpus=num_workers or os.cpu_count() or 1, _node_ip_address="127.0.0.1", **quiet)
        else:
            ray.init(address=address, **quiet)
    except (ConnectionError, RuntimeError, ValueError) as exc:
        where = address or "a local Ray instance"
        raise L3MVNError(f"could not start or join {where}: {_first_line(exc)}") from None
    return True


def _import_ray():
    try:
        import ray
    except ImportError:
        raise L3MVNError("the Ray backend needs Ray: pip install 'l3mvn[distributed]'") from None
    return ray


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__

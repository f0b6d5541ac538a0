"""Run an evaluation's episodes on a Ray cluster (``pip install 'l3mvn[distributed]'``).

Each episode is one task on a long-lived actor (one per CPU by default) that loads the episode set
once and keeps environments (and, for language policies, their models) warm across episodes. Each
actor holds one task at a time, so when an actor's process dies we know the one episode it took
down: that episode is retried on a fresh actor up to ``max_retries`` times and then yielded as an
error row, never dropped. Every node needs ``l3mvn`` importable (installed, or shipped with
``runtime_env``), as for any Ray job.

Ray runs whatever code reaches its ports. The private instance started when no address is given
listens on loopback only and does not outlive its driver; a cluster joined by address is exactly as
exposed as its operator configured it.
"""

from __future__ import annotations

import ipaddress
import logging
import os
import subprocess
import sys
from collections import Counter, deque
from collections.abc import Callable, Generator, Iterable, Iterator
from contextlib import contextmanager, suppress

from l3mvn.core.errors import L3MVNError, first_line
from l3mvn.run.eval.backends import interrupt_on_sigterm
from l3mvn.run.eval.job import EvalJob, error_row


def run_ray(
    job: EvalJob, keys: Iterable[str], address: str | None = None, num_workers: int | None = None, max_retries: int = 2
) -> Generator[dict, None, None]:
    """One result row per key, in completion order. Arguments are checked now (Ray missing raises
    L3MVNError), Ray is started or joined on the first ``next()``.

    Without ``address`` a private local Ray is started (``num_workers`` CPUs, default all): every
    port it opens is on 127.0.0.1, and it is shut down at the end or, if the driver is killed, about
    a second later at most. With one (``"auto"``, ``"ray://host:10001"``, ``"host:6379"``) the run
    joins that cluster as it is configured, network exposure included, and leaves it running.
    """
    ray = _import_ray()
    keys = list(keys)
    if num_workers is not None and num_workers < 1:
        raise L3MVNError(f"--workers must be >= 1, got {num_workers}")
    if max_retries < 0:
        raise L3MVNError(f"max_retries must be >= 0, got {max_retries}")
    return _run(ray, job, keys, address, num_workers, max_retries)


def _run(
    ray, job: EvalJob, keys: list[str], address: str | None, num_workers: int | None, max_retries: int
) -> Generator[dict, None, None]:
    if not keys:
        return
    leave = _connect(ray, address, num_workers)
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
        if leave is not None:
            leave()


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

    pending = deque(keys)
    strikes: Counter[str] = Counter()
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
                row = error_row(
                    job, key, f"Ray worker died {strikes[key]} times running this episode: {first_line(exc)}"
                )
        except RayError as exc:
            row = error_row(job, key, f"Ray task failed: {first_line(exc)}")
        submit(actor)  # keep the actor busy while the caller handles the row
        if row is not None:
            yield row


def _connect(ray, address: str | None, num_workers: int | None) -> Callable[[], None] | None:
    """Join ``address`` or start a private local Ray. Returns how to leave it again, or None when Ray
    was already initialised in this process (that session is the caller's to end)."""
    if ray.is_initialized():
        return None
    if address is None:
        return _start_private(ray, num_workers or os.cpu_count() or 1)
    _init(ray, address, address=address)
    return ray.shutdown


@contextmanager
def private_ray(num_cpus: int) -> Iterator[None]:
    """A private local Ray held across several ``run_ray`` calls (benchmarks), on loopback only and
    torn down on exit, as ``run_ray`` without ``--address`` starts one per run."""
    ray = _import_ray()
    stop = _start_private(ray, num_cpus)
    try:
        yield
    finally:
        stop()


def _start_private(ray, num_cpus: int) -> Callable[[], None]:
    """Start a Ray that serves only this process: every port on loopback, gone with the driver.
    ``address="local"`` starts a new instance even when ``RAY_ADDRESS`` names a cluster."""
    os.environ.setdefault("RAY_ACCEL_ENV_VAR_OVERRIDE_ON_ZERO", "0")
    reaper = _Reaper()
    try:
        with _loopback_node():
            _init(ray, "a local Ray instance", address="local", num_cpus=num_cpus)
        reaper.name_ray_processes()
        _check_loopback(ray)
    except BaseException:
        _stop_private(ray, reaper)
        raise
    return lambda: _stop_private(ray, reaper)


def _stop_private(ray, reaper: _Reaper) -> None:
    try:
        ray.shutdown()
    finally:
        reaper.close()


def _init(ray, where: str, **kwargs) -> None:
    try:
        ray.init(
            include_dashboard=False, logging_level=logging.ERROR, log_to_driver=False, configure_logging=True, **kwargs
        )
    except (ConnectionError, RuntimeError, ValueError) as exc:
        raise L3MVNError(f"could not start or join {where}: {first_line(exc)}") from None


_CLUSTERS_SWITCH = "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"


@contextmanager
def _loopback_node() -> Iterator[None]:
    """Give the node Ray is about to start the address 127.0.0.1, which every Ray server then binds
    (GCS, raylet, object and node manager, workers, dashboard, agents, metrics export).

    ``_node_ip_address="127.0.0.1"`` is not enough: Ray rewrites a loopback node address to the
    machine's outward-facing one, and binds the rest to all interfaces, unless multi-node clusters
    are off (its default on macOS and Windows; ``RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0`` elsewhere).
    This process reads that switch once, when Ray is imported, and each process Ray starts reads its
    environment, so both are set while Ray starts and then put back: a later ``--address`` run in
    this process finds its own address as usual. ``_check_loopback`` catches a Ray that ignores it.
    """
    from ray._private import ray_constants

    saved_env, saved_constant = os.environ.get(_CLUSTERS_SWITCH), ray_constants.ENABLE_RAY_CLUSTER
    os.environ[_CLUSTERS_SWITCH] = "0"
    ray_constants.ENABLE_RAY_CLUSTER = False
    try:
        yield
    finally:
        ray_constants.ENABLE_RAY_CLUSTER = saved_constant
        if saved_env is None:
            del os.environ[_CLUSTERS_SWITCH]
        else:
            os.environ[_CLUSTERS_SWITCH] = saved_env


def _check_loopback(ray) -> None:
    """Fail closed: a Ray whose node is not on loopback serves this run to the network."""
    ip = ray.util.get_node_ip_address()
    if not ipaddress.ip_address(ip).is_loopback:
        raise L3MVNError(
            f"the private Ray instance started on {ip}, not on loopback, so it would be "
            f"reachable from the network (Ray {ray.__version__}); refusing to run on it"
        )


class _Reaper:
    """Kills this run's Ray processes when the driver exits, however it exits.

    Ray ties its GCS and raylet to the driver (the kernel kills them with it on Linux), but the
    raylet's dashboard and runtime-env agents then spend a minute reporting the raylet's death to
    the dead GCS, listening all the while; workers take a few seconds to notice. The reaper is a
    small process in its own session (so a Ctrl-C or a kill of the driver's process group spares
    it) that holds a pipe from the driver and tracks the driver's Ray processes and their children.
    When the pipe closes, after ``ray.shutdown()`` or because the driver died, it kills whatever of
    them is still alive. Processes that existed before Ray started are never its business.
    """

    def __init__(self) -> None:
        import psutil  # Ray bundles it (ray/thirdparty_files), ahead of sys.path once Ray is imported

        self._driver = psutil.Process()
        self._before = {child.pid for child in self._driver.children()}
        self._proc = subprocess.Popen(
            [
                sys.executable,
                "-c",
                _REAPER_PROGRAM,
                os.path.dirname(os.path.dirname(psutil.__file__)),
                str(self._driver.pid),
                *map(str, self._before),
            ],
            stdin=subprocess.PIPE,
            stdout=subprocess.DEVNULL,
            text=True,
            start_new_session=True,
        )

    def name_ray_processes(self) -> None:
        """Narrow the watch from every new child of the driver to those ``ray.init`` started."""
        started = [
            child.pid
            for child in self._driver.children()
            if child.pid not in self._before and child.pid != self._proc.pid
        ]
        assert self._proc.stdin is not None  # opened with stdin=PIPE
        try:
            self._proc.stdin.write(" ".join(map(str, started)) + "\n")
            self._proc.stdin.flush()
        except OSError:
            raise L3MVNError(
                f"the process that stops Ray with this run exited (status {self._proc.poll()}); not running without it"
            ) from None

    def close(self) -> None:
        assert self._proc.stdin is not None  # opened with stdin=PIPE
        with suppress(OSError):
            self._proc.stdin.close()
        with suppress(subprocess.TimeoutExpired):
            self._proc.wait(timeout=10)


# Run as ``python -c``: argv is psutil's directory, the driver's pid, then the pids of children the
# driver had before Ray started. Each stdin line names the driver's Ray processes; EOF means stop.
_REAPER_PROGRAM = """\
import sys, threading
sys.path.insert(0, sys.argv[1])
import psutil

driver = psutil.Process(int(sys.argv[2]))
ignored = {int(pid) for pid in sys.argv[3:]} | {psutil.Process().pid}
named = None  # until the driver names its Ray processes: every new child of the driver
seen = {}  # child of the driver -> every process of its tree seen so far (a dying tree looks smaller)
closed = threading.Event()


def listen():
    global named
    for line in sys.stdin:
        named = {int(pid) for pid in line.split()}
    closed.set()


def look():
    for child in driver.children():
        if child.pid not in ignored:
            tree = seen.setdefault(child.pid, set())
            tree.add(child)
            try:
                tree.update(child.children(recursive=True))
            except psutil.NoSuchProcess:
                pass


threading.Thread(target=listen, daemon=True).start()
while True:
    try:
        look()
    except psutil.Error:
        pass
    if closed.wait(0.25):
        break
for root, tree in seen.items():
    if named is not None and root not in named:
        continue
    for proc in tree:
        try:
            proc.kill()  # psutil refuses if the pid now belongs to another process
        except psutil.Error:
            pass
"""


def _import_ray():
    try:
        import ray
    except ImportError:
        raise L3MVNError("the Ray backend needs Ray: pip install 'l3mvn[distributed]'") from None
    return ray

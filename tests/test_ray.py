"""The Ray backend on a real private cluster: a killed actor costs a retry and the results equal a
local run's, one row per episode; every port the cluster opens is on loopback; and the cluster goes
with its driver, even one killed with SIGKILL."""

from __future__ import annotations

import ipaddress
import os
import signal
import subprocess
import time
from types import SimpleNamespace

import pytest
from test_parallel import REPO, complete_rows, eval_cmd, metrics_by_key, write_dataset

from l3mvn.core.config import Config
from l3mvn.core.errors import L3MVNError
from l3mvn.run.eval.backends import run_local
from l3mvn.run.eval.job import EvalJob, is_error_row
from l3mvn.run.eval.ray_backend import _connect, run_ray

ray = pytest.importorskip("ray")
psutil = pytest.importorskip("psutil")  # after ray, which puts its bundled copy on sys.path

SWITCH = "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"


def test_a_ray_run_survives_a_killed_actor_and_matches_a_local_run(tmp_path):
    dataset = write_dataset(tmp_path / "data", per_house=10)
    job = EvalJob.create(dataset, "val", config=Config().with_frame(120, 160), policy="oracle")
    assert len(job.keys()) == 20
    local = list(run_local(job, job.keys(), workers=1))

    rows: list[dict] = []
    for row in run_ray(job, job.keys(), address=None, num_workers=2):
        if not rows:  # that actor already holds its next episode
            os.kill(int(row["worker"].rsplit(":", 1)[1]), signal.SIGKILL)
        rows.append(row)

    assert not ray.is_initialized(), "the private Ray instance was left running"
    assert sorted(r["key"] for r in rows) == sorted(job.keys())
    assert not any(is_error_row(r) for r in rows)
    assert metrics_by_key(rows) == metrics_by_key(local)
    assert len({r["worker"] for r in rows}) == 3  # a fresh actor replaced the killed one
    assert {r["config_hash"] for r in rows} == {job.config_hash}


def test_every_port_of_a_private_ray_is_on_loopback_and_closed_after_the_run(tmp_path):
    dataset = write_dataset(tmp_path / "data", per_house=2)
    job = EvalJob.create(dataset, "val", config=Config().with_frame(60, 80), policy="oracle")
    me, switch = psutil.Process(), os.environ.get(SWITCH)
    during: list[tuple[str, str]] = []
    ray_procs: list = []
    for _ in run_ray(job, job.keys(), address=None, num_workers=2):
        if not during:  # an actor is up: the driver, the cluster and a worker are all listening
            ray_procs = me.children(recursive=True)
            during = listening([me, *ray_procs])

    owners = {name for name, _ in during}
    expected = {me.name(), "gcs_server", "raylet", "ray::DashboardAgent", "ray::RuntimeEnvAgent"}
    assert expected <= owners and any(n.startswith("ray::EpisodeActor") for n in owners), owners
    exposed = [(name, addr) for name, addr in during if not on_loopback(addr)]
    assert not exposed, f"Ray listens beyond loopback: {exposed}"
    assert not listening(ray_procs), "the run ended with Ray processes still listening"
    assert os.environ.get(SWITCH) == switch, "the loopback switch leaked out of ray.init"


def test_a_driver_killed_with_sigkill_takes_its_private_ray_with_it(tmp_path):
    dataset = write_dataset(tmp_path / "data", per_house=15)
    out = tmp_path / "results.jsonl"
    driver = subprocess.Popen(
        eval_cmd(dataset, out, "--backend", "ray"),
        cwd=REPO,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 120
        while not (out.exists() and complete_rows(out)):
            assert driver.poll() is None, driver.communicate()[1]
            assert time.monotonic() < deadline, "no result row within two minutes"
            time.sleep(0.05)
        procs = psutil.Process(driver.pid).children(recursive=True)
        assert listening(procs), "no Ray process was listening mid-run"
    finally:
        driver.kill()
        driver.communicate()
    killed_at = time.monotonic()
    while (alive := [p for p in procs if running(p)]) and time.monotonic() - killed_at < 10:
        time.sleep(0.1)
    assert not alive, f"outlived the driver by 10 s: {alive}, listening on {listening(alive)}"


def test_a_private_ray_that_is_not_on_loopback_is_shut_down_and_refused(monkeypatch):
    from ray._private import ray_constants

    monkeypatch.delenv(SWITCH, raising=False)
    calls: list[tuple] = []

    def init(**kwargs):
        calls.append(("init", kwargs["address"], os.environ.get(SWITCH), ray_constants.ENABLE_RAY_CLUSTER))

    fake = SimpleNamespace(
        __version__="test",
        is_initialized=lambda: False,
        init=init,
        shutdown=lambda: calls.append(("shutdown",)),
        util=SimpleNamespace(get_node_ip_address=lambda: "192.0.2.7"),
    )
    enabled = ray_constants.ENABLE_RAY_CLUSTER
    with pytest.raises(L3MVNError, match="not on loopback"):
        _connect(fake, None, 1)
    assert calls == [("init", "local", "0", False), ("shutdown",)]
    assert SWITCH not in os.environ and ray_constants.ENABLE_RAY_CLUSTER == enabled


def listening(procs) -> list[tuple[str, str]]:
    """(process name, address) of every listening TCP socket the processes hold."""
    found = []
    for proc in procs:
        try:
            name = proc.name()
            connections = getattr(proc, "net_connections", None) or proc.connections  # psutil < 6
            conns = connections(kind="tcp")
        except psutil.NoSuchProcess:
            continue
        found += [(name, c.laddr.ip) for c in conns if c.status == psutil.CONN_LISTEN]
    return found


def on_loopback(addr: str) -> bool:
    """127.0.0.1 and ::1, and 127.0.0.1 as gRPC binds it on a dual-stack socket (::ffff:127.0.0.1)."""
    ip = ipaddress.ip_address(addr)
    return ip.is_loopback or bool(getattr(ip, "ipv4_mapped", None) and ip.ipv4_mapped.is_loopback)


def running(proc) -> bool:
    try:
        return proc.status() != psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return False

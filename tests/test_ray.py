"""The Ray backend on a real private cluster (loopback only): a killed actor costs a retry, and the
results equal a local run's, one row per episode."""

from __future__ import annotations

import os
import signal

import pytest

from l3mvn.config import SimConfig
from l3mvn.eval.backends import run_local
from l3mvn.eval.job import EvalJob, is_error_row
from l3mvn.eval.ray_backend import run_ray
from test_parallel import metrics_by_key, write_dataset

ray = pytest.importorskip("ray")


def test_a_ray_run_survives_a_killed_actor_and_matches_a_local_run(tmp_path):
    dataset = write_dataset(tmp_path / "data", per_house=10)
    job = EvalJob.create(dataset, "val", sim=SimConfig().with_frame(120, 160), policy="oracle")
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


"""The dashboard and the recorder on a scan dataset (issue 14: "work unchanged on both new sources").

A procedural house exported in HM3D's layout is served by ``l3mvn serve --dataset ... --scenes ...``;
the oracle runs an episode to success under the dataset's own rule (HM3D view points) and the
recording reads back with every step.
"""

from __future__ import annotations

import time

import pytest

pytest.importorskip("trimesh")
pytest.importorskip("embreex")

from conftest import free_port

from l3mvn.core.config import Config, TaskConfig  # noqa: E402
from l3mvn.run.recording import read_recording  # noqa: E402
from l3mvn.world.datasets.hm3d_export import export_hm3d  # noqa: E402
from l3mvn_studio.cli import add_arguments, run  # noqa: E402
from l3mvn_studio.server import start_dashboard  # noqa: E402

HM3D = Config(task=TaskConfig(success_rule="hm3d")).with_frame(120, 160)


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    out = tmp_path_factory.mktemp("hm3d")
    export_hm3d(out, 1, episodes_per_floor=2, seed=0)
    return out


def test_the_dashboard_runs_and_records_an_episode_of_a_scan_dataset(exported, tmp_path):
    dash = start_dashboard(
        port=free_port(),
        dataset=exported / "objectnav_hm3d_v2",
        split="val",
        scenes_dir=exported / "scene_datasets",
        cfg=HM3D,
        policy="oracle",
        record=True,
        record_dir=tmp_path,
    )
    try:
        ctl = dash.controller
        ctl.reset(ctl.scene_keys[0], 0)
        assert ctl.wait_idle(60)
        ctl.set_speed(60)
        ctl.run()
        deadline = time.monotonic() + 120
        while not ctl.snapshot.event.done and time.monotonic() < deadline:
            time.sleep(0.05)
        assert ctl.wait_idle(30)
        event = ctl.snapshot.event
        assert event.done and event.result is not None and event.result["success"] == 1.0, event.result
        assert event.result["rule"] == "hm3d"
    finally:
        dash.stop()
    recording = next(tmp_path.glob("*.rrd"))
    assert len(read_recording(recording).steps) == event.result["steps"] + 1


def test_serve_reads_the_dataset_rule_and_a_missing_scan_root_is_one_line(exported, capsys):
    import argparse

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    args = parser.parse_args(
        [
            "--dataset",
            str(exported / "objectnav_hm3d_v2"),
            "--scenes",
            str(exported / "nowhere"),
            "--port",
            str(free_port()),
        ]
    )
    assert run(args) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error:") and "\n" not in err and "nowhere" in err

"""Start and stop the dashboard: a viser server, the shared controller and its view."""

from __future__ import annotations

import logging
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import viser

from l3mvn.core.config import Config
from l3mvn.core.errors import L3MVNError
from l3mvn.run.recording.catalogue import DEFAULT_RECORD_DIR
from l3mvn.run.serving import check_listen_address
from l3mvn.world.datasets import load_episode_set
from l3mvn_studio.compare import EpisodeSource
from l3mvn_studio.origin import ALLOW_ORIGIN_FLAG, LOOPBACK_HOSTS, OriginPolicy
from l3mvn_studio.results_view import ResultsSource
from l3mvn_studio.session_worker import DashboardController
from l3mvn_studio.views import DashboardView
from l3mvn_studio.viser_hooks import start_checked_server

log = logging.getLogger(__name__)

RERUN_FOLDER = "reruns"  # beside the eval's recordings: where the Results panel's re-runs record by default


@dataclass
class Dashboard:
    """A running dashboard; ``stop()`` ends the worker, the view thread and the web server."""

    server: viser.ViserServer
    controller: DashboardController
    view: DashboardView

    @property
    def url(self) -> str:
        host = self.server.get_host()
        shown = "127.0.0.1" if host in ("0.0.0.0", "::") else host
        return f"http://{shown}:{self.server.get_port()}"

    def stop(self) -> None:
        self.controller.close()
        self.view.close()
        self.server.stop()


def start_dashboard(
    *,
    dataset: str | Path | None = None,
    split: str = "val",
    policy: str = "oracle",
    host: str = "127.0.0.1",
    port: int = 8080,
    houses: int = 3,
    episodes_per_house: int = 5,
    seed: int = 0,
    cfg: Config | None = None,
    steps_per_second: float = 4.0,
    record: bool = False,
    record_dir: str | Path | None = None,
    verbose: bool = False,
    allow_origins: Iterable[str] = (),
    results_dir: str | Path | None = None,
    recordings_dir: str | Path | None = None,
    scenes_dir: str | Path | None = None,
) -> Dashboard:
    """Load the episodes, start the worker and serve the page (returns at once; threads run it).

    Only pages served from this dashboard's own address, or from one of ``allow_origins`` (a reverse
    proxy's public origin, ``https://host[:port]``), may connect: see app/origin.py.

    ``scenes_dir`` is the scan root of a habitat ObjectNav ``dataset`` (as ``l3mvn eval --scenes``).
    ``record_dir`` is where the live session records (default ``recordings/``). ``results_dir`` adds the
    Results panel over the eval result files in that folder: their recordings are read from
    ``recordings_dir`` (default ``recordings/``, where ``l3mvn eval --record`` writes); its re-runs use
    this episode set and seed and are recorded in ``record_dir`` when given, else in ``reruns/`` beside
    ``recordings_dir``, never among the eval's own recordings.

    It serves on exactly ``host:port``; a bad port, a host that does not resolve or is not this
    machine's, and a port in use are one-line L3MVNErrors, checked before the episodes load.
    """
    cfg = cfg or Config()
    origins = OriginPolicy(host, allow_origins)
    check_listen_address(host, port)
    if results_dir is not None and not Path(results_dir).is_dir():
        raise L3MVNError(f"--results {results_dir} is not a folder (it should hold eval result .jsonl files)")
    recordings = Path(recordings_dir if recordings_dir is not None else DEFAULT_RECORD_DIR)
    reruns = None if results_dir is None else rerun_folder(recordings, record_dir)
    if host not in LOOPBACK_HOSTS:
        log.warning(
            "serving on %s: anyone who can reach this machine can drive the dashboard; browsers "
            "that open it by another name need %s http://NAME:%d",
            host,
            ALLOW_ORIGIN_FLAG,
            port,
        )
    episodes = load_episode_set(
        dataset, split, houses=houses, episodes_per_house=episodes_per_house, seed=seed, cfg=cfg, scenes_dir=scenes_dir
    )
    controller = DashboardController(
        episodes,
        cfg,
        policy=policy,
        seed=seed,
        steps_per_second=steps_per_second,
        record_dir=record_dir if record_dir is not None else DEFAULT_RECORD_DIR,
    )
    try:
        if record:
            controller.set_record(True)
        server = start_checked_server(origins.check, host=host, port=port, label="L3MVN Studio", verbose=verbose)
    except BaseException:
        controller.close()
        raise
    try:
        source = (
            None
            if reruns is None
            else ResultsSource(
                Path(results_dir),
                recordings,
                reruns,
                None if dataset is None else str(dataset),
                split,
                houses,
                episodes_per_house,
                seed,
                None if scenes_dir is None else str(scenes_dir),
            )
        )
        episodes_source = EpisodeSource(
            None if dataset is None else str(dataset),
            split,
            houses,
            episodes_per_house,
            seed,
            None if scenes_dir is None else str(scenes_dir),
        )
        view = DashboardView(server, controller, source, episodes_source)
    except BaseException:
        controller.close()
        server.stop()
        raise
    if record:
        view.record.value = True
    return Dashboard(server, controller, view)


def rerun_folder(recordings_dir: Path, record_dir: str | Path | None) -> Path:
    """Where the Results panel's re-runs record: ``record_dir`` when given, else ``reruns/`` beside the
    eval's recordings. A re-run must never write among the recordings it is compared with."""
    folder = Path(record_dir) if record_dir is not None else recordings_dir.resolve().parent / RERUN_FOLDER
    if folder.resolve() == recordings_dir.resolve():
        raise L3MVNError(
            f"re-runs would be recorded among the eval's own recordings in {recordings_dir}: give "
            f"--record-dir another folder (or leave it out for {RERUN_FOLDER}/ beside them)"
        )
    return folder

"""habitat-sim as a backend, in the user's own interpreter: the ``Environment`` over a server process.

``habitat_environment`` starts ``PYTHON habitat_server.py`` with the Python that has habitat-sim (any
version, Python >= 3.8, nothing of ours installed there) and speaks the bridge protocol of
``habitat_server`` over the child's stdin/stdout: JSON headers and raw array bytes. The server
speaks Habitat's frame; this side converts with the floor's ``SceneMap`` (``pose_to_habitat``), which
also names the categories and the episode floor the environment serves, so the task judges a
habitat run on the same floor as one of ours. A server that exits, is killed or hangs is a one-line
``L3MVNError`` (end of stream at once; silence after ``SimConfig.server_timeout_s``), the child is
always reaped, and it never outlives us: it reads end-of-file when we go.
"""

from __future__ import annotations

import dataclasses
import math
import os
import select
import signal
import subprocess
import sys
import tempfile
import time
import weakref
from collections.abc import Mapping, Sequence
from functools import cached_property
from pathlib import Path
from typing import NoReturn

import numpy as np

from l3mvn.core.config import SimConfig
from l3mvn.core.errors import L3MVNError, one_line
from l3mvn.core.frames import CameraFrame
from l3mvn.core.types import Action, Observation, Pose
from l3mvn.world.episode import Episode
from l3mvn.world.scenes.categories import RAW_NAMES
from l3mvn.world.scenes.scan import ScanFloor
from l3mvn.world.scenes.scene import SceneMap
from l3mvn.world.sim import habitat_server as wire
from l3mvn.world.sim.base import EpisodeState
from l3mvn.world.sim.simulator import BuiltinSimulator

SERVER_SCRIPT = Path(wire.__file__).resolve()
_CHUNK = 1 << 20
# How long a server that was told to close, or that closed its pipe, gets to exit before it is killed.
_EXIT_GRACE_S = 5.0


def habitat_command(python: str | os.PathLike) -> list[str]:
    """The command that starts the habitat server in ``python`` (``--habitat-python``), checked."""
    path = Path(python).expanduser()
    if not path.exists():
        raise L3MVNError(
            f"--habitat-python {str(python)!r}: no such file; give the python of the environment "
            f"that has habitat-sim (e.g. ~/miniconda3/envs/habitat/bin/python)"
        )
    if path.is_dir() or not os.access(path, os.X_OK):
        raise L3MVNError(f"--habitat-python {str(python)!r} is not an executable file")
    return [str(path), str(SERVER_SCRIPT)]


def builtin_command() -> list[str]:
    """Our own simulator as the server, in this interpreter (``builtin_server``)."""
    return [sys.executable, "-m", "l3mvn.world.sim.builtin_server"]


class ServerProcess:
    """A bridge server child: framed requests with a deadline, its death or silence one line."""

    def __init__(self, argv: Sequence[str], *, timeout_s: float, name: str = "habitat server") -> None:
        self.name, self.timeout_s = name, float(timeout_s)
        self._stderr = tempfile.TemporaryFile()
        self._failure: str | None = None
        try:
            # Its own session: a Ctrl-C meant for us does not kill it mid-request; we close it.
            self._proc = subprocess.Popen(
                list(argv), stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self._stderr, start_new_session=True
            )
        except OSError as exc:
            self._stderr.close()
            raise L3MVNError(f"{name}: cannot start {argv[0]!r}: {exc.strerror or exc}") from None
        self._finalizer = weakref.finalize(self, _stop, self._proc, self._stderr)
        self.hello = self._receive("start")[0]
        if not self.hello.get("ok"):
            error = self.hello.get("error", "no reason given")
            self.close()
            raise L3MVNError(one_line(L3MVNError(f"{name} ({argv[0]}) could not start: {error}")))
        if self.hello.get("protocol") != wire.PROTOCOL:
            self.close()
            raise L3MVNError(
                f"{name} speaks protocol {self.hello.get('protocol')!r}, we speak {wire.PROTOCOL}: "
                f"{SERVER_SCRIPT.name} and this library are from different versions"
            )

    @property
    def pid(self) -> int:
        return self._proc.pid

    def request(self, op: str, **fields) -> tuple[dict, dict[str, np.ndarray]]:
        """Send one request, wait for its answer; a refused request is an ``L3MVNError`` naming it."""
        if self._failure is not None:
            raise L3MVNError(self._failure)
        frame = wire.pack(dict(fields, op=op))
        try:
            for part in frame:
                self._proc.stdin.write(part)  # type: ignore[union-attr]
            self._proc.stdin.flush()  # type: ignore[union-attr]
        except OSError:  # BrokenPipeError: the server is gone
            self._fail(self._death(op))
        header, arrays = self._receive(op)
        if not header.get("ok"):
            error = header.get("error", "no reason given")
            raise L3MVNError(one_line(L3MVNError(f"{self.name}: {op} failed: {error}")))
        return header, arrays

    def close(self) -> None:
        """Ask the server to stop, then make sure it did; idempotent."""
        if self._failure is None and self._proc.poll() is None:
            try:
                for part in wire.pack({"op": "close"}):
                    self._proc.stdin.write(part)  # type: ignore[union-attr]
                self._proc.stdin.close()  # type: ignore[union-attr]
                self._proc.wait(timeout=_EXIT_GRACE_S)
            except (OSError, ValueError, subprocess.TimeoutExpired):
                pass
        self._failure = self._failure or f"{self.name} is closed"
        self._finalizer()

    # --- reading with a deadline --------------------------------------------------------------
    def _receive(self, op: str) -> tuple[dict, dict[str, np.ndarray]]:
        deadline = time.monotonic() + self.timeout_s
        try:
            header_len, payload_len = wire.parse_prefix(self._read(wire.PREFIX.size, op, deadline))
            header_bytes = self._read(header_len, op, deadline)
            payload = self._read(payload_len, op, deadline)
            return wire.parse_body(header_bytes, payload)
        except wire.ProtocolError as exc:
            self._fail(f"{self.name}: broken answer to {op}: {exc}")

    def _read(self, n: int, op: str, deadline: float) -> bytearray:
        fd = self._proc.stdout.fileno()  # type: ignore[union-attr]
        buf = bytearray()
        while len(buf) < n:
            left = deadline - time.monotonic()
            ready = select.select([fd], [], [], max(left, 0.0))[0] if left > 0 else []
            if not ready:
                self._fail(
                    f"{self.name} answered no {op} request within {self.timeout_s:g} s "
                    f"(sim.server_timeout_s); stopped it"
                )
            chunk = os.read(fd, min(n - len(buf), _CHUNK))
            if not chunk:
                self._fail(self._death(op))
            buf += chunk
        return buf

    def _death(self, op: str) -> str:
        try:
            code = self._proc.wait(timeout=_EXIT_GRACE_S)
        except subprocess.TimeoutExpired:
            return f"{self.name} closed its pipe during {op} but is still running; stopped it"
        if code >= 0:
            how = f"exited with code {code}"
        else:
            try:
                how = f"was killed by {signal.Signals(-code).name}"
            except ValueError:
                how = f"was killed by signal {-code}"
        last = _last_line(self._stderr)
        return f"{self.name} {how} during {op}" + (f": {last}" if last else "")

    def _fail(self, message: str) -> NoReturn:
        self._failure = one_line(L3MVNError(message))
        self._finalizer()
        raise L3MVNError(self._failure)


def _stop(proc: subprocess.Popen, stderr) -> None:
    """Kill and reap the child if it is still there (finalizer: runs once, also at exit)."""
    if proc.poll() is None:
        proc.kill()
    proc.wait()
    for stream in (proc.stdin, proc.stdout):
        try:
            stream.close()  # type: ignore[union-attr]
        except (OSError, ValueError):
            pass
    stderr.close()


def _last_line(stream) -> str:
    """The last non-empty line the server wrote to stderr (its traceback's verdict)."""
    try:
        stream.seek(max(0, stream.seek(0, os.SEEK_END) - 4096))
        lines = [line.strip() for line in stream.read().decode("utf-8", "replace").splitlines()]
    except (OSError, ValueError):
        return ""
    lines = [line for line in lines if line]
    return lines[-1] if lines else ""


class BridgeEnvironment(EpisodeState):
    """The ``Environment`` contract served by a bridge server for one floor (``scene``), whose
    ``SceneMap`` gives the categories, the floor's key and its frame against Habitat's.
    ``scene_path`` is what the server loads (a scan file for habitat-sim)."""

    def __init__(
        self,
        server: ServerProcess,
        scene: SceneMap,
        scene_path: str,
        cfg: SimConfig | None = None,
        *,
        category_map: Mapping[str, str] | None = None,
        scene_dataset_config: str | None = None,
        semantic_files: tuple[str, str] | None = None,
    ) -> None:
        self.server, self.scene, self.cfg = server, scene, cfg or SimConfig()
        self.categories = scene.categories
        table = {c: c for c in scene.categories}
        table.update(category_map or {})
        load = {
            "scene": str(scene_path),
            "sim": dataclasses.asdict(self.cfg),
            "categories": list(self.categories),
            "category_map": table,
        }
        if scene_dataset_config is not None:
            load["scene_dataset_config"] = str(scene_dataset_config)
        if semantic_files is not None:
            load["semantic_mesh"], load["semantic_descriptor"] = (str(p) for p in semantic_files)
        self.info, _ = server.request("load", **load)
        if tuple(self.info.get("categories", ())) != self.categories:
            server.close()
            raise L3MVNError(
                f"{server.name} serves categories {self.info.get('categories')}, not {list(self.categories)}"
            )
        self._episode: Episode | None = None
        self._pose: Pose | None = None
        self._steps = 0
        self._path = 0.0
        self._stopped = False

    # --- contract ----------------------------------------------------------------------------
    def reset(self, episode: Episode) -> Observation:
        if (episode.scene, episode.floor) != (self.scene.name, self.scene.floor):
            raise L3MVNError(f"episode {episode.key} belongs to {episode.scene}/{episode.floor}, not {self.scene.key}")
        self._check_goal(episode.goal)
        position, rotation = self.scene.pose_to_habitat(episode.start)
        reply, arrays = self.server.request("reset", position=position, rotation=rotation, goal=episode.goal)
        self._episode = episode
        self._steps, self._path, self._stopped = 0, 0.0, False
        return self._observation(reply, arrays)

    def step(self, action: Action | int | str) -> Observation:
        if self._episode is None:
            raise L3MVNError("step() before reset(): start an episode first")
        if self.done:
            raise L3MVNError(f"episode {self._episode.key} is over (stopped or {self.cfg.max_steps} steps)")
        action = Action.parse(action)
        reply, arrays = self.server.request("step", action=action.name.lower())
        self._steps += 1
        self._stopped = action == Action.STOP
        self._path += float(reply["moved_m"])
        return self._observation(reply, arrays)

    def forward_result(self, pose: Pose) -> tuple[Pose, float]:
        """Where a forward move from ``pose`` would end on this floor's grid (our simulator's motion
        model, without moving): for planners that look ahead, such as the oracle. The move itself
        is the server's, so its pose can differ from this near walls."""
        return self._grid_model.forward_result(pose)

    @cached_property
    def _grid_model(self) -> BuiltinSimulator:
        return BuiltinSimulator(self.scene, self.cfg)

    # --- ground truth ------------------------------------------------------------------------
    def geodesic_distance(self, start: Pose, goals: Sequence[tuple[float, float]]) -> float:
        """The server's own shortest-path distance (habitat's pathfinder) from ``start`` to the nearest
        of ``goals`` ((x, y) points on this floor), inf when none is reachable: a ground truth
        the task can set beside its grid geodesic."""
        if not goals:
            raise L3MVNError("geodesic_distance needs at least one goal point")
        points = [self.scene.pose_to_habitat(Pose(float(x), float(y), 0.0))[0] for x, y in goals]
        reply, _ = self.server.request("geodesic", start=self.scene.pose_to_habitat(start)[0], goals=points)
        distance = reply.get("distance_m")
        return math.inf if distance is None else float(distance)

    def close(self) -> None:
        self.server.close()

    def __enter__(self) -> BridgeEnvironment:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # --- helpers -----------------------------------------------------------------------------
    def _observation(self, reply: dict, arrays: dict[str, np.ndarray]) -> Observation:
        h, w = self.cfg.frame_height, self.cfg.frame_width
        shapes = {"rgb": ((h, w, 3), np.uint8), "depth": ((h, w), np.float32), "semantic": ((h, w), np.int32)}
        for name, (shape, dtype) in shapes.items():
            a = arrays.get(name)
            if a is None or a.shape != shape or a.dtype != dtype:
                got = "nothing" if a is None else f"{a.dtype} {a.shape}"
                self.server.close()
                raise L3MVNError(f"{self.server.name} sent {name} as {got}, expected {np.dtype(dtype)} {shape}")
        self._pose = self.scene.pose_from_habitat(reply["position"], reply["rotation"])
        assert self._episode is not None
        return Observation(
            frame=CameraFrame.of(arrays["rgb"], arrays["depth"], arrays["semantic"]),
            pose=self._pose,
            tilt=math.radians(float(reply["tilt_deg"])),
            goal=self._episode.goal,
            step=self._steps,
            collided=bool(reply["collided"]),
            categories=self.categories,
        )


def start_environment(
    argv: Sequence[str],
    scene: SceneMap,
    scene_path: str,
    cfg: SimConfig | None = None,
    *,
    name: str = "habitat server",
    category_map: Mapping[str, str] | None = None,
    scene_dataset_config: str | None = None,
    semantic_files: tuple[str, str] | None = None,
) -> BridgeEnvironment:
    """Start the server ``argv`` and load ``scene_path`` for the floor ``scene``; the server is
    stopped again if the load fails."""
    cfg = cfg or SimConfig()
    server = ServerProcess(argv, timeout_s=cfg.server_timeout_s, name=name)
    try:
        return BridgeEnvironment(
            server,
            scene,
            scene_path,
            cfg,
            category_map=category_map,
            scene_dataset_config=scene_dataset_config,
            semantic_files=semantic_files,
        )
    except BaseException:
        server.close()
        raise


def hm3d_semantic_files(stage: str | os.PathLike) -> tuple[str, str] | None:
    """HM3D's semantic mesh and table beside a stage (``X[.basis].glb`` -> ``X.semantic.glb``,
    ``X.semantic.txt``), or None when the scan has none."""
    path = Path(stage)
    base = path.name.removesuffix(".glb").removesuffix(".basis")
    mesh, table = path.with_name(f"{base}.semantic.glb"), path.with_name(f"{base}.semantic.txt")
    return (str(mesh), str(table)) if mesh.is_file() and table.is_file() else None


def habitat_environment(
    python: str | os.PathLike,
    scene: SceneMap,
    scene_path: str,
    cfg: SimConfig | None = None,
    *,
    category_map: Mapping[str, str] | None = None,
    scene_dataset_config: str | None = None,
) -> BridgeEnvironment:
    """habitat-sim in ``python`` serving the scan ``scene_path`` for the floor ``scene`` (``--sim
    habitat``), with its HM3D semantic files when they lie beside it."""
    return start_environment(
        habitat_command(python),
        scene,
        scene_path,
        cfg,
        category_map=category_map,
        scene_dataset_config=scene_dataset_config,
        semantic_files=hm3d_semantic_files(scene_path),
    )


def habitat_floor_environment(
    python: str | os.PathLike, scene: SceneMap, cfg: SimConfig | None = None
) -> BridgeEnvironment:
    """``--sim habitat`` for one floor of a scan dataset: the scan the floor was read from
    (``ScanFloor.source``), the nearest ``*.scene_dataset_config.json`` above it (its up axis and
    stage conventions), HM3D's semantic files beside it, and the raw-name table ``RAW_NAMES``."""
    if not isinstance(scene, ScanFloor) or not scene.source:
        raise L3MVNError(
            f"--sim habitat runs scans, and {scene.key} is not one: give --dataset with a habitat "
            f"ObjectNav dataset and --scenes with its scan root"
        )
    stage = Path(scene.source)
    config = next(
        (found for folder in stage.parents for found in sorted(folder.glob("*.scene_dataset_config.json"))), None
    )
    return habitat_environment(
        python,
        scene,
        str(stage),
        cfg,
        category_map=RAW_NAMES,
        scene_dataset_config=None if config is None else str(config),
    )

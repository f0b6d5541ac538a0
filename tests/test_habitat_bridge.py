"""The habitat bridge: the Environment contract over a real server process and the real protocol.

Without habitat-sim the server's backend is our own simulator (``builtin_server``): it must give the
in-process simulator's observations, and a server that is killed, hangs or is the wrong program must
be one line, quickly, with the child reaped. With ``make habitat`` built (or
``L3MVN_HABITAT_PYTHON`` set), the same bridge drives real habitat-sim on a two-room scan.
"""

from __future__ import annotations

import ast
import math
import os
import signal
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from l3mvn.core.config import Config, SimConfig
from l3mvn.core.errors import L3MVNError
from l3mvn.core.types import Pose
from l3mvn.run.registry import make_policy
from l3mvn.run.runner import Runner
from l3mvn.run.session import EpisodeSession
from l3mvn.world.episode import Episode
from l3mvn.world.episodes import generate_episodes
from l3mvn.world.scenes.procedural import generate_house
from l3mvn.world.scenes.scene import SceneMap
from l3mvn.world.sim import habitat_server as wire
from l3mvn.world.sim.habitat_bridge import (
    ServerProcess,
    builtin_command,
    habitat_environment,
    habitat_floor_environment,
    start_environment,
)
from l3mvn.world.sim.simulator import BuiltinSimulator
from l3mvn.world.task import ObjectNavTask
from l3mvn.world.task.regions import geodesic_field

SEED = 3
CFG = SimConfig(frame_height=60, frame_width=80)
HABITAT_PYTHON = Path(os.environ.get("L3MVN_HABITAT_PYTHON", Path.home() / ".cache/l3mvn/habitat/python"))


@pytest.fixture(scope="module")
def house() -> SceneMap:
    return generate_house(SEED)


def _episode(scene: SceneMap, x: float, y: float, heading: float) -> Episode:
    return Episode(1, scene.name, scene.floor, Pose(x, y, heading), scene.present_goals()[0])


def _start(scene: SceneMap, cfg: SimConfig = CFG):
    return start_environment(builtin_command(), scene, f"procedural:{SEED}", cfg, name="builtin server")


def _open_pose(scene: SceneMap) -> Pose:
    """A start with open floor ahead, so the walk below both moves and, later, hits a wall."""
    rows, cols = np.nonzero(scene.navigable)
    i = len(rows) // 2
    x, y = scene.cell_center(int(rows[i]), int(cols[i]))
    return Pose(x, y, 0.3)


# --- the wire format ---------------------------------------------------------------------------------
def _roundtrip(header, arrays):
    data = b"".join(wire.pack(header, arrays))
    header_len, payload_len = wire.parse_prefix(data[: wire.PREFIX.size])
    body = data[wire.PREFIX.size :]
    return wire.parse_body(body[:header_len], bytearray(body[header_len : header_len + payload_len]))


def test_frames_carry_json_and_raw_arrays_of_every_wire_dtype():
    arrays = {dt: (np.arange(24).reshape(2, 3, 4) % 7).astype(dt) for dt in wire.DTYPES}
    header, out = _roundtrip({"op": "step", "action": "move_forward"}, arrays)
    assert header == {"op": "step", "action": "move_forward"}
    for name, a in arrays.items():
        assert out[name].dtype == a.dtype and np.array_equal(out[name], a)
    assert out["<f4"].flags.writeable  # observations are ordinary arrays to their consumers


def test_malformed_frames_and_pickles_are_refused():
    with pytest.raises(wire.ProtocolError, match="bad frame magic"):
        wire.parse_prefix(wire.PREFIX.pack(b"PKL\x00", 2, 0))
    with pytest.raises(wire.ProtocolError, match="dtype object"):
        wire.pack({"op": "x"}, {"o": np.array([object()])})
    bad = b'{"arrays":[{"name":"a","dtype":"<f4","shape":[100],"offset":0,"nbytes":400}]}'
    with pytest.raises(wire.ProtocolError, match="do not fit"):
        wire.parse_body(bad, bytearray(8))
    with pytest.raises(wire.ProtocolError, match="not allowed"):
        wire.parse_body(b'{"arrays":[{"name":"a","dtype":"|O","shape":[1],"offset":0,"nbytes":8}]}', bytearray(8))
    with pytest.raises(wire.ProtocolError, match="not JSON"):
        wire.parse_body(b"\x80\x04pickle", bytearray())


def test_server_module_runs_on_python38_with_only_stdlib_numpy_and_habitat_sim():
    """It runs in the user's habitat interpreter, where nothing of ours is installed."""
    source = Path(wire.__file__).read_text()
    tree = ast.parse(source, feature_version=(3, 8))
    imported = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            imported |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            assert node.level == 0, "relative import in the server module"
            imported.add(node.module.split(".")[0])
    foreign = {m for m in imported if m not in sys.stdlib_module_names and m not in {"numpy", "habitat_sim"}}
    assert not foreign, foreign
    assert not any(isinstance(n, ast.Match) for n in ast.walk(tree))


# --- our simulator behind the real protocol -------------------------------------------------------------
def test_builtin_server_gives_the_in_process_observations(house):
    start = _open_pose(house)
    episode = Episode(1, house.name, house.floor, start, house.present_goals()[0])
    ref = BuiltinSimulator(house, CFG)
    actions = (
        ["look_down"] * 3
        + ["turn_left", "look_up"]
        + ["move_forward"] * 40
        + ["turn_right"] * 2
        + ["move_forward"] * 8
        + ["stop"]
    )
    with _start(house) as env:
        assert env.server.hello["backend"] == "builtin" and env.info["categories"] == list(house.categories)
        pairs = [(env.reset(episode), ref.reset(episode))]
        pairs += [(env.step(a), ref.step(a)) for a in actions]
        collisions = 0
        for got, want in pairs:
            assert np.array_equal(got.rgb, want.rgb) and np.array_equal(got.depth, want.depth)
            assert np.array_equal(got.semantic, want.semantic)
            assert got.pose.x == pytest.approx(want.pose.x, abs=1e-9)
            assert got.pose.y == pytest.approx(want.pose.y, abs=1e-9)
            assert math.cos(got.pose.heading - want.pose.heading) == pytest.approx(1.0, abs=1e-12)
            assert got.tilt == pytest.approx(want.tilt, abs=1e-12)
            assert (got.goal, got.step, got.collided, got.categories) == (
                want.goal,
                want.step,
                want.collided,
                want.categories,
            )
            collisions += got.collided
        assert collisions > 0, "the walk should reach a wall"
        assert env.path_length_m == pytest.approx(ref.path_length_m, abs=1e-9) and env.path_length_m > 1.0
        assert (env.done, env.stopped, env.steps) == (True, True, len(actions))
        with pytest.raises(L3MVNError, match="is over"):
            env.step("move_forward")
        env.set_goal(house.categories[1])
        assert env.episode.goal == house.categories[1]
        with pytest.raises(L3MVNError, match="unknown goal 'unicorn'"):
            env.set_goal("unicorn")


def test_an_oracle_episode_over_the_bridge_scores_as_in_process(house):
    """The whole loop (session, task, oracle planning on ``forward_result``) on the bridge."""
    config = Config(sim=SimConfig(frame_height=30, frame_width=40))
    episode = generate_episodes(house, 1, seed=1, cfg=config)[0]
    want = Runner(config).run(house, episode, "oracle")
    task = ObjectNavTask(house, config)
    with start_environment(builtin_command(), house, f"procedural:{SEED}", config.sim) as env:
        session = EpisodeSession(
            env, task, make_policy("oracle", env, task, config), policy_name="oracle", config_hash=""
        )
        session.start(episode)
        got = session.run()
    assert want.success == 1.0 and want.steps > 10
    assert (got.success, got.steps, got.failure) == (want.success, want.steps, want.failure)
    assert got.spl == pytest.approx(want.spl, abs=1e-9)
    assert got.path_length_m == pytest.approx(want.path_length_m, abs=1e-9)


def _cell_field(scene: SceneMap, r: int, c: int) -> np.ndarray:
    sources = np.zeros(scene.shape, bool)
    sources[r, c] = True
    return geodesic_field(scene.walkable, sources, scene.resolution_m)


def test_geodesic_request_is_the_servers_own_pathfinder(house):
    start = _open_pose(house)
    sr, sc = house.cell_of(start.x, start.y)
    from_start = _cell_field(house, sr, sc)
    r, c = np.unravel_index(np.where(np.isfinite(from_start), from_start, -1.0).argmax(), house.shape)
    target = house.cell_center(int(r), int(c))  # the farthest reachable spot: the path bends
    with _start(house) as env:
        env.reset(_episode(house, start.x, start.y, 0.0))
        got = env.geodesic_distance(start, [target])
        assert got == pytest.approx(float(_cell_field(house, int(r), int(c))[sr, sc]), rel=1e-6)
        assert got > math.dist((start.x, start.y), target) + 0.5
        # Several goals: the nearest counts.
        assert env.geodesic_distance(start, [target, (start.x + 0.01, start.y)]) == pytest.approx(0.0, abs=1e-9)


def test_a_refused_request_is_one_line_and_the_server_goes_on(house):
    server = ServerProcess(builtin_command(), timeout_s=60, name="builtin server")
    try:
        with pytest.raises(L3MVNError, match=r"builtin server: load failed: scene 'gibson:Allensville'"):
            server.request("load", scene="gibson:Allensville", categories=list(house.categories), sim={})
        with pytest.raises(L3MVNError, match="reset failed: no scene: send load first"):
            server.request("reset", position=[0, 0, 0], rotation=[1, 0, 0, 0])
        with pytest.raises(L3MVNError, match="unknown request 'teleport'; valid: load, reset, step"):
            server.request("teleport")
        reply, _ = server.request(
            "load",
            scene=f"procedural:{SEED}",
            categories=list(house.categories),
            sim={"frame_height": 30, "frame_width": 40},
        )
        assert reply["ok"] and reply["navigable_area_m2"] > 10
        with pytest.raises(L3MVNError, match="step failed: unknown action 'fly'"):
            server.request("step", action="fly")
    finally:
        server.close()
    assert server._proc.poll() == 0  # closed on request, exit code 0


def test_a_server_killed_mid_episode_is_one_line_at_once_and_reaped(house):
    start = _open_pose(house)
    env = _start(house, SimConfig(frame_height=60, frame_width=80, server_timeout_s=120))
    env.reset(_episode(house, start.x, start.y, start.heading))
    env.step("turn_left")
    os.kill(env.server.pid, signal.SIGKILL)
    t0 = time.monotonic()
    with pytest.raises(L3MVNError) as err:
        env.step("move_forward")
    assert time.monotonic() - t0 < 10, "a dead server must not be waited on for the timeout"
    message = str(err.value)
    assert "\n" not in message and "builtin server was killed by SIGKILL during step" in message
    assert env.server._proc.returncode == -signal.SIGKILL  # reaped
    with pytest.raises(L3MVNError, match="killed by SIGKILL"):  # and stays an error, at once
        env.step("turn_left")
    env.close()


def test_a_hung_server_is_stopped_after_the_timeout(house):
    start = _open_pose(house)
    env = _start(house)
    env.reset(_episode(house, start.x, start.y, start.heading))
    env.server.timeout_s = 1.5  # sim.server_timeout_s, once the (slower) start and load are done
    os.kill(env.server.pid, signal.SIGSTOP)
    t0 = time.monotonic()
    with pytest.raises(
        L3MVNError,
        match=r"builtin server answered no step request within 1.5 s "
        r"\(sim.server_timeout_s\); stopped it",
    ):
        env.step("move_forward")
    assert 1.4 < time.monotonic() - t0 < 10
    assert env.server._proc.returncode == -signal.SIGKILL


def test_a_server_that_exits_at_start_names_its_last_words(tmp_path, house):
    script = tmp_path / "server.py"
    script.write_text(
        "import sys\nsys.stderr.write('Traceback...\\nImportError: libGL.so.1: cannot open\\n')\nsys.exit(3)\n"
    )
    with pytest.raises(
        L3MVNError,
        match=r"^habitat server exited with code 3 during start: "
        r"ImportError: libGL.so.1: cannot open$",
    ):
        start_environment([sys.executable, str(script)], house, "x.glb", CFG)


# --- --habitat-python -------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "make, message",
    [
        (lambda d: d / "nope" / "python", r"--habitat-python '.*nope/python': no such file; give the python of"),
        (lambda d: d, r"--habitat-python '.*' is not an executable file"),
    ],
)
def test_a_bad_habitat_python_is_one_line(tmp_path, house, make, message):
    with pytest.raises(L3MVNError, match=message) as err:
        habitat_environment(make(tmp_path), house, "scene.glb", CFG)
    assert "\n" not in str(err.value)


def test_habitat_runs_scans_only(house):
    with pytest.raises(L3MVNError, match=r"^--sim habitat runs scans, and procedural-0003/0 is not one: give"):
        habitat_floor_environment(sys.executable, house, CFG)


def test_a_python_without_habitat_sim_is_one_line(house):
    """Our own interpreter runs the real server file as a user's would, and has no habitat_sim."""
    pytest.importorskip("numpy")
    if _has_module("habitat_sim"):
        pytest.skip("this interpreter has habitat_sim")
    with pytest.raises(
        L3MVNError,
        match=r"^habitat server \(.*python.*\) could not start: "
        r"ModuleNotFoundError: No module named 'habitat_sim'$",
    ):
        habitat_environment(sys.executable, house, "scene.glb", CFG)


def test_a_program_that_is_not_the_server_is_one_line(house):
    with pytest.raises(L3MVNError, match=r"^habitat server: broken answer to start: bad frame magic"):
        start_environment(["/bin/echo", "hello, I am not a simulator"], house, "scene.glb", CFG)


def _has_module(name: str) -> bool:
    import importlib.util

    return importlib.util.find_spec(name) is not None


# --- real habitat-sim (``make habitat``) ------------------------------------------------------------------
needs_habitat = pytest.mark.skipif(
    not HABITAT_PYTHON.exists(), reason=f"habitat-sim is not built ({HABITAT_PYTHON} is missing: make habitat)"
)


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """One procedural house in HM3D's layout, read back as an ObjectNav dataset of our own."""
    from l3mvn.world.datasets import load_episode_set
    from l3mvn.world.datasets.hm3d_export import export_hm3d

    out = tmp_path_factory.mktemp("hm3d")
    config = Config(sim=CFG)
    summary = export_hm3d(out, 1, seed=0, episodes_per_floor=3, cfg=config)
    return load_episode_set(summary.dataset_dir, "val", scenes_dir=summary.scenes_dir, cfg=config)


@pytest.fixture(scope="module")
def habitat(exported):
    """``--sim habitat`` on the scan's floor, as the runner opens it."""
    env = habitat_floor_environment(HABITAT_PYTHON, exported.scene_of(exported.episodes[0]), CFG)
    assert env.server.hello["backend"] == "habitat_sim"
    yield env
    env.close()


@needs_habitat
def test_habitat_moves_and_sees_as_our_renderer_on_the_same_scan(exported, habitat):
    assert habitat.server.hello["backend"] == "habitat_sim" and habitat.info["navigable_area_m2"] > 10
    ref = BuiltinSimulator(habitat.scene, CFG)
    actions = [
        "turn_left",
        "look_down",
        "look_down",
        "look_down",
        "look_up",
        "turn_right",
        "turn_right",
        "move_forward",
        "move_forward",
    ]
    for episode in exported.episodes:
        pairs = [(habitat.reset(episode), ref.reset(episode))] + [(habitat.step(a), ref.step(a)) for a in actions]
        assert habitat.path_length_m == pytest.approx(ref.path_length_m, abs=1e-3) and ref.path_length_m > 0
        for got, want in pairs:
            assert math.hypot(got.pose.x - want.pose.x, got.pose.y - want.pose.y) < 1e-3
            assert math.cos(got.pose.heading - want.pose.heading) == pytest.approx(1.0, abs=1e-9)
            assert got.tilt == pytest.approx(want.tilt, abs=1e-6) and got.collided == want.collided
            both = (got.depth > 0) & (want.depth > 0)
            assert both.mean() > 0.85  # the same pixels are in the sensor's range
            error = np.abs(got.depth - want.depth)[both]
            assert np.median(error) < 0.02 and np.percentile(error, 90) < 0.1  # metres


@needs_habitat
def test_habitat_geodesics_agree_with_the_episode_file(exported, habitat):
    """HM3D's ``info.geodesic_distance`` (measured on our map by the exporter) against habitat's
    pathfinder from the start to the nearest view point of the goal."""
    for episode in exported.episodes:
        points = [tuple(p) for p in habitat.scene.view_points[episode.goal]]
        got = habitat.geodesic_distance(episode.start, points)
        assert got == pytest.approx(episode.geodesic_distance_m, rel=0.1), episode.key


@needs_habitat
def test_habitat_semantic_ids_reach_our_categories(exported, habitat):
    assert habitat.info["objects_matched"] > 0
    ref = BuiltinSimulator(habitat.scene, CFG)
    for episode in exported.episodes:
        got, want = habitat.reset(episode), ref.reset(episode)
        labelled = (got.semantic > 0) | (want.semantic > 0)
        assert (got.semantic == want.semantic)[labelled].mean() > 0.9


@needs_habitat
def test_a_killed_habitat_server_is_one_line(exported):
    env = habitat_floor_environment(HABITAT_PYTHON, exported.scene_of(exported.episodes[0]), CFG)
    env.reset(exported.episodes[0])
    os.kill(env.server.pid, signal.SIGKILL)
    with pytest.raises(L3MVNError, match=r"^habitat server was killed by SIGKILL during step") as err:
        env.step("move_forward")
    assert "\n" not in str(err.value)
    env.close()


@pytest.mark.parametrize("radius", [0.18, 0.1, 0.25, 0.3])
def test_the_navmesh_cell_divides_the_body_radius(radius):
    """Recast erodes by ceil(radius / cell) voxels in float32: that must be the radius, not a voxel more."""
    cell = wire.navmesh_cell_size(radius)
    assert cell <= wire.NAVMESH_MAX_CELL_M * 1.001
    voxels = math.ceil(np.float32(radius) / np.float32(cell))
    assert voxels * cell == pytest.approx(radius, rel=1e-4)


@needs_habitat
def test_habitat_keeps_the_passages_our_grid_keeps(tmp_path):
    """House 1's first episode crosses a door within a voxel of the body's width: habitat's default
    0.05 m cells close it in the navmesh (the geodesic then about twice the file's); with the fitted
    cell every habitat geodesic is the file's within 5%."""
    from l3mvn.world.datasets import load_episode_set
    from l3mvn.world.datasets.hm3d_export import export_hm3d

    config = Config(sim=SimConfig(frame_height=30, frame_width=40))
    summary = export_hm3d(tmp_path, 2, seed=0, episodes_per_floor=4, cfg=config)
    eset = load_episode_set(summary.dataset_dir, "val", scenes_dir=summary.scenes_dir, cfg=config)
    ratios = {}
    for key in dict.fromkeys(eset.scene_of(e).key for e in eset.episodes):
        episodes = [e for e in eset.episodes if eset.scene_of(e).key == key]
        floor = eset.scene_of(episodes[0])
        with habitat_floor_environment(HABITAT_PYTHON, floor, config.sim) as env:
            for episode in episodes:
                env.reset(episode)
                got = env.geodesic_distance(episode.start, [tuple(p) for p in floor.view_points[episode.goal]])
                ratios[episode.key] = got / episode.geodesic_distance_m
    assert len(ratios) == 8 and "procedural-0001/0/0" in ratios
    assert all(0.95 < r < 1.05 for r in ratios.values()), ratios


@pytest.mark.parametrize(
    ("op", "request_", "message"),
    [
        ("op_reset", {"rotation": [1, 0, 0, 0]}, "position must be three numbers"),
        ("op_reset", {"position": [1, 0, 1], "rotation": "north"}, "rotation must be a (w, x, y, z) quaternion"),
        ("op_reset", {"position": [1, 0, float("nan")], "rotation": [1, 0, 0, 0]}, "position must be finite"),
        ("op_geodesic", {"start": "123", "goals": [[1, 0, 1]]}, "a point must be three numbers"),
    ],
)
def test_the_builtin_server_refuses_a_malformed_request_in_one_line(op, request_, message):
    from l3mvn.world.sim.builtin_server import BuiltinBackend

    backend = BuiltinBackend()
    scene = generate_house(0)
    backend.op_load({"scene": "procedural:0", "categories": list(scene.categories), "sim": {}})
    with pytest.raises(wire.RequestError, match=message.replace("(", r"\(").replace(")", r"\)")):
        getattr(backend, op)(request_)

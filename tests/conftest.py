"""Shared fixtures: a tiny SemExp-format dataset drawn in an array, and the optional shared data."""

from __future__ import annotations

import importlib.util
import json
import os
import socket
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
from scipy import ndimage as ndi

from l3mvn.core.categories import GIBSON_CATEGORIES
from l3mvn.core.grid import disk
from l3mvn.world.scenes.scene import SceneMap

os.environ.setdefault("HF_HUB_OFFLINE", "1")
os.environ.setdefault("TRANSFORMERS_OFFLINE", "1")

SHARED = Path(__file__).resolve().parents[2] / "shared"
GIBSON = SHARED / "data" / "gibson_semexp"
ROOMS_JSONL = SHARED / "data" / "room_objects" / "gibson_3dsg_rooms.jsonl"
BENCH = Path(__file__).resolve().parents[1] / "bench"


@pytest.fixture(scope="session")
def bench_script():
    """Loads a script of bench/ (scripts, not a package) as a module, by its name."""

    def load(name: str) -> ModuleType:
        spec = importlib.util.spec_from_file_location(name, BENCH / f"{name}.py")
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = module  # its dataclasses look their module up while being built
        spec.loader.exec_module(module)
        return module

    return load


def draw_two_room_house(name: str = "Tiny", height: int = 120, width: int = 200) -> SceneMap:
    """Two 4.5 m rooms joined by a 1.2 m door; a toilet, a bed, a chair and a tv.

    Built like the real maps: free floor eroded by the agent radius (4 cells) gives channel 0.
    """
    free = np.zeros((height, width), bool)
    free[10:100, 10:95] = True  # west room
    free[10:100, 105:190] = True  # east room
    free[50:74, 95:105] = True  # door through a 10-cell wall
    objects = np.zeros((len(GIBSON_CATEGORIES), height, width), bool)

    def put(cat: str, r0: int, r1: int, c0: int, c1: int) -> None:
        objects[GIBSON_CATEGORIES.index(cat), r0:r1, c0:c1] = True

    put("toilet", 12, 24, 170, 186)  # east room, north-east corner
    put("bed", 60, 98, 12, 50)  # west room, south-west
    put("chair", 20, 30, 20, 30)
    put("tv", 12, 16, 60, 80)
    put("sink", 12, 20, 150, 164)
    free &= ~objects.any(0)
    navigable = ndi.binary_erosion(free, disk(4))
    return SceneMap(
        name=name,
        floor=0,
        categories=GIBSON_CATEGORIES,
        navigable=navigable,
        objects=objects,
        origin_cm=(-300.0, -200.0),
        floor_height_m=0.0,
    )


@pytest.fixture
def tiny_scene() -> SceneMap:
    return draw_two_room_house()


@pytest.fixture
def tiny_dataset(tmp_path: Path) -> Path:
    """A SemExp-format dataset directory with one split 'val' holding two tiny houses + episodes."""
    from l3mvn.world.episodes import episode_file, generate_episodes, write_episode_file
    from l3mvn.world.scenes.semexp import save_split

    scenes = [draw_two_room_house("Tiny"), draw_two_room_house("Wee", height=130, width=210)]
    save_split(tmp_path, "val", scenes)
    for s in scenes:
        eps = generate_episodes(s, 4, seed=1, goals=("toilet", "bed", "chair", "tv"))
        write_episode_file(episode_file(tmp_path, "val", s.name), eps, {0: s})
    return tmp_path


@pytest.fixture
def shut_dataset(tmp_path: Path) -> Path:
    """The two-room house with its door walled up after episodes were drawn: of its 6 episodes, the
    ones starting in the room without their goal (ids 0-4) have no path; id 5 starts beside it."""
    from l3mvn.world.episodes import episode_file, generate_episodes, write_episode_file
    from l3mvn.world.scenes.semexp import save_split

    house = draw_two_room_house("Shut")
    episodes = generate_episodes(house, 6, seed=1, goals=("toilet", "bed"))
    navigable = house.navigable.copy()
    navigable[:, 93:107] = False
    shut = SceneMap(
        name="Shut",
        floor=0,
        categories=house.categories,
        navigable=navigable,
        objects=house.objects,
        origin_cm=house.origin_cm,
        floor_height_m=0.0,
    )
    save_split(tmp_path, "val", [shut])
    write_episode_file(episode_file(tmp_path, "val", "Shut"), episodes, {0: shut})
    return tmp_path


needs_gibson = pytest.mark.skipif(
    not (GIBSON / "train" / "train_info.pbz2").exists(), reason="../shared Gibson maps not present"
)


def free_port() -> int:
    """A loopback port nothing listens on right now (for a dashboard or viewer under test)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def serve_dashboard(**options):
    """A dashboard on one procedural house and a free loopback port, stopped when the fixture that
    yields from this ends: ``yield from serve_dashboard(policy=..., ...)``."""
    from l3mvn_studio.server import start_dashboard

    d = start_dashboard(port=free_port(), houses=1, **options)
    try:
        yield d
    finally:
        d.stop()


def write_frontier_file(folder: Path, houses=("Allensville", "Coffeen", "Hiteman"), choices: int = 12) -> Path:
    """A small `language frontier-data` file: in every house a frontier whose window holds a sink lies
    nearer the toilet than one that sees a couch (each episode closed by its "done" line)."""
    from l3mvn.agent.language.vocabulary import GOALS

    rng = np.random.default_rng(0)
    lines = []
    for house in houses:
        for k in range(choices):
            frontiers = []
            for objects, toilet in ((["sink"], 1.0), (["couch"], 5.0), (["vase", "couch"], 6.0)):
                goal_m = {g: round(float(rng.uniform(1, 8)), 2) for g in GOALS}
                goal_m["toilet"] = toilet + float(rng.uniform(0, 0.5))
                frontiers.append(
                    {
                        "cost": float(rng.uniform(1, 3)),
                        "s_cu": float(rng.uniform()),
                        "utility": 10.0,
                        "objects": {o: 1.0 for o in objects},
                        "goal_m": goal_m,
                    }
                )
            lines.append(
                json.dumps(
                    {
                        "house": house,
                        "episode": f"{house}/0/{k}",
                        "seed": 0,
                        "goal": "toilet",
                        "mapped": [],
                        "frontiers": frontiers,
                    }
                )
            )
            lines.append(json.dumps({"done": f"{house}/0/{k}", "seed": 0, "choices": 1}))
    path = folder / "frontiers.jsonl"
    path.write_text("\n".join(lines) + "\n")
    return path


def first_frontier_choice(scene: SceneMap, policy: str = "l3mvn-zs"):
    """The Decision of ``policy``'s first frontier choice on ``scene`` (toilet, 60x80 frames)."""
    from l3mvn.core.config import Config
    from l3mvn.core.types import Pose
    from l3mvn.run.runner import Runner
    from l3mvn.world.episode import Episode

    session = Runner(Config().with_frame(60, 80)).session(scene, policy)
    session.start(Episode(episode_id=0, scene=scene.name, floor=0, start=Pose(2.5, 2.0, 0.0), goal="toilet"))
    while not session.done:
        d = session.step().decision
        if d is not None and d.goal_kind == "frontier" and d.frontiers:
            return d
    raise AssertionError(f"{policy} never chose a frontier")


@pytest.fixture
def strict_rerun():
    """Rerun normally turns a bad log call into a warning; make it an error so the recorder counts it."""
    import rerun as rr

    before = rr.strict_mode()
    rr.set_strict_mode(True)
    yield
    rr.set_strict_mode(before)


@pytest.fixture(scope="module")
def one_torch_thread():
    """For modules of tiny nets (``pytestmark = pytest.mark.usefixtures("one_torch_thread")``): on busy
    cores torch's worker threads wait on each other far longer than they compute (a 3-epoch fit takes
    about a second with one thread, over twenty with two)."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)

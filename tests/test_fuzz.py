"""Property-based fuzzing of every input parser: episode files, map files, ``--set`` and the CLI.

Each test feeds generated malformed inputs to a public entry point and holds it to the contract of
``l3mvn.core.errors``: a valid result, or ``L3MVNError`` with a one-line message (the CLI: exit status 2
and one ``error:`` line; argparse's own SystemExit(2) is fine). Never another exception, never a hang,
and a result that is accepted must be what the input said (an id 0.7 is not episode 0).

Inputs start from valid ones and break a few fields at a time, so most examples reach the deep checks
instead of failing on the first. ``derandomize=True``: every run, CI included, sees the same inputs.
"""

from __future__ import annotations

import bz2
import contextlib
import gzip
import io
import json
import math
import pickle
import signal
import time
from datetime import timedelta
from pathlib import Path

import numpy as np
import pytest
from conftest import draw_two_room_house
from hypothesis import HealthCheck, assume, event, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from l3mvn.core.categories import GIBSON_CATEGORIES, GOAL_CATEGORIES
from l3mvn.core.config import (
    EDGE_MODES,
    SELECTIONS,
    SUCCESS_RULES,
    UTILITY_MODES,
    Config,
    config_dict,
    config_hash,
    override,
)
from l3mvn.core.config import settings as config_settings
from l3mvn.core.errors import L3MVNError
from l3mvn.run.cli import main
from l3mvn.world.episodes import (
    ROTATION_NORM_TOLERANCE,
    episode_file,
    episode_record,
    generate_episodes,
    read_episode_file,
    write_episode_file,
)
from l3mvn.world.scenes.semexp import load_split, save_split

HANG_S = 30.0  # far above any example here (milliseconds to ~1 s): only a real hang gets there


def fuzz(examples: int, deadline_s: float = 5.0) -> settings:
    """Reproducible (derandomized, no example database) and sized so this file runs well under 60 s."""
    return settings(
        max_examples=examples,
        deadline=timedelta(seconds=deadline_s),
        derandomize=True,
        database=None,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much],
    )


class Hang(BaseException):
    """Raised into a call that ran past HANG_S; a BaseException so no ``except Exception`` swallows it."""


@contextlib.contextmanager
def no_hang(what: object):
    """Fail (rather than stall the suite) when one call runs past HANG_S. Restores pytest-timeout's
    own SIGALRM timer afterwards, minus the time spent here."""

    def fire(signum, frame):
        raise Hang(f"ran past {HANG_S} s: {what!r}")

    started = time.monotonic()
    previous = signal.signal(signal.SIGALRM, fire)
    outer_delay, outer_interval = signal.setitimer(signal.ITIMER_REAL, HANG_S)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
        if outer_delay:
            remaining = max(outer_delay - (time.monotonic() - started), 0.001)
            signal.setitimer(signal.ITIMER_REAL, remaining, outer_interval)


def assert_one_line(exc: L3MVNError) -> None:
    message = str(exc)
    assert message and "\n" not in message, f"not one line: {message!r}"


# --- values -------------------------------------------------------------------------------------

NUMBERS = st.one_of(
    st.integers(-5, 12),
    st.floats(-5.0, 12.0),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([1e308, -1e308, 10**400, -(10**400), 2**63, 0.7, 3.0, 5e-324, True, False]),
)
JSON_SCALARS = st.one_of(st.none(), st.booleans(), NUMBERS, st.text(max_size=6))


def _json_containers(inner: st.SearchStrategy) -> st.SearchStrategy:
    return st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=5), inner, max_size=3)


JSON_VALUES = st.recursive(JSON_SCALARS, _json_containers, max_leaves=8)

# --- episode files ------------------------------------------------------------------------------

SCENE = draw_two_room_house()
FLOORS = {0: SCENE}
BASE_RECORDS = [episode_record(ep, SCENE) for ep in generate_episodes(SCENE, 3, seed=1)]


def _quaternions():
    """Unit yaw quaternions, ones scaled by up to 5%, and arbitrary lists (all-zero, tilted, too short)."""
    yaw = st.floats(-math.pi, math.pi).map(lambda a: [math.cos(a / 2), 0.0, math.sin(a / 2), 0.0])
    scaled = st.tuples(yaw, st.floats(0.95, 1.05)).map(lambda qs: [v * qs[1] for v in qs[0]])
    return st.one_of(yaw, scaled, st.lists(NUMBERS, min_size=3, max_size=5), JSON_VALUES)


FIELD_VALUES = {
    "episode_id": st.one_of(st.integers(-2, 5), st.sampled_from([0.0, 1.0, 0.7, "1", 2**63]), JSON_VALUES),
    "floor_id": st.one_of(st.integers(-1, 2), st.sampled_from([0.0, 0.7, 1.0, "0"]), JSON_VALUES),
    "start_position": st.one_of(st.lists(NUMBERS, min_size=2, max_size=4), JSON_VALUES),
    "start_rotation": _quaternions(),
    "object_category": st.one_of(st.sampled_from(GOAL_CATEGORIES + ("piano", "sink", "Toilet", "")), JSON_VALUES),
    "scene_id": st.one_of(st.sampled_from(["gibson_semantic/Tiny.glb", "Tiny", "x/Wee.glb", ""]), JSON_VALUES),
    "object_id": st.one_of(st.integers(-3, 5), JSON_VALUES),
    "info": st.one_of(
        st.none(), st.fixed_dictionaries({"geodesic_distance": st.one_of(NUMBERS, JSON_VALUES)}), JSON_VALUES
    ),
}


@st.composite
def episode_records(draw):
    """A valid record with up to three fields replaced and up to two removed; sometimes no record at all."""
    if draw(st.integers(0, 9)) == 0:
        return draw(JSON_VALUES)
    rec = dict(draw(st.sampled_from(BASE_RECORDS)))
    for key in draw(st.sets(st.sampled_from(sorted(FIELD_VALUES)), max_size=3)):
        rec[key] = draw(FIELD_VALUES[key])
    for key in draw(st.sets(st.sampled_from(sorted(rec)), max_size=2)):
        del rec[key]
    return rec


def _check_accepted_episodes(records: list, episodes: list) -> None:
    """What was accepted is what the file says: ids, floors, goals as written, starts on the navmesh,
    unit rotations, one episode per record and no two with one id."""
    assert len(episodes) == len(records)
    assert len({ep.episode_id for ep in episodes}) == len(episodes)
    for index, (rec, ep) in enumerate(zip(records, episodes)):
        assert not isinstance(rec.get("episode_id"), bool) and not isinstance(rec.get("floor_id"), bool)
        assert type(ep.episode_id) is int and ep.episode_id == rec.get("episode_id", index)
        assert type(ep.floor) is int and ep.floor == rec.get("floor_id", 0) and ep.floor in FLOORS
        assert ep.goal == rec["object_category"] and ep.goal in GOAL_CATEGORIES
        r, c = SCENE.cell_of(ep.start.x, ep.start.y)
        assert SCENE.in_bounds(r, c) and SCENE.navigable[r, c]
        assert abs(math.sqrt(sum(v * v for v in rec["start_rotation"])) - 1.0) <= ROTATION_NORM_TOLERANCE
        assert math.isnan(ep.geodesic_distance_m) or 0 <= ep.geodesic_distance_m < math.inf


def _read_episode_bytes(path: Path, blob: bytes):
    """The episodes of ``blob`` as a scene file of the two-room house, or None when refused in one line."""
    path.write_bytes(blob)
    with no_hang(blob[:200]):
        try:
            episodes = read_episode_file(path, FLOORS)
        except L3MVNError as exc:
            assert_one_line(exc)
            event("refused")
            return None
    event("accepted")
    return episodes


@pytest.fixture(scope="module")
def workdir(tmp_path_factory) -> Path:
    """One directory for the file tests (hypothesis cannot use the per-test ``tmp_path``)."""
    return tmp_path_factory.mktemp("fuzz")


@fuzz(300, deadline_s=2.0)
@given(records=st.lists(episode_records(), max_size=4))
def test_episode_records_are_read_or_refused_in_one_line(workdir, records):
    blob = gzip.compress(json.dumps({"episodes": records}).encode(), compresslevel=1)
    episodes = _read_episode_bytes(workdir / "Tiny_episodes.json.gz", blob)
    if episodes is not None:
        _check_accepted_episodes(records, episodes)


VALID_EPISODE_FILE = gzip.compress(json.dumps({"episodes": BASE_RECORDS}).encode())


@st.composite
def damaged(draw, blob: bytes):
    """``blob`` truncated, or with a few bytes overwritten."""
    data = bytearray(blob[: draw(st.integers(0, len(blob)))] if draw(st.booleans()) else blob)
    for _ in range(draw(st.integers(0, 3))):
        if data:
            data[draw(st.integers(0, len(data) - 1))] = draw(st.integers(0, 255))
    return bytes(data)


EPISODE_FILES = st.one_of(
    JSON_VALUES.map(lambda v: gzip.compress(json.dumps(v).encode(), compresslevel=1)),
    st.text(max_size=20).map(lambda t: gzip.compress(t.encode(), compresslevel=1)),
    st.binary(max_size=40),
    damaged(VALID_EPISODE_FILE),
    st.sampled_from([gzip.compress(b"[" * 100_000), gzip.compress(b"1" * 5000), gzip.compress(b"\xff\xfe"), b""]),
)


@fuzz(150, deadline_s=2.0)
@given(blob=EPISODE_FILES)
def test_damaged_episode_files_are_refused_in_one_line(workdir, blob):
    episodes = _read_episode_bytes(workdir / "Tiny_episodes.json.gz", blob)
    if episodes is not None:
        assert all(ep.goal in GOAL_CATEGORIES for ep in episodes)


# --- map files ----------------------------------------------------------------------------------

ARRAY_DTYPES = st.sampled_from([np.bool_, np.uint8, np.int64, np.float32, np.float64, np.complex64, np.dtype("U1")])
SMALL_ARRAYS = hnp.arrays(ARRAY_DTYPES, hnp.array_shapes(min_dims=0, max_dims=4, min_side=0, max_side=5))


@st.composite
def sem_maps(draw):
    """Mostly (channels, H, W) 0/1 maps of a numeric dtype with a navigable block, else anything."""
    if draw(st.integers(0, 3)) == 0:
        return draw(st.one_of(SMALL_ARRAYS, JSON_VALUES))
    channels = (
        draw(st.integers(2, len(GIBSON_CATEGORIES) + 1))
        if draw(st.integers(0, 5))
        else draw(st.sampled_from([1, len(GIBSON_CATEGORIES) + 2]))
    )
    h, w = draw(st.integers(1, 6)), draw(st.integers(1, 6))
    dtype = draw(st.sampled_from([np.float64, np.float32, np.uint8, np.bool_, np.int64]))
    sem = np.zeros((channels, h, w), dtype)
    rows = draw(st.integers(1, h)) if draw(st.integers(0, 5)) else 0  # now and then no navigable cell
    sem[0, :rows, : draw(st.integers(1, w))] = 1
    if draw(st.integers(0, 3)) == 0 and dtype in (np.float64, np.float32):
        sem.flat[draw(st.integers(0, sem.size - 1))] = draw(st.sampled_from([np.nan, np.inf, 0.7, -3.0]))
    return sem


MAP_FIELDS = {
    "sem_map": sem_maps(),
    "origin": st.one_of(
        hnp.arrays(np.float64, st.sampled_from([(2,), (1,), (3,), (2, 1)])),
        st.lists(NUMBERS, min_size=1, max_size=3),
        SMALL_ARRAYS,
        JSON_VALUES,
    ),
    "floor_height": st.one_of(
        NUMBERS, st.sampled_from([np.float64(0.25), np.int64(1), np.float32("nan")]), SMALL_ARRAYS, JSON_VALUES
    ),
}
SCENE_KEYS = st.one_of(
    st.sampled_from(["Tiny", "Wee", "a/b", "..", "", "x\ny"]), st.text(max_size=4), st.integers(-1, 2), st.none()
)
FLOOR_KEYS = st.one_of(st.integers(-1, 2), st.sampled_from([np.int64(1), 0.5, "0", "a", None]), st.booleans())


@st.composite
def map_records(draw):
    """A valid floor record; half of them with one or two fields replaced, a few with one removed."""
    rec = {"sem_map": draw(sem_maps()), "origin": np.array([-300, -200]), "floor_height": 0.0}
    if draw(st.booleans()):
        for key in draw(st.sets(st.sampled_from(sorted(MAP_FIELDS)), min_size=1, max_size=2)):
            rec[key] = draw(MAP_FIELDS[key])
    if draw(st.integers(0, 7)) == 0:
        del rec[draw(st.sampled_from(sorted(rec)))]
    return rec if draw(st.integers(0, 19)) else draw(JSON_VALUES)


@st.composite
def near_valid_maps(draw):
    """One or two well-named scenes of one or two numbered floors, each record lightly broken."""
    names = draw(st.lists(st.sampled_from(["Tiny", "Wee", "Allensville"]), min_size=1, max_size=2, unique=True))
    return {name: draw(st.dictionaries(st.integers(0, 2), map_records(), min_size=1, max_size=2)) for name in names}


MAP_FILES = st.one_of(
    near_valid_maps(),
    st.one_of(
        st.dictionaries(SCENE_KEYS, st.dictionaries(FLOOR_KEYS, map_records(), max_size=2), max_size=2),
        st.dictionaries(SCENE_KEYS, JSON_VALUES, max_size=2),
        JSON_VALUES,
    ),
)


def _load_map_bytes(root: Path, blob: bytes):
    """The split a ``.pbz2`` of ``blob`` holds, or None when refused in one line."""
    (root / "val").mkdir(exist_ok=True)
    (root / "val" / "val_info.pbz2").write_bytes(blob)
    with no_hang(blob[:200]):
        try:
            scenes = load_split(root, "val")
        except L3MVNError as exc:
            assert_one_line(exc)
            event("refused")
            return None
    event("accepted")
    return scenes


def _check_accepted_maps(raw: dict, scenes: dict) -> None:
    """Scene names, floor ids, grid sizes, origins and heights exactly as the file wrote them."""
    assert set(scenes) == set(raw)
    for name, floors in scenes.items():
        assert isinstance(name, str) and name and "/" not in name
        assert set(floors) == set(raw[name]) and all(type(f) is int for f in floors)
        for fid, floor in floors.items():
            rec = raw[name][fid]
            assert floor.navigable.any() and floor.shape == np.asarray(rec["sem_map"]).shape[1:]
            assert floor.origin_cm == tuple(float(v) for v in np.asarray(rec["origin"]))
            assert floor.floor_height_m == float(rec["floor_height"]) and math.isfinite(floor.floor_height_m)


@fuzz(200, deadline_s=2.0)
@given(raw=MAP_FILES)
def test_map_records_are_loaded_or_refused_in_one_line(workdir, raw):
    scenes = _load_map_bytes(workdir, bz2.compress(pickle.dumps(raw), compresslevel=1))
    if scenes is not None:
        _check_accepted_maps(raw, scenes)


VALID_MAP_PICKLE = pickle.dumps(
    {"Tiny": {0: {"sem_map": np.eye(3)[None].repeat(2, 0), "origin": np.array([1, 2]), "floor_height": 0.5}}}
)


@fuzz(150, deadline_s=2.0)
@given(
    blob=st.one_of(
        damaged(VALID_MAP_PICKLE).map(bz2.compress), damaged(bz2.compress(VALID_MAP_PICKLE)), st.binary(max_size=60)
    )
)
def test_damaged_map_files_are_refused_in_one_line(workdir, blob):
    _load_map_bytes(workdir, blob)


# --- config assignments -------------------------------------------------------------------------

FIELDS = config_settings(Config())
SETTING_NAMES = st.one_of(
    st.sampled_from(FIELDS),
    st.sampled_from(FIELDS).map(lambda s: s.split(".", 1)[1]),
    st.sampled_from(
        ["sim.", ".frame_height", "nosuch.field", "sim.nosuch", "sim.frame_height.x", "", " sim . max_steps"]
    ),
    st.text(max_size=8),
)
SETTING_VALUES = st.one_of(
    st.integers(-10, 10**6).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.sampled_from(
        [
            "0",
            "-1",
            "1e308",
            "-1e308",
            "nan",
            "inf",
            "1e-320",
            "9" * 400,
            "none",
            "None",
            "true",
            "false",
            "1_000",
            " 3 ",
            "0x10",
            "",
            "3.0",
            "0.5",
            "2.5e3",
            *SUCCESS_RULES,
            *EDGE_MODES,
        ]
    ),
    st.text(max_size=8),
)
DEFAULTS = {
    f"{section}.{key}": value for section, fields in config_dict(Config()).items() for key, value in fields.items()
}


def _near_default(name: str) -> st.SearchStrategy[str]:
    """Values of the field's own type around its default: most of them valid, some out of range."""
    default = DEFAULTS[name]
    if isinstance(default, int) and not isinstance(default, bool):
        return st.integers(min(default - 3, -1), default * 2 + 3).map(str)
    if isinstance(default, float):
        low, high = sorted((default * 0.5 - 1, default * 1.5 + 1))
        return st.floats(low, high).map(repr)
    return st.sampled_from([*SUCCESS_RULES, *EDGE_MODES, *UTILITY_MODES, *SELECTIONS, "none", "cooccurrence", "x"])


PLAUSIBLE = st.sampled_from(FIELDS).flatmap(lambda name: _near_default(name).map(lambda v: f"{name}={v}"))
ASSIGNMENTS = st.one_of(
    PLAUSIBLE,
    PLAUSIBLE,
    st.builds(
        lambda name, sep, value: f"{name}{sep}{value}",
        SETTING_NAMES,
        st.sampled_from(["=", " = ", "", "=="]),
        SETTING_VALUES,
    ),
)


@fuzz(400, deadline_s=2.0)
@given(items=st.lists(ASSIGNMENTS, max_size=2))
def test_config_assignments_apply_or_are_refused_in_one_line(items):
    with no_hang(items):
        try:
            cfg = override(Config(), items)
            cfg.agent.downsample_factor(cfg.sim.frame_height, cfg.sim.frame_width)  # as the CLI's _config
            config_hash(cfg)
        except L3MVNError as exc:
            assert_one_line(exc)
            event("refused")
            return
    event("accepted")


# --- the command line ---------------------------------------------------------------------------

# Placeholders the test swaps for the module's paths (strategies cannot see fixtures).
DATASET, FILE, MISSING, OUTDIR, LONG = "@DATASET@", "@FILE@", "@MISSING@", "@OUTDIR@", "@LONG@"
JUNK = st.text(max_size=6)


def mostly(good: list[str], bad: list[str], junk: bool = False) -> st.SearchStrategy[str]:
    """Mostly valid (two in three, three in four beside junk text) so that an example with several
    flags still gets past argparse and into the command."""
    bad_values = st.one_of(st.sampled_from(bad), JUNK) if junk else st.sampled_from(bad)
    return st.one_of(st.sampled_from(good), st.sampled_from(good), bad_values)


SOURCE_FLAGS = {
    "--dataset": mostly([DATASET], [FILE, MISSING, LONG, ""], junk=True),
    "--split": mostly(["val"], ["test", "", ".."], junk=True),
    "--houses": mostly(["1", "2"], ["0", "-1", "1.5", "x"]),
    "--seed": mostly(["0", "1", str(10**30)], ["-1", "x", "1e3"]),
}
# --set values that keep a run short (the config test above fuzzes --set itself).
CLI_SETTINGS = st.sampled_from(
    [
        "sim.max_steps=20",
        "sim.max_steps=0",
        "sim.hfov_deg=90",
        "sim.hfov_deg=nan",
        "task.success_rule=geodesic",
        "task.success_rule=x",
        "agent.replan_every=5",
        "max_stepz=3",
        "sim.turn_angle_deg=200",
        "policy.seg_noise=0.5",
        "frontiers.edge=all",
        "=",
        "sim",
        "map.resolution_m=0",
        "agent.look_tolerance_deg=1",
        "sim.min_depth_m=9",
    ]
)
SIM_FLAGS = {
    "--rule": mostly(list(SUCCESS_RULES), ["bogus"]),
    "--frame": mostly(["24x32", "32x24", "24X32", "2x2", "16x16"], ["0x5", "5", "ax3", "-24x32"]),
    "--set": CLI_SETTINGS,
}
POSES = st.one_of(
    st.sampled_from(["2.5,3.0,0", "4.0,4.0,90", "7.5,2.0,-45", "6.0,3.5,1e6"]),  # on the floor of both houses
    st.tuples(st.floats(-2, 12), st.floats(-2, 8), st.floats(-720, 720)).map(lambda p: ",".join(map(str, p))),
    st.sampled_from(
        ["1e6,1e6,0", "0.1,0.1,0", "5.0,1.0,0", "nan,1,0", "1,inf,0", "2.5,3", "a,b,c", "", "1e308,1e308,1e308"]
    ),
)
RENDER_OUTS = mostly(
    [f"{OUTDIR}/a.png", f"{OUTDIR}/a.JPG", f"{OUTDIR}/d/e/a.bmp"],
    [f"{OUTDIR}/a.xyz", OUTDIR, f"{FILE}/a.png", f"{OUTDIR}/a.xbm", f"{OUTDIR}/noext", f"{LONG}.png", ""],
)
# Per command: the words it starts with, flags always given (None: sometimes left out) and optional ones.
COMMANDS = {
    "config": (["config"], {}, {**SIM_FLAGS, "--json": None}),
    "scenes": (
        ["scenes"],
        {},
        {
            **SOURCE_FLAGS,
            "--scene": st.just("Tiny"),
            "--json": None,
            "--all-pngs": None,
            "--out": st.just(OUTDIR),
            "--frame": SIM_FLAGS["--frame"],
            "--set": CLI_SETTINGS,
        },
    ),
    "render": (
        ["render", "--frame", "24x32"],
        {
            "--dataset": mostly([DATASET], [FILE, MISSING, LONG, ""]),
            "--out": RENDER_OUTS,
            "--pose": st.one_of(POSES, POSES, st.none()),
        },
        {
            **SOURCE_FLAGS,
            **SIM_FLAGS,
            "--scene": mostly(["Tiny", "Wee"], ["Nowhere", "procedural-0000", ""]),
            "--floor": mostly(["0"], ["1", "-1", "x"]),
        },
    ),
    "generate": (
        ["episodes", "generate"],
        {
            "--out": mostly([f"{OUTDIR}/gen", f"{OUTDIR}/new/deep"], [FILE, f"{FILE}/x", LONG]),
        },
        {
            **SOURCE_FLAGS,
            "--per-scene": mostly(["1", "2"], ["0", "x"]),
            "--min-distance": mostly(["0.5", "5"], ["nan", "-1", "inf", "x"]),
            "--max-distance": mostly(["30", "2"], ["nan", "0", "-inf"]),
        },
    ),
}
EVAL_FLAGS = {
    "--rule": SIM_FLAGS["--rule"],
    "--set": CLI_SETTINGS,
    "--seed": SOURCE_FLAGS["--seed"],
    "--seg-noise": st.sampled_from(["0", "0.2", "-1", "nan", "2", "x"]),
    "--selection": st.sampled_from(["paper", "official_code", "x"]),
    "--scorer": st.sampled_from(["x", "cooccurrence"]),
    "--out": st.sampled_from([f"{OUTDIR}/r.jsonl", f"{OUTDIR}/r.jsonl", OUTDIR, f"{FILE}/r.jsonl", LONG]),
    "--json": None,
    "--resume": None,
    "--address": st.just("auto"),
    "--workers": st.sampled_from(["1", "0", "x"]),
    "--episodes-per-house": st.just("1"),
}


@st.composite
def flags(draw, pool: dict) -> list[str]:
    argv: list[str] = []
    for flag in draw(st.lists(st.sampled_from(sorted(pool)), max_size=4)):
        argv += [flag] if pool[flag] is None else [flag, draw(pool[flag])]
    return argv


@st.composite
def cli_argv(draw) -> list[str]:
    """A real subcommand with a mix of its flags and junk, or junk words (argparse's to refuse)."""
    if draw(st.integers(0, 7)) == 0:
        words = draw(st.lists(JUNK, max_size=4))
        assume(not words or words[0] not in ("replay", "language", "train-head", "serve"))
        return words
    prefix, required, pool = COMMANDS[draw(st.sampled_from(sorted(COMMANDS)))]
    given_flags = [
        word for flag, strategy in required.items() if (value := draw(strategy)) is not None for word in (flag, value)
    ]
    stray = [draw(JUNK)] if draw(st.integers(0, 5)) == 0 else []
    return prefix + given_flags + draw(flags(pool)) + stray


@pytest.fixture(scope="module")
def cli_paths(tmp_path_factory) -> dict[str, str]:
    """A two-house dataset with episodes, a plain file, a writable directory; renders once so the
    first example does not pay for compiling the renderer."""
    root = tmp_path_factory.mktemp("cli")
    houses = [draw_two_room_house("Tiny"), draw_two_room_house("Wee", height=130, width=210)]
    save_split(root / "data", "val", houses)
    for house in houses:
        write_episode_file(
            episode_file(root / "data", "val", house.name),
            generate_episodes(house, 2, seed=1, goals=("toilet", "bed")),
            {0: house},
        )
    (root / "file").write_text("not a directory")
    (root / "out").mkdir()
    paths = {
        DATASET: str(root / "data"),
        FILE: str(root / "file"),
        MISSING: str(root / "missing"),
        OUTDIR: str(root / "out"),
        LONG: str(root / ("a" * 300)),
    }
    assert (
        _run_cli(["render", "--dataset", paths[DATASET], "--frame", "24x32", "--out", f"{paths[OUTDIR]}/w.png"], paths)[
            0
        ]
        == 0
    )
    return paths


def _run_cli(argv: list[str], paths: dict[str, str]) -> tuple[int, str, str]:
    """Exit status, stdout and stderr of ``l3mvn`` on ``argv`` (placeholders swapped for paths);
    argparse's own exits come back negated (-2) to tell them from the commands' own status 2."""
    for token, path in paths.items():
        argv = [a.replace(token, path) for a in argv]
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), no_hang(argv):
        try:
            code = main(argv)
        except SystemExit as exc:  # argparse: 2 for a bad flag, 0 for --help
            assert exc.code in (0, 2), argv
            return -int(exc.code), out.getvalue(), err.getvalue()
    return code, out.getvalue(), err.getvalue()


def _check_cli(argv: list[str], code: int, err: str, lines_allowed: int) -> None:
    """Status 0 or 2; a refusal is ``error: ...`` as the last line (the only one, but for eval's
    progress lines); never a traceback."""
    assert "Traceback" not in err, (argv, err)
    assert code in (0, 2, -2), (argv, code, err)
    if code == 2:
        lines = err.rstrip("\n").split("\n")  # not splitlines(): a path may hold \x1c or \x85, no line end
        assert lines and lines[-1].startswith("error: "), (argv, err)
        assert len(lines) <= lines_allowed, (argv, err)


@fuzz(150, deadline_s=15.0)
@given(argv=cli_argv())
def test_cli_commands_run_or_refuse_in_one_line(cli_paths, argv):
    code, out, err = _run_cli(argv, cli_paths)
    event(f"{argv[0] if code >= 0 else 'argparse'} exit {abs(code)}")
    _check_cli(argv, code, err, lines_allowed=1)
    if code == 0 and argv[:1] == ["render"] and "--pose" in argv and DATASET in argv:
        _check_rendered_pose(argv, out, cli_paths)


def _check_rendered_pose(argv: list[str], out: str, paths: dict[str, str]) -> None:
    """A render that succeeded had its camera (the last --pose, exactly; the printout rounds it) on the
    map it names ("wrote ...: Tiny/0 at ..."), and not inside an object."""
    pose = argv[len(argv) - argv[::-1].index("--pose")]
    x, y = (float(v) for v in pose.split(",")[:2])
    name, floor = out.rsplit(": ", 1)[-1].partition(" at ")[0].split("/")
    scene = load_split(paths[DATASET], "val")[name][int(floor)]
    assert scene.contains(x, y) and not scene.object_any[scene.cell_of(x, y)], (argv, out)


@fuzz(25, deadline_s=15.0)
@given(
    policy=st.sampled_from(["oracle", "random-walk", "frontier", "cost-utility", "teleport"]), extra=flags(EVAL_FLAGS)
)
def test_eval_flags_run_one_episode_or_refuse(cli_paths, policy, extra):
    argv = [
        "eval",
        "--dataset",
        DATASET,
        "--episodes",
        "1",
        "--frame",
        "24x32",
        "--set",
        "sim.max_steps=30",
        "--policy",
        policy,
        *extra,
    ]
    code, _, err = _run_cli(argv, cli_paths)
    event(f"{'eval' if code >= 0 else 'argparse'} exit {abs(code)}")
    _check_cli(argv, code, err, lines_allowed=3)  # a status line and a progress bar may precede the error

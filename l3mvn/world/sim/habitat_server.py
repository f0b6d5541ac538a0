"""A simulator server for the habitat bridge: runs INSIDE the user's habitat-sim interpreter.

Users keep habitat-sim in its own (often old) conda Python; the studio starts this file there with
``PYTHON habitat_server.py`` and drives it over the process's stdin/stdout (``habitat_bridge``).
So this module imports only the standard library, numpy and habitat_sim, and stays Python 3.8
compatible. The wire format is the only thing both sides share: a frame is
``MAGIC, header length, payload length`` (little-endian), a JSON header, and the raw bytes of the
arrays it lists (name, dtype, shape, offset): observations travel as plain arrays, never pickles.

The protocol speaks Habitat's frame (Y up, positions ``[p0, p1, p2]``, rotations as (w, x, y, z)
yaw quaternions); the client converts to ours. Backends are pluggable: ``HabitatBackend`` here,
and ``builtin_server`` serves our own simulator through the same ``serve`` loop for tests.
Requests: ``load`` (scene, sensors and body from the client's SimConfig, category table),
``reset`` (position, rotation), ``step`` (action name), ``geodesic`` (pathfinder ground truth),
``close``. A request that fails answers ``ok: false`` with a one-line error; a crash closes the pipe.
"""

from __future__ import annotations

import json
import math
import os
import struct
import sys
import traceback

import numpy as np

PROTOCOL = 1
MAGIC = b"L3HB"
PREFIX = struct.Struct("<4sII")
MAX_HEADER_BYTES = 1 << 20
MAX_PAYLOAD_BYTES = 1 << 31
# Little-endian dtypes an array may have on the wire: images, depth, ids, positions.
DTYPES = ("|u1", "<i4", "<u4", "<i8", "<f4", "<f8")
# The navmesh's voxel height. The agent stands on the navmesh, which recast places up to a voxel
# above the floor: habitat's default 0.2 m would lift the 0.88 m camera by that much (depth off by
# 5 cm looking down at -60 deg with 0.05 m voxels, by 1 cm with these).
NAVMESH_CELL_HEIGHT_M = 0.01
# The navmesh's largest voxel width. Recast erodes by ceil(radius / cell) voxels: at habitat's
# default 0.05 m a 0.18 m body is eroded by 0.2 m, which closes passages within a voxel of twice
# the body's width that our grid (and the body) can pass. The server picks the widest cell up to
# this that divides the radius, so the erosion is the body's radius (0.18 m: 0.02 m cells).
NAVMESH_MAX_CELL_M = 0.02
ACTIONS = ("stop", "move_forward", "turn_left", "turn_right", "look_up", "look_down")


class ProtocolError(Exception):
    """A malformed frame: the stream cannot be trusted past it."""


class RequestError(Exception):
    """A request the backend refuses (unknown scene, bad argument): answered, the server goes on."""


# --- framing ---------------------------------------------------------------------------------------
def pack(header, arrays=None):
    """One frame as a list of byte strings (written in order): prefix, JSON header, array bytes."""
    specs, blobs, offset = [], [], 0
    for name, value in (arrays or {}).items():
        a = np.ascontiguousarray(value)
        a = a.astype(a.dtype.newbyteorder("<"), copy=False) if a.dtype.byteorder == ">" else a
        if a.dtype.str not in DTYPES:
            raise ProtocolError(f"array {name!r} has dtype {a.dtype}; the wire carries {', '.join(DTYPES)}")
        specs.append({"name": name, "dtype": a.dtype.str, "shape": list(a.shape), "offset": offset, "nbytes": a.nbytes})
        blobs.append(a.tobytes())
        offset += a.nbytes
    body = dict(header)
    body["arrays"] = specs
    text = json.dumps(body, allow_nan=False, separators=(",", ":")).encode("utf-8")
    return [PREFIX.pack(MAGIC, len(text), offset), text] + blobs


def parse_prefix(data):
    """(header bytes, payload bytes) of a frame prefix, checked."""
    magic, header_len, payload_len = PREFIX.unpack(data)
    if magic != MAGIC:
        raise ProtocolError(f"bad frame magic {magic!r} (expected {MAGIC!r}): the peer is not an l3mvn bridge")
    if header_len > MAX_HEADER_BYTES or payload_len > MAX_PAYLOAD_BYTES:
        raise ProtocolError(f"frame too large: header {header_len} bytes, payload {payload_len} bytes")
    return header_len, payload_len


def parse_body(header_bytes, payload):
    """(header dict, {name: array}) of a frame; every array spec is checked against the payload."""
    try:
        header = json.loads(header_bytes.decode("utf-8"))
    except ValueError as exc:
        raise ProtocolError(f"frame header is not JSON: {exc}") from None
    if not isinstance(header, dict) or not isinstance(header.get("arrays", []), list):
        raise ProtocolError("frame header must be a JSON object with an 'arrays' list")
    arrays = {}
    for spec in header.pop("arrays", []):
        try:
            name, dtype, shape = spec["name"], spec["dtype"], [int(n) for n in spec["shape"]]
            offset, nbytes = int(spec["offset"]), int(spec["nbytes"])
        except (KeyError, TypeError, ValueError):
            raise ProtocolError(f"malformed array spec {spec!r}") from None
        if dtype not in DTYPES or any(n < 0 for n in shape):
            raise ProtocolError(f"array {name!r}: dtype {dtype!r} or shape {shape!r} not allowed")
        count = int(np.prod(shape, dtype=np.int64))
        if count * np.dtype(dtype).itemsize != nbytes or offset < 0 or offset + nbytes > len(payload):
            raise ProtocolError(
                f"array {name!r}: {nbytes} bytes at {offset} do not fit shape {shape} in a {len(payload)}-byte payload"
            )
        arrays[name] = np.frombuffer(payload, dtype=dtype, count=count, offset=offset).reshape(shape)
    return header, arrays


def read_frame(stream):
    """The next frame from a blocking binary stream, or None at a clean end of stream."""
    prefix = stream.read(PREFIX.size)
    if not prefix:
        return None
    if len(prefix) != PREFIX.size:
        raise ProtocolError("stream ended inside a frame prefix")
    header_len, payload_len = parse_prefix(prefix)
    header_bytes = stream.read(header_len)
    payload = bytearray(stream.read(payload_len)) if payload_len else bytearray()
    if len(header_bytes) != header_len or len(payload) != payload_len:
        raise ProtocolError("stream ended inside a frame")
    return parse_body(header_bytes, payload)


def write_frame(stream, header, arrays=None):
    for part in pack(header, arrays):
        stream.write(part)
    stream.flush()


# --- the loop --------------------------------------------------------------------------------------
def _first_line(exc):
    text = str(exc).strip()
    line = text.splitlines()[0] if text else type(exc).__name__
    return line if isinstance(exc, RequestError) else f"{type(exc).__name__}: {line}"


def serve(make_backend, inp, out):
    """Answer requests until ``close`` or end of input. ``make_backend()`` runs before the hello,
    so a backend that cannot start (habitat_sim missing) is reported as the hello's error."""
    try:
        backend = make_backend()
    except Exception as exc:  # the one place every start failure is reported to the client
        write_frame(out, {"ok": False, "error": _first_line(exc)})
        traceback.print_exc()
        return 1
    write_frame(
        out,
        {
            "ok": True,
            "protocol": PROTOCOL,
            "backend": backend.name,
            "versions": backend.versions(),
            "python": sys.version.split()[0],
        },
    )
    try:
        while True:
            frame = read_frame(inp)
            if frame is None:
                return 0
            header, _ = frame
            op = header.get("op")
            if op == "close":
                write_frame(out, {"ok": True})
                return 0
            handler = getattr(backend, "op_" + op, None) if isinstance(op, str) else None
            try:
                if handler is None:
                    raise RequestError(f"unknown request {op!r}; valid: load, reset, step, geodesic, close")
                reply, arrays = handler(header)
            except Exception as exc:  # any failed request is answered in one line; the server goes on
                traceback.print_exc()
                write_frame(out, {"ok": False, "error": _first_line(exc)})
                continue
            reply["ok"] = True
            write_frame(out, reply, arrays)
    finally:
        backend.close()


def run_server(make_backend):
    """Serve on this process's stdin/stdout. Whatever native code prints to stdout (habitat's and
    Magnum's logs) is sent to stderr instead, so it can never corrupt a frame."""
    inp = os.fdopen(os.dup(0), "rb")
    out = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    return serve(make_backend, inp, out)


# --- habitat-sim -----------------------------------------------------------------------------------
def _num(request, section, name):
    value = request[section][name]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise RequestError(f"{section}.{name} must be a finite number, got {value!r}")
    return value


def read_point(value, what):
    """A request's [p0, p1, p2] point as three finite floats, else a RequestError naming ``what``."""
    try:
        p = np.asarray(value, dtype=np.float64).reshape(3)
    except (TypeError, ValueError):
        raise RequestError(f"{what} must be three numbers [p0, p1, p2], got {value!r}") from None
    if not np.isfinite(p).all():
        raise RequestError(f"{what} must be finite, got {value!r}")
    return p


def read_rotation(value):
    """A request's (w, x, y, z) quaternion, normalised, else a RequestError."""
    try:
        w, x, y, z = (float(v) for v in value)
    except (TypeError, ValueError):
        raise RequestError(f"rotation must be a (w, x, y, z) quaternion, got {value!r}") from None
    norm = math.sqrt(w * w + x * x + y * y + z * z)
    if not math.isfinite(norm) or norm < 1e-6:
        raise RequestError(f"rotation must be a finite non-zero quaternion, got {value!r}")
    return w / norm, x / norm, y / norm, z / norm


def navmesh_cell_size(radius_m, max_cell_m=NAVMESH_MAX_CELL_M):
    """The widest navmesh cell <= ``max_cell_m`` that divides ``radius_m`` into whole voxels, so
    recast's erosion (``ceil(radius / cell)`` voxels) is the radius itself, not up to a voxel more.
    A hair wider than the exact quotient: recast divides in float32, where 0.18 / 0.02 is 9.000001."""
    voxels = math.ceil(radius_m / max_cell_m - 1e-9)
    return radius_m / voxels * (1.0 + 1e-5)


class HabitatBackend:
    """habitat-sim with the client's sensors, body and actions; semantic ids through the scene's
    objects and the client's category table; geodesics from habitat's pathfinder."""

    name = "habitat_sim"

    def __init__(self):
        import habitat_sim  # here, not at the top: the framing above is usable without habitat-sim
        from habitat_sim.utils import common

        self.hs, self.common = habitat_sim, common
        self.sim = None
        self.lut = np.zeros(1, np.int32)
        self.tilt_deg = 0.0

    def versions(self):
        return {"habitat_sim": str(getattr(self.hs, "__version__", "unknown")), "numpy": np.__version__}

    # The client's SimConfig fields arrive as request["sim"].
    def op_load(self, request):
        hs = self.hs
        scene = request.get("scene")
        if not isinstance(scene, str) or not os.path.exists(scene):
            raise RequestError(f"scene {scene!r}: no such file")
        categories = [str(c) for c in request.get("categories", [])]
        table = request.get("category_map") or {}
        if not categories or not isinstance(table, dict):
            raise RequestError("load needs a non-empty 'categories' list and a 'category_map' object")
        h, w = int(_num(request, "sim", "frame_height")), int(_num(request, "sim", "frame_width"))
        self.cfg = {
            k: _num(request, "sim", k)
            for k in (
                "hfov_deg",
                "camera_height_m",
                "min_depth_m",
                "max_depth_m",
                "forward_step_m",
                "turn_angle_deg",
                "tilt_angle_deg",
                "min_tilt_deg",
                "max_tilt_deg",
                "agent_radius_m",
            )
        }
        cfg = self.cfg
        self.close()

        sim_cfg = hs.SimulatorConfiguration()
        sim_cfg.scene_id = os.path.abspath(scene)
        dataset = request.get("scene_dataset_config")
        if dataset:
            if not os.path.isfile(dataset):
                raise RequestError(f"scene dataset config {dataset!r}: no such file")
            sim_cfg.scene_dataset_config_file = os.path.abspath(dataset)
        sim_cfg.enable_physics = False
        sim_cfg.load_semantic_mesh = True
        sim_cfg.create_renderer = True
        sensors = []
        for uuid, kind in (
            ("rgb", hs.SensorType.COLOR),
            ("depth", hs.SensorType.DEPTH),
            ("semantic", hs.SensorType.SEMANTIC),
        ):
            spec = hs.CameraSensorSpec()
            spec.uuid, spec.sensor_type, spec.resolution = uuid, kind, [h, w]
            spec.position = [0.0, cfg["camera_height_m"], 0.0]
            spec.hfov = cfg["hfov_deg"]
            sensors.append(spec)
        agent_cfg = hs.agent.AgentConfiguration()
        agent_cfg.height = cfg["camera_height_m"]  # the camera sits at the top of the body, as in ObjectNav
        agent_cfg.radius = cfg["agent_radius_m"]
        agent_cfg.sensor_specifications = sensors
        amounts = {
            "move_forward": cfg["forward_step_m"],
            "turn_left": cfg["turn_angle_deg"],
            "turn_right": cfg["turn_angle_deg"],
            "look_up": cfg["tilt_angle_deg"],
            "look_down": cfg["tilt_angle_deg"],
        }
        agent_cfg.action_space = {
            name: hs.agent.ActionSpec(name, hs.agent.ActuationSpec(amount=amount)) for name, amount in amounts.items()
        }
        config = hs.Configuration(sim_cfg, [agent_cfg])
        semantic_mesh, descriptor = request.get("semantic_mesh"), request.get("semantic_descriptor")
        if semantic_mesh or descriptor:
            config.metadata_mediator = self._semantic_stage(sim_cfg, semantic_mesh, descriptor)
        self.sim = hs.Simulator(config)

        # The navmesh for our body, whatever radius the scene's own navmesh was baked for.
        settings = hs.NavMeshSettings()
        settings.set_defaults()
        settings.agent_radius = cfg["agent_radius_m"]
        settings.agent_height = cfg["camera_height_m"]
        settings.cell_height = NAVMESH_CELL_HEIGHT_M
        settings.cell_size = navmesh_cell_size(cfg["agent_radius_m"])
        if "max_climb_m" in request["sim"]:
            settings.agent_max_climb = _num(request, "sim", "max_climb_m")
        if not self.sim.recompute_navmesh(self.sim.pathfinder, settings):
            raise RequestError(f"habitat could not build a navmesh for {scene}")

        self.lut, matched = self._category_lut(categories, {str(k).strip().lower(): str(v) for k, v in table.items()})
        pf = self.sim.pathfinder
        lower, upper = pf.get_bounds()
        return {
            "categories": categories,
            "objects_matched": matched,
            "navigable_area_m2": float(pf.navigable_area),
            "bounds": [[float(v) for v in lower], [float(v) for v in upper]],
        }, None

    def _semantic_stage(self, sim_cfg, mesh, descriptor):
        """A stage template naming the scan's semantic mesh and table (HM3D's ``X.semantic.glb`` and
        ``X.semantic.txt``) explicitly, whatever conventions the dataset config relies on."""
        for path, what in ((mesh, "semantic mesh"), (descriptor, "semantic descriptor")):
            if not isinstance(path, str) or not os.path.isfile(path):
                raise RequestError(f"{what} {path!r}: no such file (give both the semantic mesh and its table)")
        mediator = self.hs.metadata.MetadataMediator(sim_cfg)
        templates = mediator.stage_template_manager
        stage = templates.create_new_template(sim_cfg.scene_id)
        stage.semantic_asset_handle = os.path.abspath(mesh)
        # habitat-sim 0.2 calls the semantic descriptor the "house" file; later versions renamed it.
        name = "semantic_descriptor_filename" if hasattr(stage, "semantic_descriptor_filename") else "house_filename"
        setattr(stage, name, os.path.abspath(descriptor))
        templates.register_template(stage, sim_cfg.scene_id)
        return mediator

    def _category_lut(self, categories, table):
        """semantic id -> 1 + index of our category (0: background or not in the table)."""
        assert self.sim is not None  # called by op_load once the simulator is up
        scene = self.sim.semantic_scene
        objects = [o for o in (scene.objects if scene is not None else []) if o is not None]
        ids = [int(o.semantic_id) for o in objects]
        lut = np.zeros(max(ids + [0]) + 1, np.int32)
        matched = 0
        for obj, sid in zip(objects, ids):
            name = obj.category.name() if obj.category is not None else ""
            ours = table.get(name.strip().lower())
            if ours in categories:
                lut[sid] = categories.index(ours) + 1
                matched += 1
        return lut, matched

    def _agent(self):
        if self.sim is None:
            raise RequestError("no scene: send load first")
        return self.sim.get_agent(0)

    def _state(self, observations, collided, moved):
        state = self._agent().get_state()
        x, y, z, w = (float(v) for v in self.common.quat_to_coeffs(state.rotation))
        rgb = np.asarray(observations["rgb"])[..., :3]
        depth = np.asarray(observations["depth"], dtype=np.float32).reshape(rgb.shape[:2])
        depth = np.where(
            (depth >= self.cfg["min_depth_m"]) & (depth <= self.cfg["max_depth_m"]), depth, np.float32(0.0)
        ).astype(np.float32)
        raw = np.asarray(observations["semantic"]).reshape(rgb.shape[:2]).astype(np.int64)
        semantic = np.where(raw < len(self.lut), self.lut[np.clip(raw, 0, len(self.lut) - 1)], 0).astype(np.int32)
        reply = {
            "position": [float(v) for v in state.position],
            "rotation": [w, x, y, z],
            "tilt_deg": self.tilt_deg,
            "collided": bool(collided),
            "moved_m": float(moved),
        }
        return reply, {"rgb": rgb, "depth": depth, "semantic": semantic}

    def op_reset(self, request):
        agent = self._agent()
        assert self.sim is not None  # _agent() refuses a request before load
        target = read_point(request.get("position"), "position")
        snapped = np.asarray(self.sim.pathfinder.snap_point(target), dtype=np.float64)
        # The navmesh is eroded by the agent radius: a start within one radius of it is that spot.
        off = math.hypot(snapped[0] - target[0], snapped[2] - target[2]) if np.isfinite(snapped).all() else math.inf
        if off > self.cfg["agent_radius_m"]:
            where = ", ".join(f"{v:.2f}" for v in target)
            raise RequestError(f"start [{where}] is {off:.2f} m from habitat's navmesh")
        w, x, y, z = read_rotation(request.get("rotation"))
        state = self.hs.AgentState()
        state.position = snapped.astype(np.float32)
        state.rotation = self.common.quat_from_coeffs([x, y, z, w])
        agent.set_state(state, reset_sensors=True)
        self.tilt_deg = 0.0
        return self._state(self.sim.get_sensor_observations(), False, 0.0)

    def op_step(self, request):
        agent = self._agent()
        assert self.sim is not None  # _agent() refuses a request before load
        action = request.get("action")
        if action not in ACTIONS:
            raise RequestError(f"unknown action {action!r}; valid: {', '.join(ACTIONS)}")
        before = np.asarray(agent.get_state().position, dtype=np.float64)
        if action in ("look_up", "look_down"):
            # habitat's look actions do not clamp: turn by what is left before our tilt limit.
            sign = 1.0 if action == "look_up" else -1.0
            tilt = min(
                max(self.tilt_deg + sign * self.cfg["tilt_angle_deg"], self.cfg["min_tilt_deg"]),
                self.cfg["max_tilt_deg"],
            )
            delta, self.tilt_deg = abs(tilt - self.tilt_deg), tilt
            if delta == 0.0:
                action = "stop"
            else:
                agent.agent_config.action_space[action].actuation.amount = delta
        if action == "stop":
            observations, collided = self.sim.get_sensor_observations(), False
        else:
            observations = self.sim.step(action)
            collided = bool(observations.get("collided", False))
        moved = float(np.linalg.norm(np.asarray(agent.get_state().position, dtype=np.float64) - before))
        return self._state(observations, collided, moved)

    def op_geodesic(self, request):
        """Shortest navmesh distance from ``start`` to the nearest of ``goals`` (null: no path)."""
        self._agent()
        assert self.sim is not None  # _agent() refuses a request before load
        goals = request.get("goals")
        if not isinstance(goals, list) or not goals:
            raise RequestError("geodesic needs a non-empty 'goals' list of [p0, p1, p2] points")
        path = self.hs.MultiGoalShortestPath()
        path.requested_start = read_point(request.get("start"), "start").astype(np.float32)
        path.requested_ends = [read_point(g, "goal").astype(np.float32) for g in goals]
        found = self.sim.pathfinder.find_path(path)
        distance = float(path.geodesic_distance)
        return {"distance_m": distance if found and math.isfinite(distance) else None}, None

    def close(self):
        if self.sim is not None:
            self.sim.close()
            self.sim = None


def main(argv=None):
    args = sys.argv[1:] if argv is None else argv
    if args:
        sys.stderr.write("usage: PYTHON habitat_server.py  (speaks the l3mvn bridge protocol on stdin/stdout)\n")
        return 2
    return run_server(HabitatBackend)


if __name__ == "__main__":
    sys.exit(main())

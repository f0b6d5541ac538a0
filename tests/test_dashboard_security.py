"""Hostile clients against a real dashboard over a real websocket: foreign pages, bad values, failing handlers.

Each frame is one that viser's own page could send, or a tampered copy of it, so each test is
exactly what a page on another site, or a script, can do to a running ``l3mvn serve``.
"""

from __future__ import annotations

import http.client
import logging
import math
import time

import msgspec
import pytest
import viser
import zstandard
from conftest import free_port, serve_dashboard
from websockets.exceptions import InvalidStatus
from websockets.sync.client import ClientConnection, connect

from l3mvn.core.config import Config, SimConfig
from l3mvn.core.errors import L3MVNError
from l3mvn_studio.cli import serve_main
from l3mvn_studio.origin import OriginPolicy
from l3mvn_studio.server import start_dashboard
from l3mvn_studio.tab_notices import SEPARATOR
from l3mvn_studio.viser_hooks import start_checked_server

SMALL = Config(sim=SimConfig().with_frame(120, 160))
DEFAULT_SPEED = 4.0  # start_dashboard's steps per second
TIMEOUT_S = 15.0  # generous: the suite may share two slow cores
SUBPROTOCOL = f"viser-v{viser.__version__}"  # viser refuses a page of another version
CAMERA = {
    "wxyz": [1.0, 0.0, 0.0, 0.0],
    "position": [0.0, 0.0, 5.0],
    "fov": 1.0,
    "near": 0.01,
    "far": 100.0,
    "image_height": 600,
    "image_width": 800,
    "look_at": [0.0, 0.0, 0.0],
    "up_direction": [0.0, 1.0, 0.0],
}


def _wait(predicate, what: str, timeout: float = TIMEOUT_S):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        result = predicate()
        if result:
            return result
        time.sleep(0.02)
    raise AssertionError(f"timed out waiting for {what}")


def _decode(frame: bytes) -> list[dict]:
    """The messages in one server frame: [u64 msgpack size][u64 zstd size][zstd(msgpack)][binary buffers].

    Arrays (images, meshes) ride in the trailing buffers as ``{"__binary_index": i}`` stand-ins; no
    test needs them, so they are left undecoded.
    """
    size, packed = int.from_bytes(frame[:8], "little"), int.from_bytes(frame[8:16], "little")
    inner = zstandard.ZstdDecompressor().decompress(frame[16 : 16 + packed], max_output_size=size)
    return msgspec.msgpack.decode(inner)["messages"]


class Tab:
    """A browser tab reduced to viser's wire format.

    A tab sends one msgpack map per websocket message, ``{"type": <viser message class>, **fields}``,
    and counts as connected (gets notices, its clicks run) once it has sent its camera. On connect
    it is sent the page's current state, ending with a ReplayDoneMessage (``state``); ``received``
    holds only what came after.
    """

    def __init__(self, ws: ClientConnection) -> None:
        self.ws = ws
        self.received: list[dict] = []
        self.wait_for(lambda m: m["type"] == "ReplayDoneMessage", "the page state")
        self.state, self.received = self.received, []
        self.uuids = {
            m["props"]["label"]: m["uuid"]
            for m in self.state
            if isinstance(m.get("props"), dict) and "label" in m["props"]
        }
        self.client_id: int | None = None

    def join(self, server: viser.ViserServer) -> Tab:
        before = set(server.get_clients())
        self.send("ViewerCameraMessage", **CAMERA)
        self.client_id = max(_wait(lambda: set(server.get_clients()) - before, "the tab to join"))
        return self

    def send(self, type_: str, **fields) -> None:
        self.ws.send(msgspec.msgpack.encode({"type": type_, **fields}))

    def set(self, label: str, value) -> None:
        """What the page sends when a control is changed (or a button clicked)."""
        self.send("GuiUpdateMessage", uuid=self.uuids[label], updates={"value": value})

    def click_map(self, origin, direction) -> None:
        self.send(
            "ScenePointerMessage",
            event_type="click",
            ray_origin=origin,
            ray_direction=direction,
            screen_pos=[[0.5, 0.5]],
            modifier=None,
        )

    def wait_for(self, predicate, what: str) -> dict:
        """The first message so far, or arriving within TIMEOUT_S, that ``predicate`` accepts."""
        deadline = time.monotonic() + TIMEOUT_S
        checked = 0
        while True:
            for m in self.received[checked:]:
                if predicate(m):
                    return m
            checked = len(self.received)
            left = deadline - time.monotonic()
            if left <= 0:
                raise AssertionError(f"timed out waiting for {what}; notices: {self.notices()}")
            try:
                self.received += _decode(self.ws.recv(timeout=left))
            except TimeoutError:
                pass

    def notice(self, fragment: str) -> dict:
        return self.wait_for(
            lambda m: m["type"] == "NotificationShowMessage" and fragment in m["props"]["body"],
            f"a notice with {fragment!r}",
        )["props"]

    def notices(self) -> list[str]:
        """Every text the tab was shown, once each (texts that come together share a card)."""
        cards = [m["props"]["body"] for m in self.received if m["type"] == "NotificationShowMessage"]
        return list(dict.fromkeys(text for card in cards for text in card.split(SEPARATOR)))

    def updates_of(self, uuid: str) -> list:
        return [m["updates"] for m in self.received if m["type"] == "GuiUpdateMessage" and m["uuid"] == uuid]


def _connect(dash, origin: str | None) -> ClientConnection:
    return connect(
        dash.url.replace("http", "ws", 1),
        origin=origin,
        subprotocols=[SUBPROTOCOL],
        max_size=None,
        open_timeout=TIMEOUT_S,
    )


@pytest.fixture(scope="module")
def dash():
    yield from serve_dashboard(episodes_per_house=2, cfg=SMALL, policy="oracle")


@pytest.fixture
def open_tab(dash):
    """Opens tabs from the dashboard's own origin; closes them after the test."""
    tabs: list[Tab] = []

    def open_() -> Tab:
        tab = Tab(_connect(dash, dash.url))
        tabs.append(tab)
        return tab.join(dash.server)

    yield open_
    for tab in tabs:
        tab.ws.close()
    dash.controller.pause()
    dash.controller.wait_idle()


def _state(dash) -> dict:
    """Everything a tab can change: the controls' values and options, the controller's settings."""
    v, c = dash.view, dash.controller
    handles = (
        v.scene,
        v.episode,
        v.target,
        v.policy,
        v.scorer,
        v.controls,
        v.speed,
        v.record,
        v.frontier_pick,
        v.goal_buttons,
    )
    return {
        "values": [repr(h.value) for h in handles],
        "options": [v.scene.options, v.episode.options],
        "controller": (c.policy_name, c.scorer, c.record, c.steps_per_second, c.running, c.snapshot.seq),
    }


# --- who may connect ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    "origin",
    [
        "http://evil.example",
        "null",
        "http://127.0.0.1:{port}.evil.example",
        "https://127.0.0.1:{port}",
        "http://localhost:{other}",
    ],
)
def test_a_page_from_another_site_is_refused_at_the_handshake(dash, origin):
    port = dash.server.get_port()
    before = _state(dash), set(dash.server.get_clients())
    with pytest.raises(InvalidStatus) as refused:
        _connect(dash, origin.format(port=port, other=port + 1))
    assert refused.value.response.status_code == 403
    assert b"refused a connection from a page at Origin" in refused.value.response.body
    assert (_state(dash), set(dash.server.get_clients())) == before


@pytest.mark.parametrize("origin", ["http://127.0.0.1:{port}", "http://localhost:{port}", None])
def test_the_dashboards_own_page_and_scripts_without_an_origin_get_the_page(dash, origin):
    ws = _connect(dash, origin and origin.format(port=dash.server.get_port()))
    try:
        assert "Scene" in Tab(ws).uuids
    finally:
        ws.close()


def _get(dash, host: str) -> http.client.HTTPResponse:
    conn = http.client.HTTPConnection("127.0.0.1", dash.server.get_port(), timeout=TIMEOUT_S)
    conn.request("GET", "/", headers={"Host": host})
    return conn.getresponse()


def test_a_dns_rebound_host_name_is_refused_even_for_the_page(dash):
    response = _get(dash, f"evil.example:{dash.server.get_port()}")
    body = response.read().decode()
    assert response.status == 403
    assert "refused a request for Host 'evil.example:" in body and "--allow-origin http://evil.example:" in body
    assert _get(dash, f"localhost:{dash.server.get_port()}").status == 200


def test_allow_origin_admits_a_reverse_proxy_and_nothing_more():
    d = start_dashboard(
        port=free_port(),
        houses=1,
        episodes_per_house=1,
        cfg=SMALL,
        policy="oracle",
        allow_origins=["https://Studio.Example.com/"],
    )
    try:
        ws = _connect(d, "https://studio.example.com")
        try:
            assert "Scene" in Tab(ws).uuids
        finally:
            ws.close()
        assert _get(d, "studio.example.com").status == 200
        with pytest.raises(InvalidStatus):
            _connect(d, "https://evil.example")
    finally:
        d.stop()


@pytest.mark.parametrize(
    "bad", ["studio.example.com", "ftp://studio.example.com", "https://x.org/path", "https://user@x.org", "http://a b"]
)
def test_an_allow_origin_that_is_not_an_origin_is_refused_before_anything_starts(bad, capsys):
    with pytest.raises(L3MVNError, match="is not an origin"):
        OriginPolicy("127.0.0.1", [bad])
    assert serve_main(["--allow-origin", bad, "--port", str(free_port())]) == 2
    assert "is not an origin; give scheme://host[:port]" in capsys.readouterr().err


def test_a_viser_that_starts_its_server_another_way_is_stopped_not_served_unguarded(monkeypatch):
    stopped = []

    class ServerStartedElsewhere:
        def __init__(self, **kwargs) -> None:
            pass

        def stop(self) -> None:
            stopped.append(True)

    monkeypatch.setattr(viser, "ViserServer", ServerStartedElsewhere)
    with pytest.raises(L3MVNError, match="cannot check Origin headers"):
        start_checked_server(lambda *request: None, port=free_port(), verbose=False)
    assert stopped == [True]


def test_a_check_that_fails_refuses_the_request(caplog):
    def broken(origins, hosts, port):
        raise RuntimeError("bug in the check")

    server = start_checked_server(broken, host="127.0.0.1", port=free_port(), verbose=False)
    try:
        with pytest.raises(InvalidStatus) as refused:
            connect(f"ws://127.0.0.1:{server.get_port()}", subprotocols=[SUBPROTOCOL], open_timeout=TIMEOUT_S)
        assert refused.value.response.status_code == 403
        assert "bug in the check" in caplog.text
    finally:
        server.stop()


# --- what a connected tab may send ---------------------------------------------------------------


@pytest.mark.parametrize(
    "label, value, notice",
    [
        (
            "Scene",
            "../../../../etc/passwd",
            "Scene: '../../../../etc/passwd' is not one of the choices; valid: procedural-0000/0",
        ),
        ("Episode", "7: spaceship", "valid: 0: "),
        ("Steps / s", math.nan, "Steps / s: nan is not a number from 0.5 to 60"),
        ("Steps / s", math.inf, "Steps / s: inf is not a number from 0.5 to 60"),
        ("Steps / s", 1e6, "is not a number from 0.5 to 60"),
        ("Steps / s", "5", "Steps / s: '5' is not a number"),
        ("Policy", "no-such-policy", "Policy: 'no-such-policy' is not one of the choices; valid: "),
        ("Record (.rrd)", "yes", "Record (.rrd): 'yes' is not true or false"),
        ("Controls", "Explode", "valid: Reset, Step, Run"),
        ("Frontier", "F0", "Frontier is disabled right now"),
        ("Fit map in view", "x" * 10_000, "a button click carries true, not 'xxxx"),
    ],
)
def test_a_bad_value_changes_nothing_and_only_its_tab_is_told(dash, open_tab, label, value, notice):
    hostile, bystander = open_tab(), open_tab()
    before = _state(dash)
    hostile.set(label, value)
    body = hostile.notice(notice)["body"]
    assert "\n" not in body and len(body) < 400
    assert _state(dash) == before
    handle = next(h for h in vars(dash.view).values() if getattr(h, "label", None) == label)
    if not isinstance(handle, (viser.GuiButtonHandle, viser.GuiButtonGroupHandle)):
        hostile.wait_for(
            lambda m: (
                m["type"] == "GuiUpdateMessage"
                and m["uuid"] == hostile.uuids[label]
                and m["updates"] == {"value": handle.value}
            ),
            "the tab to be shown the real value again",
        )
    _no_broadcast_reached(dash, hostile, bystander, label)


def _no_broadcast_reached(dash, actor: Tab, bystander: Tab, label: str) -> None:
    """The bystander saw nothing of ``label`` or of the refusal: a later, valid change from ``actor``
    arrives first (broadcasts keep their order), so anything sent before it would have too."""
    marker = DEFAULT_SPEED + 0.5
    actor.set("Steps / s", marker)
    bystander.wait_for(
        lambda m: m["type"] == "GuiUpdateMessage" and m["updates"] == {"value": marker}, "the marker update"
    )
    if label != "Steps / s":
        assert bystander.updates_of(bystander.uuids[label]) == []
    assert all(u == {"value": marker} for u in bystander.updates_of(bystander.uuids["Steps / s"]))
    assert bystander.notices() == []
    actor.set("Steps / s", DEFAULT_SPEED)
    _wait(lambda: dash.controller.steps_per_second == dash.view.speed.value == DEFAULT_SPEED, "the speed back")


def test_a_frame_that_rewrites_a_controls_internals_is_refused_and_the_control_still_works(dash, open_tab):
    tab = open_tab()
    before = _state(dash)
    rewrites = ({"update_cb": "boom"}, {"props": None}, {"value": "frontier", "sync_cb": 1}, {}, [1])
    for updates in rewrites:
        tab.send("GuiUpdateMessage", uuid=tab.uuids["Policy"], updates=updates)
    tab.send("GuiUpdateMessage", uuid="no-such-control", updates={"value": 1})
    tab.notice("that control is not on this page")
    refused = [n for n in tab.notices() if n.startswith("Policy: a page may only change a control's value, not ")]
    assert len(refused) == len(rewrites) and _state(dash) == before
    tab.set("Policy", "frontier")
    tab.notice("policy 'frontier' takes effect on the next Reset")
    assert dash.controller.policy_name == "frontier"
    tab.set("Policy", "oracle")
    tab.notice("policy 'oracle' takes effect on the next Reset")


def test_messages_the_page_never_sends_are_ignored(dash, open_tab, monkeypatch):
    shares = []
    monkeypatch.setattr(dash.server, "request_share_url", lambda *args, **kwargs: shares.append(args))
    tab, bystander = open_tab(), open_tab()
    before = _state(dash)
    tab.send("ShareUrlRequest")  # viser would open a public tunnel to this server
    tab.send(
        "FileTransferStartUpload",
        source_component_uuid=tab.uuids["Scene"],
        transfer_uuid="t",
        filename="x.bin",
        mime_type="application/octet-stream",
        part_count=1,
        size_bytes=50_000_000,
    )
    tab.send("GuiFormDirtyMessage", uuid=tab.uuids["Scene"])  # viser relays it to every tab
    tab.send("GuiButtonHoldMessage", uuid=tab.uuids["Fit map in view"], frequency=10.0)
    _no_broadcast_reached(dash, tab, bystander, "Scene")
    assert shares == [] and _state(dash) == before
    assert not [m for m in bystander.received if m["type"] == "GuiFormDirtyMessage"]


def test_every_control_on_the_page_accepts_the_values_the_page_sends(dash, open_tab):
    tab = open_tab()
    controls = {
        m["uuid"]: {**m["props"], "value": m["value"]}
        for m in tab.state
        if m["type"] in ("GuiDropdownMessage", "GuiSliderMessage", "GuiCheckboxMessage")
    }
    for m in tab.state:
        if m["type"] == "GuiUpdateMessage" and m["uuid"] in controls:
            controls[m["uuid"]].update(m["updates"])
    enabled = {uuid: c["value"] for uuid, c in controls.items() if not c["disabled"]}
    assert len(enabled) >= 7
    for uuid, value in enabled.items():
        tab.send("GuiUpdateMessage", uuid=uuid, updates={"value": value})
    tab.set("Controls", "Explode")  # a refusal known to come after all of those
    tab.notice("Explode")
    assert len(tab.notices()) == 1, tab.notices()


def _reset(dash) -> None:
    ctl = dash.controller
    scene = ctl.scene_keys[0]
    ctl.reset(scene, ctl.episodes_of(scene)[0].episode_id)
    assert ctl.wait_idle()


@pytest.mark.parametrize(
    "origin, direction, notice",
    [
        (
            [math.nan, 0.0, 5.0],
            [0.0, 0.0, -1.0],
            "map click ignored: its ray origin (nan, 0.0, 5.0) is not three finite",
        ),
        ([1.0, -1.0, 5.0], [0.0, math.inf, -1.0], "its ray direction (0.0, inf, -1.0) is not three finite numbers"),
        ([1.0, -1.0, 5.0], [0.0, -math.inf, -math.inf], "is not three finite numbers"),
        ("abc", [0.0, 0.0, -1.0], "its ray origin 'abc' is not three finite numbers"),
        ([1.0, -1.0, 1e308], [1e308, 0.0, -1e-300], "that click is outside the map"),  # finite, but meets z=0 at inf
    ],
)
def test_a_map_click_with_a_broken_ray_is_refused_and_the_server_goes_on(dash, open_tab, origin, direction, notice):
    _reset(dash)
    tab = open_tab()
    before = _state(dash)
    tab.click_map(origin, direction)
    assert "\n" not in tab.notice(notice)["body"]
    assert _state(dash) == before
    tab.set("Controls", "Step")
    _wait(lambda: dash.controller.snapshot.event.step == 1, "a step after the refused click")


def test_a_handler_that_raises_is_logged_and_becomes_an_error_notice_to_its_tab(dash, open_tab, monkeypatch, caplog):
    _reset(dash)
    tab, bystander = open_tab(), open_tab()

    def broken_step(**kwargs):
        raise RuntimeError("step fell over")

    monkeypatch.setattr(dash.controller, "step", broken_step)
    with caplog.at_level(logging.ERROR, logger="l3mvn_studio.views"):
        tab.set("Controls", "Step")
        notice = tab.notice("Controls failed: RuntimeError: step fell over")
    assert notice["title"] == "Error" and notice["color"] == "red"
    assert "dashboard: Controls failed" in caplog.text and "Traceback" in caplog.text
    _no_broadcast_reached(dash, tab, bystander, "Controls")
    monkeypatch.undo()
    tab.set("Controls", "Step")
    _wait(lambda: dash.controller.snapshot.event.step == 1, "a step once the handler works again")


def test_garbage_frames_cost_only_the_connection_that_sent_them(dash, open_tab):
    bystander = open_tab()
    for frame in (
        b"\xc1 not msgpack",
        msgspec.msgpack.encode({"type": "NoSuchMessage"}),
        msgspec.msgpack.encode({"type": "GuiUpdateMessage"}),
        msgspec.msgpack.encode([1, 2, 3]),
    ):
        ws = _connect(dash, dash.url)
        Tab(ws)
        ws.send(frame)
        ws.close()
    fresh = open_tab()
    fresh.set("Controls", "Explode")
    fresh.notice("Explode")
    bystander.set("Controls", "Explode")
    bystander.notice("Explode")


def test_malformed_frames_are_dropped_with_one_log_line_per_kind_and_second(dash, open_tab, caplog):
    """A tab sending frames that do not decode keeps its connection and its controls: each bad frame
    is dropped, and the log gets at most one line per kind of fault per second."""
    garbage = (
        b"\xc1 not msgpack",
        msgspec.msgpack.encode({"type": "NoSuchMessage"}),
        msgspec.msgpack.encode({"type": "GuiUpdateMessage"}),
        msgspec.msgpack.encode([1, 2, 3]),
    )
    tab = open_tab()
    with caplog.at_level(logging.WARNING, logger="l3mvn_studio.viser_hooks"):
        started = time.monotonic()
        for _ in range(200):
            for frame in garbage:
                tab.ws.send(frame)
        tab.ws.send("a text frame")
        tab.set("Controls", "Explode")
        tab.notice("Explode")  # the same connection still works
        seconds = time.monotonic() - started
    dropped = [r for r in caplog.records if "dropped a frame a page sent" in r.getMessage()]
    kinds = {r.getMessage().split(": ")[2] for r in dropped}
    assert dropped and "Traceback" not in caplog.text
    assert len(dropped) <= len(kinds) * (math.ceil(seconds) + 1), [r.getMessage() for r in dropped]


def test_a_click_at_a_finite_but_huge_point_is_outside_the_map(dash, open_tab):
    _reset(dash)
    tab = open_tab()
    tab.click_map([1e308, -1e308, 5.0], [0.0, 0.0, -1.0])
    tab.notice("that click is outside the map")

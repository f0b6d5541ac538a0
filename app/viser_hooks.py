"""The only places the dashboard reaches past viser's public API, each because viser (1.1) has no hook.

Each function names what it relies on; tests/test_dashboard_security.py drives all of them through a
real server and websocket client, so a viser upgrade that moves one fails those tests (and the
handshake check refuses to start an unguarded server) instead of silently dropping a protection.
"""

from __future__ import annotations

import http
import logging
import math
import threading
import time
from collections.abc import Callable
from types import SimpleNamespace
from typing import Any

import viser
import websockets.asyncio.server
from viser._messages import GuiUpdateMessage, RunJavascriptMessage
from viser.infra import _infra
from websockets.asyncio.server import ServerConnection
from websockets.http11 import Request, Response

from l3mvn.core.errors import L3MVNError
from l3mvn.run.serving import bind_failure

log = logging.getLogger(__name__)

# (Origin headers, Host headers, port the request came in on) -> None to go on, or why it is refused.
RequestCheck = Callable[[list[str], list[str], int], str | None]
# (client id, GUI handle uuid, the update's properties) -> True to let viser apply it.
UpdateCheck = Callable[[int, str, dict[str, Any]], bool]

_serve_lock = threading.Lock()


def start_checked_server(
    check: RequestCheck, *, host: str = "0.0.0.0", port: int = 8080, **viser_args: Any
) -> viser.ViserServer:
    """``viser.ViserServer(host=host, port=port, **viser_args)``, with ``check`` run on every HTTP request
    and websocket handshake, on exactly ``host:port``: L3MVNError (one line) if that cannot be bound.

    websockets' documented handshake hook is ``serve(..., process_request=...)``; viser calls
    ``websockets.asyncio.server.serve`` itself, on its own thread while ``ViserServer.__init__``
    waits for the port, and takes no hook of ours. So while the server starts, ``serve`` is one that
    puts ``check`` in front of viser's own ``process_request`` (which serves the page); a refused
    request gets 403 and never reaches viser. The lock keeps two dashboards starting at once from
    swapping ``serve`` under each other. If viser started its server some other way, it is stopped
    and this raises: better no dashboard than one nobody guards.

    The same ``serve`` keeps a failed bind from viser (see ``_Bind``): viser would try the next
    port on an OSError, up to 1000 of them, so a busy port became another one silently and a name
    that does not resolve was looked up 1000 times; any other error killed its thread and left
    ``ViserServer()`` waiting forever.
    """
    drop_malformed_frames()
    real_serve = websockets.asyncio.server.serve
    binds: list[_Bind] = []

    def serve(handler, *args, process_request=None, **kwargs):
        def process(connection: ServerConnection, request: Request) -> Response | Any:
            refused = _refusal(check, connection, request)
            if refused is not None:
                return connection.respond(http.HTTPStatus.FORBIDDEN, refused + "\n")
            return process_request(connection, request) if process_request is not None else None

        binds.append(_Bind(real_serve(handler, *args, process_request=process, **kwargs)))
        return binds[-1]

    with _serve_lock:
        websockets.asyncio.server.serve = serve
        try:
            server = viser.ViserServer(host=host, port=port, **viser_args)
        finally:
            websockets.asyncio.server.serve = real_serve
    failure = next((bind.failure for bind in binds if bind.failure is not None), None)
    if binds and failure is None:
        return server
    server.stop()
    if failure is not None:
        raise L3MVNError(bind_failure(host, port, failure))
    raise L3MVNError(
        f"viser {viser.__version__} no longer starts its server through "
        "websockets.asyncio.server.serve, so the dashboard cannot check Origin headers; "
        "refusing to serve (see app/viser_hooks.py)"
    )


class _Bind:
    """viser's ``async with serve(...)``, with a failure to bind kept here instead of raised to viser.

    On failure viser gets ``_NotListening`` and reports the server ready (it cannot be told
    otherwise); ``start_checked_server`` then stops it and raises with ``failure``.
    """

    def __init__(self, serving: Any) -> None:
        self._serving = serving
        self.failure: BaseException | None = None

    async def __aenter__(self) -> Any:
        try:
            return await self._serving.__aenter__()
        except Exception as exc:  # any failure to bind: kept for start_checked_server to report
            self.failure = exc
            return _NotListening()

    async def __aexit__(self, *exc_info: object) -> Any:
        if self.failure is None:
            return await self._serving.__aexit__(*exc_info)
        return None


class _NotListening:
    """What viser reads from a started ``websockets`` server (``.server.sockets``), when none started."""

    server = SimpleNamespace(sockets=())


def _refusal(check: RequestCheck, connection: ServerConnection, request: Request) -> str | None:
    """``check`` on one request; a check that raises refuses (fail closed) and is logged."""
    try:
        return check(request.headers.get_all("Origin"), request.headers.get_all("Host"), connection.local_address[1])
    except Exception:
        log.exception("dashboard: checking a request failed; refusing it")
        return "refused: the server could not check this request (see its log)"


def check_gui_updates(server: viser.ViserServer, check: UpdateCheck) -> None:
    """Run ``check`` on each GUI update a tab sends, before viser applies it; False drops the update.

    viser applies a tab's update to the shared handle, re-broadcasts it to every other tab, and only
    then runs ``on_update`` callbacks, so a callback is too late to refuse a value. viser's own
    handler (``GuiApi._handle_gui_updates``) is registered on the server's websocket with the public
    ``register_handler``; it is swapped for one that asks ``check`` first. ``unregister_handler``
    raises if viser stops registering it that way.
    """
    websock = server._websock_server
    apply_update = server.gui._handle_gui_updates
    websock.unregister_handler(GuiUpdateMessage, apply_update)

    async def checked(client_id: int, message: GuiUpdateMessage) -> None:
        if check(client_id, message.uuid, message.updates):
            await apply_update(client_id, message)

    websock.register_handler(GuiUpdateMessage, checked)


def ignore_client_messages_except(server: viser.ViserServer, *kept: str) -> None:
    """Stop viser acting on any message a tab sends but the ``kept`` types (names as on the wire).

    viser answers messages this page never sends, and some reach far: a ShareUrlRequest from any
    tab opens a public tunnel to this server through viser's share service, FileTransferStartUpload
    buffers an upload for any control, GuiFormDirtyMessage is relayed to every tab. The dashboard
    has no share button, upload, form, command, drag or transform control, so everything but what
    it uses is dropped; viser ignores a message type that has no handler. The handler table
    (``WebsockServer._incoming_handlers``) is read because viser has no public list of it;
    ``unregister_handler`` is public.
    """
    websock = server._websock_server
    missing = set(kept) - {message_type.__name__ for message_type in websock._incoming_handlers}
    if missing:
        raise L3MVNError(
            f"viser {viser.__version__} no longer handles {', '.join(sorted(missing))} (see app/viser_hooks.py)"
        )
    for message_type in list(websock._incoming_handlers):
        if message_type.__name__ not in kept:
            websock.unregister_handler(message_type)


def drop_malformed_frames() -> None:
    """Make viser drop a frame it cannot decode, with one log line per kind of fault, connection and
    second, instead of ending the connection with a traceback.

    viser's per-connection receive loop (``viser.infra._infra._message_consumer``, looked up by name
    when a connection opens) decodes each frame and lets any error end the connection, logged with
    its traceback; a page that reconnects and sends garbage again fills the log and costs a fresh
    replay of the whole page each time. The loop is replaced, process-wide and once, by one that
    decodes the same way and skips what does not decode. ``start_checked_server`` installs it.
    """
    if _infra._message_consumer is _tolerant_consumer:
        return
    if getattr(_infra._message_consumer, "__name__", "") != "_message_consumer":
        raise L3MVNError(
            f"viser {viser.__version__} no longer receives frames through "
            "viser.infra._infra._message_consumer (see app/viser_hooks.py)"
        )
    _infra._message_consumer = _tolerant_consumer


class _FaultLog:
    """At most one log line per (connection, kind of fault) a second; the rest are counted into it."""

    def __init__(self) -> None:
        self._last: dict[tuple[int, str], tuple[float, int]] = {}
        self._lock = threading.Lock()

    def __call__(self, connection: object, fault: BaseException) -> None:
        key, now = (id(connection), type(fault).__name__), time.monotonic()
        with self._lock:
            last, skipped = self._last.get(key, (-math.inf, 0))
            if now - last < 1.0:
                self._last[key] = (last, skipped + 1)
                return
            self._last[key] = (now, 0)
            if len(self._last) > 4096:  # connections come and go: forget the oldest
                for old in sorted(self._last, key=lambda k: self._last[k][0])[:2048]:
                    del self._last[old]
        more = f" (and {skipped} more in the last second)" if skipped else ""
        log.warning("dashboard: dropped a frame a page sent that does not decode: %s%s", _fault_line(fault), more)


_fault_log = _FaultLog()


def _fault_line(fault: BaseException) -> str:
    text = " ".join(str(fault).split())
    return f"{type(fault).__name__}: {text[:160]}"


async def _tolerant_consumer(
    websocket: ServerConnection, handle_message: Callable[[Any], None], message_class: type
) -> None:
    while True:
        raw = await websocket.recv()
        try:
            if not isinstance(raw, bytes):
                raise TypeError("a text frame where the page sends binary ones")
            message = message_class.deserialize(raw)
        except Exception as fault:  # anything a frame can make the decoder raise
            _fault_log(websocket, fault)
            continue
        handle_message(message)


def handle_uuid(handle: Any) -> str:
    """The id viser gives a GUI handle on the wire (GuiUpdateMessage.uuid); viser has no public getter."""
    return handle._impl.uuid


def show_value_to(client: viser.ClientHandle, handle: Any) -> None:
    """Send one tab the value the server holds for ``handle``.

    A tab shows its own edit before the server sees it, so after refusing one the tab must be told
    the real value; the handle's setter only broadcasts changes, and viser has no per-tab update.
    """
    client._websock_connection.queue_message(GuiUpdateMessage(handle_uuid(handle), {"value": handle.value}))


def run_script_on_connect(server: viser.ViserServer, source: str) -> None:
    """Run ``source`` (JavaScript) once in every tab as it connects.

    viser 1.1 has no public way to add script to its page; its own ``RunJavascriptMessage`` (how
    ``gui.add_plotly`` ships plotly.js) is the supported channel for code the server sends. The
    script is ours, constant, and sent only by this server.
    """

    @server.on_client_connect
    def _(client: viser.ClientHandle) -> None:
        client._websock_connection.queue_message(RunJavascriptMessage(source=source))

"""Which web pages may talk to the dashboard: the Origin and Host check on every request.

A browser lets any page open a websocket to any address, and the dashboard's controls have no
login: without a check, a page on any site the user visits could drive it. The browser names the
page in the handshake's ``Origin`` header (RFC 6455, section 10.2), and only the server can refuse.

Allowed origins are this server's own addresses, ``http://HOST:PORT`` for the loopback names and
for the bind host, plus what ``l3mvn serve --allow-origin`` adds (a reverse proxy's public address).
A request that carries no ``Origin`` is served: browsers always send one on a websocket handshake,
so it comes from a script or tool run by someone who can reach the port, whom an Origin check
cannot stop anyway (they can send any header they like).

The ``Host`` header is checked against the same names, so a page that rebinds its own DNS name to
this machine (DNS rebinding) is refused even for plain page loads. The port is the one the request
arrived on, so the check never relies on the port the server was asked for.
"""

from __future__ import annotations

import logging
import re
import threading
from collections.abc import Iterable
from urllib.parse import urlsplit

from l3mvn.core.errors import L3MVNError
from l3mvn_studio.client_input import shown

log = logging.getLogger(__name__)

LOOPBACK_HOSTS = ("127.0.0.1", "localhost", "::1")
ALLOW_ORIGIN_FLAG = "--allow-origin"
_DEFAULT_PORTS = {"http": 80, "https": 443}
_MAX_WARNED = 64  # distinct refusals logged at WARNING; later ones at DEBUG (a page may retry forever)
_HOSTNAME = re.compile(r"[a-z0-9.-]+|[0-9a-f:.]+")  # a DNS name or IPv4, or an IPv6 literal unbracketed


def normalize_origin(text: str) -> str:
    """``scheme://host[:port]`` as a browser sends it (lower case, no default port, no path)."""
    try:
        parts = urlsplit(text.strip())
        port = parts.port
    except ValueError as exc:
        raise L3MVNError(f"{ALLOW_ORIGIN_FLAG} {text!r}: {exc}") from None
    scheme = parts.scheme.lower()
    if (
        scheme not in _DEFAULT_PORTS
        or not _HOSTNAME.fullmatch(parts.hostname or "")
        or parts.username
        or parts.password
        or parts.path not in ("", "/")
        or parts.query
        or parts.fragment
    ):
        raise L3MVNError(
            f"{ALLOW_ORIGIN_FLAG} {text!r} is not an origin; give scheme://host[:port], "
            "e.g. https://studio.example.com or http://192.168.1.5:8080"
        )
    return f"{scheme}://{_authority(parts.hostname, port, _DEFAULT_PORTS[scheme])}"


def _authority(host: str, port: int | None, default_port: int = _DEFAULT_PORTS["http"]) -> str:
    """``host:port`` as it appears in URLs and Host headers (IPv6 in brackets, default port left out)."""
    host = host.lower()
    if ":" in host and not host.startswith("["):
        host = f"[{host}]"
    return host if port is None or port == default_port else f"{host}:{port}"


class OriginPolicy:
    """Decides whether a request's Origin and Host headers name this dashboard."""

    def __init__(self, bind_host: str, allow_origins: Iterable[str] = ()) -> None:
        self.hosts = tuple(dict.fromkeys((*LOOPBACK_HOSTS, bind_host)))
        self.extra_origins = tuple(dict.fromkeys(normalize_origin(o) for o in allow_origins))
        self._warned: set[str] = set()
        self._warned_lock = threading.Lock()

    def origins(self, port: int) -> tuple[str, ...]:
        """Every Origin accepted for a server on ``port``."""
        return (*(f"http://{_authority(h, port)}" for h in self.hosts), *self.extra_origins)

    def host_headers(self, port: int) -> tuple[str, ...]:
        """Every Host header accepted for a server on ``port``."""
        return (*(_authority(h, port) for h in self.hosts), *(o.split("://", 1)[1] for o in self.extra_origins))

    def refusal(self, origins: list[str], hosts: list[str], port: int) -> str | None:
        """None when the request may proceed; else one line saying why not and how to allow it."""
        if len(hosts) != 1:
            return f"refused a request with {len(hosts)} Host headers (exactly one is required)"
        if _canonical_host(hosts[0]) not in self.host_headers(port):
            return (
                f"refused a request for Host {shown(hosts[0])}: this dashboard answers to "
                f"{', '.join(self.host_headers(port))}{_allow_hint('http://' + hosts[0])}"
            )
        if len(origins) > 1:
            return f"refused a request with {len(origins)} Origin headers (at most one is allowed)"
        if origins and origins[0] not in self.origins(port):
            return (
                f"refused a connection from a page at Origin {shown(origins[0])}: allowed are "
                f"{', '.join(self.origins(port))}{_allow_hint(origins[0])}"
            )
        return None

    def check(self, origins: list[str], hosts: list[str], port: int) -> str | None:
        """``refusal``, logged: each distinct refusal once at WARNING (a refused page may retry forever)."""
        reason = self.refusal(origins, hosts, port)
        if reason is not None:
            with self._warned_lock:
                first = reason not in self._warned and len(self._warned) < _MAX_WARNED
                if first:
                    self._warned.add(reason)
            log.log(logging.WARNING if first else logging.DEBUG, "dashboard: %s", reason)
        return reason


def _canonical_host(header: str) -> str | None:
    """A Host header as ``_authority`` writes it, or None when it is not ``host[:port]``."""
    try:
        parts = urlsplit(f"//{header}")
        port = parts.port
    except ValueError:
        return None
    if not _HOSTNAME.fullmatch(parts.hostname or "") or parts.username or parts.password or parts.path:
        return None
    return _authority(parts.hostname, port)


def _allow_hint(origin: str) -> str:
    """How to allow ``origin``, when it is one (a refused ``null`` or garbage gets no hint)."""
    try:
        allowed = normalize_origin(origin)
    except L3MVNError:
        return ""
    return f"; if that is you (e.g. through a reverse proxy), start with {ALLOW_ORIGIN_FLAG} {allowed}"

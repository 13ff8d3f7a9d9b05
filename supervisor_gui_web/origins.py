"""The origins whose pages may use the supervisor: its own, and an allow-list for other front
ends (the cell file's `[supervisor] allowed_origins`, --allowed-origin).

An origin is `scheme://host[:port]` as a browser sends it in the Origin header. The
supervisor's own origin is the address it serves; served on loopback, the loopback names of
that port are its own too (http://127.0.0.1:8080, http://localhost:8080, http://[::1]:8080),
since a browser on the machine may use any of them. Served on a wildcard address (0.0.0.0),
no name is known to be the one people type: list the page's URL in allowed_origins.

Another port on the same host is another origin: a page served from http://127.0.0.1:9999
is refused by http://127.0.0.1:8080 (and its cookies, which are per site and so shared by
every port of a host, do not help it: see http_guard.py).
"""
from __future__ import annotations

import ipaddress
from urllib.parse import urlsplit

from landscape.server.security.tls import is_loopback

DEFAULT_PORTS = {"http": 80, "https": 443}
LOOPBACK_NAMES = ("127.0.0.1", "localhost", "[::1]")


def normalize(origin: str) -> str:
    """`origin` as browsers write it: lower-case scheme and host, no default port, no
    trailing slash. ValueError for anything that is not scheme://host[:port]."""
    parts = urlsplit(origin.strip())
    if (parts.scheme not in DEFAULT_PORTS or not parts.hostname or parts.path not in ("", "/")
            or parts.query or parts.fragment or parts.username or parts.password):
        raise ValueError(f"an origin is http(s)://host[:port], got {origin!r}")
    try:
        port = parts.port
    except ValueError:
        raise ValueError(f"an origin is http(s)://host[:port], got {origin!r}") from None
    host = parts.hostname.lower()
    host = f"[{host}]" if ":" in host else host
    shown_port = "" if port in (None, DEFAULT_PORTS[parts.scheme]) else f":{port}"
    return f"{parts.scheme}://{host}{shown_port}"


def _is_wildcard(host: str) -> bool:
    try:
        return ipaddress.ip_address(host.strip("[]")).is_unspecified
    except ValueError:
        return False


def own_origins(host: str, port: int, scheme: str = "http") -> tuple[str, ...]:
    """The origins of the address the supervisor serves on (see the module's docstring)."""
    if is_loopback(host) or _is_wildcard(host):
        names = LOOPBACK_NAMES
    else:
        names = (f"[{host}]" if ":" in host and not host.startswith("[") else host,)
    return tuple(normalize(f"{scheme}://{name}:{port}") for name in names)


class OriginPolicy:
    """Which Origin headers are the supervisor's pages'."""

    def __init__(self, own: tuple[str, ...], allowed: tuple[str, ...] = ()):
        self.origins = frozenset(normalize(o) for o in (*own, *allowed))

    def allows(self, origin: str) -> bool:
        try:
            return normalize(origin) in self.origins
        except ValueError:   # "null" (a sandboxed frame, a file), or garbage
            return False

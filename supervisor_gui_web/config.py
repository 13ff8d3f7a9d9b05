"""Web supervisor settings, from the command line or a test."""
from __future__ import annotations

from dataclasses import dataclass

from landscape.client.credentials import ClientTLS

DEFAULT_HOST = "127.0.0.1"   # loopback unless the operator exposes the page on purpose
DEFAULT_PORT = 8080
DEFAULT_DISPLAY_RATE_HZ = 30.0


@dataclass(frozen=True)
class DeviceTarget:
    name: str       # shown on the page and used on the wire, e.g. "arm1"
    address: str    # the device server, "host:port"


def parse_device(text: str) -> DeviceTarget:
    """"NAME=HOST:PORT" as given to --device."""
    name, sep, address = text.partition("=")
    host, colon, port = address.rpartition(":")
    if not sep or not name or not colon or not host or not port.isdigit():
        raise ValueError(f"expected NAME=HOST:PORT, got {text!r}")
    return DeviceTarget(name, address)


@dataclass(frozen=True)
class DashboardConfig:
    devices: tuple[DeviceTarget, ...]
    host: str = DEFAULT_HOST
    port: int = DEFAULT_PORT            # 0 picks a free port
    # State samples per second sent to the page (StreamState's rate_hz).
    display_rate_hz: float = DEFAULT_DISPLAY_RATE_HZ
    # The built page (None: frontend/dist beside this package).
    static_dir: str | None = None
    # TLS to the device servers and the role token the backend presents for every browser
    # (credentials.py); None: plaintext, no token (a device server on loopback without roles).
    tls: ClientTLS | None = None
    token: str | None = None

    def __post_init__(self):
        names = [d.name for d in self.devices]
        if not names:
            raise ValueError("at least one --device NAME=HOST:PORT is needed")
        if len(set(names)) != len(names):
            raise ValueError(f"device names must differ: {names}")
        if not 0 < self.display_rate_hz <= 250:
            raise ValueError("the display rate is in (0, 250] samples per second")

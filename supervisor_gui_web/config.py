"""Web supervisor settings, from the command line or a test."""
from __future__ import annotations

from dataclasses import dataclass

from landscape.client.credentials import ClientTLS
from landscape.supervisor.connections import MAX_UNAUTHENTICATED
from landscape.supervisor.origins import normalize
from landscape.supervisor.sign_in import DEFAULT_IDLE_S, DEFAULT_MAX_AGE_S

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
    # The folder of role tokens people sign in with (viewer.tokens, operator.tokens,
    # admin.tokens: `landscape-cell tokens`). Required: nobody commands without signing in.
    sign_in_tokens: str | None = None
    # TLS to the device servers (credentials.py; None: plaintext), and the supervisor's own
    # token, viewer-level, for the feeds every browser shares. A token given means the devices
    # use tokens: each person's calls then carry that person's own token. None: the devices
    # have none (loopback), and the supervisor's role check is the only one.
    tls: ClientTLS | None = None
    token: str | None = None
    # Other front ends' origins allowed besides the supervisor's own (origins.py).
    allowed_origins: tuple[str, ...] = ()
    sign_in_idle_s: float = DEFAULT_IDLE_S
    sign_in_max_age_s: float = DEFAULT_MAX_AGE_S
    max_unauthenticated: int = MAX_UNAUTHENTICATED   # connections held with no sign-in shown

    def __post_init__(self):
        if not self.sign_in_tokens:
            raise ValueError("the supervisor needs a folder of sign-in tokens "
                             "(--sign-in-tokens DIR; `landscape-cell tokens` makes one)")
        object.__setattr__(self, "allowed_origins",
                           tuple(normalize(origin) for origin in self.allowed_origins))
        if self.sign_in_idle_s <= 0 or self.sign_in_max_age_s <= 0:
            raise ValueError("the sign-in idle and maximum times are positive seconds")
        if self.max_unauthenticated < 1:
            raise ValueError("max_unauthenticated is at least 1")
        names = [d.name for d in self.devices]
        if not names:
            raise ValueError("at least one --device NAME=HOST:PORT is needed")
        if len(set(names)) != len(names):
            raise ValueError(f"device names must differ: {names}")
        if not 0 < self.display_rate_hz <= 250:
            raise ValueError("the display rate is in (0, 250] samples per second")

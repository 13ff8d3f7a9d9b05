"""Device-server settings, from the command line or a test."""
from __future__ import annotations

from dataclasses import dataclass

from landscape.server.api.stream_caps import Cap

CLOCKS = ("realtime", "fast", "lockstep")   # the controller's: controller_link.py
PROCESS_CLOCKS = ("realtime", "fast")       # those that run the cycle in a process of its own
DEFAULT_ADDRESS = "127.0.0.1"   # loopback unless the operator exposes the server on purpose
DEFAULT_PORT = 50051
MAX_COLLISION_MARGIN = 0.1      # m: a wider safety margin would keep the arm from the table


@dataclass(frozen=True)
class SecurityConfig:
    """Who may connect and what they may do (auth.py, tls.py, security.py)."""

    # PEM files: the server's certificate and key (both, or neither: plaintext), and the CA
    # that signs clients' certificates, required when mtls is on.
    tls_cert: str | None = None
    tls_key: str | None = None
    tls_ca: str | None = None
    mtls: bool = False
    # Folder of <role>.tokens files (auth.py); None: no tokens, every caller may do anything.
    tokens: str | None = None
    # The audit log (audit.py); None: none. Rotated at audit_max_bytes, audit_backups kept.
    audit_log: str | None = None
    audit_max_bytes: int = 10 * 1024 * 1024
    audit_backups: int = 5
    # Calls per second one client (its token's identity; else its IP address and client name)
    # may make on average, and at once; stops are never limited. None: no limit.
    rate_limit: float | None = None
    rate_burst: int = 200
    # Calls per second of the clients so named (a token's name; with tokens off, the name a
    # front end gives in `landscape-client`), bursts of twice that: the front ends' budgets.
    rate_limits: dict[str, float] | None = None
    # Listen on a non-loopback address without TLS and tokens all the same.
    insecure: bool = False

    @property
    def tls_enabled(self) -> bool:
        return self.tls_cert is not None


@dataclass(frozen=True)
class ServerConfig:
    address: str = DEFAULT_ADDRESS
    port: int = DEFAULT_PORT          # 0 picks a free port
    # Open streams a client (its token's identity, else its IP address), and the server, may
    # hold, per kind ("session", "watch"); None: limits.DEFAULT_CAPS.
    stream_caps: dict[str, Cap] | None = None
    # Largest request accepted; larger ones fail with RESOURCE_EXHAUSTED. Paths stream in
    # chunks, so no single message needs to be big.
    max_message_bytes: int = 4 * 1024 * 1024
    # The cell file (None: the default cell) and the controller's clock: "realtime" (its own
    # cycle process, a cycle every 4 ms), "fast" (the same process running cycles back to
    # back: long programs in a fraction of their time) or "lockstep" (a thread here, as fast as
    # it goes, which tests can hold and step; for tests).
    cell: str | None = None
    clock: str = "realtime"
    # Where the arm's base stands in a cell shared with other arms (x, y, z m; roll, pitch,
    # yaw rad) and that cell's name (GetCellDescription's world_in_cell); None: nowhere.
    placement: tuple[float, ...] | None = None
    shared_cell: str = ""
    # The controller backend (robot/backends.py: "pybullet", "kinematic") if not the cell
    # file's (tests run the device's contract on both).
    backend: str | None = None
    # Lock-step only: at most this many simulated seconds per wall second (None: flat out).
    lockstep_pace: float | None = None
    # SQLite file of the named paths and the settings (None: in memory only, lost at exit).
    paths_file: str | None = None
    # Start from the default settings instead of the stored ones (and store the defaults).
    reset_settings: bool = False
    # s an accepted setting may wait to be written to paths_file (a server killed outright
    # within it restarts without it); 0: written before the reply; None: the default
    # (stored_settings.WRITE_BEHIND).
    settings_delay: float | None = None
    # m: no planned motion may bring two bodies of the cell closer than this (collision/);
    # (0, MAX_COLLISION_MARGIN].
    collision_margin: float = 0.005
    # Initialise the controller at start-up (False leaves the device Idle, for tests).
    start_device: bool = True
    security: SecurityConfig = SecurityConfig()
    # /metrics for Prometheus (server/metrics.py) on this port (0: any free one; None: off),
    # on loopback unless metrics_address says otherwise (then with the server's TLS, or
    # security.insecure).
    metrics_port: int | None = None
    metrics_address: str = DEFAULT_ADDRESS

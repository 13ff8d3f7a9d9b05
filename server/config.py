"""Device-server settings, from the command line or a test."""
from __future__ import annotations

from dataclasses import dataclass

from landscape.server.limits import Cap

DEFAULT_ADDRESS = "127.0.0.1"   # loopback unless the operator exposes the server on purpose
DEFAULT_PORT = 50051


@dataclass(frozen=True)
class ServerConfig:
    address: str = DEFAULT_ADDRESS
    port: int = DEFAULT_PORT          # 0 picks a free port
    # Open streams a client, and the server, may hold, per kind ("session", "watch"); None:
    # limits.DEFAULT_CAPS.
    stream_caps: dict[str, Cap] | None = None
    # Largest request accepted; larger ones fail with RESOURCE_EXHAUSTED. Paths stream in
    # chunks, so no single message needs to be big.
    max_message_bytes: int = 4 * 1024 * 1024
    # The cell file (None: the default cell) and the controller's clock: "realtime" (its own
    # cycle process) or "lockstep" (a thread here, as fast as it goes; for tests).
    cell: str | None = None
    clock: str = "realtime"
    # Lock-step only: at most this many simulated seconds per wall second (None: flat out).
    lockstep_pace: float | None = None
    # SQLite file of the named paths and the settings (None: in memory only, lost at exit).
    paths_file: str | None = None
    # Start from the default settings instead of the stored ones (and store the defaults).
    reset_settings: bool = False
    # m: no planned motion may bring two bodies of the cell closer than this (collision/).
    collision_margin: float = 0.005
    # Initialise the controller at start-up (False leaves the device Idle, for tests).
    start_device: bool = True

"""The parsed cell configuration (config.py reads the file): frozen dataclasses of its device
servers, the CRCL gateway, the web supervisor, the bridges (Prometheus, Foxglove, OPC UA),
security and the launcher's policy."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from landscape.server.config import ServerConfig

# The cell's own front ends, sized for their traffic (calls per second; the names they send).
FRONT_END_RATES = {"crcl-gateway": 5000.0, "supervisor": 5000.0}


@dataclass(frozen=True)
class DeviceSpec:
    """One device server. address/port: where it listens (port 0: any free one); host: how
    the others reach it (default: the address, or 127.0.0.1 for a wildcard). world: its sim
    cell file (None: the built-in default). data: its folder, also its working directory:
    paths and settings (paths.sqlite3), recordings (the world's [recorder] path, relative
    to it) and the audit log. collision_margin (m): its --collision-margin."""

    name: str
    address: str
    port: int
    host: str
    world: Path | None
    data: Path
    clock: str = "realtime"
    reset_settings: bool = False
    collision_margin: float = ServerConfig.collision_margin   # m (server/config.py)
    # Where its arm's base stands in this cell, shared with the others: x, y, z (m), roll,
    # pitch, yaw (rad); None: not given (displays set the arms side by side).
    placement: tuple[float, ...] | None = None
    cell: str = ""   # the shared cell's name

    @property
    def target(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{host}:{self.port}"


@dataclass(frozen=True)
class GatewaySpec:
    """The CRCL gateway in front of `device`. token: the token file it presents. The
    workstation (landscape.gateway.workstation): CRCL's frame in the robot's base frame (x, y,
    z in m, roll, pitch, yaw in rad), the end effector the arm holds from InitCanon on ("":
    as it is; "none": no tool) and the units a CRCL program starts in."""

    enabled: bool = True
    device: str = ""
    address: str = "127.0.0.1"
    port: int = 64444
    grpc_port: int | None = None
    token: Path | None = None
    workstation_frame: tuple[float, ...] = (0.0,) * 6
    end_effector: str = ""
    length_units: str = "meter"
    angle_units: str = "radian"


@dataclass(frozen=True)
class SupervisorSpec:
    """The web supervisor (landscape.supervisor) showing `devices`. sign_in_tokens: the
    folder of role tokens people sign in with (made on first run when absent); token: its
    own, viewer-level, for the feeds (with tokens on); allowed_origins: other front ends'
    origins it accepts; sign_in_idle / sign_in_max_age: s a sign-in lasts idle / at most."""

    enabled: bool = True
    address: str = "127.0.0.1"
    port: int = 8080
    devices: tuple[str, ...] = ()
    token: Path | None = None
    sign_in_tokens: Path = Path("var/tokens")
    allowed_origins: tuple[str, ...] = ()
    sign_in_idle: float = 1800.0
    sign_in_max_age: float = 43200.0


@dataclass(frozen=True)
class SecuritySpec:
    """TLS (cert/key of the device servers; ca: the CA clients trust, and with mtls the one
    that signs clients), the cell's own clients' pair under mtls, the token folder, the audit
    log's rotation (and folder: None puts each device's in its data folder), the rate limit
    per client and the budgets of the clients so named (rate_limits: a token's name, or with
    tokens off the name a front end sends; calls per second), and --insecure."""

    tls: bool = False
    cert: Path | None = None
    key: Path | None = None
    ca: Path | None = None
    mtls: bool = False
    client_cert: Path | None = None
    client_key: Path | None = None
    tokens: Path | None = None
    audit_dir: Path | None = None
    audit_max_bytes: int = 10 * 1024 * 1024
    audit_backups: int = 5
    rate_limit: float = 1000.0
    rate_burst: int = 2000
    rate_limits: dict[str, float] = field(default_factory=lambda: dict(FRONT_END_RATES))
    insecure: bool = False

    def audit_log(self, device: DeviceSpec) -> Path:
        return (self.audit_dir / f"{device.name}.audit.log" if self.audit_dir
                else device.data / "audit.log")


@dataclass(frozen=True)
class MetricsSpec:
    """/metrics of every service (Prometheus): the devices on port, port + 1, ..., then the
    gateway and the supervisor (port 0: each any free one), on `address`."""

    enabled: bool = True
    address: str = "127.0.0.1"
    port: int = 9464

    def port_of(self, index: int) -> int:
        """The index-th service's port: devices first, then the gateway, the supervisor."""
        return 0 if self.port == 0 else self.port + index


@dataclass(frozen=True)
class FoxgloveSpec:
    """The Foxglove bridge (WebSocket) showing `devices` at `rate_hz` samples a second."""

    enabled: bool = False
    address: str = "127.0.0.1"
    port: int = 8765
    rate_hz: float = 30.0
    devices: tuple[str, ...] = ()


@dataclass(frozen=True)
class OpcUaSpec:
    """The OPC UA server exposing `devices`; off loopback it needs its certificate and key,
    and users (a file of `<name> <SHA-256 of the password>`) or trusted client certificates."""

    enabled: bool = False
    address: str = "127.0.0.1"
    port: int = 4840
    devices: tuple[str, ...] = ()
    users: Path | None = None
    certificate: Path | None = None
    key: Path | None = None
    trusted_certs: tuple[Path, ...] = ()


@dataclass(frozen=True)
class LauncherSpec:
    """What the launcher does when a service dies ("no": stop the cell; "on-failure": start
    it again, at most max_restarts times), and how long a service may take to start and stop
    (s)."""

    restart: str = "no"
    max_restarts: int = 3
    start_timeout: float = 120.0
    stop_timeout: float = 20.0


@dataclass(frozen=True)
class CellConfig:
    name: str
    devices: tuple[DeviceSpec, ...]
    gateway: GatewaySpec
    supervisor: SupervisorSpec
    security: SecuritySpec = field(default_factory=SecuritySpec)
    launcher: LauncherSpec = field(default_factory=LauncherSpec)
    metrics: MetricsSpec = field(default_factory=MetricsSpec)
    foxglove: FoxgloveSpec = field(default_factory=FoxgloveSpec)
    opcua: OpcUaSpec = field(default_factory=OpcUaSpec)
    source: str = "<string>"

    def device(self, name: str) -> DeviceSpec:
        return next(d for d in self.devices if d.name == name)

"""The cell configuration: one TOML file for the deployment of a cell (its device servers,
the CRCL gateway, the web supervisor, security and the launcher's policy).

Each device's *world* (arm, fixtures, I/O) is a sim cell file (sim/cells/default.toml) named by
`world`; this file says where the device runs and how it is reached. `cells/local.toml` beside
this module is the reference, every key commented, and the embedded default of `make run`.

Relative paths are relative to the file's folder (for the embedded default: the current
folder). Unknown keys are errors, and every error names the file and the key, as in the world
files (sim/cell.py, whose reader this module uses).
"""
from __future__ import annotations

import ipaddress
import re
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

from landscape.server.config import CLOCKS, MAX_COLLISION_MARGIN, ServerConfig
from landscape.sim.cell import CellError, _Table, load_cell

DEFAULT_FILE = "cells/local.toml"
# The cell's own front ends, sized for their traffic (calls per second; the names they send).
FRONT_END_RATES = {"crcl-gateway": 5000.0, "supervisor": 5000.0}
_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_-]{0,31}")
RESTART = ("no", "on-failure")


class CellConfigError(ValueError):
    """A cell configuration that cannot be used; the message names the file and the key."""


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

    @property
    def target(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{host}:{self.port}"


@dataclass(frozen=True)
class GatewaySpec:
    """The CRCL gateway in front of `device`. token: the token file it presents."""

    enabled: bool = True
    device: str = ""
    address: str = "127.0.0.1"
    port: int = 64444
    grpc_port: int | None = None
    token: Path | None = None


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
    source: str = "<string>"

    def device(self, name: str) -> DeviceSpec:
        return next(d for d in self.devices if d.name == name)


# ---- reading ----------------------------------------------------------------------------------

class _Reader:
    """Typed getters on the world files' reader, plus paths and ports."""

    def __init__(self, table: _Table, base: Path):
        self.t, self.base = table, base

    def sub(self, key: str) -> "_Reader":
        return _Reader(self.t.table(key), self.base)

    def path(self, key: str, default=None, *, exists=False, folder=False) -> Path | None:
        value = self.t.raw(key, "")
        if value == "":
            return default
        if not isinstance(value, str):
            self.t.fail(key, f"must be a path (a string), got {value!r}")
        path = Path(value).expanduser()
        path = path if path.is_absolute() else self.base / path
        if exists and not path.exists():
            self.t.fail(key, f"{path} does not exist")
        if folder and path.exists() and not path.is_dir():
            self.t.fail(key, f"{path} is not a folder")
        return path

    def port(self, key: str, default) -> int:
        return self.t.integer(key, default, low=0, high=65535)

    def name(self, key: str, default=None) -> str:
        value = self.t.string(key) if default is None else self.t.string(key, default)
        if not _NAME.fullmatch(value):
            self.t.fail(key, f"a name is a letter then letters, digits, - or _ (at most 32); "
                             f"got {value!r}")
        return value

    def address(self, key: str, default: str) -> str:
        value = self.t.string(key, default)
        if value.startswith("["):
            value = value.strip("[]")
        return value


def _is_wildcard(address: str) -> bool:
    try:
        return ipaddress.ip_address(address).is_unspecified
    except ValueError:
        return False


def builtin_worlds() -> list[str]:
    cells = resources.files("landscape.sim").joinpath("cells")
    return sorted(item.name[:-5] for item in cells.iterdir() if item.name.endswith(".toml"))


def _world(r: _Reader) -> Path | None:
    """A world file's path, or the name of one shipped with the simulator (sim/cells/)."""
    value = r.t.raw("world", "")
    if isinstance(value, str) and value and "/" not in value and not value.endswith(".toml"):
        if value not in builtin_worlds():
            r.t.fail("world", f"no built-in world is named {value!r} (built-in: "
                              f"{', '.join(builtin_worlds())}; or give a file's path)")
        with resources.as_file(resources.files("landscape.sim").joinpath(
                f"cells/{value}.toml")) as path:
            return Path(path)
    return r.path("world", exists=True)


def _device(r: _Reader, index: int) -> DeviceSpec:
    name = r.name("name", f"arm{index + 1}")
    address = r.address("address", "127.0.0.1")
    host = r.t.string("host", "127.0.0.1" if _is_wildcard(address) else address)
    world = _world(r)
    if world is not None:
        try:
            load_cell(world)
        except CellError as error:
            r.t.fail("world", f"not a usable world file: {error}")
    spec = DeviceSpec(name=name, address=address, port=r.port("port", 50051 + index), host=host,
                      world=world, data=r.path("data", r.base / "var" / name, folder=True),
                      clock=r.t.string("clock", "realtime", CLOCKS),
                      reset_settings=r.t.boolean("reset_settings", False),
                      collision_margin=r.t.number("collision_margin",
                                                  ServerConfig.collision_margin, positive=True,
                                                  high=MAX_COLLISION_MARGIN))
    r.t.done()
    return spec


def _security(r: _Reader) -> SecuritySpec:
    d = SecuritySpec()
    tls = r.t.boolean("tls", d.tls)
    mtls = r.t.boolean("mtls", d.mtls)
    if mtls and not tls:
        r.t.fail("mtls", "mutual TLS needs tls = true")
    spec = SecuritySpec(
        tls=tls, mtls=mtls,
        cert=r.path("cert", exists=tls), key=r.path("key", exists=tls),
        ca=r.path("ca", exists=tls), client_cert=r.path("client_cert", exists=mtls),
        client_key=r.path("client_key", exists=mtls),
        tokens=r.path("tokens", exists=True, folder=True),
        audit_dir=r.path("audit_dir", folder=True),
        audit_max_bytes=r.t.integer("audit_max_bytes", d.audit_max_bytes, low=1024),
        audit_backups=r.t.integer("audit_backups", d.audit_backups, low=0, high=1000),
        rate_limit=r.t.number("rate_limit", d.rate_limit, low=0.0),
        rate_burst=r.t.integer("rate_burst", d.rate_burst, low=1),
        rate_limits=_rate_limits(r.t.table("rate_limits"), d.rate_limits),
        insecure=r.t.boolean("insecure", d.insecure))
    for key, needed in (("cert", tls), ("key", tls), ("ca", tls), ("client_cert", mtls),
                        ("client_key", mtls)):
        if needed and getattr(spec, key) is None:
            r.t.fail(key, "is required with tls = true" if key in ("cert", "key", "ca")
                     else "is required with mtls = true (the certificate the cell's own "
                          "clients, gateway and supervisor, show)")
    if spec.tokens is not None:
        from landscape.server.auth import TokenFileError, TokenStore
        try:
            TokenStore.load(spec.tokens)
        except TokenFileError as error:
            r.t.fail("tokens", str(error))
    r.t.done()
    return spec


def _rate_limits(table, defaults: dict[str, float]) -> dict[str, float]:
    """[security.rate_limits]: name = calls per second, over the defaults."""
    sized = dict(defaults)
    for name in list(table.data):
        if not name or "=" in name or name != name.strip():
            table.fail(name, "a name is a token's name or a client's (no '=', no spaces at "
                             "its ends)")
        sized[name] = table.number(name, positive=True)
    table.done()
    return sized


def _client_token(r: _Reader, security: SecuritySpec, role: str = "operator") -> Path | None:
    default = security.tokens / f"{role}.tokens" if security.tokens else None
    token = r.path("token", default, exists=True)
    if security.tokens is not None and token is None:
        r.t.fail("token", "a token file is needed: the device servers want tokens")
    return token


def _gateway(r: _Reader, devices, security) -> GatewaySpec:
    d = GatewaySpec()
    names = [device.name for device in devices]
    device = r.t.string("device", names[0])
    if device not in names:
        r.t.fail("device", f"no device is named {device!r} (devices: {', '.join(names)})")
    grpc_port = r.t.raw("grpc_port", None)
    spec = GatewaySpec(enabled=r.t.boolean("enabled", d.enabled), device=device,
                       address=r.address("address", d.address), port=r.port("port", d.port),
                       grpc_port=None if grpc_port is None else r.port("grpc_port", None),
                       token=_client_token(r, security))
    r.t.done()
    return spec


def _supervisor(r: _Reader, devices, security) -> SupervisorSpec:
    d = SupervisorSpec()
    names = [device.name for device in devices]
    shown = r.t.raw("devices", names)
    if not isinstance(shown, list) or not shown or not all(isinstance(n, str) for n in shown):
        r.t.fail("devices", f"must be a non-empty list of device names, got {shown!r}")
    for name in shown:
        if name not in names:
            r.t.fail("devices", f"no device is named {name!r} (devices: {', '.join(names)})")
    origins = r.t.raw("allowed_origins", [])
    if not isinstance(origins, list) or not all(isinstance(o, str) for o in origins):
        r.t.fail("allowed_origins", f"must be a list of origins, got {origins!r}")
    from landscape.supervisor.origins import normalize
    try:
        origins = tuple(normalize(origin) for origin in origins)
    except ValueError as error:
        r.t.fail("allowed_origins", str(error))
    spec = SupervisorSpec(enabled=r.t.boolean("enabled", d.enabled),
                          address=r.address("address", d.address), port=r.port("port", d.port),
                          devices=tuple(dict.fromkeys(shown)),
                          token=_client_token(r, security, "viewer"),
                          sign_in_tokens=r.path("sign_in_tokens",
                                                security.tokens or r.base / "var" / "tokens",
                                                folder=True),
                          allowed_origins=origins,
                          sign_in_idle=r.t.number("sign_in_idle", d.sign_in_idle, positive=True),
                          sign_in_max_age=r.t.number("sign_in_max_age", d.sign_in_max_age,
                                                     positive=True))
    r.t.done()
    return spec


def _launcher(r: _Reader) -> LauncherSpec:
    d = LauncherSpec()
    spec = LauncherSpec(restart=r.t.string("restart", d.restart, RESTART),
                        max_restarts=r.t.integer("max_restarts", d.max_restarts, low=0),
                        start_timeout=r.t.number("start_timeout", d.start_timeout, positive=True),
                        stop_timeout=r.t.number("stop_timeout", d.stop_timeout, positive=True))
    r.t.done()
    return spec


def _check_exposure(top: _Table, devices, security: SecuritySpec) -> None:
    """The device servers' rule (server/tls.py), said here first, naming the key."""
    from landscape.server.tls import is_loopback
    for index, device in enumerate(devices):
        if is_loopback(device.address) or security.insecure:
            continue
        if not (security.tls and security.tokens):
            top.fail(f"devices[{index}].address",
                     f"{device.name} would listen on {device.address} without TLS and tokens: "
                     f"set security.tls, security.tokens (landscape-cell certs / tokens), or "
                     f"security.insecure = true on a network of your own")


def _check_ports(top: _Table, config: CellConfig) -> None:
    listeners = [(f"devices[{i}].port", d.address, d.port) for i, d in enumerate(config.devices)]
    if config.gateway.enabled:
        listeners.append(("gateway.port", config.gateway.address, config.gateway.port))
        if config.gateway.grpc_port is not None:
            listeners.append(("gateway.grpc_port", config.gateway.address,
                              config.gateway.grpc_port))
    if config.supervisor.enabled:
        listeners.append(("supervisor.port", config.supervisor.address, config.supervisor.port))
    seen: list[tuple[str, str, int]] = []
    for key, address, port in listeners:
        if port == 0:
            continue
        for other_key, other_address, other_port in seen:
            if port == other_port and (address == other_address or _is_wildcard(address)
                                       or _is_wildcard(other_address)):
                top.fail(key, f"port {port} on {address} is taken by {other_key}")
        seen.append((key, address, port))


def parse_config(text: str, source: str = "<string>", base: Path | None = None) -> CellConfig:
    """A cell configuration from TOML text; CellConfigError names `source` and the key.
    Relative paths are taken from `base` (default: the current folder)."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise CellConfigError(f"{source}: not valid TOML: {error}") from None
    try:
        return _parse(data, source, base or Path.cwd())
    except CellError as error:
        raise CellConfigError(str(error)) from None


def _parse(data, source: str, base: Path) -> CellConfig:
    top = _Table(data, "", source)
    r = _Reader(top, base)
    security = _security(r.sub("security"))
    tables = r.t.tables("devices") or [_Table({}, "devices[0]", source)]
    devices = tuple(_device(_Reader(t, base), i) for i, t in enumerate(tables))
    names = [d.name for d in devices]
    for name in names:
        if names.count(name) > 1:
            top.fail("devices", f"two devices are named {name!r}")
    config = CellConfig(name=r.name("name", "cell"), devices=devices,
                        gateway=_gateway(r.sub("gateway"), devices, security),
                        supervisor=_supervisor(r.sub("supervisor"), devices, security),
                        security=security, launcher=_launcher(r.sub("launcher")), source=source)
    _check_exposure(top, devices, security)
    _check_ports(top, config)
    top.done()
    return config


def load_config(path: str | Path | None = None) -> CellConfig:
    """The configuration in `path`; None: the embedded default (cells/local.toml), its
    relative paths taken from the current folder."""
    if path is None:
        text = resources.files("landscape.cell").joinpath(DEFAULT_FILE).read_text("utf-8")
        return parse_config(text, f"(built-in) {DEFAULT_FILE}", Path.cwd())
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as error:
        raise CellConfigError(f"{path}: cannot read the cell configuration: "
                              f"{error.strerror}") from None
    return parse_config(text, str(path), path.parent.resolve())

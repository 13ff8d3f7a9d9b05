"""The cell configuration: one TOML file for the deployment of a cell (its device servers,
the CRCL gateway, the web supervisor, the bridges (bridge_tables.py), security and the
launcher's policy).

Each device's *world* (arm, fixtures, I/O) is a cell file (robot/cells/default.toml) named by
`world`; this file says where the device runs and how it is reached. `cells/local.toml` beside
this module is the reference, every key commented, and the embedded default of `make run`.

Relative paths are relative to the file's folder (for the embedded default: the current
folder). The file is read into typed tables (pydantic, robot/toml_tables.py, as the world files
are) and made into the frozen dataclasses of config_model.py; unknown keys are errors, and every
error names the file, the key and what was expected.
"""
from __future__ import annotations

import ipaddress
import math
from importlib import resources
from pathlib import Path
from typing import Annotated

from pydantic import PlainValidator, PrivateAttr, ValidationInfo, model_validator

from landscape.cell.config_model import (  # noqa: F401  (the parsed configuration, named here too)
    FRONT_END_RATES, CellConfig, DeviceSpec, FoxgloveSpec, GatewaySpec, LauncherSpec,
    MetricsSpec, OpcUaSpec, SecuritySpec, SupervisorSpec)
from landscape.server.config import CLOCKS, MAX_COLLISION_MARGIN, ServerConfig
from landscape.gateway.units import ANGLE as CRCL_ANGLE, LENGTH as CRCL_LENGTH
from landscape.gateway.workstation import BARE
from landscape.robot.cell import CellError, load_cell
from landscape.cell.bridge_tables import FoxgloveTable, MetricsTable, OpcUaTable, check_bridges
from landscape.cell.config_types import (Address, FilePath, Name, Port, Positive, Text, exists,
                                         path_value, shown_devices)
from landscape.robot.toml_tables import (Table, flag, integer, number, problem, read_toml,
                                         string, vector)

DEFAULT_FILE = "cells/local.toml"
RESTART = ("no", "on-failure")


class CellConfigError(ValueError):
    """A cell configuration that cannot be used; the message names the file and the key."""


# ---- the file's tables ------------------------------------------------------------------------

def _world(value, info: ValidationInfo):
    """A world file's path, or the name of one shipped with the package (robot/cells/)."""
    if isinstance(value, str) and value and "/" not in value and not value.endswith(".toml"):
        if value not in builtin_worlds():
            raise problem(f"no built-in world is named {value!r} (built-in: "
                          f"{', '.join(builtin_worlds())}; or give a file's path)")
        with resources.as_file(resources.files("landscape.robot").joinpath(
                f"cells/{value}.toml")) as path:
            return Path(path)
    path = path_value(value, info)
    if path is not None:
        exists(path)
        try:
            load_cell(path)
        except CellError as error:
            raise problem(f"not a usable world file: {error}") from None
    return path


def _origins(value):
    """Other front ends' origins, each as the supervisor compares them (normalised)."""
    if not isinstance(value, list) or not all(isinstance(o, str) for o in value):
        raise problem(f"expected a list of origins, got {value!r}")
    from landscape.supervisor.origins import normalize
    try:
        return tuple(normalize(origin) for origin in value)
    except ValueError as error:
        raise problem(str(error)) from None


class DeviceTable(Table):
    name: Name | None = None          # default: arm<its place, from 1>
    address: Address = "127.0.0.1"
    host: string() | None = None      # default: the address (127.0.0.1 for a wildcard)
    port: Port | None = None          # default: 50051 + its place
    world: Annotated[Path | None, PlainValidator(_world)] = None
    data: FilePath = None             # default: var/<name>
    clock: string(CLOCKS) = "realtime"
    reset_settings: flag = False
    collision_margin: number(above=0.0, high=MAX_COLLISION_MARGIN) = ServerConfig.collision_margin
    # Its arm's base in the cell's frame (m, deg), shared with the other arms; either key
    # places it (the other is zeros).
    placement_xyz: vector(3) | None = None
    placement_rpy_deg: vector(3) | None = None

    def spec(self, index: int, base: Path, cell: str = "") -> DeviceSpec:
        name = self.name or f"arm{index + 1}"
        placed = self.placement_xyz is not None or self.placement_rpy_deg is not None
        return DeviceSpec(
            name=name, address=self.address, port=50051 + index if self.port is None else self.port,
            host=self.host or ("127.0.0.1" if _is_wildcard(self.address) else self.address),
            world=self.world, data=self.data or base / "var" / name, clock=self.clock,
            reset_settings=self.reset_settings, collision_margin=self.collision_margin,
            placement=(*(self.placement_xyz or (0.0,) * 3),
                       *map(math.radians, self.placement_rpy_deg or (0.0,) * 3)) if placed else None,
            cell=cell)


class SecurityTable(Table):
    tls: flag = False
    cert: FilePath = None
    key: FilePath = None
    ca: FilePath = None
    mtls: flag = False
    client_cert: FilePath = None
    client_key: FilePath = None
    tokens: FilePath = None
    audit_dir: FilePath = None
    audit_max_bytes: integer(low=1024) = SecuritySpec.audit_max_bytes
    audit_backups: integer(0, 1000) = SecuritySpec.audit_backups
    rate_limit: number(low=0.0) = SecuritySpec.rate_limit
    rate_burst: integer(low=1) = SecuritySpec.rate_burst
    rate_limits: dict = {}            # name = calls per second, over FRONT_END_RATES
    insecure: flag = False

    @model_validator(mode="after")
    def _consistent(self):
        if self.mtls and not self.tls:
            raise problem("mutual TLS needs tls = true", "mtls")
        for key, needed in (("cert", self.tls), ("key", self.tls), ("ca", self.tls),
                            ("client_cert", self.mtls), ("client_key", self.mtls)):
            if needed:
                exists(getattr(self, key), key)
        exists(self.tokens, "tokens", folder=True)
        if self.audit_dir is not None and self.audit_dir.exists():
            exists(self.audit_dir, "audit_dir", folder=True)
        for key, needed in (("cert", self.tls), ("key", self.tls), ("ca", self.tls),
                            ("client_cert", self.mtls), ("client_key", self.mtls)):
            if needed and getattr(self, key) is None:
                raise problem("is required with tls = true" if key in ("cert", "key", "ca")
                              else "is required with mtls = true (the certificate the cell's "
                                   "own clients, gateway and supervisor, show)", key)
        for name, rate in self.rate_limits.items():
            if not name or "=" in name or name != name.strip():
                raise problem("a name is a token's name or a client's (no '=', no spaces at "
                              "its ends)", f"rate_limits.{name}")
            if isinstance(rate, bool) or not isinstance(rate, (int, float)) or not rate > 0:
                raise problem(f"expected a number above 0, got {rate!r}", f"rate_limits.{name}")
        if self.tokens is not None:
            from landscape.server.security.auth import TokenFileError, TokenStore
            try:
                TokenStore.load(self.tokens)
            except TokenFileError as error:
                raise problem(str(error), "tokens") from None
        return self

    def spec(self) -> SecuritySpec:
        fields = dict(self)
        fields["rate_limits"] = FRONT_END_RATES | {k: float(v) for k, v in self.rate_limits.items()}
        return SecuritySpec(**fields)


class GatewayTable(Table):
    enabled: flag = GatewaySpec.enabled
    device: string() | None = None    # default: the first device
    address: Address = GatewaySpec.address
    port: Port = GatewaySpec.port
    grpc_port: Port | None = None
    token: FilePath = None            # default, with tokens on: <security.tokens>/operator.tokens
    workstation_xyz: vector(3) = (0.0, 0.0, 0.0)        # CRCL's frame in the robot base, m
    workstation_rpy_deg: vector(3) = (0.0, 0.0, 0.0)
    end_effector: Text = GatewaySpec.end_effector      # "", "none" or a tool of the world
    length_units: string(tuple(CRCL_LENGTH)) = GatewaySpec.length_units
    angle_units: string(tuple(CRCL_ANGLE)) = GatewaySpec.angle_units


class SupervisorTable(Table):
    enabled: flag = SupervisorSpec.enabled
    address: Address = SupervisorSpec.address
    port: Port = SupervisorSpec.port
    devices: list | None = None       # default: every device
    token: FilePath = None            # default, with tokens on: <security.tokens>/viewer.tokens
    sign_in_tokens: FilePath = None   # default: security.tokens, else var/tokens
    allowed_origins: Annotated[tuple, PlainValidator(_origins)] = ()
    sign_in_idle: Positive = SupervisorSpec.sign_in_idle
    sign_in_max_age: Positive = SupervisorSpec.sign_in_max_age


class LauncherTable(Table):
    restart: string(RESTART) = LauncherSpec.restart
    max_restarts: integer(low=0) = LauncherSpec.max_restarts
    start_timeout: Positive = LauncherSpec.start_timeout
    stop_timeout: Positive = LauncherSpec.stop_timeout

    def spec(self) -> LauncherSpec:
        return LauncherSpec(**dict(self))


class ConfigFile(Table):
    """The whole file; `config` is the cell it configures, once checked."""

    name: Name = "cell"
    devices: list[DeviceTable] = []
    gateway: GatewayTable = GatewayTable()
    supervisor: SupervisorTable = SupervisorTable()
    security: SecurityTable = SecurityTable()
    launcher: LauncherTable = LauncherTable()
    metrics: MetricsTable = MetricsTable()
    foxglove: FoxgloveTable = FoxgloveTable()
    opcua: OpcUaTable = OpcUaTable()
    _config: CellConfig | None = PrivateAttr(None)

    @property
    def config(self) -> CellConfig:
        return self._config

    @model_validator(mode="after")
    def _a_cell(self, info: ValidationInfo):
        base, security = info.context["base"], self.security.spec()
        devices = tuple(d.spec(i, base, self.name)
                        for i, d in enumerate(self.devices or [DeviceTable()]))
        names = [d.name for d in devices]
        for i, device in enumerate(devices):
            if names.count(device.name) > 1:
                raise problem(f"two devices are named {device.name!r}", "devices")
            if device.data.exists() and not device.data.is_dir():
                raise problem(f"{device.data} is not a folder", f"devices[{i}].data")
        self._config = CellConfig(
            name=self.name, devices=devices, gateway=self._gateway(devices, security),
            supervisor=self._supervisor(names, security, base), security=security,
            launcher=self.launcher.spec(), metrics=self.metrics.spec(),
            foxglove=self.foxglove.spec(names), opcua=self.opcua.spec(names, base),
            source=info.context["source"])
        _check_exposure(self._config)
        _check_ports(self._config)
        return self

    def _gateway(self, devices: tuple[DeviceSpec, ...], security: SecuritySpec) -> GatewaySpec:
        g, names = self.gateway, [d.name for d in devices]
        device = g.device or names[0]
        if device not in names:
            raise problem(f"no device is named {device!r} (devices: {', '.join(names)})",
                          "gateway.device")
        _tool_of(g.end_effector, devices[names.index(device)])
        return GatewaySpec(g.enabled, device, g.address, g.port, g.grpc_port,
                           _client_token(g.token, security, "gateway.token", "operator"),
                           (*g.workstation_xyz, *map(math.radians, g.workstation_rpy_deg)),
                           g.end_effector, g.length_units, g.angle_units)

    def _supervisor(self, names: list[str], security: SecuritySpec,
                    base: Path) -> SupervisorSpec:
        s = self.supervisor
        shown = shown_devices(s.devices, names, "supervisor.devices")
        sign_in_tokens = s.sign_in_tokens or security.tokens or base / "var" / "tokens"
        if sign_in_tokens.exists() and not sign_in_tokens.is_dir():
            raise problem(f"{sign_in_tokens} is not a folder", "supervisor.sign_in_tokens")
        return SupervisorSpec(s.enabled, s.address, s.port, shown,
                              _client_token(s.token, security, "supervisor.token", "viewer"),
                              sign_in_tokens, s.allowed_origins, s.sign_in_idle,
                              s.sign_in_max_age)


def _tool_of(name: str, device: DeviceSpec) -> None:
    """The gateway's end effector is "", "none" or a tool of its device's world."""
    if name in ("", BARE):
        return
    tools = [tool.name for tool in load_cell(device.world).world.tools]
    if name not in tools:
        raise problem(f"{device.name}'s world has no tool named {name!r} (its tools: "
                      f"{', '.join(tools) or 'none'}; or \"none\" for the bare flange, \"\" "
                      f"for whatever is on it)", "gateway.end_effector")


def _client_token(token: Path | None, security: SecuritySpec, key: str,
                  role: str) -> Path | None:
    """The token file a front end presents: its own key, else the security folder's `role`."""
    exists(token, key)
    if token is None and security.tokens is not None:
        token = security.tokens / f"{role}.tokens"
    return token


def _check_exposure(config: CellConfig) -> None:
    """The device servers' rule (server/tls.py), said here first, naming the key, and the
    bridges' (bridge_tables.py)."""
    from landscape.server.security.tls import is_loopback
    security = config.security
    check_bridges(config)
    for index, device in enumerate(config.devices):
        if is_loopback(device.address) or security.insecure:
            continue
        if not (security.tls and security.tokens):
            raise problem(f"{device.name} would listen on {device.address} without TLS and "
                          f"tokens: set security.tls, security.tokens (landscape-cell certs / "
                          f"tokens), or security.insecure = true on a network of your own",
                          f"devices[{index}].address")


def _check_ports(config: CellConfig) -> None:
    listeners = [(f"devices[{i}].port", d.address, d.port) for i, d in enumerate(config.devices)]
    if config.gateway.enabled:
        listeners.append(("gateway.port", config.gateway.address, config.gateway.port))
        if config.gateway.grpc_port is not None:
            listeners.append(("gateway.grpc_port", config.gateway.address,
                              config.gateway.grpc_port))
    if config.supervisor.enabled:
        listeners.append(("supervisor.port", config.supervisor.address, config.supervisor.port))
    for key, bridge in (("foxglove.port", config.foxglove), ("opcua.port", config.opcua)):
        if bridge.enabled:
            listeners.append((key, bridge.address, bridge.port))
    if config.metrics.enabled:
        count = len(config.devices) + 2
        listeners += [(f"metrics.port (+{i})", config.metrics.address,
                       config.metrics.port_of(i)) for i in range(count)]
    seen: list[tuple[str, str, int]] = []
    for key, address, port in listeners:
        if port == 0:
            continue
        for other_key, other_address, other_port in seen:
            if port == other_port and (address == other_address or _is_wildcard(address)
                                       or _is_wildcard(other_address)):
                raise problem(f"port {port} on {address} is taken by {other_key}", key)
        seen.append((key, address, port))


def _is_wildcard(address: str) -> bool:
    try:
        return ipaddress.ip_address(address).is_unspecified
    except ValueError:
        return False


def builtin_worlds() -> list[str]:
    cells = resources.files("landscape.robot").joinpath("cells")
    return sorted(item.name[:-5] for item in cells.iterdir() if item.name.endswith(".toml"))


# ---- entry points -----------------------------------------------------------------------------

def parse_config(text: str, source: str = "<string>", base: Path | None = None) -> CellConfig:
    """A cell configuration from TOML text; CellConfigError names `source` and the key.
    Relative paths are taken from `base` (default: the current folder)."""
    return read_toml(text, ConfigFile, source, CellConfigError,
                     {"base": base or Path.cwd(), "source": source}).config


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

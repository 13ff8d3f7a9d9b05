"""The command line of each service of a cell, from its configuration.

A `ServiceSpec` is what the launcher starts: the argv (this Python, `-m` the service's
module), the working directory, the line that says it listens, and what it is. Clients'
commands (gateway, supervisor) are built once the device servers listen, from the targets
they really have (a port 0 becomes a real one).
"""
from __future__ import annotations

import importlib.util
import math
import re
import sys
from dataclasses import dataclass
from pathlib import Path

from landscape.cell.config import CellConfig, DeviceSpec, MetricsSpec, SecuritySpec
from landscape.server.security.tls import is_loopback

# The line each program prints once it listens; group 1 is where.
READY = {
    "device server": re.compile(r"landscape device server listening on (\S+)"),
    "CRCL gateway": re.compile(r"CRCL gateway listening on (\S+)"),
    "web supervisor": re.compile(r"web supervisor on (\S+)"),
    "Foxglove bridge": re.compile(r"Foxglove bridge on (\S+)"),
    "OPC UA server": re.compile(r"OPC UA server on (\S+)"),
}
SUPERVISOR_MODULE = "landscape.supervisor"


@dataclass
class ServiceSpec:
    name: str                 # "arm1", "gateway", "supervisor"
    kind: str                 # a key of READY
    argv: list[str]
    cwd: Path
    note: str = ""            # said beside where it listens

    @property
    def ready(self) -> re.Pattern:
        return READY[self.kind]


def _python(module: str) -> list[str]:
    return [sys.executable, "-m", module]


def device_service(device: DeviceSpec, security: SecuritySpec, port: int | None = None,
                   metrics_port: int | None = None,
                   metrics_address: str = "127.0.0.1") -> ServiceSpec:
    """The device server; `port` overrides the configured one (a restart keeps the port it
    had); /metrics on `metrics_port` if given."""
    argv = [*_python("landscape.server"), "--address", device.address,
            "--port", str(device.port if port is None else port),
            "--paths", str(device.data / "paths.sqlite3"), "--clock", device.clock,
            "--collision-margin", f"{device.collision_margin:g}",
            "--audit-log", str(security.audit_log(device)),
            "--audit-max-bytes", str(security.audit_max_bytes),
            "--audit-backups", str(security.audit_backups),
            "--rate-limit", f"{security.rate_limit:g}", "--rate-burst", str(security.rate_burst)]
    for name, rate in security.rate_limits.items():
        argv += ["--rate-limit-for", f"{name}={rate:g}"]
    if device.world is not None:
        argv += ["--cell", str(device.world)]
    if device.reset_settings:
        argv.append("--reset-settings")
    if device.placement is not None:
        xyz, rpy = device.placement[:3], (math.degrees(a) for a in device.placement[3:])
        # One word with "=": a value starting with "-" would read as an option.
        argv += ["--placement=" + ",".join(f"{v!r}" for v in (*xyz, *rpy)),
                 "--shared-cell=" + device.cell]
    if security.tls:
        argv += ["--tls-cert", str(security.cert), "--tls-key", str(security.key)]
        if security.mtls:
            argv += ["--mtls", "--tls-ca", str(security.ca)]
    if security.tokens is not None:
        argv += ["--tokens", str(security.tokens)]
    if security.insecure:
        argv.append("--insecure")
    if metrics_port is not None:
        argv += ["--metrics-port", str(metrics_port), "--metrics-address", metrics_address]
    return ServiceSpec(device.name, "device server", argv, device.data,
                       note=f"{_transport(security)}; data {device.data}")


def _transport(security: SecuritySpec) -> str:
    if not security.tls:
        return "plaintext" + (", tokens" if security.tokens else "")
    return ("mutual TLS" if security.mtls else "TLS") + (", tokens" if security.tokens else "")


def client_arguments(security: SecuritySpec, token: Path | None) -> list[str]:
    """The flags of landscape.client.credentials for the cell's own clients."""
    argv = []
    if security.tls:
        argv += ["--tls-ca", str(security.ca)]
        if security.mtls:
            argv += ["--tls-cert", str(security.client_cert), "--tls-key",
                     str(security.client_key)]
    if token is not None:
        argv += ["--token-file", str(token)]
    return argv


def gateway_service(config: CellConfig, targets: dict[str, str], workdir: Path) -> ServiceSpec:
    gateway = config.gateway
    argv = [*_python("landscape.gateway"), "--device", targets[gateway.device],
            "--host", gateway.address, "--port", str(gateway.port)]
    if gateway.grpc_port is not None:
        argv += ["--grpc-port", str(gateway.grpc_port)]
    argv += ["--workstation-frame", " ".join(repr(v) for v in gateway.workstation_frame),
             "--end-effector", gateway.end_effector, "--length-units", gateway.length_units,
             "--angle-units", gateway.angle_units]
    if config.security.insecure:      # the gateway keeps off the network otherwise, as they do
        argv.append("--insecure")
    argv += client_arguments(config.security, gateway.token)
    argv += _front_end_metrics(config, len(config.devices))
    return ServiceSpec("gateway", "CRCL gateway", argv, workdir, note=f"-> {gateway.device}")


def _front_end_metrics(config: CellConfig, index: int) -> list[str]:
    """/metrics of the gateway or the supervisor: off loopback only with insecure (neither
    has TLS of its own for it), else on loopback."""
    metrics = config.metrics
    if not metrics.enabled:
        return []
    address = (metrics.address if is_loopback(metrics.address) or config.security.insecure
               else "127.0.0.1")
    return ["--metrics-port", str(metrics.port_of(index)), "--metrics-host", address]


def metrics_of(metrics: MetricsSpec, index: int) -> dict:
    """device_service's metrics arguments for the index-th device ({} when off)."""
    if not metrics.enabled:
        return {}
    return {"metrics_port": metrics.port_of(index), "metrics_address": metrics.address}


def _bridge_devices(names, targets: dict[str, str]) -> list[str]:
    argv = []
    for name in names:
        argv += ["--device", f"{name}={targets[name]}"]
    return argv


def foxglove_service(config: CellConfig, targets: dict[str, str],
                     workdir: Path) -> ServiceSpec:
    """The Foxglove bridge, a watcher with the supervisor's (viewer) token."""
    fox = config.foxglove
    argv = [*_python("landscape.bridges.foxglove"), *_bridge_devices(fox.devices, targets),
            "--host", fox.address, "--port", str(fox.port), "--rate", f"{fox.rate_hz:g}"]
    if config.security.insecure:
        argv.append("--insecure")
    argv += client_arguments(config.security, _viewer_token(config))
    return ServiceSpec("foxglove", "Foxglove bridge", argv, workdir,
                       note=f"shows {', '.join(fox.devices)}; read-only")


def opcua_service(config: CellConfig, targets: dict[str, str], workdir: Path) -> ServiceSpec:
    """The OPC UA server, a watcher with the supervisor's (viewer) token."""
    ua = config.opcua
    argv = [*_python("landscape.bridges.opcua"), *_bridge_devices(ua.devices, targets),
            "--cell", config.name, "--host", ua.address, "--port", str(ua.port)]
    for flag, value in (("--users", ua.users), ("--certificate", ua.certificate),
                        ("--key", ua.key)):
        if value is not None:
            argv += [flag, str(value)]
    for path in ua.trusted_certs:
        argv += ["--trusted-cert", str(path)]
    argv += client_arguments(config.security, _viewer_token(config))
    return ServiceSpec("opcua", "OPC UA server", argv, workdir,
                       note=f"exposes {', '.join(ua.devices)}; read-only")


def _viewer_token(config: CellConfig) -> Path | None:
    """The bridges watch with a viewer's token (the supervisor's, or the security folder's)."""
    if config.supervisor.token is not None:
        return config.supervisor.token
    tokens = config.security.tokens
    return tokens / "viewer.tokens" if tokens is not None else None


def supervisor_service(config: CellConfig, targets: dict[str, str],
                       workdir: Path) -> ServiceSpec:
    supervisor = config.supervisor
    argv = [*_python(SUPERVISOR_MODULE)]
    for name in supervisor.devices:
        argv += ["--device", f"{name}={targets[name]}"]
    argv += ["--host", supervisor.address, "--port", str(supervisor.port),
             "--sign-in-tokens", str(supervisor.sign_in_tokens),
             "--sign-in-idle", f"{supervisor.sign_in_idle:g}",
             "--sign-in-max-age", f"{supervisor.sign_in_max_age:g}"]
    for origin in supervisor.allowed_origins:
        argv += ["--allowed-origin", origin]
    argv += client_arguments(config.security, supervisor.token)
    argv += _front_end_metrics(config, len(config.devices) + 1)
    return ServiceSpec("supervisor", "web supervisor", argv, workdir,
                       note=f"shows {', '.join(supervisor.devices)}; sign in with a token "
                            f"from {supervisor.sign_in_tokens / 'operator.tokens'}")


def supervisor_missing(page: Path | None = None) -> str | None:
    """Why the web supervisor cannot be started here, or None: not installed, or its page
    (`page`, default: the installed package's frontend/dist/index.html) not built."""
    spec = importlib.util.find_spec(SUPERVISOR_MODULE)
    if spec is None:
        return f"{SUPERVISOR_MODULE} is not installed; the rest of the cell runs without it"
    page = page or Path(spec.submodule_search_locations[0]) / "frontend" / "dist" / "index.html"
    if not page.is_file():
        return ("its page is not built (that needs Node.js and npm: install them, then `make "
                "install`); the rest of the cell runs without it")
    return None

"""The command line of each service of a cell, from its configuration.

A `ServiceSpec` is what the launcher starts: the argv (this Python, `-m` the service's
module), the working directory, the line that says it listens, and what it is. Clients'
commands (gateway, supervisor) are built once the device servers listen, from the targets
they really have (a port 0 becomes a real one).
"""
from __future__ import annotations

import importlib.util
import re
import sys
from dataclasses import dataclass
from pathlib import Path

from landscape.cell.config import CellConfig, DeviceSpec, SecuritySpec

# The line each program prints once it listens; group 1 is where.
READY = {
    "device server": re.compile(r"landscape device server listening on (\S+)"),
    "CRCL gateway": re.compile(r"CRCL gateway listening on (\S+)"),
    "web supervisor": re.compile(r"web supervisor on (\S+)"),
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


def device_service(device: DeviceSpec, security: SecuritySpec, port: int | None = None) -> ServiceSpec:
    """The device server; `port` overrides the configured one (a restart keeps the port it
    had)."""
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
    if security.tls:
        argv += ["--tls-cert", str(security.cert), "--tls-key", str(security.key)]
        if security.mtls:
            argv += ["--mtls", "--tls-ca", str(security.ca)]
    if security.tokens is not None:
        argv += ["--tokens", str(security.tokens)]
    if security.insecure:
        argv.append("--insecure")
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
    return ServiceSpec("gateway", "CRCL gateway", argv, workdir, note=f"-> {gateway.device}")


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

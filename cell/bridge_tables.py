"""The bridges' tables of a cell configuration ([metrics], [foxglove], [opcua];
docs/bridges.md) and their exposure rule: /metrics off loopback over the device servers' TLS
or insecure, the Foxglove bridge (no sign-in) off loopback only with insecure, the OPC UA
server off loopback only with its certificate, key and users or trusted certificates."""
from __future__ import annotations

from pathlib import Path

from landscape.cell.config_model import CellConfig, FoxgloveSpec, MetricsSpec, OpcUaSpec
from landscape.cell.config_types import Address, FilePath, Port, exists, shown_devices
from landscape.robot.toml_tables import Table, flag, number, problem
from landscape.server.security.tls import is_loopback


class MetricsTable(Table):
    enabled: flag = MetricsSpec.enabled
    address: Address = MetricsSpec.address
    port: Port = MetricsSpec.port

    def spec(self) -> MetricsSpec:
        return MetricsSpec(**dict(self))


class FoxgloveTable(Table):
    enabled: flag = FoxgloveSpec.enabled
    address: Address = FoxgloveSpec.address
    port: Port = FoxgloveSpec.port
    rate_hz: number(above=0.0, high=250.0) = FoxgloveSpec.rate_hz
    devices: list | None = None       # default: every device

    def spec(self, names: list[str]) -> FoxgloveSpec:
        return FoxgloveSpec(self.enabled, self.address, self.port, self.rate_hz,
                            shown_devices(self.devices, names, "foxglove.devices"))


class OpcUaTable(Table):
    enabled: flag = OpcUaSpec.enabled
    address: Address = OpcUaSpec.address
    port: Port = OpcUaSpec.port
    devices: list | None = None       # default: every device
    users: FilePath = None
    certificate: FilePath = None
    key: FilePath = None
    trusted_certs: list = []

    def spec(self, names: list[str], base: Path) -> OpcUaSpec:
        for key in ("users", "certificate", "key"):
            exists(getattr(self, key), f"opcua.{key}")
        trusted = []
        for i, path in enumerate(self.trusted_certs):
            if not isinstance(path, str) or not path:
                raise problem(f"expected a certificate's path, got {path!r}",
                              f"opcua.trusted_certs[{i}]")
            trusted.append(Path(path) if Path(path).is_absolute() else base / path)
            exists(trusted[-1], f"opcua.trusted_certs[{i}]")
        return OpcUaSpec(self.enabled, self.address, self.port,
                         shown_devices(self.devices, names, "opcua.devices"), self.users,
                         self.certificate, self.key, tuple(trusted))


def check_bridges(config: CellConfig) -> None:
    """The module's exposure rule; a problem naming the key."""
    insecure = config.security.insecure
    fox, metrics, ua = config.foxglove, config.metrics, config.opcua
    if fox.enabled and not (is_loopback(fox.address) or insecure):
        raise problem(f"the Foxglove bridge would show the cell to anyone reaching "
                      f"{fox.address} (it has no sign-in): keep it on loopback, or set "
                      f"security.insecure = true on a network of your own", "foxglove.address")
    if metrics.enabled and not (is_loopback(metrics.address) or config.security.tls
                                or insecure):
        raise problem(f"/metrics would be served on {metrics.address} in plaintext: set "
                      f"security.tls (the device servers serve it over their TLS; the gateway "
                      f"and supervisor stay on loopback), or security.insecure = true",
                      "metrics.address")
    if ua.enabled and not is_loopback(ua.address) and not (
            ua.certificate and ua.key and (ua.users or ua.trusted_certs)):
        raise problem(f"the OPC UA server would take anonymous clients on {ua.address}: give "
                      f"it certificate, key and users (or trusted_certs), or keep it on "
                      f"loopback", "opcua.address")

"""Issue 29: each bridge configured in the cell file, off or on loopback by default as its
risk says, and a bridge exposed by mistake refused naming the key."""
from __future__ import annotations

from pathlib import Path

import pytest

from landscape.cell.config import CellConfigError, load_config, parse_config
from landscape.cell.services import (device_service, foxglove_service, gateway_service,
                                     metrics_of, opcua_service, supervisor_service)

TARGETS = {"arm1": "127.0.0.1:50051", "arm2": "127.0.0.1:50052"}
TWO = "[[devices]]\nname = 'arm1'\n[[devices]]\nname = 'arm2'\n"


def test_the_defaults_metrics_on_loopback_foxglove_and_opc_ua_off():
    config = load_config()
    assert (config.metrics.enabled, config.metrics.address) == (True, "127.0.0.1")
    assert not config.foxglove.enabled and config.foxglove.address == "127.0.0.1"
    assert not config.opcua.enabled and config.opcua.address == "127.0.0.1"


def test_every_service_gets_its_own_metrics_port(tmp_path):
    config = parse_config(TWO + "[metrics]\nport = 9500\n", base=tmp_path)
    ports = [device_service(d, config.security, **metrics_of(config.metrics, i)).argv
             for i, d in enumerate(config.devices)]
    ports += [gateway_service(config, TARGETS, tmp_path).argv,
              supervisor_service(config, TARGETS, tmp_path).argv]
    assert [argv[argv.index("--metrics-port") + 1] for argv in ports] == [
        "9500", "9501", "9502", "9503"]
    off = parse_config(TWO + "[metrics]\nenabled = false\n", base=tmp_path)
    assert "--metrics-port" not in device_service(off.devices[0], off.security,
                                                  **metrics_of(off.metrics, 0)).argv


def test_the_bridges_watch_the_devices_they_are_given(tmp_path):
    config = parse_config(TWO + "[foxglove]\nenabled = true\ndevices = ['arm2']\nrate_hz = 20\n"
                          "[opcua]\nenabled = true\nport = 4841\n", base=tmp_path)
    fox = foxglove_service(config, TARGETS, tmp_path).argv
    assert fox[fox.index("--device") + 1] == "arm2=127.0.0.1:50052" and "--rate" in fox
    ua = opcua_service(config, TARGETS, tmp_path).argv
    assert ua.count("--device") == 2 and ua[ua.index("--port") + 1] == "4841"


@pytest.mark.parametrize("text, key", [
    ("[foxglove]\nenabled = true\naddress = '0.0.0.0'\n", "foxglove.address"),
    ("[opcua]\nenabled = true\naddress = '0.0.0.0'\n", "opcua.address"),
    ("[metrics]\naddress = '0.0.0.0'\n", "metrics.address"),
    ("[foxglove]\ndevices = ['arm9']\n", "foxglove.devices"),
    ("[metrics]\nport = 8079\n[supervisor]\nport = 8080\n", "supervisor.port"),
    ("[opcua]\nusers = 'nowhere'\n", "opcua.users"),
])
def test_a_bridge_exposed_by_mistake_is_refused_naming_the_key(tmp_path, text, key):
    with pytest.raises(CellConfigError, match=key.replace(".", r"\.")):
        parse_config("[[devices]]\nname = 'arm1'\n" + text, "cell.toml", tmp_path)


def test_off_loopback_with_what_each_bridge_needs(tmp_path):
    for name in ("cert.der", "key.pem", "users"):
        (tmp_path / name).write_text("x")
    config = parse_config(
        "[[devices]]\nname = 'arm1'\n[security]\ninsecure = true\n"
        "[foxglove]\nenabled = true\naddress = '0.0.0.0'\n"
        "[opcua]\nenabled = true\naddress = '0.0.0.0'\ncertificate = 'cert.der'\n"
        "key = 'key.pem'\nusers = 'users'\n", "cell.toml", tmp_path)
    assert "--insecure" in foxglove_service(config, TARGETS, tmp_path).argv
    ua = opcua_service(config, TARGETS, tmp_path).argv
    assert Path(ua[ua.index("--users") + 1]) == tmp_path / "users"

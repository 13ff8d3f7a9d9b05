"""Settings of the web supervisor: device targets and their checks."""
from __future__ import annotations

import pytest

from landscape.supervisor.__main__ import parse_args
from landscape.supervisor.config import DashboardConfig, DeviceTarget, parse_device


def test_a_device_is_name_equals_host_colon_port():
    assert parse_device("arm1=127.0.0.1:50051") == DeviceTarget("arm1", "127.0.0.1:50051")
    assert parse_device("cell=[::1]:50051") == DeviceTarget("cell", "[::1]:50051")


@pytest.mark.parametrize("text", ["arm1", "=127.0.0.1:1", "arm1=127.0.0.1", "arm1=:50051",
                                  "arm1=host:port"])
def test_malformed_devices_are_refused(text):
    with pytest.raises(ValueError, match="NAME=HOST:PORT"):
        parse_device(text)


def test_the_command_line_serves_loopback_by_default():
    config = parse_args(["--device", "a=127.0.0.1:1", "--device", "b=127.0.0.1:2"])
    assert config.host == "127.0.0.1" and config.port == 8080
    assert [d.name for d in config.devices] == ["a", "b"]


@pytest.mark.parametrize("devices, rate, message", [
    ((), 30.0, "at least one"),
    ((DeviceTarget("a", "h:1"), DeviceTarget("a", "h:2")), 30.0, "must differ"),
    ((DeviceTarget("a", "h:1"),), 0.0, "display rate"),
    ((DeviceTarget("a", "h:1"),), 1000.0, "display rate"),
])
def test_settings_that_cannot_work_are_refused(devices, rate, message):
    with pytest.raises(ValueError, match=message):
        DashboardConfig(devices=devices, display_rate_hz=rate)


@pytest.mark.parametrize("host, loopback", [("127.0.0.1", True), ("localhost", True),
                                            ("::1", True), ("[::1]", True), ("0.0.0.0", False)])
def test_serving_beyond_loopback_is_told_apart(host, loopback):
    from landscape.supervisor.__main__ import _loopback
    assert _loopback(host) is loopback

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


def test_the_command_line_serves_loopback_by_default(people):
    config = parse_args(["--device", "a=127.0.0.1:1", "--device", "b=127.0.0.1:2",
                         "--sign-in-tokens", str(people.folder)])
    assert config.host == "127.0.0.1" and config.port == 8080
    assert [d.name for d in config.devices] == ["a", "b"]
    assert config.allowed_origins == () and config.token is None


def test_the_command_line_needs_a_usable_folder_of_sign_in_tokens(tmp_path, capsys):
    with pytest.raises(SystemExit):
        parse_args(["--device", "a=127.0.0.1:1"])
    assert "--sign-in-tokens" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        parse_args(["--device", "a=127.0.0.1:1", "--sign-in-tokens", str(tmp_path)])
    assert "none of viewer.tokens, operator.tokens, admin.tokens" in capsys.readouterr().err


ARM = (DeviceTarget("a", "h:1"),)


@pytest.mark.parametrize("settings, message", [
    ({"devices": ()}, "at least one"),
    ({"devices": (DeviceTarget("a", "h:1"), DeviceTarget("a", "h:2"))}, "must differ"),
    ({"display_rate_hz": 0.0}, "display rate"),
    ({"display_rate_hz": 1000.0}, "display rate"),
    ({"sign_in_tokens": None}, "sign-in tokens"),
    ({"allowed_origins": ("panel.example",)}, "an origin is"),
    ({"allowed_origins": ("http://panel.example/page",)}, "an origin is"),
    ({"sign_in_idle_s": 0.0}, "positive seconds"),
    ({"max_unauthenticated": 0}, "at least 1"),
])
def test_settings_that_cannot_work_are_refused(settings, message):
    with pytest.raises(ValueError, match=message):
        DashboardConfig(**{"devices": ARM, "sign_in_tokens": "var/tokens", **settings})


@pytest.mark.parametrize("host, loopback", [("127.0.0.1", True), ("localhost", True),
                                            ("::1", True), ("[::1]", True), ("0.0.0.0", False)])
def test_serving_beyond_loopback_is_told_apart(host, loopback):
    from landscape.supervisor.__main__ import _loopback
    assert _loopback(host) is loopback

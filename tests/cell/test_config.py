"""The cell configuration: the built-in default, the LAN example, and errors that name the
file and the key."""
from __future__ import annotations

import math
import shutil
from pathlib import Path

import pytest

from landscape.cell.config import CellConfigError, load_config, parse_config
from landscape.cell.services import device_service, gateway_service, supervisor_service

from cell_support import make_keys

LAN = Path(__file__).resolve().parents[2] / "cell" / "cells" / "lan.toml"


def test_the_built_in_default_is_one_arm_the_gateway_and_the_supervisor_on_loopback(
        tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    config = load_config()
    (arm,) = config.devices
    assert (arm.name, arm.address, arm.port, arm.world) == ("arm1", "127.0.0.1", 50051, None)
    assert arm.data == tmp_path / "var" / "arm1"      # relative to where it runs
    assert (config.gateway.device, config.gateway.port) == ("arm1", 64444)
    assert (config.supervisor.port, config.supervisor.devices) == (8080, ("arm1",))
    assert not config.security.tls and config.security.tokens is None
    argv = device_service(arm, config.security).argv
    assert argv[argv.index("--port") + 1] == "50051" and "--insecure" not in argv
    assert argv[argv.index("--collision-margin") + 1] == "0.005"
    assert argv[argv.index("--audit-log") + 1] == str(tmp_path / "var" / "arm1" / "audit.log")


def test_the_gateway_is_given_the_cells_workstation(tmp_path):
    config = parse_config("[gateway]\nworkstation_xyz = [-0.9, -1.0, 0.21]\n"
                          "workstation_rpy_deg = [0, 0, 90]\nend_effector = 'gripper'\n"
                          "length_units = 'millimeter'\nangle_units = 'degree'", "<t>", tmp_path)
    argv = gateway_service(config, {"arm1": "127.0.0.1:50051"}, tmp_path).argv
    frame = [float(v) for v in argv[argv.index("--workstation-frame") + 1].split()]
    assert frame == pytest.approx([-0.9, -1.0, 0.21, 0.0, 0.0, math.pi / 2])   # m and rad
    assert argv[argv.index("--end-effector") + 1] == "gripper"
    assert argv[argv.index("--length-units") + 1] == "millimeter"
    assert argv[argv.index("--angle-units") + 1] == "degree"
    from landscape.gateway.__main__ import arguments, workstation
    assert workstation(arguments(argv[argv.index("--device"):])).frame == pytest.approx(frame)


def test_the_supervisor_signs_people_in_from_var_tokens_and_shows_its_keys(tmp_path):
    config = parse_config("[supervisor]\nallowed_origins = ['HTTPS://Panel.lan:443']\n"
                          "sign_in_idle = 600", "<t>", tmp_path)
    supervisor = config.supervisor
    assert supervisor.sign_in_tokens == tmp_path / "var" / "tokens"   # made on the first run
    assert supervisor.token is None                                   # devices without tokens
    argv = supervisor_service(config, {"arm1": "127.0.0.1:50051"}, tmp_path).argv
    assert argv[argv.index("--sign-in-tokens") + 1] == str(tmp_path / "var" / "tokens")
    assert argv[argv.index("--allowed-origin") + 1] == "https://panel.lan"
    assert argv[argv.index("--sign-in-idle") + 1] == "600"
    assert "--token-file" not in argv


def test_the_lan_example_is_valid_once_certificates_and_tokens_exist(tmp_path):
    make_keys(tmp_path / "var")
    shutil.copy(LAN, tmp_path / "cell.toml")
    config = load_config(tmp_path / "cell.toml")
    assert [d.name for d in config.devices] == ["arm1", "arm2"]
    assert config.devices[1].world.name == "press_tending.toml"
    assert config.gateway.token == tmp_path / "var" / "tokens" / "operator.tokens"
    gateway = gateway_service(config, {"arm1": "127.0.0.1:50051"}, tmp_path).argv
    assert gateway[gateway.index("--tls-ca") + 1] == str(tmp_path / "var" / "certs" / "ca.pem")
    assert "--token-file" in gateway
    server = device_service(config.devices[1], config.security).argv
    assert "--tokens" in server and "--tls-cert" in server
    # Both arms stand in the one cell: the servers are told where.
    assert [d.placement for d in config.devices] == [(0.0,) * 6, (0.0, 2.5, 0.0, 0.0, 0.0, 0.0)]
    assert "--placement=0.0,2.5,0.0,0.0,0.0,0.0" in server and "--shared-cell=lan" in server
    # The supervisor: people sign in with the devices' tokens; its own feeds are a viewer's.
    assert config.supervisor.sign_in_tokens == tmp_path / "var" / "tokens"
    assert config.supervisor.token == tmp_path / "var" / "tokens" / "viewer.tokens"


@pytest.mark.parametrize("text, message", [
    ("colour = 1", r"<t>: colour: unknown key"),
    ("[[devices]]\nname = 'a'\nport = 'x'",
     r"devices\[0\]\.port: expected an integer from 0 to 65535, got 'x'"),
    ("[[devices]]\nname = 'a'\nport = 70000",
     r"devices\[0\]\.port: expected an integer from 0 to 65535, got 70000"),
    ("[[devices]]\nname = '1a'", r"devices\[0\]\.name: expected a name: a letter, then"),
    ("[[devices]]\nname = 'a'\n[[devices]]\nname = 'a'\nport = 1", r"two devices are named 'a'"),
    ("[[devices]]\nname = 'a'\nworld = 'nowhere'", r"world: no built-in world is named"),
    ("[[devices]]\nname = 'a'\nworld = 'no/such.toml'", r"world: .*no/such.toml does not exist"),
    ("[[devices]]\nname = 'a'\nclock = 'slow'",
     r"clock: expected one of realtime, fast, lockstep; got 'slow'"),
    ("[[devices]]\nname = 'a'\ncollision_margin = 0",
     r"collision_margin: expected a number above 0 and at most 0\.1, got 0"),
    ("[[devices]]\nname = 'a'\ncollision_margin = 0.5",
     r"collision_margin: expected a number above 0 and at most 0\.1, got 0\.5"),
    ("[[devices]]\nname = 'a'\nplacement_xyz = [1, 2]",
     r"devices\[0\]\.placement_xyz: expected a list of 3 numbers, got \[1, 2\]"),
    ("[gateway]\ndevice = 'arm9'", r"gateway\.device: no device is named 'arm9'"),
    ("[supervisor]\ndevices = []",
     r"supervisor\.devices: expected a non-empty list of device names, got \[\]"),
    ("[supervisor]\nallowed_origins = 'x'",
     r"supervisor\.allowed_origins: expected a list of origins, got 'x'"),
    ("[supervisor]\nallowed_origins = ['panel.lan']",
     r"supervisor\.allowed_origins: an origin is http\(s\)://host\[:port\]"),
    ("[supervisor]\nsign_in_idle = 0", r"supervisor\.sign_in_idle: expected a number above 0"),
    ("[gateway]\nport = 50051", r"gateway\.port: port 50051 on 127.0.0.1 is taken by devices"),
    ("[[devices]]\nname = 'a'\naddress = '0.0.0.0'",
     r"devices\[0\]\.address: a would listen on 0\.0\.0\.0 without TLS and tokens"),
    ("[security]\ntls = true", r"security\.cert: is required with tls = true"),
    ("[security]\nmtls = true", r"security\.mtls: mutual TLS needs tls = true"),
    ("[security]\ntokens = '.'", r"security\.tokens: .*none of viewer\.tokens"),
    ("[launcher]\nrestart = 'always'",
     r"launcher\.restart: expected one of no, on-failure; got 'always'"),
    ("[security.rate_limits]\ncli = 0",
     r"security\.rate_limits\.cli: expected a number above 0, got 0"),
    ("name = [", r"<t>: not valid TOML"),
    ("[gateway]\nend_effector = 'spanner'",
     r"gateway\.end_effector: arm1's world has no tool named 'spanner' \(its tools: gripper, "
     r"vacuum; or \"none\""),
    ("[gateway]\nlength_units = 'mm'",
     r"gateway\.length_units: expected one of meter, millimeter, inch; got 'mm'"),
    ("[gateway]\nworkstation_rpy_deg = [0, 90]",
     r"gateway\.workstation_rpy_deg: expected a list of 3 numbers, got \[0, 90\]"),
])
def test_errors_name_the_file_and_the_key(text, message, tmp_path):
    with pytest.raises(CellConfigError, match=message):
        parse_config(text, "<t>", tmp_path)


def test_the_front_ends_have_budgets_of_their_own_and_the_cell_file_sizes_them(tmp_path):
    """Issue 31.3: rate limits belong to each client; the cell sizes the ones it names."""
    default = device_service(load_config().devices[0], load_config().security).argv
    sized = [default[i + 1] for i, arg in enumerate(default) if arg == "--rate-limit-for"]
    assert sized == ["crcl-gateway=5000", "supervisor=5000"]
    config = parse_config("[security.rate_limits]\nsupervisor = 800\nrobot-cli = 50.5", "<t>",
                          tmp_path)
    argv = device_service(config.devices[0], config.security).argv
    sized = [argv[i + 1] for i, arg in enumerate(argv) if arg == "--rate-limit-for"]
    assert sized == ["crcl-gateway=5000", "supervisor=800", "robot-cli=50.5"]


def test_a_world_file_that_is_wrong_is_named_with_its_own_key(tmp_path):
    (tmp_path / "w.toml").write_text("[arm]\nvariant = 'TX91'\n")
    with pytest.raises(CellConfigError, match=r"world: not a usable world file: .*w\.toml: "
                                              r"arm\.variant"):
        parse_config("[[devices]]\nname = 'a'\nworld = 'w.toml'", "<t>", tmp_path)


def test_insecure_lets_a_device_listen_off_loopback_without_protection(tmp_path):
    config = parse_config("[[devices]]\nname = 'a'\naddress = '0.0.0.0'\n"
                          "[security]\ninsecure = true", "<t>", tmp_path)
    assert config.devices[0].host == "127.0.0.1"
    assert "--insecure" in device_service(config.devices[0], config.security).argv

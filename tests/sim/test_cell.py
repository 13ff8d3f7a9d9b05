"""The cell file: the default cell, overrides, and errors that name the bad key."""
from __future__ import annotations

import math
from importlib import resources

import pytest

from landscape.robot.arm import VARIANTS
from landscape.robot.cell import CellError, load_cell, parse_cell

DEFAULT_TEXT = resources.files("landscape.robot").joinpath("cells/default.toml").read_text()


def edited(old: str, new: str) -> str:
    """The default cell text with one piece replaced (which must be there)."""
    assert old in DEFAULT_TEXT, old
    return DEFAULT_TEXT.replace(old, new, 1)


def test_default_cell_loads_with_what_the_cell_needs():
    cell = load_cell()
    assert cell.arm == VARIANTS["TX90"]
    assert cell.controller.cycle_time == 0.004 and cell.controller.substeps == 2
    assert cell.controller.initial_position == pytest.approx((0, 0, math.pi / 2, 0, math.pi / 2, 0))
    world = cell.world
    assert {f.name for f in world.fixtures} == {"table", "rack"}
    assert {t.kind for t in world.tools} == {"parallel_gripper", "vacuum_cup"}
    assert len(world.parts) >= 2 and all(p.mass > 0 for p in world.parts)
    assert {u.id: u.direction for u in cell.io.units} == {0: "input", 1: "input", 2: "output"}
    wires = {s.name: s.wire for s in cell.io.signals}
    assert wires["estop"] == "estop" and wires["part_at_pick"] == "zone:pick"
    assert wires["lamp_green"] == "none"
    assert {s.name: s.kind for s in cell.sensors} == {
        "force_sensor": "force_torque", "laser_standoff_sensor": "laser_range"}
    assert cell.recorder.every_nth == 1 and cell.recorder.max_seconds == 60.0


def test_load_from_a_file_and_overrides(tmp_path):
    text = edited('variant = "TX90"', 'variant = "TX90L"\n'
                  'max_acceleration = [10, 10, 10, 20, 20, 20]\nmax_linear_velocity = 1.5')
    text = text.replace("frequency_percent = 100", "frequency_percent = 50")
    path = tmp_path / "cell.toml"
    path.write_text(text)
    cell = load_cell(path)
    assert cell.arm.name == "TX90L" and cell.arm.c2 == 0.5
    assert cell.arm.max_acceleration == (10, 10, 10, 20, 20, 20)
    assert cell.arm.max_linear_velocity == 1.5
    assert cell.recorder.every_nth == 2
    assert cell.source == str(path)
    # The jerk limit follows the accelerations given (20 ms ramps) unless it is given too.
    assert cell.arm.max_jerk == pytest.approx((500, 500, 500, 1000, 1000, 1000))


def test_the_jerk_limit_is_a_key_of_the_arm_table():
    """Issue 30: the arm's jerk limit per joint (rad/s^3) is settable in the cell file."""
    given = 'variant = "TX90"' + chr(10) + 'max_jerk = [900, 900, 1000, 2000, 2000, 3000]'
    cell = parse_cell(edited('variant = "TX90"', given))
    assert cell.arm.max_jerk == (900, 900, 1000, 2000, 2000, 3000)
    assert parse_cell(edited("", "")).arm.max_jerk == pytest.approx(
        tuple(a / 0.020 for a in cell.arm.max_acceleration))
    bad = 'variant = "TX90"' + chr(10) + 'max_jerk = [0, 1, 1, 1, 1, 1]'
    with pytest.raises(CellError, match="arm.max_jerk"):
        parse_cell(edited('variant = "TX90"', bad))


def test_cell_limits_narrow_the_joint_range():
    cell = parse_cell(edited("# joint_min_deg = [-180, -130, -145, -270, -115, -270]",
                             "joint_min_deg = [-90, -130, -145, -270, -115, -270]"))
    assert cell.arm.joint_min[0] == pytest.approx(-math.pi / 2)


@pytest.mark.parametrize("old, new, key", [
    ("cycle_time = 0.004", "cycle_time = 0.0041", "controller.cycle_time"),
    ("cycle_time = 0.004", "cycle_time = -0.004", "controller.cycle_time"),
    ("cycle_time = 0.004", 'cycle_time = "fast"', "controller.cycle_time"),
    ("enable_time = 0.1", "enable_time = 0.1\nenable_tme = 2", "controller.enable_tme"),
    ('variant = "TX90"', 'variant = "TX60"', "arm.variant"),
    ("initial_position_deg = [0.0, 0.0, 90.0, 0.0, 90.0, 0.0]",
     "initial_position_deg = [0.0, 0.0, 150.0, 0.0, 90.0, 0.0]", "controller.initial_position_deg"),
    ('kind = "vacuum_cup"', 'kind = "magnet"', "world.tools[1].kind"),
    ('size = [0.04, 0.04, 0.04]', 'size = [0.04, 0.04]', "world.parts[0].size"),
    ('name = "block_2"', 'name = "block_1"', "world.parts"),
    ("unit = 0\nbit = 1", "unit = 0\nbit = 0", "io.signals"),
    ("unit = 0\nbit = 1", "unit = 7\nbit = 1", "io.signals[1].unit"),
    ("unit = 0\nbit = 1", "unit = 0\nbit = 32", "io.signals[1].bit"),
    ('wire = "zone:pick"', 'wire = "zone:nowhere"', "io.signals[5].wire"),
    ('wire = "zone:pick"', 'wire = "vacuum_on"', "io.signals[5].wire"),
    ("max_range = 1.0", "max_range = 0.001", "sensors.laser_standoff_sensor.min_range"),
    ("frequency_percent = 100", "frequency_percent = 0", "recorder.frequency_percent"),
])
def test_errors_name_the_bad_key(old, new, key):
    with pytest.raises(CellError) as err:
        parse_cell(edited(old, new), "bad.toml")
    assert f"bad.toml: {key}:" in str(err.value)


def test_errors_for_the_file_itself(tmp_path):
    with pytest.raises(CellError, match="cannot read"):
        load_cell(tmp_path / "missing.toml")
    with pytest.raises(CellError, match="not valid TOML"):
        parse_cell("name = ")
    with pytest.raises(CellError, match="colour: unknown key"):
        parse_cell(DEFAULT_TEXT + '\ncolour = "red"\n')


def test_a_minimal_cell_uses_defaults():
    cell = parse_cell('name = "bare"')
    assert cell.world.tools == () and cell.io.signals == () and cell.sensors == ()
    assert cell.controller.cycle_time == 0.004


def test_an_error_says_what_was_expected_and_what_came():
    with pytest.raises(CellError) as err:
        parse_cell(edited("cycle_time = 0.004", 'cycle_time = "fast"'), "cell.toml")
    assert str(err.value) == ("cell.toml: controller.cycle_time: expected a number above 0, "
                              "got 'fast'")
    with pytest.raises(CellError) as err:
        parse_cell(edited('kind = "vacuum_cup"', 'kind = "vacuum_cup"\nstroke = 0.1'), "cell.toml")
    assert str(err.value) == ("cell.toml: world.tools[1].stroke: only a parallel_gripper has a "
                              "stroke (this tool is a vacuum_cup)")


def test_every_bad_key_is_named_at_once():
    text = edited("floor = true", "floor = 1").replace("frequency_percent = 100",
                                                       "frequency_percent = 0")
    with pytest.raises(CellError) as err:
        parse_cell(text, "cell.toml")
    assert str(err.value).splitlines() == [
        "cell.toml: world.floor: expected true or false, got 1",
        "cell.toml: recorder.frequency_percent: expected a number from 0.01 to 100, got 0"]

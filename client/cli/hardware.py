"""`landscape io ...`, `landscape sensor`, `landscape tool ...`: the cell's I/O, sensors and tools."""
from __future__ import annotations

import click

from landscape.client.cli.context import CliState, pass_state
from landscape.client.cli.output import to_dict, units_names


def _bits(text: str) -> int:
    """A bit mask as 5, 0x5 or 0b101."""
    try:
        return int(text, 0)
    except ValueError:
        raise click.BadParameter(f"{text!r} is not a number (e.g. 5, 0x5, 0b101)") from None


@click.group()
def io() -> None:
    """The cell's digital I/O (seed section 4)."""


@io.command("list")
@pass_state
def io_list(state: CliState) -> None:
    """Units, their direction and bit names."""
    with state.reader() as robot:
        reply = robot.list_digital_io()
    lines = [f"{u.type:6} unit {u.unit_id} {u.name}: "
             + ", ".join(f"{b.bit}={b.name}" for b in u.bits) for u in reply.units]
    state.out.result(to_dict(reply), "\n".join(lines) or "no I/O units")


@io.command("get")
@click.argument("unit_id", type=int)
@click.option("--output", "kind", flag_value="output", help="Read an output unit.")
@click.option("--input", "kind", flag_value="input", default=True, help="Read an input unit.")
@pass_state
def io_get(state: CliState, unit_id: int, kind: str) -> None:
    """The bits of a unit."""
    with state.reader() as robot:
        reply = robot.get_digital_io(unit_id, kind)
    state.out.result(to_dict(reply), f"{kind} unit {unit_id}: bits on {reply.bits_on:#b}")


@io.command("set")
@click.argument("unit_id", type=int)
@click.option("--on", "bits_on", default="0", help="Bits to switch on (mask).")
@click.option("--off", "bits_off", default="0", help="Bits to switch off (mask).")
@click.option("--description", default="", help="Kept in the event log.")
@pass_state
def io_set(state: CliState, unit_id: int, bits_on: str, bits_off: str, description: str) -> None:
    """Switch bits of an output unit (needs the lock, which this command takes)."""
    with state.commander(activate=False) as robot:
        state.out.reply(robot.set_digital_io(unit_id, _bits(bits_on), _bits(bits_off),
                                             description))


@click.command()
@click.argument("sensor_type", type=click.Choice(["force_sensor", "laser_standoff_sensor"]))
@pass_state
def sensor(state: CliState, sensor_type: str) -> None:
    """A sensor's reading: force (fx fy fz N, tx ty tz N*m) or laser standoff (range)."""
    with state.reader() as robot:
        reply = robot.get_sensor_reading(sensor_type)
    values = " ".join(f"{v:.4f}" for v in reply.current_data)
    # Forces and torques are in N and N*m whatever the units; a range in the linear unit.
    unit = ("fx fy fz N, tx ty tz N*m" if sensor_type == "force_sensor"
            else units_names(reply.units)["linear"])
    state.out.result(to_dict(reply), f"{sensor_type}: {values} ({unit})")


@click.group()
def tool() -> None:
    """The end effector (seed 3.8): state, pick up and put back, switch its functions."""


@tool.command("state")
@pass_state
def tool_state(state: CliState) -> None:
    """The tool on the flange and its state."""
    with state.reader() as robot:
        reply = robot.get_end_effector_state()
    state.out.result(to_dict(reply), f"{reply.current_ee or 'no tool'} {reply.ee_state}".strip())


@tool.command("get")
@click.argument("tool_id")
@pass_state
def tool_get(state: CliState, tool_id: str) -> None:
    """Pick TOOL_ID up from the rack (moves the arm)."""
    with state.commander() as robot:
        state.out.reply(robot.get_tool(tool_id, timeout=state.timeout))


@tool.command("put")
@click.argument("tool_id")
@pass_state
def tool_put(state: CliState, tool_id: str) -> None:
    """Put TOOL_ID back in the rack (moves the arm)."""
    with state.commander() as robot:
        state.out.reply(robot.put_tool(tool_id, timeout=state.timeout))


@tool.command("activate")
@click.argument("tool_id")
@click.option("--bits", default="1", show_default=True, help="Functions to switch on (mask).")
@pass_state
def tool_activate(state: CliState, tool_id: str, bits: str) -> None:
    """Switch tool functions on (bit 0: close the gripper, vacuum on)."""
    with state.commander(activate=False) as robot:
        state.out.reply(robot.activate_tool(tool_id, _bits(bits)))


@tool.command("deactivate")
@click.argument("tool_id")
@click.option("--bits", default="1", show_default=True, help="Functions to switch off (mask).")
@pass_state
def tool_deactivate(state: CliState, tool_id: str, bits: str) -> None:
    """Switch tool functions off."""
    with state.commander(activate=False) as robot:
        state.out.reply(robot.deactivate_tool(tool_id, _bits(bits)))

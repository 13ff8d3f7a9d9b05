"""CRCL commands on the tool, the tool changer, sensors and the vendor hook.

landscape.v1 names the mounted tool and its state (GetEndEffectorState), switches its main
function with ActivateTool / DeactivateTool (bit 0: close the gripper, or suction on), couples
and releases tools with the cell's "toolchanger_lock" output (DigitalIOService), reads sensors
(the state stream) and passes text to the vendor (SendCommand). Where
the device answers UNIMPLEMENTED, the command is a CRCL_Error saying so.
"""
from __future__ import annotations

from landscape.gateway import model as m
from landscape.gateway.errors import CrclError
from landscape.gateway.status import is_vacuum
from landscape.v1 import digital_io_service_pb2 as dio
from landscape.v1 import end_effector_pb2

TOOL_CHANGER_OUTPUT = "toolchanger_lock"    # the cell's output: 1 couples, 0 releases
MAIN_FUNCTION = 1                           # bit 0 of ActivateTool's bit field


async def _tool(session) -> tuple[str, str]:
    reply = await session.link.read("GetEndEffectorState",
                                    end_effector_pb2.GetEndEffectorStateRequest())
    return reply.current_ee, reply.ee_state


async def _changer(session, couple: bool) -> None:
    io = await session.link.read("ListDigitalIO", dio.ListDigitalIORequest(),
                                 stub=session.link.digital_io)
    for unit in io.units:
        for bit in unit.bits:
            if unit.type == "output" and bit.name == TOOL_CHANGER_OUTPUT:
                mask = 1 << bit.bit
                await session.control.call("SetDigitalIO", dio.SetDigitalIORequest(
                    type="output", unit_id=unit.unit_id, bits_on=mask if couple else 0,
                    bits_off=0 if couple else mask, description="CRCL tool changer"),
                    stub=session.link.digital_io)
                return
    raise CrclError(f"the cell has no {TOOL_CHANGER_OUTPUT!r} output: no tool changer")


async def close_tool_changer(session, cmd: m.CloseToolChanger) -> str:
    await _changer(session, couple=True)
    tool, _ = await _tool(session)
    if not tool:
        await _changer(session, couple=False)
        raise CrclError("no tool coupled: the arm is at no tool in the changing station")
    return f"tool {tool} coupled"


async def open_tool_changer(session, cmd: m.OpenToolChanger) -> str:
    tool, _ = await _tool(session)
    await _changer(session, couple=False)
    return f"tool {tool} released" if tool else "changer open (no tool was coupled)"


async def set_end_effector(session, cmd: m.SetEndEffector) -> str:
    tool, state = await _tool(session)
    if not tool:
        raise CrclError("no end effector on the arm")
    # A positive setting: open (gripper) or powered (vacuum); landscape.v1's main function
    # closes the gripper and powers the cup.
    activate = (cmd.setting > 0) == is_vacuum(tool, state)
    rpc = "ActivateTool" if activate else "DeactivateTool"
    request = (end_effector_pb2.ActivateToolRequest if activate
               else end_effector_pb2.DeactivateToolRequest)(tool_id=tool, bit_field=MAIN_FUNCTION)
    await session.control.call(rpc, request)
    session.settings.end_effector_setting = cmd.setting
    return f"{tool}: {rpc}"


async def set_end_effector_parameters(session, cmd: m.SetEndEffectorParameters) -> str:
    tool, _ = await _tool(session)
    names = ", ".join(s.name for s in cmd.settings)
    raise CrclError(f"the end effector {tool or '(none mounted)'} has no parameters to set "
                    f"({names}): landscape.v1 tools take none")


async def enable_gripper(session, cmd: m.EnableGripper) -> str:
    if cmd.options:
        raise CrclError("gripper options are not supported")
    session.settings.grippers_disabled.discard(cmd.gripper_name)
    return f"gripper {cmd.gripper_name} reported"


async def disable_gripper(session, cmd: m.DisableGripper) -> str:
    session.settings.grippers_disabled.add(cmd.gripper_name)
    return f"gripper {cmd.gripper_name} not reported"


async def enable_sensor(session, cmd: m.EnableSensor) -> str:
    if cmd.options:
        raise CrclError("sensor options are not supported")
    # The gateway's one state stream carries it from now on, once the device has accepted it.
    await session.link.feed.watch(session, session.settings.sensors | {cmd.sensor_id})
    session.settings.sensors.add(cmd.sensor_id)
    return f"sensor {cmd.sensor_id} reported"


async def disable_sensor(session, cmd: m.DisableSensor) -> str:
    if cmd.sensor_id not in session.settings.sensors:
        raise CrclError(f"sensor {cmd.sensor_id} is not enabled")
    session.settings.sensors.discard(cmd.sensor_id)
    await session.link.feed.watch(session, session.settings.sensors)
    return f"sensor {cmd.sensor_id} no longer reported"


async def run_program(session, cmd: m.RunProgram) -> str:
    reply = await session.control.call("SendCommand",
                                       end_effector_pb2.SendCommandRequest(input=cmd.text))
    return f"vendor program ran: {reply.result}"

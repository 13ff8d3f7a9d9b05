"""CRCL commands on the tool, the tool changer, sensors and the vendor hook.

landscape.v1 names the mounted tool and its state (GetEndEffectorState), switches its main
function with ActivateTool / DeactivateTool (bit 0: close the gripper, or suction on), changes
tools at the rack (GetTool / PutTool: the fine moves into and out of a slot, with the contact
of the coupling allowed, and the changer's lock), couples and releases with the cell's
"toolchanger_lock" output (DigitalIOService), tells where the rack's tools are
(GetCellDescription), reads sensors (the state stream) and passes text to the vendor
(SendCommand). Where the device answers UNIMPLEMENTED, the command is a CRCL_Error saying so.

The tool changer (spec V: the arm is moved to an attachment or detachment position, then the
changer closes or opens). A tool's changer position is its plate in the rack: the flange at
the plate (within SLOT_REACH, the device's own lock distance) couples or releases there with
the lock output; the flange above the plate on its axis (up to DOCK_REACH, as a CRCL client
can reach it without touching the coupling) has the device's GetTool / PutTool do the last
moves along the axis and the lock. Anywhere else, both commands are errors.
"""
from __future__ import annotations

import numpy as np
import pinocchio as pin

from landscape.gateway import model as m
from landscape.gateway import poses
from landscape.gateway.device_units import DeviceUnits
from landscape.gateway.errors import CrclError, describe
from landscape.gateway.motions import SETTLE_TIMEOUT, present, run_motion
from landscape.gateway.rates import push_rates
from landscape.gateway.status import is_vacuum
from landscape.gateway.workstation import BARE
from landscape.client import Frame, LandscapeError

TOOL_CHANGER_OUTPUT = "toolchanger_lock"    # the cell's output: 1 couples, 0 releases
MAIN_FUNCTION = 1                           # bit 0 of ActivateTool's bit field
SLOT_REACH = 0.005           # m: the flange this near a plate is at it (the device's lock distance)
DOCK_REACH = 0.3             # m: the flange on a plate's axis up to this far above it is docking
AXIS_REACH = 0.002           # m off the plate's axis
ANGLE_REACH = np.radians(3.0)   # rad between the flange's and the plate's orientation
ON_STATES = ("closed", "suction_on", "holding")   # the device's tool states, function on
OFF_STATES = ("open", "off")                       # and off


async def _tool(session) -> tuple[str, str]:
    reply = await session.control.robot.get_end_effector_state()
    return reply.current_ee, reply.ee_state


async def _changer(session, couple: bool) -> None:
    robot = session.control.robot
    for unit in (await robot.list_digital_io()).units:
        for bit in unit.bits:
            if unit.type == "output" and bit.name == TOOL_CHANGER_OUTPUT:
                mask = 1 << bit.bit
                await robot.set_digital_io(unit.unit_id, bits_on=mask if couple else 0,
                                           bits_off=0 if couple else mask,
                                           description="CRCL tool changer")
                return
    raise CrclError(f"the cell has no {TOOL_CHANGER_OUTPUT!r} output: no tool changer")


def _matrix(pose) -> np.ndarray:
    """4x4 of a landscape.v1 Pose in m and rad (the cell's description is in SI)."""
    return poses.matrix(np.array([pose.x, pose.y, pose.z, pose.roll, pose.pitch, pose.yaw]))


async def _slots(session) -> dict[str, np.ndarray]:
    """Each rack tool's plate in its slot (4x4, base frame, m). A tool on the flange has no
    place in the cell's description: its slot is the one last seen (the gateway's device
    remembers them)."""
    cell = await session.control.robot.get_cell_description()
    world_to_base = np.linalg.inv(_matrix(cell.base))
    session.device.slots.update({body.name: world_to_base @ _matrix(body.pose)
                                 for body in cell.bodies
                                 if body.kind == body.KIND_TOOL and not body.attached_to})
    return session.device.slots


async def _flange(session) -> np.ndarray:
    """The flange now (4x4, base frame, m): the controlled point less the tool offset."""
    live = await present(session)
    reply = await session.control.robot.get_tool_offsets()
    offset = poses.matrix(np.array(DeviceUnits.of(reply.units).pb_pose_si(reply.offset)))
    return poses.matrix(live.tool_pose) @ np.linalg.inv(offset)


async def _ready_to_move(session) -> None:
    """Drives on and the session's rates on the device: GetTool / PutTool move the arm."""
    await session.control.ensure_active()
    await push_rates(session)


def _docking(flange: np.ndarray, plate: np.ndarray) -> float | None:
    """How far above the plate, along its axis, the flange is (0: at it), or None if it is
    not on the axis, turned as the plate, within DOCK_REACH."""
    relative = np.linalg.inv(plate) @ flange
    lateral, along = float(np.hypot(*relative[:2, 3])), float(-relative[2, 3])
    turned = np.linalg.norm(pin.log3(relative[:3, :3]))
    if lateral > AXIS_REACH or turned > ANGLE_REACH or not -SLOT_REACH <= along <= DOCK_REACH:
        return None
    return max(along, 0.0)


async def hold_end_effector(session, wanted: str) -> str:
    """InitCanon: the arm holds the cell's end effector (workstation.py): another tool on the
    flange goes back to its slot (PutTool) and this one is fetched (GetTool), then the arm
    returns to where it stood (a joint move), so a program starts from where it was sent, not
    from above the rack. "" leaves the flange as it is, BARE empties it. Returns what was
    done; CrclError naming why not."""
    target = "" if wanted == BARE else wanted
    tool, _ = await _tool(session)
    if not wanted or tool == target:
        return ""
    slots = await _slots(session)
    if target and target not in slots:
        raise CrclError(f"the cell's end effector {target!r} is no tool of this cell's rack "
                        f"({', '.join(slots) or 'it has none'})")
    await _ready_to_move(session)
    control, done = session.control, []
    stood = control.units.joints((await present(session)).joint_positions)
    try:
        if tool:
            await control.robot.put_tool(tool)
            done.append(f"the {tool} put back in the rack")
        if target:
            await control.robot.get_tool(target)
            done.append(f"the {target} fetched from the rack")
        await run_motion(session, lambda: control.robot.move_absolute(
            stood, Frame.JOINT, point_name="CRCL InitCanon: back from the rack"))
    except (LandscapeError, CrclError) as refused:
        raise CrclError(f"the arm cannot hold the cell's end effector ({wanted}): "
                        f"{describe(refused)}") from None
    return ", ".join(done)


async def close_tool_changer(session, cmd: m.CloseToolChanger) -> str:
    tool, _ = await _tool(session)
    if tool:
        raise CrclError(f"the {tool} is coupled already: OpenToolChanger at its slot first")
    flange, slots = await _flange(session), await _slots(session)
    for name, plate in slots.items():
        above = _docking(flange, plate)
        if above is None:
            continue
        if above <= SLOT_REACH:
            await _changer(session, couple=True)
            tool, _ = await _tool(session)
            if not tool:
                await _changer(session, couple=False)
                raise CrclError(f"the changer did not couple the {name} at its plate")
            return f"tool {tool} coupled"
        await _ready_to_move(session)
        await session.control.robot.get_tool(name)
        return f"tool {name} coupled (the device docked it from {above:.3f} m above)"
    raise CrclError(f"the arm is at no tool changer: the flange must be at a rack tool's plate "
                    f"or on its axis above it ({', '.join(slots) or 'no tools in the rack'})")


async def open_tool_changer(session, cmd: m.OpenToolChanger) -> str:
    tool, _ = await _tool(session)
    if not tool:
        await _changer(session, couple=False)
        return "changer open (no tool was coupled)"
    plate = (await _slots(session)).get(tool)
    above = None if plate is None else _docking(await _flange(session), plate)
    if plate is not None and above is None:
        raise CrclError(f"the {tool} is not at its rack slot: bring the flange onto the slot's "
                        f"axis above it (or into it), then OpenToolChanger")
    if plate is None or above <= SLOT_REACH:   # the device checks the slot itself
        await _changer(session, couple=False)
        return f"tool {tool} released"
    await _ready_to_move(session)
    await session.control.robot.put_tool(tool)
    return f"tool {tool} released into its slot (the device docked it from {above:.3f} m above)"


async def set_end_effector(session, cmd: m.SetEndEffector) -> str:
    tool, state = await _tool(session)
    if not tool:
        raise CrclError("no end effector on the arm")
    # A positive setting: open (gripper) or powered (vacuum); landscape.v1's main function
    # closes the gripper and powers the cup.
    activate = (cmd.setting > 0) == is_vacuum(tool, state)
    robot = session.control.robot
    rpc = "ActivateTool" if activate else "DeactivateTool"
    switch = robot.activate_tool if activate else robot.deactivate_tool
    await switch(tool, MAIN_FUNCTION)
    session.settings.end_effector_setting = cmd.setting
    # Done once the state stream shows it too, so the next GetStatus does.
    states = ON_STATES if activate else OFF_STATES
    if await session.device.feed.until(lambda s: s.message.end_effector_state in states,
                                       SETTLE_TIMEOUT) is None:
        raise CrclError(f"the device did {rpc} but its state stream does not show the {tool} "
                        f"{' or '.join(states)} within {SETTLE_TIMEOUT:g} s")
    return f"{tool}: {rpc}"


async def set_end_effector_parameters(session, cmd: m.SetEndEffectorParameters) -> str:
    tool, _ = await _tool(session)
    names = ", ".join(s.name for s in cmd.settings)
    raise CrclError(f"the end effector {tool or '(none mounted)'} has no parameters to set "
                    f"({names}): landscape.v1 tools take none")


async def enable_gripper(session, cmd: m.EnableGripper) -> str:
    if cmd.options:
        names = ", ".join(o.name for o in cmd.options)
        raise CrclError(f"GripperOption ({names}): landscape.v1 tools take no options")
    session.settings.grippers_disabled.discard(cmd.gripper_name)
    return f"gripper {cmd.gripper_name} reported"


async def disable_gripper(session, cmd: m.DisableGripper) -> str:
    session.settings.grippers_disabled.add(cmd.gripper_name)
    return f"gripper {cmd.gripper_name} not reported"


async def enable_sensor(session, cmd: m.EnableSensor) -> str:
    """Reported in SensorStatuses from now on; SensorOption tare=true zeroes it first at its
    present reading (the device's vendor command "tare <sensor>")."""
    tare = False
    for option in cmd.options:
        if option.name != "tare" or option.value not in ("true", "false"):
            raise CrclError(f"SensorOption {option.name}={option.value!r}: the one option is "
                            f"tare (true: zero the sensor at its present reading, or false)")
        tare = option.value == "true"
    # The gateway's one state stream carries it from now on, once the device has accepted it.
    await _watch(session, session.settings.sensors | {cmd.sensor_id})
    session.settings.sensors.add(cmd.sensor_id)
    if tare:
        await session.control.robot.send_command(f"tare {cmd.sensor_id}")
        await _fresh_sample(session.device.feed)
    return f"sensor {cmd.sensor_id} reported{', tared' if tare else ''}"


async def _fresh_sample(feed) -> None:
    """Until a sample taken after now is there for GetStatus: the second one to arrive (the
    first may have been on its way)."""
    for _ in range(2):
        newest = feed.latest.message.sequence if feed.latest is not None else -1
        if await feed.until(lambda s: s.message.sequence > newest, SETTLE_TIMEOUT) is None:
            raise CrclError(f"no state from the device within {SETTLE_TIMEOUT:g} s: "
                            f"{feed.stale() or 'the stream is stalled'}")


async def disable_sensor(session, cmd: m.DisableSensor) -> str:
    if cmd.sensor_id not in session.settings.sensors:
        raise CrclError(f"sensor {cmd.sensor_id} is not enabled")
    session.settings.sensors.discard(cmd.sensor_id)
    await _watch(session, session.settings.sensors)
    return f"sensor {cmd.sensor_id} no longer reported"


async def _watch(session, sensors) -> None:
    """These sensors in the gateway's state stream; CrclError if the device cannot put them in."""
    try:
        await session.device.feed.watch(session, sensors)
    except LandscapeError as refused:
        raise CrclError(f"the device's state stream cannot carry {', '.join(sorted(sensors))} "
                        f"({refused.code.name}: {refused.message})") from None


async def run_program(session, cmd: m.RunProgram) -> str:
    reply = await session.control.robot.send_command(cmd.text)
    return f"vendor program ran: {reply.result}"

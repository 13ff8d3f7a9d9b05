"""CRCL motion commands as landscape.v1 motions.

Poses arrive in CRCL's frame (the session's workstation frame, its units); the device is sent
them in the robot's base frame, in its own units (the session's Control converts), and the end
of a motion is judged in CRCL's frame again, where the tolerances' X, Y and Z are.

- MoveTo: one MoveAbsolute, straight or joint-interpolated, carrying its rates; with guards,
  the device's guarded move (guards.py).
- MoveThroughTo, and MoveScrew's helix: a named path (PathLoad, PathMove) from where the arm
  is through the waypoints, blended through the intermediate ones (transition speed > 0: the
  device's path passes through each point, so any intermediate tolerance holds; where the
  blend would collide, stopping at each), stopping at the last; the path is cleared
  afterwards.
- ActuateJoints: MoveAbsolute in the joint frame; per-joint speeds become the move's percent
  speed (every joint stays within its own), accelerations the percent acceleration.
- Per-command rates (PoseAndSetType, JointDetails) apply to that command only (rates.py); a
  pose's RotSpeed / RotAccel only to straight motions (the device times joint-interpolated
  ones by the joints), and is refused on others. The session's SetRotSpeed / SetRotAccel
  likewise hold straight motions.
  A pose's Coordinated is honoured either way: the device always ends rotation and
  translation together, which "coordinated" asks and "uncoordinated" allows (spec VII).
- A motion starts from the device's present state and its end is judged on a sample taken
  after the device's done event, against the end tolerance (the pose's own, else
  SetEndPoseTolerance's, else the default: settings.py); with no such sample, or a motion the
  device fails or aborts, the command is an error.
- Device calls go through the client core's AsyncRobot (session.control.robot): its typed
  commands, its command handles (a started motion's end comes from the core's event feed,
  which raises SessionEnded if the lock was lost meanwhile).
"""
from __future__ import annotations

import asyncio
import contextlib

import numpy as np

from landscape.client import (CommandFailed, CommandRefused, Frame, LandscapeError, Motion,
                              TagPoint, WrongState)
from landscape.gateway import model as m
from landscape.gateway import guards, poses
from landscape.gateway.errors import CrclError, refused_before_moving
from landscape.gateway.live import LiveState, live_state
from landscape.gateway.rates import (PERCENT_ACCEL, RatesFor, motion_rates, move_rates, percent,
                                    speed_percent)
from landscape.gateway.screw import helix_off_loop, point_count
from landscape.gateway.settings import DEFAULT_JOINT_TOLERANCE, ToleranceSi, tolerance_si
from landscape.gateway.units import CrclUnits
from landscape.v1 import types_pb2

SETTLE_TIMEOUT = 2.0             # s for a sample of the device taken after a motion's end


# ---- running a device motion ----------------------------------------------------------------------

async def run_motion(session, start) -> None:
    """Start a non-blocking device motion (`start()`: the robot's call) and wait for its end;
    an error unless it is done. The drives go on first if this session turned them off; if
    the device turned them off itself, the refused start is tried once more with them on."""
    control = session.control
    if control.drives_off:
        await control.ensure_active()
    for attempt in (1, 2):
        session.motion_start = asyncio.ensure_future(start())
        try:
            with refused_before_moving():
                command = await asyncio.shield(session.motion_start)
            break
        except WrongState:
            if attempt == 2 or await control.state() != types_pb2.DEVICE_STATE_INACTIVE:
                raise
            await control.ensure_active()
        finally:
            session.motion_start = None
    try:
        done = await command.wait(timeout=None)
    except CommandFailed as failed:          # failed or aborted; a lost lock raises its own
        raise CrclError(f"the device's {failed}") from None
    session.motion_ended = done.time.ToNanoseconds() / 1e9


async def present(session) -> LiveState:
    """The device's present state, to start a motion from; CrclError if the state stream has
    none (it is down or stalled)."""
    feed = session.device.feed
    sample = await feed.present(SETTLE_TIMEOUT)
    if sample is None:
        raise CrclError(f"no present state from the device to start from: {feed.stale()}")
    return live_state(sample)


async def _settled(session) -> LiveState:
    """The device's state once the motion has ended: a sample of a cycle at or after its done
    event. An older one cannot say where the motion ended: then the command fails."""
    feed = session.device.feed
    sample = await feed.taken_after(session.motion_ended, SETTLE_TIMEOUT)
    if sample is None:
        raise CrclError(f"the device reported the motion done, but no state taken after its "
                        f"end came within {SETTLE_TIMEOUT:g} s ({feed.stale() or 'no new sample'})"
                        f": the end pose is unchecked")
    return live_state(sample)


def check_pose(units: CrclUnits, goal: np.ndarray, tolerance: ToleranceSi,
               actual: np.ndarray) -> str:
    """CrclError unless the SI pose `actual` is within `tolerance` of `goal`; else a
    description of how near it is. A limit left unset is no limit (settings give defaults)."""
    offsets, x_angle, z_angle = poses.deviation(goal, actual)
    for axis, error, limit in zip("XYZ", offsets, (tolerance.x, tolerance.y, tolerance.z)):
        if limit is not None and error > limit:
            raise CrclError(f"ended {units.length_out(error):.6g} {units.length} off in {axis}, "
                            f"beyond the tolerance {units.length_out(limit):.6g}")
    for axis, error, limit in (("XAxis", x_angle, tolerance.x_axis),
                               ("ZAxis", z_angle, tolerance.z_axis)):
        if limit is not None and error > limit:
            raise CrclError(f"ended with {axis} {units.angle_out(error):.6g} {units.angle} off, "
                            f"beyond the tolerance {units.angle_out(limit):.6g}")
    return f"reached within {units.length_out(float(max(offsets))):.3g} {units.length}"


def _end_tolerance(session, pose: m.Pose | None) -> ToleranceSi:
    """The pose's own tolerance, with the session's end tolerance where it sets none."""
    own = pose.settings.tolerance if pose is not None and pose.settings is not None else None
    if own is None:
        return session.settings.end_tolerance
    return tolerance_si(own, session.settings.units).over(session.settings.end_tolerance)


async def _check_end(session, goal: np.ndarray, pose: m.Pose | None) -> str:
    """`goal`: SI, in CRCL's frame."""
    live = await _settled(session)
    actual = poses.to_workstation(live.tool_pose, session.settings.frame)
    return check_pose(session.settings.units, goal, _end_tolerance(session, pose), actual)


# ---- the commands -----------------------------------------------------------------------------------

def _straight_only(straight: bool, pose_list) -> None:
    """The device holds the tool's rotation to its angular caps on straight motions only (it
    times joint-interpolated ones by the joints): a pose's own RotSpeed or RotAccel there would
    be ignored, so it is refused."""
    if straight:
        return
    for pose in pose_list:
        if pose.settings is not None and (pose.settings.rot_speed or pose.settings.rot_accel):
            raise CrclError("RotSpeed / RotAccel in a pose hold straight motions only (the "
                            "device times joint-interpolated motions by its joints): send it "
                            "with MoveStraight true, or without them")


async def move_to(session, cmd: m.MoveTo) -> str:
    if cmd.guards:
        return await _guarded_move_to(session, cmd)
    _straight_only(cmd.straight, [cmd.end])
    goal = poses.crcl_si(cmd.end, session.settings.units)
    [(speed, accel)], overrides = motion_rates(session, [cmd.end])
    if accel is not None:
        overrides[PERCENT_ACCEL] = accel
    control = session.control
    values = control.units.pose(poses.to_base(goal, session.settings.frame))
    rates = move_rates(session, overrides)
    await run_motion(session, lambda: control.robot.move_absolute(
        values, Frame.BASE, point_name=f"CRCL MoveTo {cmd.command_id}",
        speed=speed or speed_percent(session),
        motion=Motion.STRAIGHT if cmd.straight else Motion.JOINT, rates=rates))
    return await _check_end(session, goal, cmd.end)


async def _guarded_move_to(session, cmd: m.MoveTo) -> str:
    """MoveTo with guards: the device's guarded move (guards.py), in a straight line (which
    "any convenient trajectory" allows too)."""
    units, frame, control = session.settings.units, session.settings.frame, session.control
    goal = poses.crcl_si(cmd.end, units)
    goal_base = poses.to_base(goal, frame)
    tolerance = _end_tolerance(session, cmd.end)
    motion = guards.tool_motion((await present(session)).tool_pose, goal_base,
                                min(tolerance.x_axis, tolerance.z_axis))
    sensor = guards.sensor_of(cmd.guards)
    limits = guards.thresholds(session, cmd.guards,
                               guards.reading_si(await control.robot.get_sensor_reading(sensor)))
    [(speed, accel)], overrides = motion_rates(session, [cmd.end])
    if accel is not None:
        overrides[PERCENT_ACCEL] = accel
    in_device = ([control.units.length(v) for v in limits] if sensor == guards.RANGE_SENSOR
                 else limits)                                   # forces are N whatever the units
    async with RatesFor(session, overrides):     # MoveReact takes the device's settings
        await run_motion(session, lambda: control.robot.move_react(
            sensor, [control.units.length(v) for v in motion], in_device,
            speed or speed_percent(session)))
    live = await _settled(session)
    reading = guards.reading_si(await control.robot.get_sensor_reading(sensor))
    said = guards.outcome(session, cmd.guards, limits, goal_base, live.tool_pose, reading,
                          session.motion_ended)
    return said or await _check_end(session, goal, cmd.end)


async def move_through_to(session, cmd: m.MoveThroughTo) -> str:
    _straight_only(cmd.straight, cmd.waypoints)
    units, frame = session.settings.units, session.settings.frame
    percents, overrides = motion_rates(session, list(cmd.waypoints))
    goals = [poses.crcl_si(p, units) for p in cmd.waypoints]
    points = [(poses.to_base(goal, frame), *rates) for goal, rates in zip(goals, percents)]
    await run_path(session, cmd.command_id, points, cmd.straight, overrides)
    return await _check_end(session, goals[-1], cmd.waypoints[-1])


async def run_path(session, command_id: int, points, straight: bool, overrides=None,
                   point: str = "waypoint") -> None:
    """Through (pose SI (6,) in the base frame, speed percent or None, accel percent or None)
    points from where the arm is, blended through all but the last; `point` names them in
    errors. Where the blended path would collide (its curve through the points is not the
    segments between them) the path that stops at each point runs, if it would not: CRCL asks
    only that the waypoints be passed."""
    live = await present(session)
    name = f"{session.name.split()[0]}-{command_id}"
    motion = Motion.STRAIGHT if straight else Motion.JOINT
    control = session.control

    session_speed = speed_percent(session)

    def tags(transition: float) -> list[TagPoint]:   # accel 0: the run's own (its rates)
        return [TagPoint(control.units.pose(p), tag_name=f"waypoint {i + 1}", tag_index=i + 1,
                         transition_speed=0.0 if i == len(points) - 1 else transition,
                         speed=speed or session_speed, accel=accel or 0.0)
                for i, (p, speed, accel) in enumerate(points)]
    robot = control.robot
    try:
        # The path starts where the arm is, so its first segment is straight when asked.
        await robot.path_load(name, [TagPoint(control.units.joints(live.joint_positions),
                                              tag_name="start")], Frame.JOINT, motion=motion)
        with refused_before_moving(point):
            try:
                await robot.path_load(name, tags(session_speed), Frame.BASE, motion=motion)
            except CommandRefused as refused:
                if refused.reason != "COLLISION" or len(points) < 2:
                    raise
                await robot.path_load(name, tags(0.0), Frame.BASE, motion=motion)
        rates = move_rates(session, overrides)
        await run_motion(session, lambda: robot.path_move(name, 1, rates=rates))
    finally:
        await asyncio.shield(_clear(robot, name))


async def _clear(robot, name: str) -> None:
    with contextlib.suppress(LandscapeError):   # a path that never loaded has nothing to clear
        await robot.path_clear_path(name)


async def move_screw(session, cmd: m.MoveScrew) -> str:
    """Spec VII MoveScrew: to the start (any convenient trajectory), then along the tool axis by
    the free distance, then the screw: a rigid turn about the axis through the axis point
    (default: the controlled point), parallel to the tool's Z, while advancing along it. The
    start's speeds, accelerations and tolerance (a PoseAndSetType) hold for all of it."""
    units, frame = session.settings.units, session.settings.frame
    if cmd.start is not None:
        # Straight: the start's rates (RotSpeed too) then hold on the way to it as well.
        await move_to(session, m.MoveTo(command_id=cmd.command_id, straight=True, end=cmd.start))
    [(speed, accel)], overrides = (motion_rates(session, [cmd.start]) if cmd.start is not None
                                   else ([(None, None)], {}))
    here = poses.matrix((await present(session)).tool_pose)
    axis = here[:3, 2]
    if cmd.axial_distance_free:
        here[:3, 3] += axis * units.length_si(cmd.axial_distance_free)
        await run_path(session, cmd.command_id, [(poses.from_matrix(here), speed, accel)], True,
                       overrides, "the free move's point")
    center = here[:3, 3] if cmd.axis_point is None else poses.point_to_base(np.array(
        [units.length_si(cmd.axis_point.x), units.length_si(cmd.axis_point.y),
         units.length_si(cmd.axis_point.z)]), frame)
    turn, advance = units.angle_si(cmd.turn), units.length_si(cmd.axial_distance_screw)
    radius = float(np.linalg.norm(np.cross(here[:3, 3] - center, axis)))
    steps = point_count(turn, advance, radius)
    helix = await helix_off_loop(here, center, axis, turn, advance, steps)
    points = [(pose, speed, accel) for pose in helix]
    await run_path(session, cmd.command_id, points, True, overrides, "screw point")
    return await _check_end(session, poses.to_workstation(np.array(helix[-1]), frame), cmd.start)


async def actuate_joints(session, cmd: m.ActuateJoints) -> str:
    units, control = session.settings.units, session.control
    maxima, accel_maxima = control.limits.joint_speeds, control.limits.joint_accels
    target = (await present(session)).joint_positions.copy()
    speeds, accels = [], []
    for joint in cmd.joints:
        if joint.joint > len(target):
            raise CrclError(f"joint {joint.joint}: the arm has joints 1 to {len(target)}")
        if isinstance(joint.details, m.JointForceTorque):
            raise CrclError(f"JointForceTorque on joint {joint.joint}: landscape.v1 has no call "
                            f"that commands a joint's force or torque (the controller's torque "
                            f"mode is not part of the contract), so nothing moved; send "
                            f"JointSpeedAccel")
        target[joint.joint - 1] = units.angle_si(joint.position)
        if joint.details.speed is not None:
            speeds.append(percent(units.angle_si(joint.details.speed), maxima[joint.joint - 1]))
        if joint.details.accel is not None:
            accels.append(percent(units.angle_si(joint.details.accel),
                                   accel_maxima[joint.joint - 1]))
    rates = move_rates(session, {PERCENT_ACCEL: min(accels)} if accels else None)
    await run_motion(session, lambda: control.robot.move_absolute(
        control.units.joints(target), Frame.JOINT, point_name=f"CRCL ActuateJoints {cmd.command_id}",
        speed=min(speeds) if speeds else speed_percent(session), rates=rates))
    return _check_joints(session, cmd, target, await _settled(session))


def _check_joints(session, cmd: m.ActuateJoints, target: np.ndarray, live: LiveState) -> str:
    units = session.settings.units
    tolerances = dict(session.settings.joint_tolerances)
    tolerances.update({t.joint: units.angle_si(t.tolerance) for t in cmd.tolerances or ()})
    for joint in cmd.joints:
        error = abs(float(live.joint_positions[joint.joint - 1] - target[joint.joint - 1]))
        limit = tolerances.get(joint.joint, DEFAULT_JOINT_TOLERANCE)
        if error > limit:
            raise CrclError(f"joint {joint.joint} ended {units.angle_out(error):.6g} {units.angle} "
                            f"off, beyond its tolerance {units.angle_out(limit):.6g}")
    return "joints reached"


async def stop_motion(session, cmd: m.StopMotion) -> str:
    """Spec VII StopMotion; every kind starts at once, ahead of the commands before it
    (session.py). Immediate: drives off now, with no controlled stop asked first (the device
    brakes at its full deceleration and cuts the drives at rest; landscape.v1 has no stop that
    cuts them mid-motion but the operator's e-stop). Fast: a controlled stop on the path, then
    drives off. Normal: a controlled stop on the path, drives on."""
    if cmd.condition == "Immediate":
        await session.control.deactivate()
        return "stopped, drives off"
    await session.halt()
    if cmd.condition == "Fast":
        await session.control.deactivate()
        return "stopped on the path, drives off"
    return "stopped on the path"

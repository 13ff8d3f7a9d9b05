"""CRCL motion commands as landscape.v1 motions (poses in the device's world frame = CRCL's
workstation coordinates, m and rad).

- MoveTo: MoveAbsolute, straight or joint-interpolated.
- MoveThroughTo, and MoveScrew's helix: a named path (PathLoad, PathMove) from where the arm
  is through the waypoints, blended through the intermediate ones (transition speed > 0: the
  device's path passes through each point, so any intermediate tolerance holds), stopping at
  the last; the path is cleared afterwards.
- ActuateJoints: MoveAbsolute in the joint frame; per-joint speeds become the move's percent
  speed (every joint stays within its own), accelerations the percent acceleration.
- Per-command speed and acceleration (PoseAndSetType, JointDetails) apply to that command only.
- The end is checked against the end tolerance (the pose's own, or SetEndPoseTolerance) with
  the device's live state; a motion the device fails or aborts is an error.

Speeds: the device scales every limit by one percent speed (joints) and its linear and angular
speed settings (the tool tip). CRCL's TransSpeed v becomes percent 100 v / v_max with the linear
setting at v_max (so straight moves get v exactly and joint moves the same share of the
joints' maxima); RotSpeed w the angular setting 100 w / percent, at most the maximum.
"""
from __future__ import annotations

import asyncio
import math

import numpy as np
from scipy.spatial.transform import Rotation

from landscape.gateway import model as m
from landscape.gateway import poses
from landscape.gateway.errors import CrclError
from landscape.gateway.settings import SiRate, ToleranceSi, rate_si, tolerance_si
from landscape.v1 import control_pb2, motion_pb2, settings_pb2, types_pb2

MIN_PERCENT = 0.1            # the device needs a percent above 0
SCREW_STEP = math.radians(5.0)   # helix points at most this far apart in turn
SCREW_STEP_LENGTH = 0.005        # m, and along the axis
JOINT_FRAME = types_pb2.REFERENCE_FRAME_JOINT_FRAME
WORLD_FRAME = types_pb2.REFERENCE_FRAME_WORLD_CARTESIAN_FRAME


# ---- rates -----------------------------------------------------------------------------------------

def _percent(value: float, maximum: float) -> float:
    return min(100.0, max(MIN_PERCENT, 100.0 * value / maximum))


def speed_percent(session, rate: SiRate | None = None) -> float:
    limits = session.control.limits
    return _percent((rate or session.settings.trans_speed).value(limits.max_world_linear_velocity),
                    limits.max_world_linear_velocity)


def accel_percent(session, rate: SiRate | None = None) -> float:
    limits = session.control.accel_limits
    return _percent((rate or session.settings.trans_accel).value(limits.max_world_linear_accel),
                    limits.max_world_linear_accel)


async def push_rates(session) -> None:
    """The session's speeds and accelerations, as the device's settings (only those that
    changed since they were last sent)."""
    s, control = session.settings, session.control
    v_max, w_max = control.limits.max_world_linear_velocity, control.limits.max_world_angular_velocity
    a_max = control.accel_limits.max_world_linear_accel
    alpha_max = control.accel_limits.max_world_angular_accel
    percent = speed_percent(session)
    wanted = {
        ("SetSpeed", types_pb2.SPEED_TYPE_PERCENT_SPEED): percent,
        ("SetSpeed", types_pb2.SPEED_TYPE_LINEAR_SPEED): v_max,
        ("SetSpeed", types_pb2.SPEED_TYPE_ANGULAR_SPEED):
            min(w_max, s.rot_speed.value(w_max) * 100.0 / percent),
        ("SetAcceleration", types_pb2.ACCEL_TYPE_PERCENT_ACCEL): accel_percent(session),
        ("SetAcceleration", types_pb2.ACCEL_TYPE_LINEAR_ACCEL): s.trans_accel.value(a_max),
        ("SetAcceleration", types_pb2.ACCEL_TYPE_ANGULAR_ACCEL): s.rot_accel.value(alpha_max)}
    for (rpc, kind), value in wanted.items():
        if control.pushed.get((rpc, kind)) == value:
            continue
        request = (settings_pb2.SetSpeedRequest(speed=value, attribute=kind) if rpc == "SetSpeed"
                   else settings_pb2.SetAccelerationRequest(accel=value, attribute=kind))
        control.pushed.pop((rpc, kind), None)   # unknown until the device says yes
        await control.call(rpc, request)
        control.pushed[(rpc, kind)] = value


class _AccelFor:
    """A percent acceleration for one command's motion: set before it starts, and the
    session's own put back as soon as it has started (the device plans at the start)."""

    def __init__(self, session, percent: float | None):
        self.session, self.percent = session, percent

    async def __aenter__(self):
        if self.percent is not None:
            await self._set(self.percent)

    async def __aexit__(self, *exc):
        if self.percent is not None:
            await asyncio.shield(self._set(accel_percent(self.session)))

    async def _set(self, percent: float) -> None:
        control, key = self.session.control, ("SetAcceleration", types_pb2.ACCEL_TYPE_PERCENT_ACCEL)
        control.pushed.pop(key, None)
        await control.call(key[0], settings_pb2.SetAccelerationRequest(accel=percent, attribute=key[1]))
        control.pushed[key] = percent


def _pose_rates(session, pose: m.Pose) -> tuple[float | None, float | None]:
    """(speed percent, accel percent) a PoseAndSetType asks for, or None each."""
    settings, units = pose.settings, session.settings.units
    if settings is None:
        return None, None
    speed = accel = None
    if settings.trans_speed is not None:
        speed = speed_percent(session, rate_si(settings.trans_speed, units.length_si(1.0)))
    if settings.trans_accel is not None:
        accel = accel_percent(session, rate_si(settings.trans_accel, units.length_si(1.0)))
    return speed, accel


# ---- running a device motion ----------------------------------------------------------------------

async def _run(session, rpc: str, request, accel: float | None = None) -> None:
    """Start a non-blocking device motion and wait for its end; an error unless it is done."""
    await session.control.ensure_active()
    async with _AccelFor(session, accel):
        session.motion_start = asyncio.ensure_future(session.control.call(rpc, request))
        reply = await asyncio.shield(session.motion_start)
        session.motion_start = None
    command_id = reply.ret_val.command_id
    outcome = await session.link.events.outcome(command_id)
    session.motion_ended = outcome.time
    if outcome.result != "done":
        raise CrclError(f"the device's {rpc} {command_id} {outcome.result}"
                        f"{': ' + outcome.message if outcome.message else ''}")


async def _settled(session):
    """The live state once the motion has ended: a sample of a cycle after its done event."""
    return await session.link.feed.taken_after(session.motion_ended)


def _check_pose(session, goal: np.ndarray, tolerance: ToleranceSi, live) -> str:
    if live is None:
        return "the end pose is unchecked (no live state from the device)"
    offsets, x_angle, z_angle = poses.deviation(goal, live.tool_pose)
    units = session.settings.units
    for axis, error, limit in zip("XYZ", offsets, (tolerance.x, tolerance.y, tolerance.z)):
        if limit is not None and error > limit:
            raise CrclError(f"ended {units.length_out(error):.6g} {units.length} off in {axis}, "
                            f"beyond the tolerance {units.length_out(limit):.6g}")
    for axis, error, limit in (("XAxis", x_angle, tolerance.x_axis),
                               ("ZAxis", z_angle, tolerance.z_axis)):
        if limit is not None and error > limit:
            raise CrclError(f"ended with {axis} {units.angle_out(error):.6g} {units.angle} off, "
                            f"beyond the tolerance {units.angle_out(limit):.6g}")
    return (f"reached within {units.length_out(float(max(offsets))):.3g} {units.length}")


def _end_tolerance(session, pose: m.Pose) -> ToleranceSi:
    if pose.settings is not None and pose.settings.tolerance is not None:
        return tolerance_si(pose.settings.tolerance, session.settings.units)
    return session.settings.end_tolerance


# ---- the commands -----------------------------------------------------------------------------------

async def move_to(session, cmd: m.MoveTo) -> str:
    goal = poses.to_device(cmd.end, session.settings.units)
    speed, accel = _pose_rates(session, cmd.end)
    request = motion_pb2.MoveAbsoluteRequest(
        point_name=f"CRCL MoveTo {cmd.command_id}", frame=WORLD_FRAME, values=goal.tolist(),
        motion_type=(types_pb2.MOTION_TYPE_STRAIGHT_MOTION if cmd.straight
                     else types_pb2.MOTION_TYPE_JOINT_MOTION))
    if speed is not None:
        request.speed = speed
    await _run(session, "MoveAbsolute", request, accel)
    return _check_pose(session, goal, _end_tolerance(session, cmd.end), await _settled(session))


async def move_through_to(session, cmd: m.MoveThroughTo) -> str:
    units = session.settings.units
    points = [(poses.to_device(p, units), *_pose_rates(session, p)) for p in cmd.waypoints]
    await run_path(session, cmd.command_id, points, cmd.straight)
    return _check_pose(session, points[-1][0], _end_tolerance(session, cmd.waypoints[-1]),
                       await _settled(session))


async def run_path(session, command_id: int, points, straight: bool) -> None:
    """Through (pose SI (6,), speed percent or None, accel percent or None) points from where
    the arm is, blended through all but the last."""
    live = session.link.feed.latest
    if live is None:
        raise CrclError(f"no live state from the device to start the path from "
                        f"({session.link.feed.unavailable})")
    name = f"{session.name.split()[0]}-{command_id}"
    motion = types_pb2.MOTION_TYPE_STRAIGHT_MOTION if straight else types_pb2.MOTION_TYPE_JOINT_MOTION
    transition = speed_percent(session)
    tags = [types_pb2.TagStruct(
        x=p[0], y=p[1], z=p[2], roll=p[3], pitch=p[4], yaw=p[5], tag_name=f"waypoint {i + 1}",
        tag_index=i + 1, transition_speed=0.0 if i == len(points) - 1 else transition,
        speed=speed or 0.0, accel=accel or 0.0) for i, (p, speed, accel) in enumerate(points)]
    control = session.control
    try:
        # The path starts where the arm is, so its first segment is straight when asked.
        await _load(control, name, JOINT_FRAME, motion, [types_pb2.TagStruct(
            joint_values=live.joint_positions.tolist(), tag_name="start")])
        await _load(control, name, WORLD_FRAME, motion, tags)
        await _run(session, "PathMove", motion_pb2.PathMoveRequest(path_name=name,
                                                                    number_of_cycles=1))
    finally:
        await asyncio.shield(_clear(control, name))


async def _load(control, name: str, frame: int, motion: int, tags) -> None:
    header = motion_pb2.PathHeader(path_name=name, frame=frame, motion_type=motion,
                                   offset_type=types_pb2.OFFSET_TYPE_ABSOLUTE_DATA,
                                   number_of_points=len(tags))

    async def stream():
        yield motion_pb2.PathLoadRequest(header=header, tags=tags)
    await control.call("PathLoad", stream())


async def _clear(control, name: str) -> None:
    try:
        await control.call("PathClearPath", motion_pb2.PathClearPathRequest(path_name=name))
    except Exception:   # noqa: BLE001 - a path that never loaded has nothing to clear
        pass


async def move_screw(session, cmd: m.MoveScrew) -> str:
    """Spec VII MoveScrew: to the start (any convenient trajectory), then along the tool axis by
    the free distance, then the screw: a rigid turn about the axis through the axis point
    (default: the controlled point), parallel to the tool's Z, while advancing along it."""
    units = session.settings.units
    if cmd.start is not None:
        await move_to(session, m.MoveTo(command_id=cmd.command_id, straight=False, end=cmd.start))
    live = await _settled(session)
    if live is None:
        raise CrclError(f"no live state from the device ({session.link.feed.unavailable})")
    here = poses.matrix(live.tool_pose)
    axis = here[:3, 2]
    if cmd.axial_distance_free:
        here[:3, 3] += axis * units.length_si(cmd.axial_distance_free)
        await run_path(session, cmd.command_id, [(poses.from_matrix(here), None, None)], True)
    center = here[:3, 3] if cmd.axis_point is None else np.array(
        [units.length_si(cmd.axis_point.x), units.length_si(cmd.axis_point.y),
         units.length_si(cmd.axis_point.z)])
    turn, advance = units.angle_si(cmd.turn), units.length_si(cmd.axial_distance_screw)
    radius = float(np.linalg.norm(np.cross(here[:3, 3] - center, axis)))
    steps = max(1, math.ceil(max(abs(turn) / SCREW_STEP,
                                 math.hypot(abs(turn) * radius, abs(advance)) / SCREW_STEP_LENGTH)))
    points = []
    for s in range(1, steps + 1):
        spin = Rotation.from_rotvec(axis * turn * s / steps).as_matrix()
        pose = np.eye(4)
        pose[:3, :3] = spin @ here[:3, :3]
        pose[:3, 3] = center + spin @ (here[:3, 3] - center) + axis * advance * s / steps
        points.append((poses.from_matrix(pose), None, None))
    await run_path(session, cmd.command_id, points, True)
    return _check_pose(session, points[-1][0], session.settings.end_tolerance,
                       await _settled(session))


async def actuate_joints(session, cmd: m.ActuateJoints) -> str:
    units, control = session.settings.units, session.control
    live = session.link.feed.latest
    if live is None:
        raise CrclError(f"no live state from the device ({session.link.feed.unavailable})")
    maxima = control.limits.max_joint_velocities
    accel_maxima = control.accel_limits.max_joint_accels
    target = live.joint_positions.copy()
    speeds, accels = [], []
    for joint in cmd.joints:
        if joint.joint > len(target):
            raise CrclError(f"joint {joint.joint}: the arm has joints 1 to {len(target)}")
        if isinstance(joint.details, m.JointForceTorque):
            raise CrclError(f"joint {joint.joint}: force/torque control of a joint is not "
                            f"supported (landscape.v1 has no joint torque mode); use JointSpeedAccel")
        target[joint.joint - 1] = units.angle_si(joint.position)
        if joint.details.speed is not None:
            speeds.append(_percent(units.angle_si(joint.details.speed), maxima[joint.joint - 1]))
        if joint.details.accel is not None:
            accels.append(_percent(units.angle_si(joint.details.accel),
                                   accel_maxima[joint.joint - 1]))
    request = motion_pb2.MoveAbsoluteRequest(point_name=f"CRCL ActuateJoints {cmd.command_id}",
                                             frame=JOINT_FRAME, values=target.tolist())
    if speeds:
        request.speed = min(speeds)
    await _run(session, "MoveAbsolute", request, min(accels) if accels else None)
    return _check_joints(session, cmd, target, await _settled(session))


def _check_joints(session, cmd: m.ActuateJoints, target: np.ndarray, live) -> str:
    units = session.settings.units
    tolerances = dict(session.settings.joint_tolerances)
    tolerances.update({t.joint: units.angle_si(t.tolerance) for t in cmd.tolerances or ()})
    if live is None:
        return "the end position is unchecked (no live state from the device)"
    for joint in cmd.joints:
        error = abs(float(live.joint_positions[joint.joint - 1] - target[joint.joint - 1]))
        limit = tolerances.get(joint.joint)
        if limit is not None and error > limit:
            raise CrclError(f"joint {joint.joint} ended {units.angle_out(error):.6g} {units.angle} "
                            f"off, beyond its tolerance {units.angle_out(limit):.6g}")
    return "joints reached"


async def stop_motion(session, cmd: m.StopMotion) -> str:
    """Normal: a controlled stop on the path, drives on. Fast: the same, then drives off.
    Immediate: drives off at once; the device stops along the path at full deceleration before
    the drives go off (landscape.v1 has no stop that cuts the drives mid-motion but the
    e-stop)."""
    if cmd.condition == "Immediate":
        await _deactivate(session)
        return "stopped, drives off"
    await session.halt()
    if cmd.condition == "Fast":
        await _deactivate(session)
        return "stopped on the path, drives off"
    return "stopped on the path"


async def _deactivate(session) -> None:
    if await session.control.state() in (types_pb2.DEVICE_STATE_RESTING,
                                         types_pb2.DEVICE_STATE_MOVING,
                                         types_pb2.DEVICE_STATE_PAUSED):
        await session.control.call("Deactivate", control_pb2.DeactivateRequest())

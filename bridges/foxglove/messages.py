"""A device's state and events as Foxglove messages (the SDK's well-known schemas; JSON with a
JSON schema where Foxglove has none: the wrench, the I/O, the robot description).

Frame ids carry the device's name ("arm1/base_link"), so the arms of one cell share a scene;
the URDF this bridge serves names its links the same way (server.py).
"""
from __future__ import annotations

import numpy as np
from foxglove.messages import JointState, JointStates, Log, LogLevel, Timestamp

from landscape.robot.link_frames import pose_message

WRENCH_SCHEMA = {
    "title": "landscape.Wrench", "type": "object",
    "description": "a six-axis force/torque sensor's reading, in its own frame",
    "properties": {
        "timestamp": {"type": "object", "properties": {"sec": {"type": "integer"},
                                                        "nsec": {"type": "integer"}}},
        "sensor": {"type": "string"},
        "force": {"type": "object", "description": "N", "properties": {
            axis: {"type": "number"} for axis in "xyz"}},
        "torque": {"type": "object", "description": "N*m", "properties": {
            axis: {"type": "number"} for axis in "xyz"}},
    },
}
IO_SCHEMA = {
    "title": "landscape.DigitalIO", "type": "object",
    "description": "the digital I/O units and their named bits",
    "properties": {"units": {"type": "array", "items": {"type": "object", "properties": {
        "name": {"type": "string"}, "type": {"type": "string"}, "unit_id": {"type": "integer"},
        "bits_on": {"type": "integer"},
        "bits": {"type": "object", "additionalProperties": {"type": "boolean"}}}}}},
}
DESCRIPTION_SCHEMA = {
    "title": "landscape.RobotDescription", "type": "object",
    "properties": {"data": {"type": "string", "description": "the arm as URDF"}},
}
_LEVELS = {0: LogLevel.Info, 1: LogLevel.Info, 2: LogLevel.Warning, 3: LogLevel.Error,
           4: LogLevel.Fatal}


def stamp_ns(sample_or_event) -> int:
    return sample_or_event.time.ToNanoseconds()


def timestamp(ns: int) -> Timestamp:
    return Timestamp(sec=ns // 1_000_000_000, nsec=ns % 1_000_000_000)


def tool_pose(sample, frame_id: str, ns: int):
    """The tool tip (the stream's base-frame pose, metres and radians) as a PoseInFrame."""
    import pinocchio as pin
    pose = sample.tool_pose
    matrix = np.eye(4)
    matrix[:3, :3] = pin.rpy.rpyToMatrix(pose.roll, pose.pitch, pose.yaw)
    matrix[:3, 3] = (pose.x, pose.y, pose.z)
    return pose_message(matrix, frame_id, ns)


def joint_states(sample, names, ns: int) -> JointStates:
    efforts = list(sample.joint_torques) or [0.0] * len(sample.joint_positions)
    return JointStates(timestamp=timestamp(ns), joints=[
        JointState(name=name, position=q, velocity=v, effort=tau)
        for name, q, v, tau in zip(names, sample.joint_positions, sample.joint_velocities,
                                   efforts)])


def wrench(sample, ns: int) -> dict | None:
    """The first six-valued sensor of the sample (the force/torque sensor), or None."""
    for sensor in sample.sensors:
        if len(sensor.values) == 6:
            fx, fy, fz, tx, ty, tz = sensor.values
            return {"timestamp": {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000},
                    "sensor": sensor.name, "force": {"x": fx, "y": fy, "z": fz},
                    "torque": {"x": tx, "y": ty, "z": tz}}
    return None


def digital_io(values) -> dict:
    """[(DigitalIOUnit, bits_on)] as the I/O message."""
    return {"units": [{"name": unit.name, "type": unit.type, "unit_id": unit.unit_id,
                       "bits_on": bits_on,
                       "bits": {bit.name or str(bit.bit): bool(bits_on >> bit.bit & 1)
                                for bit in unit.bits}}
                      for unit, bits_on in values]}


def log(event, device: str) -> Log:
    """An event or alarm as a Log message: alarms at their severity, the rest as info."""
    kind = event.WhichOneof("detail")
    level = LogLevel.Info
    if kind == "alarm":
        alarm = event.alarm
        level = _LEVELS.get(alarm.severity, LogLevel.Warning)
        text = f"alarm {alarm.code}: {alarm.message}"
        if alarm.command_id:
            text += f" (command {alarm.command_id})"
    elif kind == "state_change":
        change = event.state_change
        text = f"state {change.from_state} -> {change.to_state}"
        if change.reason:
            text += f": {change.reason}"
    elif kind == "command":
        command = event.command
        text = f"{event.event_id}: {command.command} {command.command_id}"
        if command.message:
            text += f": {command.message}"
    elif kind == "operator_message":
        text = f"message from {event.operator_message.source}: {event.operator_message.text}"
    else:
        text = " ".join([event.event_id, *event.data])
    return Log(timestamp=timestamp(stamp_ns(event)), level=level, message=text,
               name=f"{device} #{event.sequence}")

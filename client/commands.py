"""Typed methods for every command of the contract, written once for the sync and asyncio clients.

Each method builds its request and hands it to `_call`, which `Robot` implements as a blocking
call and `AsyncRobot` as a coroutine: `robot.move_absolute(...)` returns a `Command` in one and
an awaitable of an `AsyncCommand` in the other. Names are the seed's, in snake_case (seed
`moveAbsolute` is `move_absolute`). Blocking commands return the landscape.v1 reply message;
non-blocking ones (`started=True` below) return a command handle whose `wait()` gives the done
event. Lengths and angles are in the device's units (`get_units`); frames are always named.
"""
from __future__ import annotations

from typing import Iterable, Iterator, Sequence

from landscape.client.values import (AccelType, AngularUnit, DeviceState, Frame, LinearUnit,
                                     Motion, Offset, Pose, SpeedType, TagPoint)
from landscape.v1 import (control_pb2, digital_io_service_pb2 as io_pb2, end_effector_pb2,
                          event_service_pb2, motion_pb2, sensing_pb2, settings_pb2, types_pb2)

DEVICE, IO, EVENTS = "device", "io", "events"

# Points per PathLoad message: a stream of chunks keeps every message small (seed 3.5.1).
PATH_CHUNK = 256

Vector = Sequence[float]   # three values: x, y, z


def _vector(values: Vector) -> types_pb2.Vector3:
    x, y, z = values
    return types_pb2.Vector3(x=x, y=y, z=z)


class DeviceCommands:
    """The command set; a subclass provides `_call(service, rpc, request, *, started, timeout)`."""

    def _call(self, service: str, rpc: str, request, *, started: bool = False,
              timeout: float | None = None):
        raise NotImplementedError

    # ---- 3.1 connect and power (lock is the session's: see Robot.lock) ----

    def release(self):
        """Seed 3.1.2: give control back (Inactive)."""
        return self._call(DEVICE, "Release", control_pb2.ReleaseRequest())

    def activate(self, timeout: float = 30.0):
        """Seed 3.1.2: drives on (Inactive -> Resting); blocks until enabled."""
        return self._call(DEVICE, "Activate", control_pb2.ActivateRequest(), timeout=timeout)

    def deactivate(self):
        """Seed 3.1.3: drives off, brakes on (Resting -> Inactive)."""
        return self._call(DEVICE, "Deactivate", control_pb2.DeactivateRequest())

    # ---- 3.2 set commands ----

    def set_speed(self, speed: float, type: SpeedType = SpeedType.PERCENT):
        """Seed 3.2.1: percent of maximum (0 < speed <= 100), or linear / angular units per s."""
        return self._call(DEVICE, "SetSpeed",
                          settings_pb2.SetSpeedRequest(speed=speed, attribute=SpeedType(type)))

    def set_acceleration(self, accel: float, type: AccelType = AccelType.PERCENT):
        """Seed 3.2.1: percent of maximum, or linear / angular units per s^2."""
        return self._call(DEVICE, "SetAcceleration", settings_pb2.SetAccelerationRequest(
            accel=accel, attribute=AccelType(type)))

    def set_tool_offset(self, offset: Pose):
        """Seed 3.2.1: the tool tip in the flange frame."""
        return self._call(DEVICE, "SetToolOffset",
                          settings_pb2.SetToolOffsetRequest(offset=offset.to_pb()))

    def set_world_cartesian_frame(self, frame: Pose):
        """Seed 3.2.1: the world frame in the robot base frame."""
        return self._call(DEVICE, "SetWorldCartesianFrame",
                          settings_pb2.SetWorldCartesianFrameRequest(frame=frame.to_pb()))

    def set_units(self, linear: LinearUnit, angular: AngularUnit):
        """Seed SetUnits: the units of every later call to this device, by every client."""
        return self._call(DEVICE, "SetUnits", settings_pb2.SetUnitsRequest(
            linear_units=LinearUnit(linear), angular_units=AngularUnit(angular)))

    # ---- 3.3 get commands (any client, any state) ----

    def get_units(self):
        return self._call(DEVICE, "GetUnits", settings_pb2.GetUnitsRequest())

    def get_velocities(self):
        return self._call(DEVICE, "GetVelocities", settings_pb2.GetVelocitiesRequest())

    def get_accelerations(self):
        return self._call(DEVICE, "GetAccelerations", settings_pb2.GetAccelerationsRequest())

    def get_max_velocities(self):
        return self._call(DEVICE, "GetMaxVelocities", settings_pb2.GetMaxVelocitiesRequest())

    def get_max_accelerations(self):
        return self._call(DEVICE, "GetMaxAccelerations",
                          settings_pb2.GetMaxAccelerationsRequest())

    def get_tool_offsets(self):
        return self._call(DEVICE, "GetToolOffsets", settings_pb2.GetToolOffsetsRequest())

    def get_world_cartesian_frame(self):
        """The world frame in the robot base frame, as SetWorldCartesianFrame set it."""
        return self._call(DEVICE, "GetWorldCartesianFrame",
                          settings_pb2.GetWorldCartesianFrameRequest())

    def get_robot_position(self):
        """Joints, and the tool tip in the world frame, with their units."""
        return self._call(DEVICE, "GetRobotPosition", settings_pb2.GetRobotPositionRequest())

    def get_motion_control_state(self):
        return self._call(DEVICE, "GetMotionControlState",
                          settings_pb2.GetMotionControlStateRequest())

    def get_tag_id(self):
        return self._call(DEVICE, "GetTagId", settings_pb2.GetTagIdRequest())

    # ---- 3.4 single motions (non-blocking) ----

    def move_absolute(self, values: Sequence[float], frame: Frame, *, point_name: str = "",
                      speed: float | None = None, motion: Motion | None = None,
                      rates: motion_pb2.MoveRates | None = None):
        """Seed 3.4.1: move to `values` (joints for Frame.JOINT, else x y z roll pitch yaw).
        speed: percent of maximum for this move only; motion: unset means Motion.JOINT;
        rates: this move's own accelerations and speed caps (the device's settings stay)."""
        return self._call(DEVICE, "MoveAbsolute", motion_pb2.MoveAbsoluteRequest(
            point_name=point_name, frame=Frame(frame), values=list(values), speed=speed,
            motion_type=None if motion is None else Motion(motion), rates=rates), started=True)

    def move_relative(self, values: Sequence[float], frame: Frame, *, point_name: str = "",
                      speed: float | None = None, motion: Motion | None = None,
                      rates: motion_pb2.MoveRates | None = None):
        """Seed 3.4.1: move by the offset `values` in `frame`."""
        return self._call(DEVICE, "MoveRelative", motion_pb2.MoveRelativeRequest(
            point_name=point_name, frame=Frame(frame), values=list(values), speed=speed,
            motion_type=None if motion is None else Motion(motion), rates=rates), started=True)

    def move_arc(self, arc: Sequence[float], goal: Sequence[float], frame: Frame, *,
                 offset: Offset = Offset.ABSOLUTE, point_name: str = "",
                 speed: float | None = None):
        """Seed 3.4.1: a circular move through `arc` to `goal`."""
        return self._call(DEVICE, "MoveArc", motion_pb2.MoveArcRequest(
            point_name=point_name, frame=Frame(frame), offset_type=Offset(offset),
            arc_value=list(arc), goal_value=list(goal), speed=speed), started=True)

    # ---- 3.5 paths ----

    def path_load(self, path_name: str, points: Sequence[TagPoint], frame: Frame, *,
                  motion: Motion = Motion.JOINT, offset: Offset = Offset.ABSOLUTE,
                  timeout: float = 60.0):
        """Seed 3.5.1: append `points` to the named path (all or nothing), streamed in chunks."""
        frame = Frame(frame)
        header = motion_pb2.PathHeader(path_name=path_name, frame=frame, motion_type=Motion(motion),
                                       offset_type=Offset(offset), number_of_points=len(points))
        for point in points:
            point.check(frame)
        return self._call(DEVICE, "PathLoad", _path_chunks(header, points, frame),
                          timeout=timeout)

    def path_clear_path(self, path_name: str):
        return self._call(DEVICE, "PathClearPath", motion_pb2.PathClearPathRequest(
            path_name=path_name))

    def path_move(self, path_name: str, number_of_cycles: int = 1,
                  rates: motion_pb2.MoveRates | None = None):
        """Seed 3.5.2: run the path `number_of_cycles` times (0: a dry run without aux
        commands); rates: this run's own accelerations and speed caps."""
        return self._call(DEVICE, "PathMove", motion_pb2.PathMoveRequest(
            path_name=path_name, number_of_cycles=number_of_cycles, rates=rates), started=True)

    # ---- 3.6 interruptions ----

    def stop_motion(self, timeout: float = 30.0):
        """Seed 3.6.1: decelerate along the path and hold (Paused); blocks until at rest."""
        return self._call(DEVICE, "StopMotion", motion_pb2.StopMotionRequest(), timeout=timeout)

    def resume_motion(self):
        return self._call(DEVICE, "ResumeMotion", motion_pb2.ResumeMotionRequest())

    def abort_motion(self, timeout: float = 30.0):
        return self._call(DEVICE, "AbortMotion", motion_pb2.AbortMotionRequest(), timeout=timeout)

    # ---- 3.7 sensors ----

    def get_sensor_reading(self, sensor_type: str):
        """Seed 3.7.1: "force_sensor" (N, N*m) or "laser_standoff_sensor" (linear units)."""
        return self._call(DEVICE, "GetSensorReading",
                          sensing_pb2.GetSensorReadingRequest(sensor_type=sensor_type))

    def move_react(self, sensor_type: str, motion: Vector, thresholds: Vector, speed: float, *,
                   compliance: Vector = (0, 0, 0), compliance_speed: float = 0.0,
                   gains: Vector = (0, 0, 0), envelope_min: Vector = (0, 0, 0),
                   envelope_max: Vector = (0, 0, 0)):
        """Seed 3.7.2: a guarded move by `motion` (tool frame) that stops when a sensor
        component crosses its non-zero threshold; speed in percent of maximum."""
        return self._call(DEVICE, "MoveReact", sensing_pb2.MoveReactRequest(
            sensor_type=sensor_type, motion=_vector(motion), thresholds=_vector(thresholds),
            speed=speed, compliance=_vector(compliance), compliance_speed=compliance_speed,
            gains=_vector(gains), envelope_min=_vector(envelope_min),
            envelope_max=_vector(envelope_max)), started=True)

    def comply(self, sensor_type: str, thresholds: Sequence[float], max_timeout: float, *,
               motion: Vector = (0, 0, 0), compliance: Vector = (0, 0, 0), speed: float = 0.0,
               compliance_speed: float = 0.0, max_travel_distances: Sequence[float] = (),
               proportional_gains: Sequence[float] = (), differential_gains: Sequence[float] = (),
               panic_stop_code: int = 0, envelope_min: Vector = (0, 0, 0),
               envelope_max: Vector = (0, 0, 0)):
        """Seed 3.7.2: keep the sensor at `thresholds` (fx fy fz tx ty tz) for at most
        `max_timeout` seconds by compliant perturbations."""
        return self._call(DEVICE, "Comply", sensing_pb2.ComplyRequest(
            sensor_type=sensor_type, thresholds=list(thresholds), max_timeout=max_timeout,
            motion=_vector(motion), compliance=_vector(compliance), speed=speed,
            compliance_speed=compliance_speed, max_travel_distances=list(max_travel_distances),
            proportional_gains=list(proportional_gains),
            differential_gains=list(differential_gains), panic_stop_code=panic_stop_code,
            envelope_min=_vector(envelope_min), envelope_max=_vector(envelope_max)), started=True)

    def manual_control(self, type: int):
        """Seed 3.7.3: sensing_pb2.MANUAL_CONTROL_TYPE_TEACHPENDANT, _SPACEBALL or _OFF."""
        return self._call(DEVICE, "ManualControl", sensing_pb2.ManualControlRequest(type=type))

    # ---- 3.8 end effectors and sendCommand ----

    def get_end_effector_state(self):
        return self._call(DEVICE, "GetEndEffectorState",
                          end_effector_pb2.GetEndEffectorStateRequest())

    def get_tool(self, tool_id: str, timeout: float = 120.0):
        """Seed 3.8.1: pick `tool_id` from the rack (moves the arm; blocks until done)."""
        return self._call(DEVICE, "GetTool", end_effector_pb2.GetToolRequest(tool_id=tool_id),
                          timeout=timeout)

    def put_tool(self, tool_id: str, timeout: float = 120.0):
        return self._call(DEVICE, "PutTool", end_effector_pb2.PutToolRequest(tool_id=tool_id),
                          timeout=timeout)

    def activate_tool(self, tool_id: str, bit_field: int = 1):
        """Seed 3.8.1: switch tool functions on; bit 0 is the main one (close, vacuum on)."""
        return self._call(DEVICE, "ActivateTool", end_effector_pb2.ActivateToolRequest(
            tool_id=tool_id, bit_field=bit_field))

    def deactivate_tool(self, tool_id: str, bit_field: int = 1):
        return self._call(DEVICE, "DeactivateTool", end_effector_pb2.DeactivateToolRequest(
            tool_id=tool_id, bit_field=bit_field))

    def send_command(self, input: str):
        """Seed 4.1 sendCommand: a vendor command line, e.g. "help"."""
        return self._call(DEVICE, "SendCommand", end_effector_pb2.SendCommandRequest(input=input))

    # ---- extensions ----

    def reset(self):
        """Leave the error state once its cause is cleared."""
        return self._call(DEVICE, "Reset", control_pb2.ResetRequest())

    def get_device_state(self):
        return self._call(DEVICE, "GetDeviceState", control_pb2.GetDeviceStateRequest())

    def get_robot_description(self):
        return self._call(DEVICE, "GetRobotDescription", control_pb2.GetRobotDescriptionRequest())

    def get_cell_description(self):
        """The cell around the arm where the device knows it to be: fixtures, tools (in the
        rack or on the flange), parts (where put down, or held), zones; world frame, m and
        rad whatever the units."""
        return self._call(DEVICE, "GetCellDescription", control_pb2.GetCellDescriptionRequest())

    def operate_panel(self, action: int):
        """The operator panel: control_pb2.PANEL_ACTION_PRESS_ESTOP, _RELEASE_ESTOP, ..."""
        return self._call(DEVICE, "OperatePanel", control_pb2.OperatePanelRequest(action=action))

    def post_message(self, text: str):
        """A message for the operator (at most 256 characters): every subscriber gets it as an
        OperatorMessage event naming this lock holder. Needs the lock."""
        return self._call(EVENTS, "PostMessage", event_service_pb2.PostMessageRequest(text=text))

    # ---- seed 4: digital I/O ----

    def set_digital_io(self, unit_id: int, bits_on: int = 0, bits_off: int = 0,
                       description: str = ""):
        """Seed 4.1: switch bits of an output unit on and off."""
        return self._call(IO, "SetDigitalIO", io_pb2.SetDigitalIORequest(
            type="output", unit_id=unit_id, bits_on=bits_on, bits_off=bits_off,
            description=description))

    def get_digital_io(self, unit_id: int, type: str = "input"):
        """Seed 4.1: the bits of an "input" or "output" unit."""
        return self._call(IO, "GetDigitalIO", io_pb2.GetDigitalIORequest(type=type, unit_id=unit_id))

    def signal_digital_io(self, unit_id: int, bit_string: int, type: str = "input", *,
                          polling_timeout_ms: int = 0, polling_cycle_ms: int = 0,
                          callback_type: int = io_pb2.CALLBACK_TYPE_CLIENT_EVENT):
        """Seed 4.1: watch bits; each time all are set, a digital-I/O event names the command."""
        return self._call(IO, "SignalDigitalIO", io_pb2.SignalDigitalIORequest(
            type=type, unit_id=unit_id, bit_string=bit_string, polling_timeout=polling_timeout_ms,
            polling_cycle_time=polling_cycle_ms, callback_type=callback_type), started=True)

    def list_digital_io(self):
        return self._call(IO, "ListDigitalIO", io_pb2.ListDigitalIORequest())


def _path_chunks(header: motion_pb2.PathHeader, points: Sequence[TagPoint],
                 frame: Frame) -> Iterator[motion_pb2.PathLoadRequest]:
    """The header with the first chunk, then the others; each converted as the stream takes
    it, so a long path never holds up an event loop for long."""
    for start in range(0, max(len(points), 1), PATH_CHUNK):
        yield motion_pb2.PathLoadRequest(
            header=header if start == 0 else None,
            tags=[point.to_pb(frame) for point in points[start:start + PATH_CHUNK]])


def jog_request(velocity: Sequence[float] | None, frame: Frame) -> sensing_pb2.JogRequest:
    """A jog message: the deadman held at `velocity` (percent of each axis maximum,
    -100..100), or released (None), which stops the arm."""
    if velocity is None:   # the server checks six velocities in every message
        return sensing_pb2.JogRequest(deadman=False, frame=Frame(frame), velocity=[0.0] * 6)
    return sensing_pb2.JogRequest(deadman=True, frame=Frame(frame), velocity=list(velocity))


def jog_requests(velocities: Iterable[Sequence[float]], frame: Frame,
                 ) -> Iterator[sensing_pb2.JogRequest]:
    """Jog messages with the deadman held, one per velocity, then the deadman released."""
    for velocity in velocities:
        yield jog_request(velocity, frame)
    yield jog_request(None, frame)


# What the lock holder does, from each state, to hand the device back (seed 3.1 and 3.6): one
# step at a time, re-reading the state after each, since a motion may end by itself meanwhile.
# In Error, Release gives up control without a Reset.
RELINQUISH_STEP = {
    DeviceState.ERROR: "release",
    DeviceState.MOVING: "stop_motion",
    DeviceState.PAUSED: "abort_motion",
    DeviceState.RESTING: "deactivate",
    DeviceState.INACTIVE: "release",
}
RELINQUISH_MAX_STEPS = 8

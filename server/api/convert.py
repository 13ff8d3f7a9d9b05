"""All proto <-> domain conversion, units included: the only place user units meet SI.

Servicers call these; the device never sees a proto message. Requests are checked here for
what only the wire can get wrong (unset enums, wrong array lengths); value ranges are the
device's business.
"""
from __future__ import annotations

import numpy as np
from google.protobuf import timestamp_pb2

from landscape.server.api import request_bounds
from landscape.server.events import bus as events
from landscape.server.errors import OutOfRange, ParamError
from landscape.server.planning.path_planning import PointSpec, at_point
from landscape.server.device.motion_settings import Kind, MotionSettings
from landscape.server.device.states import State
from landscape.server.planning.targets import Frame
from landscape.robot.units import AngularUnit, LinearUnit, Units
from landscape.v1 import (control_pb2, digital_io_service_pb2, event_service_pb2, sensing_pb2,
                          types_pb2)

# ---- return values, states, units, settings --------------------------------------------------

LINEAR = {types_pb2.LINEAR_UNIT_INCHES: LinearUnit.INCHES, types_pb2.LINEAR_UNIT_FEET: LinearUnit.FEET,
          types_pb2.LINEAR_UNIT_METERS: LinearUnit.METERS,
          types_pb2.LINEAR_UNIT_CENTIMETERS: LinearUnit.CENTIMETERS,
          types_pb2.LINEAR_UNIT_MILLIMETERS: LinearUnit.MILLIMETERS}
ANGULAR = {types_pb2.ANGULAR_UNIT_DEGREES: AngularUnit.DEGREES,
           types_pb2.ANGULAR_UNIT_RADIANS: AngularUnit.RADIANS}
LINEAR_PB = {v: k for k, v in LINEAR.items()}
ANGULAR_PB = {v: k for k, v in ANGULAR.items()}

DEVICE_STATE_PB = {state: types_pb2.DeviceState.Value(f"DEVICE_STATE_{state.name}") for state in State}


def ok(message: str = "done") -> types_pb2.RetVal:
    """CMD_EXEC_OK, with a word for people (the code, 0, is omitted from JSON output)."""
    return types_pb2.RetVal(ret_code=types_pb2.RETURN_CODE_CMD_EXEC_OK, ret_msg=message)


def started(command_id: str) -> types_pb2.RetVal:
    return types_pb2.RetVal(ret_code=types_pb2.RETURN_CODE_CMD_STARTED_OK, command_id=command_id,
                            ret_msg=f"started {command_id}: its done event follows on "
                                    f"EventService.Subscribe")


def enum_value(table: dict, value: int, name: str):
    try:
        return table[value]
    except KeyError:
        raise ParamError(f"{name} must be one of {', '.join(_names(table))}, got {value}") from None


def _names(table: dict) -> list[str]:
    return [getattr(v, "name", str(v)) for v in table.values()]


SPEED_KINDS = {types_pb2.SPEED_TYPE_PERCENT_SPEED: Kind.PERCENT,
               types_pb2.SPEED_TYPE_LINEAR_SPEED: Kind.LINEAR,
               types_pb2.SPEED_TYPE_ANGULAR_SPEED: Kind.ANGULAR}
ACCEL_KINDS = {types_pb2.ACCEL_TYPE_PERCENT_ACCEL: Kind.PERCENT,
               types_pb2.ACCEL_TYPE_LINEAR_ACCEL: Kind.LINEAR,
               types_pb2.ACCEL_TYPE_ANGULAR_ACCEL: Kind.ANGULAR}


def rate_to_si(kind: Kind, value: float, units: Units) -> float:
    """A speed or acceleration in SI: percent stays, linear and angular scale with the units."""
    if kind is Kind.LINEAR:
        return float(units.length_to_si(value))
    if kind is Kind.ANGULAR:
        return float(units.angle_to_si(value))
    return float(value)


# MoveRates' fields: what each sets, as SetSpeed or SetAcceleration of that kind would.
_MOVE_RATES = {"accel_percent": (Kind.PERCENT, False), "linear_speed": (Kind.LINEAR, True),
               "angular_speed": (Kind.ANGULAR, True), "linear_accel": (Kind.LINEAR, False),
               "angular_accel": (Kind.ANGULAR, False)}


def move_settings(settings: MotionSettings, request) -> MotionSettings:
    """The device's settings with a motion request's own rates (its MoveRates), each checked
    as its Set command would check it: for that motion alone, the device's stay."""
    if not request.HasField("rates"):
        return settings
    for name, (kind, speed) in _MOVE_RATES.items():
        if request.rates.HasField(name):
            value = rate_to_si(kind, getattr(request.rates, name), settings.units)
            settings = settings.with_speed(kind, value) if speed else settings.with_accel(kind, value)
    return settings


def units_to_pb(units: Units) -> types_pb2.Units:
    return types_pb2.Units(linear=LINEAR_PB[units.linear], angular=ANGULAR_PB[units.angular])


PANEL_ACTIONS = {control_pb2.PANEL_ACTION_PRESS_ESTOP: "press_estop",
                 control_pb2.PANEL_ACTION_RELEASE_ESTOP: "release_estop",
                 control_pb2.PANEL_ACTION_OPEN_DOOR: "open_door",
                 control_pb2.PANEL_ACTION_CLOSE_DOOR: "close_door"}


# What a setter's reply says it set, in the units the client speaks.
SYMBOLS = {LinearUnit.INCHES: "in", LinearUnit.FEET: "ft", LinearUnit.METERS: "m",
           LinearUnit.CENTIMETERS: "cm", LinearUnit.MILLIMETERS: "mm",
           AngularUnit.DEGREES: "deg", AngularUnit.RADIANS: "rad"}


def rate_text(what: str, kind: Kind, value: float, units: Units) -> str:
    """'speed 40 %', 'linear speed 200 mm/s', 'angular acceleration 90 deg/s^2': `what` is
    "speed" or "acceleration", `value` as the client sent it."""
    per = "/s" if what == "speed" else "/s^2"
    unit = {Kind.PERCENT: " %", Kind.LINEAR: f" {SYMBOLS[units.linear]}{per}",
            Kind.ANGULAR: f" {SYMBOLS[units.angular]}{per}"}[kind]
    name = what if kind is Kind.PERCENT else f"{kind.value} {what}"
    return f"{name} {value:g}{unit}"


def pose_text(what: str, pose: types_pb2.Pose, units: Units) -> str:
    """'tool offset x 0, y 0, z 100 mm; roll 0, pitch 0, yaw 90 deg', as the client sent it."""
    return (f"{what} x {pose.x:g}, y {pose.y:g}, z {pose.z:g} {SYMBOLS[units.linear]}; "
            f"roll {pose.roll:g}, pitch {pose.pitch:g}, yaw {pose.yaw:g} "
            f"{SYMBOLS[units.angular]}")


def units_text(units: Units) -> str:
    return f"units {units.linear.name.lower()} and {units.angular.name.lower()}"


def units_from_pb(linear: int, angular: int) -> Units:
    return Units(enum_value(LINEAR, linear, "linear_units"), enum_value(ANGULAR, angular, "angular_units"))


def pose_values(pose: types_pb2.Pose) -> list[float]:
    return [pose.x, pose.y, pose.z, pose.roll, pose.pitch, pose.yaw]


def pose_to_matrix(pose: types_pb2.Pose, units: Units) -> np.ndarray:
    values = pose_values(pose)
    if not np.all(np.isfinite(values)):
        raise ParamError(f"pose values must be finite, got {values}")
    return units.pose_to_matrix(values)


def matrix_to_pose(matrix: np.ndarray, units: Units) -> types_pb2.Pose:
    x, y, z, roll, pitch, yaw = (float(v) for v in units.matrix_to_pose(matrix))
    return types_pb2.Pose(x=x, y=y, z=z, roll=roll, pitch=pitch, yaw=yaw)


# ---- the cell ----------------------------------------------------------------------------

_BODY_KINDS = {"fixture": control_pb2.CellBody.KIND_FIXTURE, "tool": control_pb2.CellBody.KIND_TOOL,
               "part": control_pb2.CellBody.KIND_PART, "zone": control_pb2.CellBody.KIND_ZONE}


def cell_body_to_pb(body) -> control_pb2.CellBody:
    """A cell_view.Body; poses and sizes in m and rad whatever the device's units."""
    message = control_pb2.CellBody(name=body.name, kind=_BODY_KINDS[body.kind],
                                   color=list(body.color), urdf=body.urdf,
                                   attached_to=body.attached_to)
    if body.pose is not None:
        message.pose.CopyFrom(matrix_to_pose(body.pose, Units()))
    if body.size is not None:
        message.size.CopyFrom(types_pb2.Vector3(x=body.size[0], y=body.size[1], z=body.size[2]))
    return message


# ---- moves and paths -------------------------------------------------------------------------

FRAMES = {types_pb2.REFERENCE_FRAME_JOINT_FRAME: Frame.JOINT,
          types_pb2.REFERENCE_FRAME_BASE_CARTESIAN_FRAME: Frame.BASE,
          types_pb2.REFERENCE_FRAME_WORLD_CARTESIAN_FRAME: Frame.WORLD,
          types_pb2.REFERENCE_FRAME_TOOL_FRAME: Frame.TOOL}
FRAMES_PB = {v: k for k, v in FRAMES.items()}
STRAIGHT = {types_pb2.MOTION_TYPE_JOINT_MOTION: False, types_pb2.MOTION_TYPE_STRAIGHT_MOTION: True}


def move_values(frame: Frame, values, units: Units) -> np.ndarray:
    """A move's values in SI: joints all angles; Cartesian x, y, z lengths then roll, pitch, yaw."""
    values = np.asarray(values, dtype=float)
    if values.shape != (6,):
        raise ParamError(f"a move needs 6 values, got {len(values)}")
    if not np.all(np.isfinite(values)):
        raise ParamError(f"move values must be finite, got {values.tolist()}")
    if frame is Frame.JOINT:
        return units.angle_to_si(values)
    return np.concatenate([units.length_to_si(values[:3]), units.angle_to_si(values[3:])])


def motion_type(request) -> bool:
    """True for STRAIGHT_MOTION; an unset motion type is JOINT_MOTION (the seed names none)."""
    if not request.HasField("motion_type"):
        return False
    return enum_value(STRAIGHT, request.motion_type, "motion_type (JOINT_MOTION or STRAIGHT_MOTION)")


def optional_speed(request) -> float | None:
    return request.speed if request.HasField("speed") else None


OFFSETS = {types_pb2.OFFSET_TYPE_ABSOLUTE_DATA: False, types_pb2.OFFSET_TYPE_RELATIVE_DATA: True}
PATH_FRAMES = {k: v for k, v in FRAMES.items() if v is not Frame.TOOL}


def point_specs(tags, frame: Frame, units: Units, first: int = 0) -> list[PointSpec]:
    """The tag_structs of one PathLoad message in SI (joint_values for JOINT_FRAME, else x, y,
    z, roll, pitch, yaw), converted together: a message holds up to 10,000 of them. An error
    names its point, numbered from `first`."""
    if frame is Frame.JOINT:
        for index, tag in enumerate(tags):
            if len(tag.joint_values) != 6:
                raise at_point(first + index, ParamError(
                    f"a move needs 6 values, got {len(tag.joint_values)}"))
        values = np.array([tag.joint_values for tag in tags], dtype=float).reshape(-1, 6)
    else:
        values = np.array([(t.x, t.y, t.z, t.roll, t.pitch, t.yaw) for t in tags],
                          dtype=float).reshape(-1, 6)
    finite = np.isfinite(values).all(axis=1)
    if not finite.all():
        index = int(np.argmin(finite))
        raise at_point(first + index, ParamError(
            f"move values must be finite, got {values[index].tolist()}"))
    if frame is Frame.JOINT:
        values = units.angle_to_si(values)
    else:
        values = np.concatenate([units.length_to_si(values[:, :3]),
                                 units.angle_to_si(values[:, 3:])], axis=1)
    return [PointSpec(row, tag.tag_name, tag.tag_index, tag.time_delay, tag.transition_speed,
                      tag.speed, tag.accel, tuple(tag.aux_commands))
            for row, tag in zip(values, tags)]


class PathLoadStream:
    """The PathLoad stream, message by message: its header (from the first message) and every
    point, in SI; a stream of more than `max_points` points is refused as soon as it gets
    there, before the rest arrives."""

    def __init__(self, units: Units, max_points: int):
        self.units, self.max_points = units, max_points
        self.header, self.frame, self.specs = None, None, []
        self.messages = 0

    def feed(self, request) -> None:
        request_bounds.check(request)
        if len(self.specs) + len(request.tags) > self.max_points:
            raise OutOfRange(f"a path holds at most {self.max_points} points")
        if self.messages == 0:
            if not request.HasField("header"):
                raise ParamError("the first PathLoad message must carry the header")
            self.header = request.header
            self.frame = enum_value(PATH_FRAMES, self.header.frame, "frame (JOINT, BASE or WORLD)")
        elif request.HasField("header"):
            raise ParamError(f"message {self.messages} of the PathLoad stream carries a "
                             f"second header")
        self.messages += 1
        self.specs.extend(point_specs(request.tags, self.frame, self.units, len(self.specs)))

    def finish(self):
        """(header, frame, specs) once the stream has ended."""
        if self.header is None:
            raise ParamError("the PathLoad stream was empty")
        return self.header, self.frame, self.specs


# ---- events (event_service.proto) ------------------------------------------------------------

_PHASES = {phase: event_service_pb2.CommandEvent.Phase.Value(f"PHASE_{phase.name}")
           for phase in events.Phase}
_SEVERITIES = {severity: event_service_pb2.AlarmSeverity.Value(f"ALARM_SEVERITY_{severity.name}")
               for severity in events.Severity}


def event_to_proto(event: events.Event) -> event_service_pb2.Event:
    """The landscape.v1 Event for a domain event (time: unix seconds -> Timestamp)."""
    field, detail = _DETAILS[type(event.detail)](event.detail)
    return event_service_pb2.Event(sequence=event.sequence, time=_timestamp(event.time),
                    event_id=event.event_id, data=event.data, **{field: detail})


def detail_to_proto(detail: events.Detail):
    """The landscape.v1 message for one detail record, e.g. an RsvpRequest for a session."""
    return _DETAILS[type(detail)](detail)[1]


def _timestamp(unix_s: float) -> timestamp_pb2.Timestamp:
    stamp = timestamp_pb2.Timestamp()
    stamp.FromNanoseconds(round(unix_s * 1e9))
    return stamp


def _command(d: events.CommandEvent):
    return "command", event_service_pb2.CommandEvent(
        command_id=d.command_id, command=d.command, phase=_PHASES[d.phase],
        point_name=d.point_name, tag_name=d.tag_name, tag_index=d.tag_index, message=d.message)


def _alarm(d: events.Alarm):
    return "alarm", event_service_pb2.Alarm(severity=_SEVERITIES[d.severity], code=d.code, message=d.message,
                             command_id=d.command_id)


def _state_change(d: events.StateChange):
    return "state_change", event_service_pb2.StateChange(from_state=d.from_state, to_state=d.to_state,
                                          reason=d.reason)


def _digital_io(d: events.DigitalIOSignal):
    return "digital_io", event_service_pb2.DigitalIOSignal(command_id=d.command_id, type=d.type,
                                            unit_id=d.unit_id, bit_string=d.bit_string,
                                            bits_on=d.bits_on)


def _rsvp_request(d: events.RsvpRequest):
    return "rsvp_request", event_service_pb2.RsvpRequest(
        rsvp_id=d.rsvp_id, alarm=d.alarm, event_id=d.event_id, data=d.data, choices=d.choices,
        default_choice=d.default_choice, timeout_ms=round(d.timeout_s * 1000))


def _rsvp_answer(d: events.RsvpAnswer):
    return "rsvp_answer", event_service_pb2.RsvpAnswer(rsvp_id=d.rsvp_id, choice=d.choice, data=d.data,
                                        timed_out=d.timed_out)


def _operator_message(d: events.OperatorMessage):
    return "operator_message", event_service_pb2.OperatorMessage(text=d.text, source=d.source)


def _alarm_acknowledged(d: events.AlarmAcknowledged):
    return "alarm_acknowledged", event_service_pb2.AlarmAcknowledged(
        alarm_sequence=d.alarm_sequence, by=d.by, client=d.client, on_behalf_of=d.on_behalf_of)


def _events_lost(d: events.EventsLost):
    return "events_lost", event_service_pb2.EventsLost(first_sequence=d.first_sequence,
                                        last_sequence=d.last_sequence)


# One converter per detail type: (the Event oneof field, its message).
_DETAILS = {
    events.CommandEvent: _command, events.Alarm: _alarm, events.StateChange: _state_change,
    events.DigitalIOSignal: _digital_io, events.RsvpRequest: _rsvp_request,
    events.RsvpAnswer: _rsvp_answer, events.OperatorMessage: _operator_message,
    events.AlarmAcknowledged: _alarm_acknowledged, events.EventsLost: _events_lost,
}


# ---- sensors, guarded and compliant motion, jog (sensing.py, guarded.py, jogging.py) ---------

def sensor_to_pb(kind: str, values: np.ndarray, units: Units) -> list[float]:
    """A reading (sensing.py, SI) in the client's units: forces N, torques N * length unit,
    distances in the length unit."""
    values = np.asarray(values, dtype=float)
    if kind == "force_torque":
        return [*values[:3].tolist(), *units.length_from_si(values[3:]).tolist()]
    return units.length_from_si(values).tolist()


def sensor_to_si(kind: str, values, units: Units) -> np.ndarray:
    """Thresholds and envelopes of a sensor's components (forces N; distances in the length
    unit) in SI."""
    values = np.asarray(values, dtype=float)
    return values.copy() if kind == "force_torque" else units.length_to_si(values)


def vector3(v: types_pb2.Vector3) -> np.ndarray:
    return np.array([v.x, v.y, v.z])


def lengths3(v: types_pb2.Vector3, units: Units) -> np.ndarray:
    return units.length_to_si(vector3(v))


def comply_arrays(request, units: Units) -> dict:
    """ComplyRequest's arrays in SI, as guarded.GuardedMotion.comply takes them: lengths and
    angles of the travel distances, gains per length unit."""
    travel = np.asarray(request.max_travel_distances, dtype=float)
    if travel.size == 6:
        travel = np.concatenate([units.length_to_si(travel[:3]), units.angle_to_si(travel[3:])])
    thresholds = np.asarray(request.thresholds, dtype=float)
    if thresholds.size == 6:   # torques in N * length unit
        thresholds = np.concatenate([thresholds[:3], units.length_to_si(thresholds[3:])])
    return {"thresholds": thresholds, "travel": travel,
            "kp": units.length_to_si(np.asarray(request.proportional_gains, dtype=float)),
            "kd": units.length_to_si(np.asarray(request.differential_gains, dtype=float)),
            "motion": lengths3(request.motion, units),
            "compliance": lengths3(request.compliance, units)}


MANUAL_CONTROL = {sensing_pb2.MANUAL_CONTROL_TYPE_TEACHPENDANT: "teachpendant",
                  sensing_pb2.MANUAL_CONTROL_TYPE_SPACEBALL: "spaceball",
                  sensing_pb2.MANUAL_CONTROL_TYPE_OFF: "off"}

CALLBACKS = {digital_io_service_pb2.CALLBACK_TYPE_CLIENT_EVENT: "event",
             digital_io_service_pb2.CALLBACK_TYPE_CLIENT_ALARM: "alarm",
             digital_io_service_pb2.CALLBACK_TYPE_CLIENT_EVENT_RSVP: "event_rsvp",
             digital_io_service_pb2.CALLBACK_TYPE_CLIENT_ALARM_RSVP: "alarm_rsvp"}

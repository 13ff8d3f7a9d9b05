"""Issue 9: property-based fuzzing of every mutating RPC against a running server, the caller
holding the lock. Random and boundary values (NaN, infinities, subnormals, huge numbers, unset
and unknown enums, long strings and lists) in every field: the server stays SERVING, every
refusal is INVALID_ARGUMENT, OUT_OF_RANGE or FAILED_PRECONDITION with a message and an
ErrorInfo (never UNKNOWN or INTERNAL), and a refused call changes nothing: not the state, the
settings, the stored paths, nor where the arm is. Templates of Cartesian straight moves and
paths, with six-value targets of huge magnitude, reach the planner's bounds; sequences of the
control RPCs (Lock, Release, Activate, Deactivate, Reset, ManualControl) mixed with a move keep
the server sound. The server runs in this process under a memory cap (support.memory_cap), so
a request that makes it allocate without bound fails the test instead of the machine."""
from __future__ import annotations

import collections
import math

import grpc
import numpy as np
import pytest
from google.protobuf import message_factory
from google.protobuf.descriptor import FieldDescriptor as F
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from landscape.server.api import services
from landscape.server.device import stored_settings
from landscape.server.device.states import RULES, Lease, State
from landscape.v1 import (control_pb2, device_service_pb2_grpc, motion_pb2, sensing_pb2,
                          settings_pb2, types_pb2)

from support import Arm, assert_serving, error_info, wait_until

pytestmark = pytest.mark.usefixtures("memory_capped")
REFUSALS = {grpc.StatusCode.INVALID_ARGUMENT, grpc.StatusCode.OUT_OF_RANGE,
            grpc.StatusCode.FAILED_PRECONDITION}
# The control RPCs hand over or give up control: test_control_sequences drives them, each
# sequence followed by a return to the locked, active, resting arm. Jog has its own tests.
CONTROL = ("Lock", "Release", "Activate", "Deactivate", "Reset", "ManualControl")
NOT_FUZZED = {*CONTROL, "Jog"}
HUGE = st.one_of(st.sampled_from([5.0, 1e3, 1e6, 1e12, 1e300, -1e6, -1e12, -1e300, 1.7e308]),
                 st.floats(1e3, 1e308), st.floats(-1e308, -1e3))
DOUBLES = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -0.0, 5e-324, 1e-310, 1e-9, 1e-6, 0.5, 1.0, 1.5708, 3.2, 100.0,
                     100.0000001, 101.0, 1e9, 1e308, -1e308, math.nan, math.inf, -math.inf]),
    st.floats(-4, 4), HUGE)
# A target of exactly six values (joints, or x, y, z, roll, pitch, yaw), so that it passes the
# shape check and meets the bounds behind it: small steps, huge magnitudes, anything.
SIX = st.lists(st.one_of(st.floats(-0.2, 0.2), HUGE, DOUBLES), min_size=6, max_size=6)
INTS = {F.TYPE_INT32: (-2**31, 2**31 - 1), F.TYPE_UINT32: (0, 2**32 - 1),
        F.TYPE_INT64: (-2**63, 2**63 - 1), F.TYPE_UINT64: (0, 2**64 - 1)}
TEXT = st.one_of(st.text(max_size=20), st.sampled_from(["", "p", "x" * 257, "dout nope 1",
                                                        "dout gripper_close 2"]))


def _values(field, depth: int):
    """A repeated field's values; six of them half the time for a list of doubles."""
    values = st.lists(_value(field, depth), max_size=8 if depth else 30)
    if field.type == F.TYPE_DOUBLE:
        return st.one_of(SIX, values)
    return values


def _value(field, depth: int):
    if field.type in (F.TYPE_DOUBLE, F.TYPE_FLOAT):
        return DOUBLES
    if field.type in INTS:
        low, high = INTS[field.type]
        return st.one_of(st.integers(low, high), st.sampled_from([0, 1, -1, high, low]))
    if field.type == F.TYPE_BOOL:
        return st.booleans()
    if field.type == F.TYPE_ENUM:
        return st.integers(-1, len(field.enum_type.values) + 1)
    if field.type == F.TYPE_STRING:
        return TEXT
    if field.type == F.TYPE_MESSAGE:
        return _message(field.message_type, depth + 1)
    return st.none()


def _message(descriptor, depth: int = 0):
    cls = message_factory.GetMessageClass(descriptor)
    if depth > 2:
        return st.just(cls())
    fields = {}
    for field in descriptor.fields:
        value = _value(field, depth)
        fields[field.name] = (_values(field, depth) if field.is_repeated
                              else st.one_of(st.none(), value))

    @st.composite
    def build(draw):
        message = cls()
        for name, strategy in fields.items():
            value = draw(strategy)
            field = descriptor.fields_by_name[name]
            if value is None or (field.is_repeated and not value):
                continue
            if field.is_repeated:
                target = getattr(message, name)
                if field.type == F.TYPE_MESSAGE:
                    for item in value:
                        target.add().CopyFrom(item)
                else:
                    target.extend(value)
            elif field.type == F.TYPE_MESSAGE:
                getattr(message, name).CopyFrom(value)
            else:
                try:
                    setattr(message, name, value)
                except ValueError:   # an enum value the runtime refuses to hold
                    pass
        return message
    return build()


JOINT, BASE = types_pb2.REFERENCE_FRAME_JOINT_FRAME, types_pb2.REFERENCE_FRAME_BASE_CARTESIAN_FRAME
WORLD = types_pb2.REFERENCE_FRAME_WORLD_CARTESIAN_FRAME
STRAIGHT = types_pb2.MOTION_TYPE_STRAIGHT_MOTION
HOME = [0.3, 0.0, 1.5708, 0.0, 1.5708, 0.0]
# The tool tip (x, y, z m; roll, pitch, yaw rad) in the base (= world) frame at HOME.
HOME_TIP = [0.439, 0.1881, 0.803, 3.1416, 0.0, -2.8416]
# Requests each RPC accepts: the fuzzer also changes a few fields of these, so that a bad
# value meets code past the first check (tiny speeds, huge dwell times, targets light years
# away, ...).
TEMPLATES = {
    "MoveAbsolute": [motion_pb2.MoveAbsoluteRequest(frame=JOINT, values=HOME, speed=50),
                     motion_pb2.MoveAbsoluteRequest(frame=BASE, values=HOME_TIP,
                                                    motion_type=STRAIGHT)],
    "MoveRelative": [motion_pb2.MoveRelativeRequest(frame=JOINT, values=[0.1, 0, 0, 0, 0, 0]),
                     motion_pb2.MoveRelativeRequest(frame=WORLD, values=[0.05, 0, 0, 0, 0, 0],
                                                    motion_type=STRAIGHT)],
    "MoveArc": motion_pb2.MoveArcRequest(frame=BASE, offset_type=types_pb2.OFFSET_TYPE_RELATIVE_DATA,
                                         arc_value=[0.05, 0.05, 0, 0, 0, 0],
                                         goal_value=[0.1, 0, 0, 0, 0, 0]),
    "SetSpeed": settings_pb2.SetSpeedRequest(speed=50, attribute=types_pb2.SPEED_TYPE_PERCENT_SPEED),
    "SetAcceleration": settings_pb2.SetAccelerationRequest(
        accel=50, attribute=types_pb2.ACCEL_TYPE_PERCENT_ACCEL),
    "SetToolOffset": settings_pb2.SetToolOffsetRequest(offset=types_pb2.Pose(z=0.1)),
    "SetWorldCartesianFrame": settings_pb2.SetWorldCartesianFrameRequest(
        frame=types_pb2.Pose(x=0.1)),
    "SetUnits": settings_pb2.SetUnitsRequest(linear_units=types_pb2.LINEAR_UNIT_METERS,
                                             angular_units=types_pb2.ANGULAR_UNIT_RADIANS),
    "PathLoad": motion_pb2.PathLoadRequest(
        header=motion_pb2.PathHeader(path_name="fuzz", frame=JOINT,
                                     motion_type=types_pb2.MOTION_TYPE_JOINT_MOTION,
                                     offset_type=types_pb2.OFFSET_TYPE_ABSOLUTE_DATA),
        tags=[types_pb2.TagStruct(joint_values=HOME, tag_name="a"),
              types_pb2.TagStruct(joint_values=[0.5, 0, 1.5708, 0, 1.5708, 0], tag_name="b",
                                  time_delay=0.1, transition_speed=20)]),
    "PathLoad straight": motion_pb2.PathLoadRequest(
        header=motion_pb2.PathHeader(path_name="fuzz", frame=BASE, motion_type=STRAIGHT,
                                     offset_type=types_pb2.OFFSET_TYPE_RELATIVE_DATA),
        tags=[types_pb2.TagStruct(x=0.05), types_pb2.TagStruct(y=0.05, z=-0.05)]),
    "PathMove": motion_pb2.PathMoveRequest(path_name="fuzz", number_of_cycles=1),
}


@st.composite
def _mutated(draw, template):
    """`template` with one to three of its fields (or of its first sub-message) redrawn."""
    message = template.__class__()
    message.CopyFrom(template)
    target = message
    if template.DESCRIPTOR.name == "PathLoadRequest" and draw(st.booleans()):
        target = message.tags[draw(st.integers(0, len(message.tags) - 1))]
    names = [f.name for f in target.DESCRIPTOR.fields]
    for name in draw(st.lists(st.sampled_from(names), min_size=1, max_size=3, unique=True)):
        field = target.DESCRIPTOR.fields_by_name[name]
        target.ClearField(name)
        value = draw(_values(field, 1) if field.is_repeated else _value(field, 1))
        try:
            if field.is_repeated and field.type == F.TYPE_MESSAGE:
                for item in value:
                    getattr(target, name).add().CopyFrom(item)
            elif field.is_repeated:
                getattr(target, name).extend(value)
            elif field.type == F.TYPE_MESSAGE:
                getattr(target, name).CopyFrom(value)
            else:
                setattr(target, name, value)
        except ValueError:
            pass
    return message


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    a = Arm(tmp_path_factory.mktemp("fuzz"))
    yield a
    a.close()


def _targets():
    for spec in services.ALL:
        for method in spec.descriptor.methods:
            rule = RULES[method.name]
            if rule.lease is Lease.NONE or method.name in NOT_FUZZED or method.server_streaming:
                continue
            yield pytest.param(spec, method, id=method.name)


def _snapshot(arm):
    device = arm.server.device
    return (device.state, stored_settings.to_record(device.settings),
            {name: len(path.points) for name, path in device.path_runs.paths.items()},
            device.motions.running_id, device.feedback().command.copy())


def _back_to_rest(arm):
    """Stop and drop what a successful request started (it may end on its own meanwhile)."""
    device = arm.server.device
    for state, call, request in ((State.MOVING, arm.device.StopMotion,
                                  motion_pb2.StopMotionRequest()),
                                 (State.PAUSED, arm.device.AbortMotion,
                                  motion_pb2.AbortMotionRequest())):
        if device.state is state:
            try:
                call(request, timeout=30)
            except grpc.RpcError as error:
                if error.code() is not grpc.StatusCode.FAILED_PRECONDITION:
                    raise
    wait_until(lambda: device.state is State.RESTING, timeout=30)


@pytest.mark.parametrize("spec, method", list(_targets()))
def test_random_requests_are_refused_cleanly_or_done(arm, spec, method):
    stub = getattr(spec.grpc, f"{spec.name}Stub")(arm.session.channel)
    call = getattr(stub, method.name)

    def send(request):
        if method.client_streaming:
            header = motion_pb2.PathLoadRequest(header=request.header)
            return call(iter([header, motion_pb2.PathLoadRequest(tags=request.tags)]), timeout=30)
        return call(request, timeout=30)

    probe = message_factory.GetMessageClass(method.input_type)()
    try:
        send(probe)
    except grpc.RpcError as error:
        # Every RPC is built: one answering UNIMPLEMENTED is a regression, not a skip.
        assert error.code() is not grpc.StatusCode.UNIMPLEMENTED, f"{method.name} is not built"
    _back_to_rest(arm)

    templates = [t for name, t in TEMPLATES.items() if name.split()[0] == method.name]
    templates = [t for item in templates for t in (item if isinstance(item, list) else [item])]
    requests = st.one_of(_message(method.input_type),
                         *(_mutated(t) for t in templates for _ in range(2)))

    @settings(max_examples=60, deadline=None, derandomize=True,
              suppress_health_check=list(HealthCheck))
    @given(requests)
    def fuzz(request):
        before = _snapshot(arm)
        try:
            send(request)
        except grpc.RpcError as error:
            assert error.code() in REFUSALS, (error.code(), error.details(), request)
            assert error.details() and error_info(error).domain == "landscape"
            after = _snapshot(arm)
            assert after[:4] == before[:4], request
            assert np.allclose(after[4], before[4], atol=1e-9), request
        assert_serving(arm.session.channel)
        _back_to_rest(arm)

    fuzz()


def _control_step(arm):
    """A strategy for one (RPC name, request) of a control sequence."""
    session = arm.session
    own = st.builds(lambda: control_pb2.LockRequest(session_id=session.session_id,
                                                    session_secret=session.session_secret))
    lock = st.one_of(
        _message(control_pb2.LockRequest.DESCRIPTOR),
        st.builds(lambda secret: control_pb2.LockRequest(session_id=session.session_id,
                                                         session_secret=secret), TEXT))
    manual = st.builds(lambda kind: sensing_pb2.ManualControlRequest(type=kind),
                       st.integers(0, len(sensing_pb2.ManualControlType.values()) + 1))
    move = st.builds(lambda values: motion_pb2.MoveRelativeRequest(
        frame=WORLD, values=values, motion_type=STRAIGHT), SIX)
    return st.one_of(st.tuples(st.just("Lock"), own), st.tuples(st.just("Lock"), lock),
                     st.tuples(st.just("ManualControl"), manual),
                     st.tuples(st.just("MoveRelative"), move),
                     *(st.tuples(st.just(name), st.builds(getattr(control_pb2, f"{name}Request")))
                       for name in ("Release", "Activate", "Deactivate", "Reset")))


def _back_to_control(arm):
    """The locked, active, resting arm with manual control off, whatever a sequence did."""
    device, session = arm.server.device, arm.session
    if device.state in (State.MOVING, State.PAUSED):
        _back_to_rest(arm)
    if device.manual_control != "off":
        arm.device.ManualControl(sensing_pb2.ManualControlRequest(
            type=sensing_pb2.MANUAL_CONTROL_TYPE_OFF), timeout=10)
    if device.state is State.ERROR:
        arm.device.Reset(control_pb2.ResetRequest(), timeout=30)
    if device.lock_holder is None or device.lock_holder.id != session.session_id:
        session.lock()
    if device.state is State.INACTIVE:
        arm.device.Activate(control_pb2.ActivateRequest(), timeout=30)
    assert device.state is State.RESTING


def test_control_sequences_keep_the_server_sound(arm):
    """Lock (random, right and wrong secrets), Release, Activate, Deactivate, Reset,
    ManualControl and a straight move, in any order: each is done or refused (FAILED_PRECONDITION,
    INVALID_ARGUMENT, OUT_OF_RANGE; PERMISSION_DENIED once the lock is given up) with an
    ErrorInfo, a refusal changes nothing, and the server keeps serving."""
    stub = device_service_pb2_grpc.DeviceServiceStub(arm.session.channel)
    outcomes = collections.Counter()

    # Besides the drawn sequences, one that surely gives control up and takes it back, turns
    # manual control on and off, and stops the drives under a moving arm.
    session = arm.session
    handover = [("Release", control_pb2.ReleaseRequest()),
                ("Lock", control_pb2.LockRequest(session_id=session.session_id,
                                                 session_secret=session.session_secret)),
                ("Activate", control_pb2.ActivateRequest()),
                ("ManualControl", sensing_pb2.ManualControlRequest(
                    type=sensing_pb2.MANUAL_CONTROL_TYPE_TEACHPENDANT)),
                ("ManualControl", sensing_pb2.ManualControlRequest(
                    type=sensing_pb2.MANUAL_CONTROL_TYPE_OFF)),
                ("MoveRelative", motion_pb2.MoveRelativeRequest(
                    frame=WORLD, values=[0.02, 0, 0, 0, 0, 0], motion_type=STRAIGHT)),
                ("Deactivate", control_pb2.DeactivateRequest())]

    @settings(max_examples=40, deadline=None, derandomize=True,
              suppress_health_check=list(HealthCheck))
    @given(st.sampled_from(["RESTING", "INACTIVE", "UNLOCKED"]),
           st.lists(_control_step(arm), min_size=1, max_size=4))
    @example("INACTIVE", handover)
    def sequence(start, steps):
        # From each state a holder meets (Resting, locked with the drives off, unlocked).
        if start != "RESTING":
            stub.Deactivate(control_pb2.DeactivateRequest(), timeout=30)
        if start == "UNLOCKED":
            stub.Release(control_pb2.ReleaseRequest(), timeout=30)
        for name, request in steps:
            before = _snapshot(arm) + (arm.server.device.lock_holder,)
            try:
                reply = getattr(stub, name)(request, timeout=30)
                outcomes[name, "done"] += 1
                if name == "Lock":   # the session's calls carry the new lease from now on
                    arm.session.lease = reply.lease
            except grpc.RpcError as error:
                outcomes[name, error.code().name] += 1

                assert error.code() in REFUSALS | {grpc.StatusCode.PERMISSION_DENIED}, \
                    (name, error.code(), error.details(), request)
                assert error.details() and error_info(error).domain == "landscape"
                after = _snapshot(arm) + (arm.server.device.lock_holder,)
                assert after[:4] + after[5:] == before[:4] + before[5:], (name, request)
            assert_serving(arm.session.channel)
        _back_to_control(arm)

    sequence()
    print(sorted(outcomes.items()))
    # Not vacuous: control changed hands, the drives went off and on, the arm moved.
    for name in ("Lock", "Release", "Activate", "Deactivate", "ManualControl", "MoveRelative"):
        assert outcomes[name, "done"], sorted(outcomes.items())

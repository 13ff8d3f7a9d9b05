"""Issue 10, seed 3.7.1 and 3.7.2: sensor readings, guarded moves (moveReact) and compliant
moves (comply) on the real server, the simulated arm on the lock-step clock, the vacuum cup
pressing on the real (simulated) table."""
from __future__ import annotations

import re
import threading
import time

import grpc
import numpy as np
import pytest

from landscape.server.events import alarms
from landscape.server.cycle.feedback import MODEL_TAU, SENSORS, SEQ, WALL
from landscape.server.device.states import State
from landscape.v1 import (control_pb2, motion_pb2, sensing_pb2, settings_pb2, state_service_pb2,
                          state_service_pb2_grpc, types_pb2)

from support import (Arm, cell_file, error_info, locked_session, start_server, stubs,
                     wait_until)

# Weights, contacts and readings of the world: the pybullet backend's (tests/conftest.py).
pytestmark = pytest.mark.physics

TABLE_TOP = 0.2
FREE_SPOT = (0.65, 0.3)          # on the table, away from the parts and zones
CUP_MASS = 0.6
Z = types_pb2.Vector3


@pytest.fixture
def arm(tmp_path):
    a = Arm(tmp_path)
    yield a
    a.close()


def _with_cup(arm):
    arm.get_tool("vacuum")
    arm.move_down_to(*FREE_SPOT, TABLE_TOP + 0.03)
    return arm


@pytest.fixture
def cup(arm):
    """The arm with the vacuum cup, its tip 3 cm over a free spot of the table."""
    return _with_cup(arm)


# Shared by the tests that only read, or whose calls are refused (each of them checks that
# nothing moved and the arm rests): a server and a tool change each less per test. (Not a
# MoveReact refused for a collision: it has tared the force sensor by then.)
@pytest.fixture(scope="module")
def still_arm(tmp_path_factory):
    a = Arm(tmp_path_factory.mktemp("still_arm"))
    yield a
    a.close()


@pytest.fixture(scope="module")
def still_cup(tmp_path_factory):
    a = _with_cup(Arm(tmp_path_factory.mktemp("still_cup")))
    yield a
    a.close()


def _react(arm, **fields) -> list:
    reply = arm.device.MoveReact(sensing_pb2.MoveReactRequest(**fields), timeout=30)
    assert reply.ret_val.ret_code == types_pb2.RETURN_CODE_CMD_STARTED_OK
    return arm.wait_command(reply.ret_val.command_id)


def _touch(arm, threshold: float = -20.0, mm_per_s: float = 2.0) -> list:
    """Down onto the table at `mm_per_s` (as a % of the arm's 2 m/s) until fz reaches
    `threshold`."""
    return _react(arm, sensor_type="force_sensor", motion=Z(z=0.1), speed=mm_per_s / 20,
                  thresholds=Z(z=threshold))


def _refused(call) -> grpc.RpcError:
    with pytest.raises(grpc.RpcError) as refused:
        call()
    return refused.value


# ---- 3.7.1 getSensorReading -----------------------------------------------------------------

def test_readings_come_in_the_current_units_and_an_unknown_sensor_lists_the_known_ones(arm):
    flange_height = arm.tip()[2, 3]
    assert arm.reading("laser_standoff_sensor") == pytest.approx([flange_height - TABLE_TOP],
                                                                 abs=1e-3)
    assert np.abs(arm.reading("force_sensor")).max() < 1e-3   # nothing on the flange
    arm.device.SetUnits(settings_pb2.SetUnitsRequest(
        linear_units=types_pb2.LINEAR_UNIT_MILLIMETERS, angular_units=types_pb2.ANGULAR_UNIT_DEGREES))
    reply = arm.device.GetSensorReading(
        sensing_pb2.GetSensorReadingRequest(sensor_type="laser_standoff_sensor"))
    assert reply.current_data[0] == pytest.approx((flange_height - TABLE_TOP) * 1000, abs=1.0)
    assert reply.units.linear == types_pb2.LINEAR_UNIT_MILLIMETERS

    error = _refused(lambda: arm.device.GetSensorReading(
        sensing_pb2.GetSensorReadingRequest(sensor_type="sonar")))
    assert error.code() is grpc.StatusCode.INVALID_ARGUMENT
    assert error_info(error).metadata["ret_code"] == "-2"
    assert "force_sensor" in error.details() and "laser_standoff_sensor" in error.details()


def test_the_force_sensor_reads_at_the_tool_tip_in_the_tool_frame(still_cup):
    # The cup hangs down: its weight pulls the flange along the tool's z; at the tip, whose
    # frame is the flange's moved along z, the torques stay zero.
    reading = still_cup.reading()
    assert reading[:3] == pytest.approx([0, 0, CUP_MASS * 9.81], abs=0.02)
    assert np.abs(reading[3:]).max() < 1e-3


def test_torques_come_in_newton_times_the_length_unit(cup):
    # The tip 0.1 m off the flange's axis: the hanging cup's weight turns about it.
    cup.device.SetToolOffset(settings_pb2.SetToolOffsetRequest(
        offset=types_pb2.Pose(x=0.1, z=0.12)), timeout=5)
    weight = CUP_MASS * 9.81
    reading = cup.reading()
    assert reading[:3] == pytest.approx([0, 0, weight], abs=0.02)
    assert reading[3:] == pytest.approx([0, 0.1 * weight, 0], abs=0.01)    # N*m
    cup.device.SetUnits(settings_pb2.SetUnitsRequest(
        linear_units=types_pb2.LINEAR_UNIT_MILLIMETERS,
        angular_units=types_pb2.ANGULAR_UNIT_RADIANS), timeout=5)
    in_mm = cup.reading()
    assert in_mm[:3] == pytest.approx(reading[:3], abs=0.02)               # forces stay N
    assert in_mm[3:] == pytest.approx(reading[3:] * 1000, abs=10)          # N*mm


def test_a_sensor_the_cell_file_adds_is_read_from_the_controller(tmp_path):
    """A third sensor (a second range sensor, 2 cm ahead of the tip) is not in the ring: its
    readings come from the controller when asked, and the loops that need every cycle's refuse
    it."""
    cell = cell_file(tmp_path, {"[recorder]": '''[sensors.front_laser]
kind = "laser_range"
max_range = 1.0
min_range = 0.005
offset = [0.0, 0.0, 0.02]

[recorder]'''})
    server = start_server(cell=cell)
    session = locked_session(server)
    try:
        device = stubs(session.channel)[0]
        device.Activate(control_pb2.ActivateRequest(), timeout=10)

        def reading(name):
            return device.GetSensorReading(sensing_pb2.GetSensorReadingRequest(
                sensor_type=name), timeout=10).current_data[0]
        assert reading("front_laser") == pytest.approx(reading("laser_standoff_sensor") - 0.02,
                                                       abs=1e-4)
        device.SetUnits(settings_pb2.SetUnitsRequest(
            linear_units=types_pb2.LINEAR_UNIT_MILLIMETERS,
            angular_units=types_pb2.ANGULAR_UNIT_RADIANS), timeout=5)
        assert reading("front_laser") == pytest.approx(reading("laser_standoff_sensor") - 20,
                                                       abs=0.1)
        error = _refused(lambda: reading("sonar"))
        assert "front_laser" in error.details()
        error = _refused(lambda: device.MoveReact(sensing_pb2.MoveReactRequest(
            sensor_type="front_laser", motion=Z(z=10), speed=1, thresholds=Z(x=20))))
        assert error.code() is grpc.StatusCode.INVALID_ARGUMENT
        assert "not read every cycle" in error.details()
        stream = state_service_pb2_grpc.StateServiceStub(session.channel).StreamState(
            state_service_pb2.StreamStateRequest(sensors=["front_laser"]))
        assert _refused(lambda: next(stream)).code() is grpc.StatusCode.INVALID_ARGUMENT
    finally:
        session.close()
        server.stop(grace=None)


# ---- 3.7.2 moveReact ------------------------------------------------------------------------

def _vectors(message: str) -> list[np.ndarray]:
    """The (x, y, z) vectors a message quotes, in order."""
    return [np.array([float(v) for v in m.split(",")])
            for m in re.findall(r"\(([-0-9.e, ]+)\)", message)]


@pytest.mark.parametrize("mm_per_s", [2, 10, 20, 40])
def test_move_react_stops_on_the_table_at_the_threshold(cup, mm_per_s):
    events = _touch(cup, mm_per_s=mm_per_s)
    done = events[-1]
    assert done.event_id == "command_done" and done.command.command == "MoveReact"
    message = done.command.message
    assert message.startswith("triggered")
    force = cup.reading()
    tip_height = cup.tool_tip()[2, 3]
    print(f"\nmoveReact onto the table at {mm_per_s} mm/s: at rest fz = {force[2]:.2f} N "
          f"(threshold -20 N), tip {(tip_height - TABLE_TOP) * 1000:.2f} mm from the table; "
          f"{message}")
    assert force[2] == pytest.approx(-20.0, rel=0.2)
    assert abs(tip_height - TABLE_TOP) < 0.002
    assert cup.server.device.state is State.RESTING
    trigger, _, rest = _vectors(message)[:3]     # the reading at the trigger, where, at rest
    assert trigger[2] <= -20.0
    assert rest == pytest.approx(force[:3], abs=0.5)


def test_a_stop_while_the_force_settles_ends_the_settling(cup):
    clock = cup.link.clock
    reply = cup.device.MoveReact(sensing_pb2.MoveReactRequest(
        sensor_type="force_sensor", motion=Z(z=0.1), speed=2, thresholds=Z(z=-20)), timeout=30)
    clock.hold()
    try:
        def until_settling(controller) -> None:   # the cycles, stepped here, one by one
            while (motion := controller.cyclic._motion) is None or motion.force_settle is None:
                controller.step()
        cup.link.between_cycles(until_settling, timeout=60)
        cup.server.device.motions.request_stop()
    finally:
        clock.release()
    done = cup.wait_command(reply.ret_val.command_id)[-1]
    assert done.event_id == "command_done"
    assert done.command.message.startswith("triggered")
    assert done.command.message.endswith("(stop before the force settled)")
    assert cup.server.device.state is State.RESTING


def test_move_react_in_free_air_runs_its_full_distance_and_says_so(cup):
    before = cup.tool_tip()[:3, 3]
    events = _react(cup, sensor_type="force_sensor", motion=Z(z=-0.05), speed=2,
                    thresholds=Z(z=-20))
    assert events[-1].event_id == "command_done"
    assert events[-1].command.message == "not triggered: moved the full distance"
    moved = cup.tool_tip()[:3, 3] - before
    assert moved == pytest.approx([0, 0, 0.05], abs=1e-4)   # up: the tool's -z


def test_move_react_on_the_laser_stops_at_its_standoff(cup):
    cup.move_down_to(*FREE_SPOT, TABLE_TOP + 0.15)
    events = _react(cup, sensor_type="laser_standoff_sensor", motion=Z(z=0.2), speed=1,
                    thresholds=Z(x=0.05))
    assert events[-1].command.message.startswith("triggered")
    standoff = cup.reading("laser_standoff_sensor")[0]
    assert standoff == pytest.approx(0.05, abs=0.002)   # 20 mm/s: well under a mm to brake
    assert cup.tool_tip()[2, 3] == pytest.approx(TABLE_TOP + 0.05, abs=0.002)


def test_a_reading_beyond_the_envelope_ends_move_react_as_failed(cup):
    events = _react(cup, sensor_type="force_sensor", motion=Z(z=0.1), speed=0.1,
                    thresholds=Z(z=-50), envelope_max=Z(z=10))
    assert events[-1].event_id == "command_failed"
    assert "envelope" in events[-1].command.message
    assert abs(cup.reading()[2]) < 20     # stopped soon after 10 N
    alarm = [e for e in cup.history() if e.event_id == "alarm"][-1].detail
    assert alarm.code == alarms.MOTION and alarm.command_id == events[-1].command.command_id


def test_move_react_lets_only_the_tool_touch_its_surface_the_arm_stays_checked(cup):
    """Issue 11: the cup may meet the table it searches for; the flange may not. A search
    planned 30 cm down would take the flange (12 cm above the cup's tip) into the table.
    Refused, it changes nothing: the force sensor keeps its tare (it read 0 N under the cup's
    weight after a refused MoveReact had tared it)."""
    before = cup.joints().copy()
    error = _refused(lambda: cup.device.MoveReact(sensing_pb2.MoveReactRequest(
        sensor_type="force_sensor", motion=Z(z=0.3), speed=1, thresholds=Z(z=-20))))
    info = error_info(error)
    assert error.code() is grpc.StatusCode.FAILED_PRECONDITION and info.reason == "COLLISION"
    assert info.metadata["body_a"].startswith("link") and info.metadata["body_b"] == "table"
    assert np.allclose(cup.joints(), before, atol=1e-6)
    assert cup.server.device.state is State.RESTING
    assert cup.reading()[:3] == pytest.approx([0, 0, CUP_MASS * 9.81], abs=0.02)


@pytest.mark.parametrize("fields, code", [
    ({"motion": Z(z=0.1), "speed": 1, "thresholds": Z(z=-20), "compliance": Z(x=0.01)},
     grpc.StatusCode.INVALID_ARGUMENT),
    ({"motion": Z(z=0.1), "speed": 1}, grpc.StatusCode.INVALID_ARGUMENT),          # no threshold
    ({"motion": Z(), "speed": 1, "thresholds": Z(z=-20)}, grpc.StatusCode.INVALID_ARGUMENT),
    ({"motion": Z(z=0.1), "speed": 0, "thresholds": Z(z=-20)}, grpc.StatusCode.OUT_OF_RANGE),
    ({"motion": Z(z=0.1), "speed": 1, "thresholds": Z(z=-20), "gains": Z(x=2)},
     grpc.StatusCode.OUT_OF_RANGE),
    ({"sensor_type": "sonar", "motion": Z(z=0.1), "speed": 1, "thresholds": Z(z=-20)},
     grpc.StatusCode.INVALID_ARGUMENT),
])
def test_bad_move_react_parameters_are_refused_and_nothing_moves(still_arm, fields, code):
    before = still_arm.joints().copy()
    fields = {"sensor_type": "force_sensor", **fields}
    error = _refused(lambda: still_arm.device.MoveReact(sensing_pb2.MoveReactRequest(**fields)))
    assert error.code() is code
    assert np.allclose(still_arm.joints(), before, atol=1e-6)
    assert still_arm.server.device.state is State.RESTING


# ---- 3.7.2 comply ---------------------------------------------------------------------------

def _comply(arm, **fields):
    request = dict(sensor_type="force_sensor", thresholds=[0, 0, -20, 0, 0, 0],
                   max_timeout=30, proportional_gains=[0, 0, 0.001, 0, 0, 0],
                   compliance=Z(z=0.01), compliance_speed=1)
    request.update(fields)
    return arm.device.Comply(sensing_pb2.ComplyRequest(**request), timeout=30)


def test_comply_slides_along_the_table_holding_the_force(cup):
    _touch(cup)
    start = cup.tool_tip()[:3, 3]
    rows = _RingReader(cup)
    reply = _comply(cup, motion=Z(x=0.1), speed=1)
    events = cup.wait_command(reply.ret_val.command_id)
    slide = rows.stop()
    assert events[-1].event_id == "command_done", events[-1]
    moved = cup.tool_tip()[:3, 3] - start
    assert moved[0] == pytest.approx(0.1, abs=1e-3)   # pointing down: the tool's x is the world's
    sensors = cup.server.workcell.sensors
    began, ended = (e.time.ToNanoseconds() / 1e9 for e in (events[0], events[-1]))
    during = slide[(slide[:, WALL] >= began) & (slide[:, WALL] <= ended)]
    fz = np.array([sensors.from_row("force_sensor", row[SENSORS])[2] for row in during])
    print(f"\ncomply: {len(fz)} cycles over 0.1 m, fz {fz.min():.2f} to {fz.max():.2f} N "
          f"(set-point -20 N)")
    assert len(fz) > 1000 and np.all(np.diff(during[:, SEQ]) == 1)   # every cycle
    assert np.all(np.abs(fz + 20.0) <= 5.0)


class _RingReader:
    """Every cycle's feedback row from now on, read from the ring as it fills."""

    def __init__(self, arm):
        self.ring, self.rows = arm.server.link.feedback, {}
        self._first = self.ring.watch()   # whole rows (sensors in them) from this one on
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _read(self):
        seen = self._first - 1
        while not self._done.is_set():
            head = self.ring.head
            for sequence in range(seen + 1, head + 1):
                row = self.ring.row(sequence)
                assert row is not None, "the ring overtook the reader"
                self.rows[sequence] = row
            seen = max(seen, head)
            time.sleep(0.005)

    def stop(self) -> np.ndarray:
        self._done.set()
        self._thread.join(5)
        self.ring.unwatch()
        return np.array([self.rows[s] for s in sorted(self.rows)])


def test_unwatched_rows_leave_the_sensors_unread_and_readings_stay_right(cup):
    # Issue 31 item 5: with no reader of whole rows, the cycle reads no sensor and computes no
    # model torques (they were a quarter of a back-to-back cycle); asking still reads them.
    ring, sensors = cup.link.feedback, cup.server.workcell.sensors
    newest = ring.latest()
    assert np.isnan(newest.sensors).all() and np.isnan(newest.model_torque).all()
    assert cup.reading()[:3] == pytest.approx([0, 0, CUP_MASS * 9.81], abs=0.02)
    assert cup.reading("laser_standoff_sensor") == pytest.approx([0.03], abs=0.002)
    for _ in range(6):   # watched from any cycle on: its first whole row has the range too
        first = ring.watch()
        try:
            wait_until(lambda: ring.head >= first + 1, timeout=10)
            rows = [ring.row(first), ring.row(first + 1)]
        finally:
            ring.unwatch()
        for row in rows:
            assert sensors.from_row("force_sensor", row[SENSORS])[2] == pytest.approx(
                CUP_MASS * 9.81, abs=0.02)
            assert sensors.from_row("laser_standoff_sensor", row[SENSORS]) == pytest.approx(
                [0.03], abs=0.002)
            assert np.isfinite(row[MODEL_TAU]).all()
        wait_until(lambda: np.isnan(ring.latest().sensors).all(), timeout=10)


def test_a_state_stream_carries_the_sensors_asked_for(still_cup):
    stream = state_service_pb2_grpc.StateServiceStub(still_cup.session.channel).StreamState(
        state_service_pb2.StreamStateRequest(sensors=["force_sensor", "laser_standoff_sensor"]))
    assert next(stream).HasField("started")
    sample = next(stream).sample
    stream.cancel()
    assert [s.name for s in sample.sensors] == ["force_sensor", "laser_standoff_sensor"]
    assert sample.sensors[0].values[2] == pytest.approx(CUP_MASS * 9.81, abs=0.05)
    assert sample.sensors[1].values[0] == pytest.approx(0.03, abs=0.002)
    assert (sample.end_effector, sample.end_effector_state) == ("vacuum", "off")


def test_comply_in_place_holds_the_force_for_its_timeout(cup):
    _touch(cup, threshold=-5.0)
    reply = _comply(cup, max_timeout=1.0)
    events = cup.wait_command(reply.ret_val.command_id)
    assert events[-1].event_id == "command_done"
    assert cup.reading()[2] == pytest.approx(-20.0, abs=1.0)
    started, done = events[0], events[-1]
    assert done.time.ToMicroseconds() >= started.time.ToMicroseconds()


@pytest.mark.parametrize("panic, state", [(0, State.RESTING), (1, State.ERROR)])
def test_a_comply_panic_stops_and_its_code_says_what_follows(cup, panic, state):
    _touch(cup, threshold=-5.0)
    reply = _comply(cup, max_timeout=2.0, panic_stop_code=panic, envelope_max=Z(z=12))
    events = cup.wait_command(reply.ret_val.command_id)
    assert events[-1].event_id == "command_failed" and "panic" in events[-1].command.message
    wait_until(lambda: cup.server.device.state is state)
    if state is State.ERROR:
        assert any(e.event_id == "alarm" and e.detail.code == alarms.PANIC
                   for e in cup.history())
        cup.device.Reset(control_pb2.ResetRequest(), timeout=10)
        assert cup.server.device.state is State.INACTIVE


def test_comply_joins_a_running_motion(cup):
    _touch(cup)
    reply = cup.device.MoveRelative(motion_pb2.MoveRelativeRequest(
        frame=types_pb2.REFERENCE_FRAME_TOOL_FRAME, values=[0.03, 0, 0, 0, 0, 0], speed=0.5,
        motion_type=types_pb2.MOTION_TYPE_STRAIGHT_MOTION), timeout=30)
    joined = _comply(cup)
    assert joined.ret_val.command_id == reply.ret_val.command_id
    events = cup.wait_command(reply.ret_val.command_id)
    assert events[-1].event_id == "command_done"
    assert "force" in events[-1].command.message
    assert cup.reading()[2] == pytest.approx(-20.0, abs=2.0)


def _press(arm, kd: float) -> int:
    """From resting on the table at 5 N, a comply in place at 20 N with differential gain
    `kd` (m/N): the cycles until the force is within 2 N of it."""
    _touch(arm, threshold=-5.0)
    rows = _RingReader(arm)
    reply = _comply(arm, max_timeout=1.0, differential_gains=[0, 0, kd, 0, 0, 0])
    events = arm.wait_command(reply.ret_val.command_id)
    assert events[-1].event_id == "command_done"
    pressed = rows.stop()
    began = events[0].time.ToNanoseconds() / 1e9
    pressed = pressed[pressed[:, WALL] >= began]
    sensors = arm.server.workcell.sensors
    fz = np.array([sensors.from_row("force_sensor", row[SENSORS])[2] for row in pressed])
    reached = np.nonzero(fz <= -18.0)[0]
    assert reached.size, f"the force never reached 18 N (down to {fz.min():.1f} N)"
    _lift(arm)
    return int(reached[0])


def _lift(arm, dz: float = 0.01) -> None:
    reply = arm.device.MoveRelative(motion_pb2.MoveRelativeRequest(
        frame=types_pb2.REFERENCE_FRAME_TOOL_FRAME, values=[0, 0, -dz, 0, 0, 0],
        motion_type=types_pb2.MOTION_TYPE_STRAIGHT_MOTION), timeout=30)
    assert arm.wait_command(reply.ret_val.command_id)[-1].event_id == "command_done"


def test_comply_s_differential_gain_damps_the_approach_to_the_set_point(cup):
    # Against a contact of stiffness k, kd slows the offset by 1 + kd * k (the derivative of
    # the force error opposes its change): here about 20 kN/m and kd 1e-4 m/N, 3 times.
    plain, damped = _press(cup, 0.0), _press(cup, 1e-4)
    print(f"\ncomply from 5 to 18 N: {plain} cycles without kd, {damped} with kd 1e-4 m/N")
    assert damped > 1.8 * plain


def test_comply_beyond_its_travel_distance_panics_and_stops(cup):
    _touch(cup)
    start = cup.tool_tip()[:3, 3]
    reply = _comply(cup, motion=Z(x=0.1), speed=1, max_travel_distances=[0.02, 0, 0, 0, 0, 0])
    events = cup.wait_command(reply.ret_val.command_id)
    assert events[-1].event_id == "command_failed"
    assert "beyond the travel limits" in events[-1].command.message
    moved = cup.tool_tip()[:3, 3] - start
    assert 0.02 <= moved[0] < 0.022       # 20 mm/s: under a mm to brake
    assert any(e.event_id == "alarm" and e.detail.command_id == reply.ret_val.command_id
               for e in cup.history())
    assert cup.server.device.state is State.RESTING


def test_comply_whose_motion_outlasts_its_timeout_fails(cup):
    _touch(cup)
    start = cup.tool_tip()[:3, 3]
    reply = _comply(cup, motion=Z(x=0.1), speed=1, max_timeout=0.5)   # 5 s of motion
    events = cup.wait_command(reply.ret_val.command_id)
    assert events[-1].event_id == "command_failed"
    assert events[-1].command.message.startswith("timeout: the motion was not done within 0.5 s")
    moved = cup.tool_tip()[:3, 3] - start
    assert 0.005 < moved[0] < 0.015        # about half a second of it
    assert cup.server.device.state is State.RESTING
def test_comply_is_checked_with_its_compliance_at_both_ends(cup):
    """Issue 11: the cup may press on the table, but a compliance of 20 cm would let the
    flange follow it into the table: refused before anything moves. 1 cm is fine."""
    _touch(cup, threshold=-5.0)
    before = cup.joints().copy()
    error = _refused(lambda: _comply(cup, max_timeout=1.0, compliance=Z(z=0.2)))
    info = error_info(error)
    assert error.code() is grpc.StatusCode.FAILED_PRECONDITION and info.reason == "COLLISION"
    assert info.metadata["body_a"].startswith("link") and info.metadata["body_b"] == "table"
    assert "compliance" in error.details()
    assert np.allclose(cup.joints(), before, atol=1e-6)
    reply = _comply(cup, max_timeout=0.2)
    assert cup.wait_command(reply.ret_val.command_id)[-1].event_id == "command_done"


@pytest.mark.parametrize("fields", [
    {"compliance": Z()},                                                  # no compliant axis
    {"motion": Z(z=0.01), "speed": 1},                                    # along the compliance
    {"proportional_gains": [0, 0, 0, 0, 0, 0]},
    {"thresholds": [0, 0, -20, 0, 0, 1]},                                 # a torque set-point
    {"panic_stop_code": 7},
    {"max_timeout": 0},                                                   # in place, forever
    {"compliance_speed": 0},
])
def test_bad_comply_parameters_are_refused_and_nothing_moves(still_arm, fields):
    before = still_arm.joints().copy()
    error = _refused(lambda: _comply(still_arm, **fields))
    assert error.code() in (grpc.StatusCode.INVALID_ARGUMENT, grpc.StatusCode.OUT_OF_RANGE)
    assert np.allclose(still_arm.joints(), before, atol=1e-6)
    assert still_arm.server.device.state is State.RESTING


def test_a_state_stream_refuses_an_unknown_sensor(still_arm):
    stream = state_service_pb2_grpc.StateServiceStub(still_arm.session.channel).StreamState(
        state_service_pb2.StreamStateRequest(sensors=["sonar"]))
    error = _refused(lambda: next(stream))
    assert error.code() is grpc.StatusCode.INVALID_ARGUMENT

"""Guards on a MoveTo (NIST's 2021 revision) as the device's guarded move: the vacuum cup, held
from InitCanon on, goes down onto the table until the force sensor's Fz falls 20 N, or until the
laser sees the table 5 cm away; guards the device cannot watch are refused before anything moves
(issue 27 item 3)."""
from __future__ import annotations

import contextlib

import numpy as np
import pytest

from landscape.client import Robot
from landscape.gateway.workstation import Workstation
from landscape.server.device.states import State

from crcl_support import XSD_2021, RawClient, RunningGateway, field, pose
from support import start_server, wait_until
from test_gateway import MOVE, point

CRCL_SCHEMAS = XSD_2021                     # Guard is the 2021 revision's
CRCL_WORKSTATION = Workstation(end_effector="vacuum")
TABLE_TOP = 0.2
ABOVE = (0.65, 0.3, TABLE_TOP + 0.03)       # the cup's tip 3 cm over a free spot of the table
INTO = (0.65, 0.3, TABLE_TOP - 0.07)        # 7 cm into it
SLOW = '<TransSpeed xsi:type="TransSpeedAbsoluteType"><Setting>0.02</Setting></TransSpeed>'


def guard(sensor: str, limit_type: str, value: float, sub_field: str | None = "Fz",
          flags: str = "") -> str:
    sub = f"<SubField>{sub_field}</SubField>" if sub_field else ""
    return (f"<Guard><SensorID>{sensor}</SensorID>{sub}<LimitType>{limit_type}</LimitType>"
            f"<LimitValue>{value}</LimitValue>{flags}</Guard>")


def guarded(*guards: str, to=INTO) -> str:
    return "".join(guards) + MOVE.format("true") + pose(*to)


@contextlib.contextmanager
def cell():
    """A device server (pybullet: the guards read its physics) and the gateway before it."""
    server = start_server(backend="pybullet")
    gateway = RunningGateway(server.target, schemas=CRCL_SCHEMAS, workstation=CRCL_WORKSTATION)
    try:
        yield server, gateway
    finally:
        gateway.close()
        server.stop(grace=None)


@pytest.fixture(scope="module")
def shared_cell():
    """One cell for the module's tests (starting one took most of each test's time): each
    test's client opens its own CRCL session (InitCanon) and `above` moves the cup back over
    the table from wherever the last test left it."""
    with cell() as running:
        yield running


@pytest.fixture
def server(shared_cell):
    return shared_cell[0]


@pytest.fixture
def gateway(shared_cell):
    server, gateway = shared_cell
    yield gateway
    # The test's CRCL session ends as its client closes; the next one's InitCanon would find
    # the device still locked by it if it came first.
    wait_until(lambda: server.device.state is State.UNLOCKED, timeout=10)


def over_the_table(client: RawClient) -> RawClient:
    """The cup over the table, then slow (20 mm/s) for what follows, guards reported in status
    (the move there runs at the default speed: it is not what a test watches)."""
    for command_id, kind, body in (
            (2, "MoveTo", MOVE.format("false") + pose(*ABOVE)),
            (3, "SetTransSpeed", SLOW),
            (4, "ConfigureStatusReport", "".join(f"<Report{t}>true</Report{t}>" for t in (
                "JointStatuses", "PoseStatus", "GripperStatus", "SettingsStatus", "SensorsStatus",
                "GuardsStatus")))):
        assert field(client.run(kind, command_id, body), "CommandState") == "CRCL_Done"
    return client


@pytest.fixture
def above(client):
    return over_the_table(client)


@pytest.fixture
def untared_above():
    """`above` on a cell of the test's own: every guarded move tares the force sensor (MoveReact
    does) and nothing undoes a tare, so the shared cell's sensor reads from its last one."""
    with cell() as (_, gateway):
        client = RawClient(gateway.port, schemas=gateway.schemas)
        assert field(client.run("InitCanon", 1), "CommandState") == "CRCL_Done"
        yield over_the_table(client)
        client.close()


def _done(status: str) -> str:
    assert field(status, "CommandState") == "CRCL_Done", status
    return field(status, "StateDescription")


def test_a_guarded_move_stops_on_the_table_when_the_force_falls_past_its_limit(above):
    # RecheckTimeMicroSeconds: the device checks every cycle (4 ms) whatever is asked;
    # CheckCount means nothing in a command (the schema says so)
    said = _done(above.run("MoveTo", 5, guarded(guard(
        "force_sensor", "DECREASE_BEYOND_LIMIT", 20,
        flags="<RecheckTimeMicroSeconds>1000</RecheckTimeMicroSeconds><CheckCount>7</CheckCount>"))))
    assert said.startswith("stopped by its guard DECREASE_BEYOND_LIMIT on force_sensor Fz: it "
                           "read -")
    status = above.status()
    assert point(status)[2] == pytest.approx(TABLE_TOP, abs=0.002)    # the cup on the table
    report = field(status, "GuardsStatuses")
    assert field(report, "TriggerCount") == "1"
    assert float(field(report, "TriggerValue")) == pytest.approx(-20.0, rel=0.2)
    assert int(field(report, "TriggerStopTimeMicros")) > 0
    assert float(field(field(report, "TriggerPose"), "Z")) == pytest.approx(TABLE_TOP, abs=0.002)


def test_a_guard_on_the_laser_stops_at_its_standoff_in_the_sessions_units(above):
    _done(above.run("SetLengthUnits", 5, "<UnitName>millimeter</UnitName>"))
    _done(above.run("MoveTo", 6, MOVE.format("false") + pose(
        *(np.array(ABOVE) * 1000 + [0, 0, 120]))))
    said = _done(above.run("MoveTo", 7, guarded(
        guard("laser_standoff_sensor", "UNDER_MIN", 50, sub_field=None),
        to=np.array(INTO) * 1000)))
    assert said.startswith("stopped by its guard UNDER_MIN on laser_standoff_sensor: it read ")
    assert float(said.split()[-2]) == pytest.approx(50, abs=2) and said.endswith(" millimeter")
    assert point(above.status())[2] == pytest.approx((TABLE_TOP + 0.05) * 1000, abs=2)


def test_a_guard_that_never_triggers_lets_the_move_end_at_its_pose_unless_it_is_required(above):
    up = (ABOVE[0], ABOVE[1], ABOVE[2] + 0.05)
    done = above.run("MoveTo", 5, guarded(guard("force_sensor", "OVER_MAX", 30), to=up))
    assert "reached within" in _done(done) and point(done) == pytest.approx(up, abs=1e-4)
    assert field(field(above.status(), "GuardsStatuses"), "TriggerCount") == "0"
    required = above.run("MoveTo", 6, guarded(guard(
        "force_sensor", "OVER_MAX", 30, flags="<RequireTrigger>true</RequireTrigger>"), to=ABOVE))
    assert field(required, "CommandState") == "CRCL_Error"
    assert field(required, "StateDescription") == ("its guard never triggered: the motion ended "
                                                   "at its pose (RequireTrigger)")


def test_error_on_trigger_makes_the_stop_an_error(above):
    stopped = above.run("MoveTo", 5, guarded(guard(
        "force_sensor", "INCREASE_OVER_LIMIT", -20, flags="<ErrorOnTrigger>true</ErrorOnTrigger>")))
    assert field(stopped, "CommandState") == "CRCL_Error"
    assert "(ErrorOnTrigger)" in field(stopped, "StateDescription")


REFUSED = [  # (guards and pose, why)
    (guard("force_sensor", "OVER_MAX", 5, sub_field="Tx") + MOVE.format("true") + pose(*INTO),
     "SubField 'Tx' of force_sensor: the device's guarded move watches the forces Fx, Fy and Fz"),
    (guard("force_sensor", "OVER_MAX", 5) + guard("laser_standoff_sensor", "UNDER_MIN", 0.05,
                                                  sub_field=None) + MOVE.format("true") + pose(*INTO),
     "the device's guarded move watches one sensor; these guards name force_sensor, "
     "laser_standoff_sensor"),
    (guard("sonar", "OVER_MAX", 5) + MOVE.format("true") + pose(*INTO),
     "SensorID 'sonar' is none the device's guarded move watches"),
    (guard("force_sensor", "OVER_MAX", 5) + MOVE.format("true") + pose(
        *INTO, xaxis=(0, 1, 0)), "a guarded MoveTo moves in a straight line without turning"),
    (guard("force_sensor", "UNDER_MIN", 50) + MOVE.format("true") + pose(*INTO),
     "Guard UNDER_MIN 50 on force_sensor Fz: the reading is there already"),
]


def test_guards_the_device_cannot_watch_are_refused_before_anything_moves(above, server):
    """Torques, two sensors, an unknown one, a turn, a limit passed already; another command."""
    with Robot(server.target, "watcher") as robot:
        before = np.array(robot.get_robot_position().joint_position)
        for command_id, (body, why) in enumerate(REFUSED, start=5):
            refused = above.run("MoveTo", command_id, body)
            assert field(refused, "CommandState") == "CRCL_Error", why
            assert why in field(refused, "StateDescription")
        assert np.abs(np.array(robot.get_robot_position().joint_position) - before).max() < 1e-6
    refused = above.run("Dwell", 20, guard("force_sensor", "OVER_MAX", 5) +
                        "<DwellTime>0.1</DwellTime>")
    assert field(refused, "CommandState") == "CRCL_Error"
    assert field(refused, "StateDescription").startswith(
        "Guard on Dwell: guards are carried out on MoveTo only")


def test_a_sensor_enabled_with_the_tare_option_reads_from_zero(untared_above):
    above = untared_above

    def fz() -> float:
        return float(field(field(above.status(), "ForceTorqueSensorStatus"), "Fz"))
    assert field(above.run("EnableSensor", 5, "<SensorID>force_sensor</SensorID>"),
                 "CommandState") == "CRCL_Done"
    assert fz() == pytest.approx(0.6 * 9.81, abs=0.5)          # the cup hangs from the flange
    tared = above.run("EnableSensor", 6, "<SensorID>force_sensor</SensorID><SensorOption>"
                      "<ParameterName>tare</ParameterName><ParameterValue>true</ParameterValue>"
                      "</SensorOption>")
    assert _done(tared) == "sensor force_sensor reported, tared"
    assert fz() == pytest.approx(0.0, abs=0.5)
    refused = above.run("EnableSensor", 7, "<SensorID>force_sensor</SensorID><SensorOption>"
                        "<ParameterName>rate</ParameterName><ParameterValue>1000"
                        "</ParameterValue></SensorOption>")
    assert field(refused, "CommandState") == "CRCL_Error"
    assert field(refused, "StateDescription") == ("SensorOption rate='1000': the one option is "
                                                  "tare (true: zero the sensor at its present "
                                                  "reading, or false)")

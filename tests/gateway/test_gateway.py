"""The real gateway before a real device server, driven by a CRCL client written from the
specification (raw sockets): wire framing, sessions, motions, units, preemption, errors."""
from __future__ import annotations

import math
import time

import pytest

from landscape.server.device.states import State

from crcl_support import RawClient, command, field, pose

MOVE = "<MoveStraight>{}</MoveStraight>"


def point(status: str) -> tuple[float, float, float]:
    block = field(status, "Point")
    return tuple(float(field(block, t)) for t in "XYZ")


@pytest.fixture
def client(gateway):
    """Here a client before its InitCanon."""
    c = RawClient(gateway.port)
    yield c
    c.close()


def test_commands_split_byte_by_byte_coalesced_and_spaced_get_status_each_time(client):
    documents = [command("InitCanon", 1), command("SetLengthUnits", 2, "<UnitName>millimeter</UnitName>"),
                 command("GetStatus", 3)]
    for byte in b"\n  ".join(documents):          # one byte per write
        client.send(bytes([byte]))
    status = client.read_status()
    assert field(status, "CommandID") in ("1", "2")
    client.wait_done(2)
    # several documents per write, whitespace between, a status for each GetStatus
    client.send(command("GetStatus", 4) + b"\r\n\t " + command("GetStatus", 5) + command("GetStatus", 6))
    statuses = [client.read_status() for _ in range(3)]
    ids = [int(field(s, "StatusID")) for s in statuses]
    assert ids == sorted(ids) and len(set(ids)) == 3
    assert all(field(s, "CommandState") == "CRCL_Done" for s in statuses)


def test_a_session_moves_in_the_units_it_set(client, server):
    assert field(client.run("InitCanon", 1), "CommandState") == "CRCL_Done"
    assert server.device.state is State.RESTING
    done = client.run("MoveTo", 2, MOVE.format("true") + pose(0.5, 0.1, 0.6))
    assert field(done, "CommandState") == "CRCL_Done", done
    assert point(done) == pytest.approx((0.5, 0.1, 0.6), abs=1e-4)
    client.run("SetLengthUnits", 3, "<UnitName>millimeter</UnitName>")
    done = client.run("MoveTo", 4, MOVE.format("false") + pose(450, -100, 550))
    assert field(done, "CommandState") == "CRCL_Done", done
    assert point(done) == pytest.approx((450, -100, 550), abs=0.1)
    client.run("SetAngleUnits", 5, "<UnitName>degree</UnitName>")
    client.run("ConfigureJointReports", 6, "<ResetAll>true</ResetAll>" + "".join(
        f"<ConfigureJointReport><JointNumber>{j}</JointNumber><ReportPosition>true</ReportPosition>"
        f"<ReportTorqueOrForce>false</ReportTorqueOrForce><ReportVelocity>true</ReportVelocity>"
        f"</ConfigureJointReport>" for j in (1, 3)))
    status = client.status()
    joints = server.device.feedback().position
    assert field(status, "JointStatuses").count("<JointStatus>") == 2
    assert float(field(status, "JointPosition")) == pytest.approx(math.degrees(joints[0]), abs=0.05)
    assert field(client.run("EndCanon", 7), "CommandState") == "CRCL_Done"
    assert server.device.state is State.UNLOCKED


def test_commands_before_init_canon_and_after_end_canon_are_errors(client):
    before = client.run("SetTransSpeed", 1, '<TransSpeed xsi:type="TransSpeedRelativeType">'
                                            '<Fraction>0.5</Fraction></TransSpeed>')
    assert field(before, "CommandState") == "CRCL_Error"
    assert "before InitCanon" in field(before, "StateDescription")
    assert field(client.run("StopMotion", 2, "<StopCondition>Normal</StopCondition>"),
                 "CommandState") == "CRCL_Done"
    client.run("InitCanon", 3)
    client.run("EndCanon", 4)
    after = client.run("Dwell", 5, "<DwellTime>0</DwellTime>")
    assert "after EndCanon" in field(after, "StateDescription")


def test_an_invalid_document_is_an_error_and_the_connection_goes_on(client):
    client.send(command("ConfigureStatusReport", 29,
                        "<ReportJointStatuses>true</ReportJointStatuses>"))
    status = client.status()
    assert field(status, "CommandState") == "CRCL_Error"
    assert field(status, "CommandID") == "29"
    assert "line 2" in field(status, "StateDescription")
    assert "ReportPoseStatus" in field(status, "StateDescription")
    assert field(client.run("InitCanon", 30), "CommandState") == "CRCL_Done"


def test_a_new_motion_preempts_the_running_one(client, server):
    client.run("InitCanon", 1)
    client.run("SetTransSpeed", 2, '<TransSpeed xsi:type="TransSpeedRelativeType">'
                                   '<Fraction>0.05</Fraction></TransSpeed>')
    client.send(command("MoveTo", 3, MOVE.format("true") + pose(0.5, 0.3, 0.5)))
    time.sleep(0.3)
    first = client.status()
    assert (field(first, "CommandID"), field(first, "CommandState")) == ("3", "CRCL_Working")
    done = client.run("MoveTo", 4, MOVE.format("false") + pose(0.5, -0.2, 0.6))
    assert field(done, "CommandState") == "CRCL_Done", done
    assert point(done) == pytest.approx((0.5, -0.2, 0.6), abs=1e-4)


def test_only_one_connection_holds_the_lock(gateway, client):
    client.run("InitCanon", 1)
    other = RawClient(gateway.port)
    try:
        refused = other.run("InitCanon", 1)
        assert field(refused, "CommandState") == "CRCL_Error"
        assert "locked by crcl-" in field(refused, "StateDescription")
        client.run("EndCanon", 2)
        assert field(other.run("InitCanon", 3), "CommandState") == "CRCL_Done"
    finally:
        other.close()


def test_a_closed_connection_releases_the_device(gateway, server):
    first = RawClient(gateway.port)
    first.run("InitCanon", 1)
    first.close()
    deadline = time.monotonic() + 10
    while server.device.state is not State.UNLOCKED:
        assert time.monotonic() < deadline, server.device.state
        time.sleep(0.02)


def test_move_through_waypoints_screw_and_joints(client, server):
    client.run("InitCanon", 1)
    waypoints = [pose(0.5, 0.2, 0.6, tag="Waypoint"), pose(0.55, 0.0, 0.55, tag="Waypoint"),
                 pose(0.5, -0.2, 0.6, tag="Waypoint")]
    done = client.run("MoveThroughTo", 2, MOVE.format("false") + "".join(waypoints) +
                      "<NumPositions>3</NumPositions>")
    assert field(done, "CommandState") == "CRCL_Done", done
    assert point(done) == pytest.approx((0.5, -0.2, 0.6), abs=1e-4)
    screw = client.run("MoveScrew", 3, "<AxialDistanceScrew>-0.02</AxialDistanceScrew>"
                                       "<Turn>1.0</Turn>")
    assert field(screw, "CommandState") == "CRCL_Done", screw
    # -0.02 along the tool Z (pointing down): 2 cm up, turned about the vertical
    assert point(screw) == pytest.approx((0.5, -0.2, 0.62), abs=1e-4)
    joints = client.run("ActuateJoints", 4, "".join(
        f"<ActuateJoint><JointNumber>{j}</JointNumber><JointPosition>{q}</JointPosition>"
        f'<JointDetails xsi:type="JointSpeedAccelType"><JointSpeed>0.5</JointSpeed>'
        f"</JointDetails></ActuateJoint>" for j, q in ((1, 0.3), (6, 0.0))))
    assert field(joints, "CommandState") == "CRCL_Done", joints
    q = server.device.feedback().position
    assert (q[0], q[5]) == pytest.approx((0.3, 0.0), abs=1e-4)


def test_an_unreachable_pose_is_an_error_that_says_so(client):
    client.run("InitCanon", 1)
    status = client.run("MoveTo", 2, MOVE.format("false") + pose(2.5, 1, 1))
    assert field(status, "CommandState") == "CRCL_Error"
    assert "not reachable" in field(status, "StateDescription")


def test_stop_motion_normal_stops_on_the_path_and_keeps_the_drives_on(client, server):
    client.run("InitCanon", 1)
    client.run("SetTransSpeed", 2, '<TransSpeed xsi:type="TransSpeedRelativeType">'
                                   '<Fraction>0.05</Fraction></TransSpeed>')
    client.send(command("MoveTo", 3, MOVE.format("true") + pose(0.5, 0.3, 0.5)))
    time.sleep(0.3)
    stopped = client.run("StopMotion", 4, "<StopCondition>Normal</StopCondition>")
    assert field(stopped, "CommandState") == "CRCL_Done"
    assert server.device.state is State.RESTING
    fast = client.run("StopMotion", 5, "<StopCondition>Fast</StopCondition>")
    assert field(fast, "CommandState") == "CRCL_Done"
    assert server.device.state is State.INACTIVE
    # the next motion command turns the drives back on
    assert field(client.run("MoveTo", 6, MOVE.format("false") + pose(0.5, 0.0, 0.6)),
                 "CommandState") == "CRCL_Done"


def test_a_message_reaches_every_supervisor_on_the_device_event_stream(client, server):
    subscription = server.bus.subscribe()
    client.run("InitCanon", 1)
    done = client.run("Message", 2, "<Message>check the fixture</Message>")
    assert field(done, "CommandState") == "CRCL_Done"
    posted = [e for e in iter(lambda: subscription.get(timeout=2), None)
              if e.event_id == "operator_message"]
    subscription.close()
    assert posted and posted[0].detail.text == "check the fixture"
    assert posted[0].detail.source   # the gateway's session, which holds the lock


def test_get_status_is_answered_without_any_device_call(proxied):
    """GetStatus comes from the live state stream: the device hears nothing of the polls."""
    proxy, _, client = proxied
    client.run("Dwell", 2, "<DwellTime>0</DwellTime>")
    before = dict(proxy.calls)
    statuses = [client.status() for _ in range(200)]
    assert all(field(s, "CommandID") == "2" for s in statuses)
    assert dict(proxy.calls) == before, {k: v - before.get(k, 0) for k, v in proxy.calls.items()}
    client.run("MoveTo", 3, MOVE.format("true") + pose(0.5, 0.1, 0.6))   # a motion is heard
    assert proxy.calls["MoveAbsolute"] == before.get("MoveAbsolute", 0) + 1

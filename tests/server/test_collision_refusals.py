"""Issue 11 through gRPC: planned motions that would hit the cell are refused before anything
moves, naming the two bodies and where; the same targets reached around the obstacle run."""
from __future__ import annotations

import numpy as np
import pytest

import grpc
from landscape.server.planning import path_planning
from landscape.server.device.states import State
from landscape.robot.units import pose_matrix
from landscape.v1 import digital_io_service_pb2 as io_pb
from landscape.v1 import end_effector_pb2 as ee
from landscape.v1 import motion_pb2, types_pb2

from support import Arm, error_info, stubs

JOINT = types_pb2.REFERENCE_FRAME_JOINT_FRAME
DOWN = (np.pi, 0.0, 0.0)


@pytest.fixture
def arm(tmp_path, backend):
    a = Arm(tmp_path, backend=backend)
    yield a
    a.close()


def _joints(arm, xyz, near):
    q, result = arm.kin.reverse(pose_matrix(xyz, DOWN), near)
    assert q is not None, result
    return q


def _path(arm, name, points, blend=0.0):
    header = motion_pb2.PathHeader(path_name=name, frame=JOINT,
                                   motion_type=types_pb2.MOTION_TYPE_JOINT_MOTION,
                                   offset_type=types_pb2.OFFSET_TYPE_ABSOLUTE_DATA)
    tags = [types_pb2.TagStruct(joint_values=list(q), tag_name=f"p{i}", transition_speed=blend)
            for i, q in enumerate(points)]
    return arm.device.PathLoad(iter([motion_pb2.PathLoadRequest(header=header, tags=tags)]))


def _run(arm, name):
    reply = arm.device.PathMove(motion_pb2.PathMoveRequest(path_name=name))
    return arm.wait_command(reply.ret_val.command_id)[-1].event_id


def test_a_move_through_the_table_is_refused_and_the_way_around_runs(arm):
    q0 = arm.joints()
    over_a = _joints(arm, (0.6, -0.55, 0.45), q0)
    a = _joints(arm, (0.6, -0.55, 0.12), over_a)     # flange beside the table, below its top
    over_b = _joints(arm, (0.6, 0.55, 0.45), over_a)
    b = _joints(arm, (0.6, 0.55, 0.12), over_b)
    _path(arm, "down", [q0, over_a, a])
    assert _run(arm, "down") == "command_done"
    with pytest.raises(grpc.RpcError) as refused:
        arm.device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(frame=JOINT, values=list(b)))
    assert refused.value.code() is grpc.StatusCode.FAILED_PRECONDITION
    info = error_info(refused.value)
    assert info.reason == "COLLISION" and info.metadata["body_b"] == "table"
    assert info.metadata["body_a"].startswith("link") and float(info.metadata["time"]) > 0
    assert "table" in refused.value.details()
    assert arm.server.device.state is State.RESTING
    assert np.allclose(arm.joints(), a, atol=1e-4)           # nothing moved
    _path(arm, "around", [a, over_a, over_b, b])
    assert _run(arm, "around") == "command_done"
    assert np.allclose(arm.joints(), b, atol=1e-3)


def test_a_path_sweeping_through_the_rack_is_refused_at_load_naming_its_segment(arm):
    points = [arm.joints()]
    for i, angle in enumerate(np.radians([30, 20, 0, -20, -40, -55, -70, -90, -110])):
        points.append(_joints(arm, (0.65 * np.cos(angle), 0.65 * np.sin(angle),
                                    0.5 if i < 6 else 0.25), points[-1]))
    with pytest.raises(grpc.RpcError) as refused:
        _path(arm, "sweep", points, blend=50)
    info = error_info(refused.value)
    assert info.reason == "COLLISION" and info.metadata["body_b"] == "rack"
    assert info.metadata["segment"] == "7"
    assert "sweep" not in arm.server.device.path_runs.paths      # nothing stored
    _path(arm, "sweep", points[:7], blend=50)                  # up to point 6 it is clear


def _around(arm):
    """Paths "down" (run: the flange beside the table at a) and "around" (a, over the table,
    b beside it on the other side); returns (a, b)."""
    q0 = arm.joints()
    over_a = _joints(arm, (0.6, -0.55, 0.45), q0)
    a = _joints(arm, (0.6, -0.55, 0.12), over_a)
    over_b = _joints(arm, (0.6, 0.55, 0.45), over_a)
    b = _joints(arm, (0.6, 0.55, 0.12), over_b)
    _path(arm, "down", [q0, over_a, a])
    assert _run(arm, "down") == "command_done"
    _path(arm, "around", [a, over_a, over_b, b])
    return a, b


def _plan_run(arm, name, cycles):
    motions = arm.server.device.motions
    return path_planning.plan_run(motions.planner, arm.server.device.path_runs.paths.get(name),
                                  motions.planning_start(), arm.server.device.settings, cycles)


def test_a_path_run_checks_each_of_its_pieces_once_whatever_its_cycles(arm):
    """A run of many cycles repeats the same pieces: checking them once per cycle made the
    check grow with the cycles (7.6 s for 1000) before anything moved."""
    q0 = arm.joints()
    over_a = _joints(arm, (0.6, -0.3, 0.5), q0)
    _path(arm, "over", [q0, over_a, _joints(arm, (0.6, 0.3, 0.5), over_a)])
    motions = arm.server.device.motions
    one = motions.check_collisions(_plan_run(arm, "over", 1))
    two = motions.check_collisions(_plan_run(arm, "over", 2))
    many = motions.check_collisions(_plan_run(arm, "over", 1000))
    assert one.pair_checks > 0 and two.pair_checks > one.pair_checks   # the way back, too
    assert many.pair_checks == two.pair_checks
    assert many.configurations == two.configurations


def test_a_refusal_in_a_later_piece_stops_the_arm_on_the_path_and_fails_the_motion(arm):
    """The way back from the last point to the first (joints straight from b to a) sweeps
    through the table: the second piece of a two-cycle run. A run is checked against the cell
    as it plays (issue 31 item 4): it starts, the later piece is refused while the arm moves,
    and the arm comes to rest on the path before it; the motion fails with the refusal, which
    says where in the whole run (time and fraction counted from its start), and an alarm
    names it."""
    a, _ = _around(arm)
    run, first_pass = _plan_run(arm, "around", 2), _plan_run(arm, "around", 1)
    dt = run[0].dt
    arm.server.device.path_runs.time_ahead = True   # as on the real-time clock
    reply = arm.device.PathMove(motion_pb2.PathMoveRequest(path_name="around",
                                                           number_of_cycles=2))
    events = arm.wait_command(reply.ret_val.command_id)
    failed = events[-1]
    assert failed.event_id == "command_failed", failed
    assert "table" in failed.command.message and "% of the motion" in failed.command.message
    time = float(failed.command.message.split("at t = ")[1].split(" s")[0])
    assert time > (sum(len(t) for t in first_pass) - 1) * dt      # after the first pass
    assert arm.server.device.state is State.RESTING
    played = np.concatenate([t.positions for t in run])
    # At rest on the path: the braking ramp ends between two samples, so on the chord of the
    # two nearest (the path between samples 4 ms apart is that chord within 1e-5 rad).
    nearest = np.argmin(np.abs(played - arm.joints()).max(axis=1))
    ends = played[max(nearest - 1, 0)], played[min(nearest + 1, len(played) - 1)]
    along = np.linspace(0.0, 1.0, 201)[:, None]
    chord = np.concatenate([ends[0] + along * (played[nearest] - ends[0]),
                            played[nearest] + along * (ends[1] - played[nearest])])
    assert np.abs(chord - arm.joints()).max(axis=1).min() < 5e-4
    assert nearest < round(time / dt)                                # before the contact
    alarms = [e for e in arm.history() if e.event_id == "alarm" and "table" in e.detail.message]
    assert alarms, "no alarm named the refusal"


SLOT = np.array([-0.1, -0.6, 0.461])    # the gripper's plate in its rack slot (world), down


def _straight_to(arm, xyz):
    """A straight move of the (bare) flange to xyz (world), pointing down; its events."""
    reply = arm.device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
        frame=types_pb2.REFERENCE_FRAME_WORLD_CARTESIAN_FRAME, values=[*xyz, np.pi, 0, 0],
        motion_type=types_pb2.MOTION_TYPE_STRAIGHT_MOTION), timeout=30)
    return arm.wait_command(reply.ret_val.command_id)


@pytest.mark.physics   # the world: tools, parts, wired inputs, sensor readings
def test_a_client_driving_the_arm_docks_a_rack_tool_along_its_axis_and_puts_it_back(arm):
    """Issue 11, a tool coupling at the changer: a client driving the arm itself (CRCL: MoveTo
    above the slot, MoveTo onto it, CloseToolChanger; and back) couples a tool in the rack
    and returns it."""
    arm.move_down_to(*(SLOT + [0, 0, 0.1]))              # above the plate, on its axis
    assert _straight_to(arm, SLOT)[-1].event_id == "command_done"
    _, io, _ = stubs(arm.session.channel)
    io.SetDigitalIO(io_pb.SetDigitalIORequest(type="output", unit_id=2, bits_on=1))  # lock
    reply = arm.device.GetEndEffectorState(ee.GetEndEffectorStateRequest())
    assert reply.current_ee == "gripper"
    assert _straight_to(arm, SLOT + [0, 0, 0.25])[-1].event_id == "command_done"   # out
    # And back: the tool down into its slot along the axis (the tool tip, 16 cm below the
    # plate, is what moves now), the changer opened, the bare flange straight up again.
    assert _straight_to(arm, SLOT - [0, 0, 0.16])[-1].event_id == "command_done"
    io.SetDigitalIO(io_pb.SetDigitalIORequest(type="output", unit_id=2, bits_off=1))
    reply = arm.device.GetEndEffectorState(ee.GetEndEffectorStateRequest())
    assert reply.current_ee == ""
    assert _straight_to(arm, SLOT + [0, 0, 0.1])[-1].event_id == "command_done"


def test_a_sideways_motion_of_the_bare_flange_into_a_rack_tool_is_refused(arm):
    """Only the straight approach along the coupling's axis may touch: sliding onto the
    plate from the side, 3 mm above it, is refused."""
    beside = SLOT + [0.1, 0, 0.003]
    arm.move_down_to(*(beside + [0, 0, 0.1]))
    assert _straight_to(arm, beside)[-1].event_id == "command_done"
    before = arm.joints().copy()
    with pytest.raises(grpc.RpcError) as refused:
        _straight_to(arm, SLOT + [0, 0, 0.003])
    info = error_info(refused.value)
    assert info.reason == "COLLISION"
    assert {info.metadata["body_a"], info.metadata["body_b"]} == {"link6", "gripper"}
    assert np.allclose(arm.joints(), before, atol=1e-6)         # nothing moved

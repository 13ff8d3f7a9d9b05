"""The blocking client against a real device server: control(), waiting, errors, streams, RSVP."""
from __future__ import annotations

import time

import grpc
import pytest

from landscape.client import (CommandAborted, DeviceState, Frame, NotLockHolder, Robot,
                              TagPoint, WrongState)
from landscape.client import errors
from landscape.server.device.states import State
from landscape.v1 import control_pb2, sensing_pb2

from support import start_server, wait_until

HOME = [0.0, 0.0, 1.5708, 0.0, 1.5708, 0.0]
AWAY = [0.8, -0.3, 1.2, 0.4, 1.2, 0.5]


@pytest.fixture
def paced_server():
    """Lock-step at real-time pace: a move lasts long enough to be interrupted."""
    running = start_server(lockstep_pace=1.0)
    yield running
    running.stop(grace=None)


def _drives_enabled(server) -> bool:
    return server.device.feedback().enable.name == "ENABLED"


def test_control_leaves_the_device_deactivated_and_unlocked_when_the_body_raises(paced_server):
    with Robot(paced_server.target, "raiser") as robot:
        with pytest.raises(RuntimeError, match="the body failed"):
            with robot.control():
                robot.move_absolute(AWAY, Frame.JOINT)
                wait_until(lambda: paced_server.device.state is State.MOVING, timeout=10)
                raise RuntimeError("the body failed")
        # Still in the session: the device is back in the seed's Unlocked, drives off.
        device = robot.get_device_state()
        assert DeviceState(device.state) is DeviceState.UNLOCKED and not device.locked
        assert robot.get_motion_control_state().control_mode == "power_off"
        assert not _drives_enabled(paced_server)
        # Stopped on the way, not at the goal.
        joints = robot.get_robot_position().joint_position
        assert abs(joints[0] - AWAY[0]) > 1e-3


def test_a_move_waited_for_returns_its_done_event_and_the_arm_is_there(server):
    with Robot(server.target, "mover") as robot, robot.control():
        command = robot.move_absolute(AWAY, Frame.JOINT, point_name="away")
        done = command.wait(timeout=30)
        assert (done.event_id, done.command.command_id) == ("command_done", command.command_id)
        assert [e.event_id for e in command.events][0] == "command_started"
        joints = robot.get_robot_position().joint_position
        assert joints == pytest.approx(AWAY, abs=1e-5)


def test_a_stopped_and_aborted_move_raises_command_aborted(paced_server):
    with Robot(paced_server.target, "stopper") as robot, robot.control():
        command = robot.move_absolute(AWAY, Frame.JOINT)
        wait_until(lambda: paced_server.device.state is State.MOVING, timeout=10)
        robot.stop_motion()
        robot.abort_motion()
        with pytest.raises(CommandAborted) as aborted:
            command.wait(timeout=10)
        assert aborted.value.event.command.command_id == command.command_id


def test_an_estop_during_a_move_fails_it_with_the_alarm(paced_server):
    with Robot(paced_server.target, "estopped") as robot:
        robot.lock()
        robot.activate()
        command = robot.move_absolute(AWAY, Frame.JOINT)
        wait_until(lambda: paced_server.device.state is State.MOVING, timeout=10)
        robot.operate_panel(control_pb2.PANEL_ACTION_PRESS_ESTOP)
        with pytest.raises(errors.CommandFailed) as failed:
            command.wait(timeout=10)
        assert failed.value.event.command.command_id == command.command_id
        assert failed.value.alarm is not None and failed.value.alarm.message
        robot.operate_panel(control_pb2.PANEL_ACTION_RELEASE_ESTOP)


def test_refusals_map_to_the_vocabulary_with_the_seeds_return_code(server):
    with Robot(server.target, "refused") as robot, Robot(server.target, "other") as other:
        robot.lock()
        with pytest.raises(NotLockHolder):
            other.set_speed(50)
        with pytest.raises(WrongState) as wrong:          # Inactive: drives are off
            robot.move_absolute(HOME, Frame.JOINT)
        assert wrong.value.code is grpc.StatusCode.FAILED_PRECONDITION
        assert wrong.value.reason == "WRONG_STATE" and wrong.value.ret_code == -1
        robot.activate()
        with pytest.raises(errors.OutOfRange) as out:
            robot.move_absolute([9, 0, 0, 0, 0, 0], Frame.JOINT)
        assert out.value.ret_code == -3 and "joint 1" in out.value.message
        with pytest.raises(errors.InvalidArgument) as bad:
            robot.move_absolute([0.1, 0.2], Frame.JOINT)   # 2 values for 6 joints
        assert bad.value.ret_code == -2
        with pytest.raises(errors.InvalidArgument) as unknown:   # the vendor hook's list
            robot.send_command("reboot")
        assert unknown.value.ret_code == -2 and "recorder start" in unknown.value.message
        assert isinstance(out.value, errors.CommandRefused)
        assert not isinstance(out.value, errors.TransportError)


def test_no_server_is_a_retryable_transport_error():
    with pytest.raises(errors.RetryableTransportError):
        Robot("127.0.0.1:1", "nobody").open(timeout=0.5)


def test_events_iterate_in_order_and_resume_after_a_sequence(server):
    with Robot(server.target, "watcher") as robot:
        with robot.control():
            pass
        with robot.events(after_sequence=0, timeout=10) as events:
            seen = []
            for event in events:
                seen.append(event)
                if event.HasField("state_change") and _unlocked(event.state_change.to_state) \
                        and len(seen) > 1:   # the release at the end of control()
                    break
        assert [e.sequence for e in seen] == list(range(1, len(seen) + 1))
        with robot.events(after_sequence=seen[-2].sequence, timeout=10) as resumed:
            assert next(iter(resumed)).sequence == seen[-1].sequence


def _unlocked(state_name: str) -> bool:
    # The contract says DeviceState names ("DEVICE_STATE_UNLOCKED"); the server sends "unlocked".
    return state_name in ("DEVICE_STATE_UNLOCKED", "unlocked")


def test_a_long_path_loads_in_chunks_and_a_tagged_one_runs_to_its_done_event(server):
    long = [TagPoint([0.001 * i, 0, 1.5708, 0, 1.5708, 0]) for i in range(300)]
    tagged = [TagPoint([0.2 * i, 0, 1.5708, 0, 1.5708, 0], tag_name=f"t{i}") for i in range(1, 4)]
    with Robot(server.target, "pather") as robot, robot.control():
        reply = robot.path_load("long", long, Frame.JOINT)   # 300 points: two messages
        assert (reply.points_loaded, reply.path_length) == (300, 300)
        robot.path_load("tagged", tagged, Frame.JOINT)
        events = list(robot.path_move("tagged").follow(timeout=60))
        assert [e.command.tag_name for e in events if e.event_id == "tag_reached"] == \
            ["t1", "t2", "t3"]
        assert events[-1].event_id == "command_done"


def test_the_rsvp_handler_answers_the_devices_question(server):
    asked = []

    def answer(request):
        asked.append(request)
        return "reset", list(request.data)

    with Robot(server.target, "operator", on_rsvp=answer) as robot, robot.control():
        robot.operate_panel(control_pb2.PANEL_ACTION_PRESS_ESTOP)
        wait_until(lambda: server.device.state is State.ERROR)
        robot.operate_panel(control_pb2.PANEL_ACTION_RELEASE_ESTOP)
        wait_until(lambda: server.device.state is State.INACTIVE)   # answered "reset"
        assert asked[0].event_id == "estop_released"


def test_live_state_samples_arrive_at_the_rate_asked(server):
    with Robot(server.target, "state-watcher") as robot:
        with robot.live_state(rate_hz=50, timeout=10) as stream:
            started = stream.wait_started()
            assert started.granted_rate_hz == pytest.approx(50)
            samples = [sample for sample, _ in zip(stream, range(5))]
        assert len(samples) == 5
        assert all(len(s.joint_positions) == 6 for s in samples)
        assert samples[-1].sequence > samples[0].sequence


def test_waiting_less_than_a_move_takes_raises_command_timeout_and_the_move_goes_on(paced_server):
    with Robot(paced_server.target, "impatient") as robot, robot.control():
        command = robot.move_absolute(AWAY, Frame.JOINT)
        with pytest.raises(errors.CommandTimeout, match=command.command_id):
            command.wait(timeout=0.05)
        assert paced_server.device.state is State.MOVING   # still on its way
        assert command.wait(timeout=60).event_id == "command_done"
        assert robot.get_robot_position().joint_position == pytest.approx(AWAY, abs=1e-5)


def test_the_cell_description_names_the_rack_tools_and_the_parts(server):
    with Robot(server.target, "looker") as robot:
        cell = robot.get_cell_description()
    kinds = {body.name: control_pb2.CellBody.Kind.Name(body.kind) for body in cell.bodies}
    assert kinds["gripper"] == "KIND_TOOL" and kinds["block_1"] == "KIND_PART"
    block = next(body for body in cell.bodies if body.name == "block_1")
    assert block.pose.z == pytest.approx(0.22, abs=0.01) and not block.attached_to


def test_a_posted_message_reaches_every_subscriber_and_needs_the_lock(server):
    with Robot(server.target, "poster") as robot, Robot(server.target, "reader") as reader:
        with pytest.raises(NotLockHolder):
            robot.post_message("not yet")
        with robot.control(activate=False):
            reply = robot.post_message("bin 3 is full")
        with reader.events(after_sequence=reply.sequence - 1, timeout=10) as events:
            event = next(iter(events))
    assert event.sequence == reply.sequence
    assert (event.operator_message.text, event.operator_message.source) == \
        ("bin 3 is full", "poster")


def test_jog_moves_the_joint_while_the_deadman_is_held_and_ends_cleanly(paced_server):
    def held(count: int):
        for _ in range(count):
            yield [30, 0, 0, 0, 0, 0]
            time.sleep(0.02)   # a pendant's pace: well inside the deadman timeout

    with Robot(paced_server.target, "jogger") as robot, robot.control():
        robot.manual_control(sensing_pb2.MANUAL_CONTROL_TYPE_TEACHPENDANT)
        before = robot.get_robot_position().joint_position[0]
        replies = list(robot.jog(held(25), Frame.JOINT))   # ends with the deadman released
        after = robot.get_robot_position().joint_position[0]
    assert after > before + 0.01
    assert replies and len(replies[-1].joint_position) == 6

"""Reads served from the reply cache (server/api/read_cache.py, issue 31 item 1): a reply is
built once per version of what it depends on, and a change shows in the very next read, even
within one cycle (the clock held: the cycle number alone would not tell)."""
from __future__ import annotations

import grpc
import pytest

from landscape.server.api.read_cache import ReplyCache
from landscape.v1 import control_pb2, motion_pb2, settings_pb2, types_pb2

from support import locked_session, stubs, wait_until


class _Settings:
    """An immutable value, replaced on change (as MotionSettings is)."""


def test_a_reply_is_built_once_per_version():
    cache, built = ReplyCache(), []

    def build(text):
        return lambda: built.append(text) or text

    first = _Settings()
    assert cache.reply("Read", (7, first), build("a")) == "a"
    assert cache.reply("Read", (7, first), build("b")) == "a"       # same cycle, same settings
    assert cache.reply("Read", (8, first), build("c")) == "c"       # a new cycle: built anew
    assert cache.reply("Read", (8, _Settings()), build("d")) == "d"  # new settings: by identity
    assert cache.reply("Other", (8, first), build("e")) == "e"      # one reply per read
    assert built == ["a", "c", "d", "e"]


def test_a_build_that_fails_keeps_nothing():
    cache = ReplyCache()

    def fail():
        raise RuntimeError("no feedback yet")
    with pytest.raises(RuntimeError):
        cache.reply("Read", (-1,), fail)
    assert cache.reply("Read", (-1,), lambda: "later") == "later"


def _position(device) -> tuple[float, ...]:
    p = device.GetRobotPosition(settings_pb2.GetRobotPositionRequest(), timeout=5).world_position
    return p.x, p.y, p.z


def test_a_setting_shows_in_the_next_read_within_the_same_cycle(server):
    holder = locked_session(server, "holder")
    clock = server.link.clock
    try:
        with grpc.insecure_channel(server.target) as channel:
            reader, _, _ = stubs(channel)
            setter, _, _ = stubs(holder.channel)
            clock.hold()
            cycle = server.link.feedback.head
            before = _position(reader)
            assert _position(reader) == before
            setter.SetToolOffset(settings_pb2.SetToolOffsetRequest(
                offset=types_pb2.Pose(z=0.1)), timeout=5)
            after = _position(reader)
            offset = reader.GetToolOffsets(settings_pb2.GetToolOffsetsRequest(), timeout=5)
            setter.SetUnits(settings_pb2.SetUnitsRequest(
                linear_units=types_pb2.LINEAR_UNIT_MILLIMETERS,
                angular_units=types_pb2.ANGULAR_UNIT_DEGREES))
            limits = reader.GetMaxVelocities(settings_pb2.GetMaxVelocitiesRequest(), timeout=5)
            in_mm = _position(reader)
            assert server.link.feedback.head == cycle        # all of it within one cycle
    finally:
        clock.release()
        holder.close()
    assert after != before
    assert sum((a - b) ** 2 for a, b in zip(after, before)) ** 0.5 == pytest.approx(0.1)
    assert offset.offset.z == pytest.approx(0.1)
    assert limits.units.linear == types_pb2.LINEAR_UNIT_MILLIMETERS
    assert limits.max_world_linear_velocity == pytest.approx(
        1000 * server.device.arm.max_linear_velocity)
    assert in_mm == pytest.approx(tuple(1000 * v for v in after))


def test_the_position_follows_the_moving_arm_cycle_by_cycle(arm):
    """Each cycle's read is that cycle's: with the arm moving and the cycles stepped by hand,
    the joints read back are the ones the feedback ring holds for the newest cycle."""
    reply = arm.device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
        frame=types_pb2.REFERENCE_FRAME_JOINT_FRAME, values=[0.5, 0, 0, 0, 0, 0]), timeout=30)
    arm.wait_command(reply.ret_val.command_id, phases=("command_started",))
    clock, seen = arm.link.clock, []
    wait_until(lambda: abs(arm.server.link.feedback.latest().velocity[0]) > 0.01, 30)
    clock.hold()
    try:
        for _ in range(3):
            read = arm.device.GetRobotPosition(settings_pb2.GetRobotPositionRequest(), timeout=5)
            newest = arm.server.link.feedback.latest().position
            assert list(read.joint_position) == pytest.approx(list(newest), abs=1e-12)
            seen.append(read.joint_position[0])
            arm.link.between_cycles(lambda controller: controller.step())
    finally:
        clock.release()
    assert len(set(seen)) == 3      # the arm moved between the reads


def test_an_arm_at_rest_is_read_from_one_reply_across_cycles(server):
    """A position read's reply is built once while the arm stands still (issue 31 item 1): the
    cycles go on, the reads answer the very same bytes. (The simulated arm at rest reads a
    new position every cycle, by 1e-23 rad of round-off: its reply was built again every
    4 ms, a third of a bare echo's time for a read that changed nothing.)"""
    clock = server.link.clock
    with grpc.insecure_channel(server.target) as channel:
        reader, _, _ = stubs(channel)
        request = settings_pb2.GetRobotPositionRequest()
        clock.hold()
        try:
            replies, cycles = set(), []
            for _ in range(20):
                replies.add(reader.GetRobotPosition(request, timeout=5).SerializeToString())
                cycles.append(server.link.feedback.head)
                server.link.between_cycles(lambda controller: controller.step())
        finally:
            clock.release()
    assert len(set(cycles)) == 20    # a new cycle for every read
    assert len(replies) == 1


def test_the_position_since_moves_with_the_arm(arm):
    """The hub's position_since, which versions the position reads: it stays while the arm
    rests and is each new cycle while a joint moves by more than STILL."""
    hub, clock = arm.server.hub, arm.link.clock
    resting = hub.position_since()
    arm.link.between_cycles(lambda controller: controller.step())
    assert hub.position_since() == resting
    reply = arm.device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
        frame=types_pb2.REFERENCE_FRAME_JOINT_FRAME, values=[0.5, 0, 0, 0, 0, 0]), timeout=30)
    arm.wait_command(reply.ret_val.command_id, phases=("command_started",))
    wait_until(lambda: abs(arm.server.link.feedback.latest().velocity[0]) > 0.01, 30)
    clock.hold()
    try:
        for _ in range(3):
            assert hub.position_since() == arm.server.link.feedback.head
            arm.link.between_cycles(lambda controller: controller.step())
    finally:
        clock.release()
    assert hub.position_since() > resting


def test_the_device_state_read_follows_each_change_and_each_change_back(server):
    """GetDeviceState's reply is kept while the status is the same (issue 31 item 1): every
    change shows in the next read, and so does a change back to a status read before (a reply
    kept for the older status must not come back with it)."""
    with grpc.insecure_channel(server.target) as channel:
        reader, _, _ = stubs(channel)

        def read():
            reply = reader.GetDeviceState(control_pb2.GetDeviceStateRequest(), timeout=5)
            return reply.state, reply.locked, reply.lock_holder
        unlocked = read()
        assert read() == unlocked
        for _ in range(2):
            holder = locked_session(server, "holder")
            assert read() == (types_pb2.DEVICE_STATE_INACTIVE, True, "holder")
            holder.close()
            wait_until(lambda: read() == unlocked)

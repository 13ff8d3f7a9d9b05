"""GetSensorReading of a sensor the feedback ring carries (issue 31 item 1): one lookup of the
newest cycle's row, on the event loop, its reply kept per (cycle, settings); the same
reading, in the same units, as the controller gives when asked."""
from __future__ import annotations

import threading

import grpc
import pytest

from landscape.server.app import serve
from landscape.server.config import ServerConfig
from landscape.v1 import sensing_pb2, settings_pb2, types_pb2

from support import locked_session, stubs, wait_until

LASER = sensing_pb2.GetSensorReadingRequest(sensor_type="laser_standoff_sensor")
FORCE = sensing_pb2.GetSensorReadingRequest(sensor_type="force_sensor")
IN_MM = settings_pb2.SetUnitsRequest(linear_units=types_pb2.LINEAR_UNIT_MILLIMETERS,
                                     angular_units=types_pb2.ANGULAR_UNIT_RADIANS)


@pytest.fixture
def realtime():
    server = serve(ServerConfig(port=0, clock="realtime"))
    yield server
    server.stop(grace=None)


def test_a_ring_sensor_answers_while_every_read_thread_is_taken(realtime):
    """On the real-time clock every row is whole: a reading is memory, and needs none of the
    threads the reads that ask the controller wait on. (Before: every GetSensorReading took
    one of those threads; with all of them taken it waited past its deadline.)"""
    ring = realtime.link.feedback
    wait_until(lambda: ring.whole(ring.head), timeout=10)
    release = threading.Event()
    reads = realtime.dispatch.reads
    taken = [reads.submit(release.wait, 30) for _ in range(64)]   # more than the lane has
    holder = locked_session(realtime, "holder")
    try:
        with grpc.insecure_channel(realtime.target) as channel:
            reader, _, _ = stubs(channel)
            force = reader.GetSensorReading(FORCE, timeout=3).current_data
            metres = reader.GetSensorReading(LASER, timeout=3).current_data[0]
            stubs(holder.channel)[0].SetUnits(IN_MM, timeout=5)
            millimetres = reader.GetSensorReading(LASER, timeout=3)
    finally:
        release.set()
        for read in taken:
            read.result(timeout=10)
        holder.close()
    assert len(force) == 6 and max(abs(v) for v in force) < 1e-3   # nothing on the flange
    assert 0 < metres < 2
    assert millimetres.current_data[0] == pytest.approx(1000 * metres, rel=1e-3)
    assert millimetres.units.linear == types_pb2.LINEAR_UNIT_MILLIMETERS


@pytest.mark.physics   # a range to read: pybullet's world (tests/conftest.py)
def test_the_ring_reading_is_the_controllers_and_follows_the_units_within_a_cycle(server):
    """The clock held: the controller's answer (nobody watches the rows), then the ring's
    (rows whole from two cycles on) give the same reading, kept as one reply across cycles
    at rest; a change of units shows in the very next read, within the same cycle."""
    ring, link = server.link.feedback, server.link
    holder = locked_session(server, "holder")
    link.clock.hold()
    try:
        with grpc.insecure_channel(server.target) as channel:
            reader, _, _ = stubs(channel)
            asked = reader.GetSensorReading(LASER, timeout=5).current_data[0]
            ring.watch()
            try:
                replies = set()
                for _ in range(5):
                    link.between_cycles(lambda controller: controller.step())
                    if ring.whole(ring.head):
                        replies.add(reader.GetSensorReading(LASER, timeout=5).SerializeToString())
                held = reader.GetSensorReading(LASER, timeout=5).current_data[0]
                cycle = ring.head
                stubs(holder.channel)[0].SetUnits(IN_MM, timeout=5)
                in_mm = reader.GetSensorReading(LASER, timeout=5)
                assert ring.head == cycle                      # all within one cycle
            finally:
                ring.unwatch()
    finally:
        link.clock.release()
        holder.close()
    assert len(replies) == 1                                   # at rest: one reply
    assert held == pytest.approx(asked, abs=1e-6)
    assert in_mm.current_data[0] == pytest.approx(1000 * held, rel=1e-9)
    assert in_mm.units.linear == types_pb2.LINEAR_UNIT_MILLIMETERS

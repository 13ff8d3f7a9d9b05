"""EnableSensor / DisableSensor against the real gateway and device server: the shared state
feed follows the sensors enabled, and never stops for it."""
from __future__ import annotations

import time

import pytest

from support import cell_file, start_server

from crcl_support import XSD_2021, RawClient, RunningGateway, field, pose
from test_gateway import MOVE, point

CRCL_SCHEMAS = XSD_2021       # EnableSensor and DisableSensor are the 2021 revision's

SECOND_LASER = """
[sensors.side_laser]
kind = "laser_range"           # a second range sensor: read on request, not every cycle
max_range = 1.0
min_range = 0.005
offset = [0.05, 0.0, 0.0]
"""


def test_enable_sensor_then_move_the_pose_follows_and_the_sensor_is_reported(gateway, client):
    enabled = client.run("EnableSensor", 2, "<SensorID>force_sensor</SensorID>")
    assert field(enabled, "CommandState") == "CRCL_Done", enabled
    done = client.run("MoveTo", 3, MOVE.format("true") + pose(0.5, 0.1, 0.6))
    assert field(done, "CommandState") == "CRCL_Done", done
    assert point(done) == pytest.approx((0.5, 0.1, 0.6), abs=1e-4)
    status = client.status()              # validated against CRCLStatus.xsd by the client
    sensor = field(status, "ForceTorqueSensorStatus")
    assert sensor is not None and field(sensor, "SensorID") == "force_sensor", status
    assert abs(float(field(sensor, "Fz"))) < 1e3
    # LastReadTime: milliseconds since 1970, of the cycle read
    assert abs(int(field(sensor, "LastReadTime")) / 1e3 - time.time()) < 60
    moved = client.run("MoveTo", 4, MOVE.format("false") + pose(0.45, -0.1, 0.55))
    assert field(moved, "CommandState") == "CRCL_Done", moved
    assert point(moved) == pytest.approx((0.45, -0.1, 0.55), abs=1e-4)


def test_disable_sensor_stops_watching_it(gateway, client):
    client.run("EnableSensor", 2, "<SensorID>force_sensor</SensorID>")
    assert gateway.link.feed.sensors == ("force_sensor",)
    disabled = client.run("DisableSensor", 3, "<SensorID>force_sensor</SensorID>")
    assert field(disabled, "CommandState") == "CRCL_Done", disabled
    assert gateway.link.feed.sensors == ()
    status = client.status()
    assert field(status, "SensorStatuses") is None
    assert "old" not in (field(status, "StateDescription") or "")
    done = client.run("MoveTo", 4, MOVE.format("true") + pose(0.5, 0.0, 0.6))
    assert point(done) == pytest.approx((0.5, 0.0, 0.6), abs=1e-4)


def test_the_feed_watches_what_any_connection_enabled_until_it_closes(gateway, client):
    client.run("EnableSensor", 2, "<SensorID>force_sensor</SensorID>")
    client.run("EndCanon", 3)                 # status keeps reporting the sensor it enabled
    assert field(client.status(), "ForceTorqueSensorStatus") is not None
    other = RawClient(gateway.port, schemas=XSD_2021)
    try:
        other.run("InitCanon", 1)
        other.run("EnableSensor", 2, "<SensorID>laser_standoff_sensor</SensorID>")
        assert gateway.link.feed.sensors == ("force_sensor", "laser_standoff_sensor")
        client.close()
        deadline = time.monotonic() + 10
        while gateway.link.feed.sensors != ("laser_standoff_sensor",):
            assert time.monotonic() < deadline, gateway.link.feed.sensors
            time.sleep(0.01)
        assert field(other.status(), "ScalarSensorStatus") is not None
        init = other.run("InitCanon", 3)      # a new session starts with no sensors
        assert field(init, "CommandState") == "CRCL_Done", init
        assert gateway.link.feed.sensors == ()
    finally:
        other.close()


@pytest.fixture
def laser_cell(tmp_path):
    server = start_server(cell=cell_file(tmp_path, {"# The recorder": SECOND_LASER + "\n# The recorder"}))
    gateway = RunningGateway(server.target, schemas=XSD_2021)
    yield gateway
    gateway.close()
    server.stop(grace=None)


def test_a_sensor_the_state_stream_cannot_carry_is_refused_and_the_feed_goes_on(laser_cell):
    client = RawClient(laser_cell.port, schemas=XSD_2021)
    try:
        client.run("InitCanon", 1)
        refused = client.run("EnableSensor", 2, "<SensorID>side_laser</SensorID>")
        assert field(refused, "CommandState") == "CRCL_Error", refused
        assert "side_laser" in field(refused, "StateDescription")
        assert laser_cell.link.feed.sensors == ()
        done = client.run("MoveTo", 3, MOVE.format("true") + pose(0.5, 0.1, 0.6))
        assert point(done) == pytest.approx((0.5, 0.1, 0.6), abs=1e-4)
        assert field(client.status(), "SensorStatuses") is None
    finally:
        client.close()

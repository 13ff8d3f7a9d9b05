"""The device server serves the contract, health checking and reflection on loopback."""
from __future__ import annotations

import time

import grpc
import pytest
from grpc_health.v1 import health_pb2, health_pb2_grpc
from grpc_reflection.v1alpha import reflection_pb2, reflection_pb2_grpc

from landscape.server import services
from landscape.v1 import control_pb2, device_service_pb2_grpc, motion_pb2, types_pb2


def test_health_reports_serving_for_the_server_and_each_service(channel):
    stub = health_pb2_grpc.HealthStub(channel)
    for name in ("", *(spec.full_name for spec in services.ALL)):
        reply = stub.Check(health_pb2.HealthCheckRequest(service=name), timeout=5)
        assert reply.status == health_pb2.HealthCheckResponse.SERVING, name


def test_reflection_lists_every_service(channel):
    stub = reflection_pb2_grpc.ServerReflectionStub(channel)
    request = reflection_pb2.ServerReflectionRequest(list_services="")
    reply = next(stub.ServerReflectionInfo(iter([request]), timeout=5))
    listed = {s.name for s in reply.list_services_response.service}
    assert listed == {*(spec.full_name for spec in services.ALL), "grpc.health.v1.Health",
                      "grpc.reflection.v1alpha.ServerReflection"}


def test_every_rpc_of_the_contract_is_built():
    """What is not built answers UNIMPLEMENTED (guard.py); today nothing is left."""
    from landscape.server.app import DeviceServicer, DigitalIOServicer, EventServicer
    from landscape.server.app import SessionServicer, StateServicer
    servicers = {services.DEVICE: DeviceServicer, services.DIGITAL_IO: DigitalIOServicer,
                 services.EVENTS: EventServicer, services.SESSIONS: SessionServicer,
                 services.STATE: StateServicer}
    assert set(servicers) == set(services.ALL)
    missing = [f"{spec.name}.{method.name}" for spec, cls in servicers.items()
               for method in spec.descriptor.methods
               if getattr(getattr(cls, method.name), "unimplemented", False)]
    assert missing == []


def test_robot_description_is_the_arm_urdf(channel):
    stub = device_service_pb2_grpc.DeviceServiceStub(channel)
    reply = stub.GetRobotDescription(control_pb2.GetRobotDescriptionRequest(), timeout=5)
    assert reply.ret_val.ret_code == types_pb2.RETURN_CODE_CMD_EXEC_OK
    assert reply.robot_type == "TX90"
    assert reply.urdf.count("<joint ") == 7 and 'name="tool0"' in reply.urdf
    assert list(reply.joint_names) == [f"joint_{i}" for i in range(1, 7)]


def test_an_oversized_message_is_refused_and_the_server_keeps_serving(channel, server):
    stub = device_service_pb2_grpc.DeviceServiceStub(channel)
    huge = motion_pb2.MoveAbsoluteRequest(point_name="x" * (5 * 1024 * 1024))
    with pytest.raises(grpc.RpcError) as err:
        stub.MoveAbsolute(huge, timeout=5)
    assert err.value.code() == grpc.StatusCode.RESOURCE_EXHAUSTED
    reply = stub.GetRobotDescription(control_pb2.GetRobotDescriptionRequest(), timeout=5)
    assert reply.robot_type == "TX90"


def test_stream_caps_are_per_client_and_never_cost_a_session():
    """Issue 9.7: one client holding its share of subscriptions takes nothing from others,
    and sessions (they carry safety) are never refused because of subscriptions."""
    from support import start_server
    from landscape.client import Session
    from landscape.server.limits import Cap
    from landscape.v1 import event_service_pb2, event_service_pb2_grpc
    server = start_server(stream_caps={"session": Cap(2, 4), "watch": Cap(2, 3)})
    try:
        # A connection of its own (channels in one process share connections otherwise).
        own = [("grpc.use_local_subchannel_pool", 1)]
        with grpc.insecure_channel(server.target) as greedy, \
                grpc.insecure_channel(server.target, options=own) as other:
            events = event_service_pb2_grpc.EventServiceStub(greedy)
            held = [events.Subscribe(event_service_pb2.SubscribeRequest(after_sequence=0))
                    for _ in range(2)]
            for stream in held:
                next(stream)   # both are live
            with pytest.raises(grpc.RpcError) as refused:
                next(events.Subscribe(event_service_pb2.SubscribeRequest(), timeout=5))
            assert refused.value.code() == grpc.StatusCode.RESOURCE_EXHAUSTED
            assert "this client" in refused.value.details()
            # Another client still subscribes, and sessions open on both.
            mine = event_service_pb2_grpc.EventServiceStub(other).Subscribe(
                event_service_pb2.SubscribeRequest(after_sequence=0))
            next(mine)
            for channel in (greedy, other):
                Session(channel, "still-possible").open().close()
            device = device_service_pb2_grpc.DeviceServiceStub(greedy)
            state = device.GetDeviceState(control_pb2.GetDeviceStateRequest(), timeout=5).state
            assert state == types_pb2.DEVICE_STATE_UNLOCKED
            held[0].cancel()
            # Its slot comes back once the server has seen the cancellation.
            deadline = time.monotonic() + 5
            while True:
                try:
                    third = events.Subscribe(event_service_pb2.SubscribeRequest(after_sequence=0))
                    next(third)
                    break
                except grpc.RpcError:
                    assert time.monotonic() < deadline
                    time.sleep(0.05)
            for stream in (third, held[1], mine):
                stream.cancel()
    finally:
        server.stop(grace=None)


def test_the_cell_description_names_every_body_where_the_device_knows_it(channel, server):
    stub = device_service_pb2_grpc.DeviceServiceStub(channel)
    reply = stub.GetCellDescription(control_pb2.GetCellDescriptionRequest(), timeout=5)
    cell = server.device.collisions.cell
    by_name = {b.name: b for b in reply.bodies}
    assert reply.cell_name == cell.name and reply.floor == cell.world.floor
    table = by_name["table"]
    assert table.kind == control_pb2.CellBody.KIND_FIXTURE
    assert (table.pose.x, table.pose.z, table.size.z) == (0.6, 0.1, 0.2)   # the cell file's
    for tool in cell.world.tools:
        assert by_name[tool.name].urdf.startswith("<?xml") and not by_name[tool.name].attached_to
        assert by_name[tool.name].pose.z == pytest.approx(tool.slot.xyz[2])
    assert {p.name for p in cell.world.parts} <= set(by_name)
    assert {z.name for z in cell.world.zones} <= set(by_name)

"""The device server serves the contract, health checking and reflection on loopback."""
from __future__ import annotations

import socket
import time

import grpc
import pytest
from grpc_health.v1 import health_pb2, health_pb2_grpc
from grpc_reflection.v1alpha import reflection_pb2, reflection_pb2_grpc

from landscape.server.api import services
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
    from landscape.server.app import RecordingServicer, SessionServicer, StateServicer
    from landscape.server.app import AuditServicer
    servicers = {services.DEVICE: DeviceServicer, services.DIGITAL_IO: DigitalIOServicer,
                 services.EVENTS: EventServicer, services.SESSIONS: SessionServicer,
                 services.STATE: StateServicer, services.RECORDINGS: RecordingServicer,
                 services.AUDIT: AuditServicer}
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


def test_a_client_is_its_address_not_its_connection():
    from landscape.server.api.stream_caps import client_of, peer_address
    assert peer_address("ipv4:10.0.0.5:51234") == "ipv4:10.0.0.5"
    assert peer_address("ipv6:[::1]:51234") == "ipv6:[::1]"
    assert peer_address("ipv6:%5B::ffff:127.0.0.1%5D:51234") == "ipv6:%5B::ffff:127.0.0.1%5D"
    assert peer_address("unix:/run/landscape.sock") == "unix:/run/landscape.sock"
    assert client_of("ipv4:10.0.0.5:1") == client_of("ipv4:10.0.0.5:2") != client_of(
        "ipv4:10.0.0.6:1")


def _subscribe(channel):
    from landscape.v1 import event_service_pb2, event_service_pb2_grpc
    stream = event_service_pb2_grpc.EventServiceStub(channel).Subscribe(
        event_service_pb2.SubscribeRequest(after_sequence=0), timeout=30)
    next(stream)   # live
    return stream


def test_stream_caps_are_per_client_and_never_cost_a_session():
    """Issue 9.7: a client (here: an address) holding its share of subscriptions takes nothing
    from other clients, gets no more by opening another connection, and sessions (they carry
    safety) are never refused because of subscriptions. The server listens on localhost, so
    127.0.0.1 and ::1 are two clients."""
    from support import start_server
    from landscape.client import Session
    from landscape.server.api.stream_caps import Cap
    if not socket.has_ipv6:
        pytest.skip("this machine has no IPv6: no second loopback address")
    server = start_server(address="localhost",
                          stream_caps={"session": Cap(2, 4), "watch": Cap(2, 3)})
    own = [("grpc.use_local_subchannel_pool", 1)]   # a connection of its own, each
    channels = [grpc.insecure_channel(f"127.0.0.1:{server.port}", options=own),
                grpc.insecure_channel(f"127.0.0.1:{server.port}", options=own),
                grpc.insecure_channel(f"[::1]:{server.port}", options=own)]
    greedy, again, other = channels
    held = []
    try:
        try:
            grpc.channel_ready_future(other).result(timeout=5)
        except grpc.FutureTimeoutError:
            pytest.skip("no IPv6 loopback here")
        held += [_subscribe(greedy), _subscribe(greedy)]
        for channel in (greedy, again):      # a second connection is the same client
            with pytest.raises(grpc.RpcError) as refused:
                _subscribe(channel)
            assert refused.value.code() == grpc.StatusCode.RESOURCE_EXHAUSTED
            assert "this client" in refused.value.details()
        # Another client still subscribes, and sessions open for both.
        held.append(_subscribe(other))
        for channel in (again, other):
            Session(channel, "still-possible").open().close()
        held.pop(0).cancel()
        # Its slot comes back once the server has seen the cancellation.
        deadline = time.monotonic() + 5
        while True:
            try:
                held.append(_subscribe(again))
                break
            except grpc.RpcError:
                assert time.monotonic() < deadline
                time.sleep(0.05)
    finally:
        for stream in held:
            stream.cancel()
        for channel in channels:
            channel.close()
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

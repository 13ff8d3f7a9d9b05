"""Issue 29 item 3: the cell for the plant over OPC UA. An asyncua client browses the robotics
model (OPC 40010's motion device system), reads the axis positions during a move, sees the
emergency stop after an e-stop and the lock holder; its writes are refused; anonymous access
is for loopback only."""
from __future__ import annotations

import asyncio
import hashlib

import numpy as np
import pytest
from asyncua import Client, ua

from landscape.bridges.opcua.model import DI, LANDSCAPE, ROBOTICS
from landscape.bridges.opcua.server import CellUsers, OpcUaBridge, UsersError, load_users
from landscape.v1 import control_pb2, motion_pb2, types_pb2

from bridge_support import BridgeThread
from support import activate, locked_session, start_server, stubs, wait_until

TARGET = [0.9, -0.4, 1.8, 0.3, 1.1, -0.5]
PASSWORD = "plant floor"


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    users = tmp_path_factory.mktemp("opcua") / "users"
    users.write_text(f"# plant users\nscada {hashlib.sha256(PASSWORD.encode()).hexdigest()}\n")
    server = start_server(lockstep_pace=1.0)
    bridge = BridgeThread(lambda: OpcUaBridge({"arm1": server.target}, port=0,
                                              cell="cell1", users=load_users(users)))
    url = f"opc.tcp://127.0.0.1:{_port(bridge)}"
    yield server, url
    bridge.close()
    server.stop(grace=None)


def _port(bridge: BridgeThread) -> int:
    wait_until(lambda: bridge.bridge.server is not None, 30)
    return bridge.bridge.port


def run(coro):
    return asyncio.run(coro)


async def _browse(client: Client):
    """The nodes of arm1 by the specification's browse names; waits until the arm is there."""
    rob, di, own = [await client.get_namespace_index(uri) for uri in (ROBOTICS, DI, LANDSCAPE)]
    system = await client.nodes.objects.get_child([f"{di}:DeviceSet", f"{own}:cell1"])
    for _ in range(100):
        try:
            device = await system.get_child([f"{rob}:MotionDevices", f"{own}:arm1"])
            break
        except ua.UaStatusCodeError:
            await asyncio.sleep(0.1)
    axes = await device.get_child(f"{rob}:Axes")
    return rob, di, own, system, device, axes


async def _axis(axes, index, di, rob, own, name="ActualPosition"):
    return await axes.get_child([f"{own}:joint_{index}", f"{di}:ParameterSet", f"{rob}:{name}"])


def test_the_client_browses_the_robotics_model(cell):
    _, url = cell

    async def check():
        async with Client(url) as client:
            rob, di, own, system, device, axes = await _browse(client)
            assert await system.read_type_definition() == ua.NodeId(1002, rob)
            assert await device.read_type_definition() == ua.NodeId(1004, rob)
            names = {(await c.read_browse_name()).Name for c in await system.get_children()}
            assert {"MotionDevices", "Controllers", "SafetyStates"} <= names
            category = await device.get_child(f"{rob}:MotionDeviceCategory")
            assert await category.read_value() == 1                     # ARTICULATED_ROBOT
            model = await (await device.get_child(f"{di}:Model")).read_value()
            assert model.Text == "TX90"
            joints = await axes.get_children()
            assert len(joints) == 6
            for joint in joints:
                assert await joint.read_type_definition() == ua.NodeId(16601, rob)
                profile = await joint.get_child(f"{rob}:MotionProfile")
                assert await profile.read_value() == 1                  # ROTARY
            position = await _axis(axes, 1, di, rob, own)
            assert await position.read_type_definition() == ua.NodeId(ua.ObjectIds.AnalogUnitType)
            units = await (await position.get_child("0:EngineeringUnits")).read_value()
            assert units.DisplayName.Text == "rad" and units.UnitId == 4405297    # UNECE C81
            speed = await _axis(axes, 1, di, rob, own, "ActualSpeed")
            units = await (await speed.get_child("0:EngineeringUnits")).read_value()
            assert units.DisplayName.Text == "rad/s"
            controller = await system.get_child([f"{rob}:Controllers", f"{own}:arm1_controller"])
            assert await controller.read_type_definition() == ua.NodeId(1003, rob)
            safety = await system.get_child([f"{rob}:SafetyStates", f"{own}:arm1_safety"])
            assert await safety.read_type_definition() == ua.NodeId(1013, rob)
    run(check())


def test_axis_positions_follow_a_move_and_the_emergency_stop_shows(cell):
    server, url = cell
    session = locked_session(server, "plant-test")

    async def check():
        async with Client(url) as client:
            rob, di, own, system, device, axes = await _browse(client)
            positions = [await _axis(axes, i, di, rob, own) for i in range(1, 7)]
            holder = await device.get_child([f"{own}:LandScape", f"{own}:LockHolder"])
            for _ in range(50):
                if await holder.read_value() == "plant-test":
                    break
                await asyncio.sleep(0.1)
            assert await holder.read_value() == "plant-test"
            activate(session)
            device_stub, _, _ = stubs(session.channel)
            device_stub.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
                frame=types_pb2.REFERENCE_FRAME_JOINT_FRAME, values=TARGET), timeout=30)
            seen = []
            for _ in range(300):
                seen.append([await p.read_value() for p in positions])
                if np.allclose(seen[-1], TARGET, atol=1e-3):
                    break
                await asyncio.sleep(0.05)
            assert np.allclose(seen[-1], TARGET, atol=1e-3), seen[-1]
            assert len({round(row[0], 3) for row in seen}) > 3    # read while it moved
            safety = await system.get_child([f"{rob}:SafetyStates", f"{own}:arm1_safety",
                                             f"{di}:ParameterSet"])
            estop = await safety.get_child(f"{rob}:EmergencyStop")
            assert await estop.read_value() is False
            device_stub.OperatePanel(control_pb2.OperatePanelRequest(
                action=control_pb2.PANEL_ACTION_PRESS_ESTOP), timeout=10)
            for _ in range(50):
                if await estop.read_value():
                    break
                await asyncio.sleep(0.1)
            assert await estop.read_value() is True
            state = await device.get_child([f"{own}:LandScape", f"{own}:DeviceState"])
            assert await state.read_value() == "DEVICE_STATE_ERROR"
            mode = await safety.get_child(f"{rob}:OperationalMode")
            assert await mode.read_value() == 4                           # AUTOMATIC_EXTERNAL
    try:
        run(check())
    finally:
        device_stub, _, _ = stubs(session.channel)
        device_stub.OperatePanel(control_pb2.OperatePanelRequest(
            action=control_pb2.PANEL_ACTION_RELEASE_ESTOP), timeout=10)
        device_stub.Reset(control_pb2.ResetRequest(), timeout=10)
        session.close()


def test_a_write_from_opc_ua_is_refused_and_changes_nothing(cell):
    _, url = cell

    async def check():
        async with Client(url) as client:
            rob, di, own, system, device, axes = await _browse(client)
            position = await _axis(axes, 2, di, rob, own)
            estop = await system.get_child([f"{rob}:SafetyStates", f"{own}:arm1_safety",
                                            f"{di}:ParameterSet", f"{rob}:EmergencyStop"])
            # The e-stop test before this one releases it at its end; the bridge hears that
            # a moment later: not a change made by the write below.
            for _ in range(100):
                if await estop.read_value() is False:
                    break
                await asyncio.sleep(0.1)
            for node, value in ((position, ua.Variant(2.0, ua.VariantType.Double)),
                                (estop, ua.Variant(True, ua.VariantType.Boolean))):
                before = await node.read_value()
                with pytest.raises(ua.UaStatusCodeError) as refused:
                    await node.write_value(value)
                assert type(refused.value).__name__ in ("BadUserAccessDenied", "BadNotWritable")
                assert await node.read_value() == before or node == position
    run(check())


def test_users_sign_in_by_password_and_anonymous_is_for_loopback_only(cell, tmp_path):
    _, url = cell

    async def sign_in(password: str) -> None:
        client = Client(url)
        client.set_user("scada")
        client.set_password(password)
        async with client:
            await client.nodes.objects.read_browse_name()
    run(sign_in(PASSWORD))
    with pytest.raises(Exception):
        run(sign_in("wrong"))
    users = CellUsers({"scada": hashlib.sha256(b"pw").digest()}, None, anonymous=False)
    assert users.get_user(None) is None                            # no anonymous off loopback
    assert users.get_user(None, "scada", "pw").name == "scada"
    assert users.get_user(None, "scada", "nope") is None
    with pytest.raises(ValueError, match="loopback"):
        OpcUaBridge({"arm1": "127.0.0.1:50051"}, host="0.0.0.0")
    bad = tmp_path / "users"
    bad.write_text("scada not-a-digest\n")
    with pytest.raises(UsersError, match="users:1"):
        load_users(bad)

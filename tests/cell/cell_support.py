"""What the cell tests share: development keys (support.make_keys), and a move made the way a
remote supervisor makes it (its own channel, TLS and a token, a session, the lock)."""
from __future__ import annotations

import time

import numpy as np

from landscape.client import Session, open_channel
from landscape.v1 import (control_pb2, device_service_pb2_grpc, motion_pb2, settings_pb2,
                          types_pb2)
from support import Keys, make_keys  # noqa: F401 (the cell tests' keys)

JOINT = types_pb2.REFERENCE_FRAME_JOINT_FRAME
RESTING = types_pb2.DEVICE_STATE_RESTING


def joints(device) -> np.ndarray:
    reply = device.GetRobotPosition(settings_pb2.GetRobotPositionRequest(), timeout=10)
    return np.array(reply.joint_position)


def wait_at_rest(device, goal, timeout: float = 60.0) -> np.ndarray:
    """Polls until the device rests at `goal` (rad, (6,)); the joints."""
    deadline = time.monotonic() + timeout
    while True:
        state = device.GetDeviceState(control_pb2.GetDeviceStateRequest(), timeout=10).state
        position = joints(device)
        if state == RESTING and np.max(np.abs(position - goal)) < 1e-3:
            return position
        if time.monotonic() > deadline:
            raise AssertionError(f"not at rest at {goal} within {timeout} s: state {state}, "
                                 f"joints {position}")
        time.sleep(0.05)


def move_as_operator(target: str, keys: Keys, goal, name: str = "cell-test") -> np.ndarray:
    """Lock, activate, move to `goal` (joint angles, rad), deactivate, release; the joints
    where it came to rest."""
    with open_channel(target, keys.tls(), keys.token("operator")) as channel, \
            Session(channel, name) as session:
        session.lock()
        device = device_service_pb2_grpc.DeviceServiceStub(session.channel)
        device.Activate(control_pb2.ActivateRequest(), timeout=30)
        reply = device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
            point_name="cell-test", frame=JOINT, values=list(goal)), timeout=30)
        assert reply.ret_val.ret_code == types_pb2.RETURN_CODE_CMD_STARTED_OK
        reached = wait_at_rest(device, goal)
        device.Deactivate(control_pb2.DeactivateRequest(), timeout=30)
        device.Release(control_pb2.ReleaseRequest(), timeout=30)
        return reached


def through_the_supervisor(url: str, devices, token: str,
                           timeout: float = 60.0) -> dict[str, dict]:
    """What the web supervisor at `url` gets from each device, seen as its page sees it (its
    WebSocket, wire.py), signed in with `token`: the first reply of each read it keeps for
    the page, by device and method ("GetDeviceState", ...). A read the device refused fails
    with the device's status. Then a session and the lock on the last device, through the
    backend, as that person (an operator; the lock ends with the page's connection)."""
    import asyncio
    import json

    import aiohttp

    wanted = {"GetDeviceState", "GetCellDescription"}

    async def main():
        seen: dict[str, dict] = {name: {} for name in devices}
        origin = url.rstrip("/")
        async with aiohttp.ClientSession(cookie_jar=aiohttp.CookieJar(unsafe=True)) as http:
            async with http.get(url) as page:
                assert "LandScape supervisor" in await page.text()
            async with http.post(url + "api/sign-in", json={"token": token}, headers={
                    "Origin": origin, "X-Landscape-Request": "page"}) as signed_in:
                assert signed_in.status == 200, await signed_in.text()
            async with http.ws_connect(url + "ws", origin=origin) as ws:
                async def frame():
                    return json.loads((await ws.receive()).data)
                while any(wanted - set(got) for got in seen.values()):
                    body = await frame()
                    method = body["rpc"].rsplit("/", 1)[1]
                    if body["device"] in seen and method in wanted:
                        assert "reply" in body, f"{body['device']} {method}: {body['status']}"
                        seen[body["device"]].setdefault(method, body["reply"])
                last = devices[-1]
                for call_id, rpc, request in (
                        (1, "landscape.v1.SessionService/Connect",
                         {"hello": {"clientName": "compose-test"}}),
                        (2, "landscape.v1.DeviceService/Lock", {})):
                    await ws.send_json({"device": last, "rpc": rpc, "id": call_id,
                                        "request": request})
                    while (answer := await frame()).get("id") != call_id:
                        pass
                    assert "reply" in answer, f"{last} {rpc}: {answer['status']}"
        return seen

    return asyncio.run(asyncio.wait_for(main(), timeout))

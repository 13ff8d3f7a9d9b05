"""The dashboard backend on its WebSocket, without a browser: a real device server, the real
backend, and an aiohttp client speaking the page's frames (wire.py)."""
from __future__ import annotations

import asyncio
import json
import logging
import subprocess
import sys
import urllib.request
from pathlib import Path

import aiohttp
import pytest
from google.protobuf import any_pb2, json_format
from google.rpc import error_details_pb2

from landscape.server.app import serve
from landscape.server.config import ServerConfig
from landscape.server.states import State
from landscape.supervisor import DashboardConfig, DeviceTarget, start
from landscape.v1 import event_service_pb2, settings_pb2, state_service_pb2, types_pb2
from support import start_server, wait_until

DEVICE = "landscape.v1.DeviceService/"
CONNECT = "landscape.v1.SessionService/Connect"
CELL = DEVICE + "GetCellDescription"
TIMEOUT = 30.0
ROOT = Path(__file__).resolve().parents[2]


class PageClient:
    """The page's side of the WebSocket: numbered calls, and every frame kept for inspection."""

    def __init__(self, ws):
        self.ws = ws
        self.frames: list[dict] = []
        self._next = 1

    async def send(self, rpc: str, request=None, *, call_id=None, device="arm1", **extra) -> int:
        call_id = call_id if call_id is not None else self._next
        self._next = max(self._next, call_id) + 1
        body = {"device": device, "rpc": rpc, "id": call_id, **extra}
        if request is not None:
            body["request"] = request
        await self.ws.send_str(json.dumps(body))
        return call_id

    async def until(self, predicate, timeout: float = TIMEOUT) -> dict:
        """The first frame (kept or new) for which predicate holds."""
        for frame in self.frames:
            if predicate(frame):
                return frame
        async with asyncio.timeout(timeout):
            while True:
                message = await self.ws.receive()
                assert message.type is aiohttp.WSMsgType.TEXT, message
                frame = json.loads(message.data)
                self.frames.append(frame)
                if predicate(frame):
                    return frame

    async def answer(self, call_id: int) -> dict:
        return await self.until(lambda f: f.get("id") == call_id and ("reply" in f or "status" in f))

    async def call(self, rpc: str, request=None) -> dict:
        return await self.answer(await self.send(rpc, request))


def unpack(reply: dict, message_class):
    """The landscape.v1 message from a frame's reply (google.protobuf.Any in canonical JSON)."""
    packed = json_format.ParseDict(reply, any_pb2.Any())
    message = message_class()
    assert packed.Unpack(message), reply["@type"]
    return message


def run_with_page(server, body, devices=None, **config):
    """Run body(page, server) against a backend on a free port, within a time limit; its
    devices (DeviceTargets) default to `server` as arm1."""
    async def main():
        dashboard = await start(DashboardConfig(
            devices=devices or (DeviceTarget("arm1", server.target),), port=0, **config))
        try:
            async with aiohttp.ClientSession() as http:
                async with http.ws_connect(dashboard.url + "ws") as ws:
                    await body(PageClient(ws), dashboard)
        finally:
            await dashboard.stop()
    asyncio.run(asyncio.wait_for(main(), 120))


def test_feeds_are_landscape_messages_in_canonical_json(server):
    async def body(page, dashboard):
        started = await page.until(lambda f: f["rpc"].endswith("StreamState") and "started" in f["reply"])
        terms = unpack(started["reply"], state_service_pb2.StreamStateResponse).started
        assert terms.units.linear == types_pb2.LINEAR_UNIT_METERS
        assert terms.frame == types_pb2.REFERENCE_FRAME_BASE_CARTESIAN_FRAME
        sample = await page.until(lambda f: f["rpc"].endswith("StreamState") and "sample" in f["reply"])
        state = unpack(sample["reply"], state_service_pb2.StreamStateResponse).sample
        assert len(state.joint_positions) == 6 and state.sequence > 0
        event = await page.until(lambda f: f["rpc"] == "landscape.v1.EventService/Subscribe")
        assert unpack(event["reply"], event_service_pb2.SubscribeResponse).event.sequence == 1
        units = await page.until(lambda f: f["rpc"] == DEVICE + "GetUnits")
        assert unpack(units["reply"], settings_pb2.GetUnitsResponse).linear_units == types_pb2.LINEAR_UNIT_METERS
    run_with_page(server, body)


def test_the_lease_and_the_secret_stay_in_the_backend(server):
    async def body(page, dashboard):
        opened = await page.call(CONNECT, {"hello": {"clientName": "page-1"}})
        assert opened["reply"]["opened"]["sessionId"]
        assert opened["reply"]["opened"]["sessionSecret"] == ""
        locked = await page.call(DEVICE + "Lock")
        assert locked["reply"]["lease"] == ""
        assert (await page.call(DEVICE + "Activate"))["reply"]["retVal"]["retCode"] == "RETURN_CODE_CMD_EXEC_OK"
        assert server.device.state is State.RESTING   # the backend sent the lease
    run_with_page(server, body)


def test_a_refusal_is_the_servers_status_with_its_error_info(server):
    async def body(page, dashboard):
        refused = await page.call(DEVICE + "Activate")
        status = refused["status"]
        assert status["code"] == 9   # FAILED_PRECONDITION: Unlocked
        assert "Activate" in status["message"]
        info = json_format.ParseDict(status["details"][0], any_pb2.Any())
        error_info = error_details_pb2.ErrorInfo()
        assert info.Unpack(error_info)
        assert (error_info.reason, error_info.metadata["ret_code"]) == ("WRONG_STATE", "-1")
        assert server.device.state is State.UNLOCKED
    run_with_page(server, body)


@pytest.mark.parametrize("frame, code", [
    ({"device": "arm9", "rpc": DEVICE + "Activate"}, 5),                     # NOT_FOUND
    ({"rpc": "landscape.v1.DeviceService/Explode"}, 12),                   # UNIMPLEMENTED
    ({"rpc": "landscape.v1.StateService/StreamState"}, 12),                # the backend's feed
    ({"rpc": DEVICE + "SetSpeed", "request": {"speed": "fast"}}, 3),        # INVALID_ARGUMENT
    ({"rpc": DEVICE + "SetSpeed", "request": {"sped": 50}}, 3),
    ({"rpc": DEVICE + "Lock"}, 9),                                          # no session yet
    ({"rpc": CONNECT, "request": {"keepAlive": {}}}, 3),                    # the backend's job
    ({"rpc": CONNECT, "request": {"rsvpAnswer": {"rsvpId": "rsvp-9", "choice": "x"}}}, 5),
])
def test_frames_the_backend_cannot_send_are_refused_and_change_nothing(server, frame, code):
    async def body(page, dashboard):
        call_id = await page.send(**{"device": "arm1", **frame})
        answer = await page.answer(call_id)
        assert answer["status"]["code"] == code, answer
        assert server.device.state is State.UNLOCKED
    run_with_page(server, body)


def test_a_second_hello_is_refused(server):
    async def body(page, dashboard):
        await page.call(CONNECT, {"hello": {"clientName": "page-1"}})
        assert (await page.call(CONNECT, {"hello": {"clientName": "again"}}))["status"]["code"] == 6
    run_with_page(server, body)


def test_closing_the_page_ends_its_session_and_the_device_releases(server):
    async def body(page, dashboard):
        await page.call(CONNECT, {"hello": {"clientName": "leaving"}})
        await page.call(DEVICE + "Lock")
        await page.call(DEVICE + "Activate")
        assert server.device.state is State.RESTING
        await page.ws.close()
    run_with_page(server, body)
    wait_until(lambda: server.device.state is State.UNLOCKED, timeout=20)


async def _estop_question(page, server, name: str) -> tuple[int, dict]:
    """The page's session takes the lock; the e-stop pressed and released: the device asks
    the lock holder whether to reset. The session's call id and the question's frame."""
    session = await page.send(CONNECT, {"hello": {"clientName": name}})
    await page.answer(session)
    await page.call(DEVICE + "Lock")
    await page.call(DEVICE + "OperatePanel", {"action": "PANEL_ACTION_PRESS_ESTOP"})
    await asyncio.to_thread(wait_until, lambda: server.device.state is State.ERROR, 5)
    await page.call(DEVICE + "OperatePanel", {"action": "PANEL_ACTION_RELEASE_ESTOP"})
    return session, await page.until(
        lambda f: f.get("id") == session and "rsvpRequest" in f.get("reply", {}))


def test_the_estop_rsvp_reaches_the_page_and_its_answer_the_device(server):
    async def body(page, dashboard):
        session, question = await _estop_question(page, server, "operator")
        request = question["reply"]["rsvpRequest"]
        assert set(request["choices"]) == {"reset", "stay"} and request["timeoutMs"] > 0
        await page.send(CONNECT, {"rsvpAnswer": {"rsvpId": request["rsvpId"], "choice": "reset"}},
                        call_id=session)
        await page.until(lambda f: f.get("reply", {}).get("event", {}).get("rsvpAnswer", {}).get("choice") == "reset")
        await asyncio.to_thread(wait_until, lambda: server.device.state is State.INACTIVE, 5)
    run_with_page(server, body)


def test_a_late_page_is_sent_the_kept_events_and_the_newest_state(server):
    async def body(page, dashboard):
        await page.call(CONNECT, {"hello": {"clientName": "first"}})
        await page.call(DEVICE + "Lock")
        async with aiohttp.ClientSession() as http:
            async with http.ws_connect(dashboard.url + "ws") as ws:
                late = PageClient(ws)
                await late.until(lambda f: "locked by first" in json.dumps(f))
                holder = await late.until(lambda f: f["rpc"] == DEVICE + "GetDeviceState"
                                          and f["reply"]["lockHolder"] == "first")
                assert holder["reply"]["locked"] is True
                await late.until(lambda f: "sample" in f.get("reply", {}))
    run_with_page(server, body)


def test_make_run_command_line_serves_the_page(server):
    """`python -m landscape.supervisor` as users start it: prints its address, serves, stops."""
    proc = subprocess.Popen([sys.executable, "-m", "landscape.supervisor", "--device",
                             f"arm1={server.target}", "--port", "0"],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        line = proc.stdout.readline()
        assert line.startswith("web supervisor on http://127.0.0.1:"), line
        url = line.split()[-1]
        with urllib.request.urlopen(url + "api/devices", timeout=10) as reply:
            assert json.load(reply) == [{"name": "arm1", "target": server.target}]
        with urllib.request.urlopen(url, timeout=10) as reply:
            assert b"LandScape supervisor" in reply.read()
    finally:
        proc.terminate()
        code = proc.wait(timeout=20)
    assert code == 0


def test_a_restarted_device_server_is_followed_from_its_first_event():
    first = start_server()
    port = first.port
    second = None

    async def body(page, dashboard):
        nonlocal second
        await page.call(CONNECT, {"hello": {"clientName": "before-restart"}})
        await page.call(DEVICE + "Lock")   # events 2 and on: the first run gets ahead
        await page.until(lambda f: "locked by before-restart" in json.dumps(f))
        await asyncio.to_thread(first.stop, None)
        second = await asyncio.to_thread(serve, ServerConfig(port=port, clock="lockstep"))
        page.frames.clear()
        restarted = await page.until(
            lambda f: f.get("reply", {}).get("event", {}).get("sequence") == "1", timeout=30)
        assert restarted["reply"]["event"]["stateChange"]["toState"] == "unlocked"

    try:
        run_with_page(first, body)
    finally:
        if second is not None:
            second.stop(grace=None)


def test_the_backend_commands_over_tls_with_its_token_and_the_role_decides(secured, keys):
    """An operator's token: sessions, the lock and commands; the door (admin only) refused
    with the device's reason, and nothing opened."""
    async def body(page, dashboard):
        state = await page.until(lambda f: f["rpc"] == DEVICE + "GetDeviceState")
        assert state["reply"]["state"] == "DEVICE_STATE_UNLOCKED"
        await page.call(CONNECT, {"hello": {"clientName": "tls-page"}})
        assert "reply" in await page.call(DEVICE + "Lock")
        assert "reply" in await page.call(DEVICE + "Activate")
        assert secured.device.state is State.RESTING
        refused = (await page.call(DEVICE + "OperatePanel",
                                   {"action": "PANEL_ACTION_OPEN_DOOR"}))["status"]
        assert refused["code"] == 7 and "admin" in refused["message"]   # PERMISSION_DENIED
        assert secured.device.state is State.RESTING
    run_with_page(secured, body, tls=keys.tls(), token=keys.token("operator"))


def test_an_admin_token_presses_the_estop_through_the_backend(secured, keys):
    async def body(page, dashboard):
        pressed = await page.call(DEVICE + "OperatePanel", {"action": "PANEL_ACTION_PRESS_ESTOP"})
        assert pressed["reply"]["estopPressed"] is True
        await asyncio.to_thread(wait_until, lambda: secured.device.state is State.ERROR, 5)
        await page.call(DEVICE + "OperatePanel", {"action": "PANEL_ACTION_RELEASE_ESTOP"})
    run_with_page(secured, body, tls=keys.tls(), token=keys.token("admin"))


def test_without_a_token_every_read_is_refused_and_shown_so(secured, keys):
    async def body(page, dashboard):
        refused = await page.until(lambda f: f["rpc"] == DEVICE + "GetDeviceState")
        assert refused["status"]["code"] == 16   # UNAUTHENTICATED
    run_with_page(secured, body, tls=keys.tls())


def test_the_command_line_takes_the_client_credentials(keys):
    from landscape.supervisor.__main__ import parse_args
    config = parse_args(["--device", "a=127.0.0.1:1", "--tls-ca", str(keys.certs.ca),
                         "--token-file", str(keys.token_file("viewer"))])
    assert config.tls.ca == str(keys.certs.ca) and config.token == keys.token("viewer")


def _bodies(frame: dict) -> dict[str, dict]:
    return {body["name"]: body for body in frame["reply"]["bodies"]}


def test_each_device_describes_its_own_cell():
    first = start_server()
    second = start_server(cell=str(ROOT / "sim" / "cells" / "press_tending.toml"))

    async def body(page, dashboard):
        cells = {}
        while len(cells) < 2:
            frame = await page.until(lambda f: f["rpc"] == CELL and f["device"] not in cells)
            cells[frame["device"]] = frame["reply"]
        assert (cells["arm1"]["cellName"], cells["arm2"]["cellName"]) == ("default",
                                                                          "press_tending")
        assert "block_1" in _bodies({"reply": cells["arm1"]})
        assert "blank_1" in _bodies({"reply": cells["arm2"]})

    try:
        run_with_page(None, body, devices=(DeviceTarget("arm1", first.target),
                                           DeviceTarget("arm2", second.target)))
    finally:
        first.stop(grace=None)
        second.stop(grace=None)


def test_the_world_follows_tool_changes_and_parts_taken_and_put(server):
    """examples/02 fetches the gripper, carries block_1 to the place zone and puts the gripper
    back: each change of the cell reaches the page as a new GetCellDescription."""
    async def next_cell(page):   # each description once, in order
        frame = await page.until(lambda f: f["rpc"] == CELL, timeout=120)
        page.frames.remove(frame)
        return _bodies(frame)

    async def body(page, dashboard):
        bodies = await next_cell(page)
        seen = [(bodies["gripper"]["attachedTo"], bodies["block_1"]["attachedTo"])]
        assert seen == [("", "")]
        example = await asyncio.create_subprocess_exec(
            sys.executable, str(ROOT / "examples" / "02_pick_and_place.py"), "--target",
            server.target, stdout=asyncio.subprocess.DEVNULL, stderr=asyncio.subprocess.PIPE)
        while len(seen) < 5:   # (gripper, block_1) attachments, each change once
            bodies = await next_cell(page)
            now = (bodies["gripper"]["attachedTo"], bodies["block_1"]["attachedTo"])
            if seen[-1] != now:
                seen.append(now)
        _, errors = await example.communicate()
        assert example.returncode == 0, errors.decode()
        assert seen == [("", ""), ("flange", ""), ("flange", "tool"), ("flange", ""), ("", "")]
        block = bodies["block_1"]["pose"]
        assert (block["x"], block["y"]) == pytest.approx((0.73, -0.15), abs=0.01)   # placed
    run_with_page(server, body)


def test_an_unanswered_question_times_out_on_the_device_and_the_backend_sends_nothing(
        server, caplog):
    """The device's own timer decides: the backend answers nothing when the page does not (a
    default sent for it would race that timer and be logged as an answer)."""
    server.device.rsvp_timeout = 0.5

    async def body(page, dashboard):
        await _estop_question(page, server, "silent")
        settled = await page.until(lambda f: "rsvpAnswer" in f.get("reply", {}).get("event", {}))
        answer = settled["reply"]["event"]["rsvpAnswer"]
        assert (answer["choice"], answer["timedOut"]) == ("stay", True)
        await asyncio.sleep(1.0)   # an answer the backend sent would have arrived by now

    with caplog.at_level(logging.WARNING, logger="landscape.server.servicers.session"):
        run_with_page(server, body)
    late = [r.getMessage() for r in caplog.records if "no such question waits" in r.getMessage()]
    assert not late
    assert server.device.state is State.ERROR   # "stay": the default kept it there

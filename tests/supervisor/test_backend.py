"""The dashboard backend on its WebSocket, without a browser: a real device server, the real
backend, and an aiohttp client speaking the page's frames (wire.py), signed in as one of the
test's people (olga, an operator, unless a test says otherwise)."""
from __future__ import annotations

import asyncio
import json
import logging
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest
from google.protobuf import any_pb2, json_format
from google.rpc import error_details_pb2

from dashboard_support import (CONNECT, DEVICE, PageClient, open_page, run_with_page,
                               signed_in_http)
from landscape.client import Frame, Robot, TagPoint
from landscape.server.app import serve
from landscape.server.config import SecurityConfig, ServerConfig
from landscape.server.device.states import State
from landscape.supervisor import DeviceTarget
from landscape.v1 import event_service_pb2, settings_pb2, state_service_pb2, types_pb2
from support import start_server, wait_until

CELL = DEVICE + "GetCellDescription"
ROOT = Path(__file__).resolve().parents[2]


def unpack(reply: dict, message_class):
    """The landscape.v1 message from a frame's reply (google.protobuf.Any in canonical JSON)."""
    packed = json_format.ParseDict(reply, any_pb2.Any())
    message = message_class()
    assert packed.Unpack(message), reply["@type"]
    return message


@pytest.fixture
def secured_people(keys, people):
    """A device server with TLS whose role tokens are the people's (the supervisor forwards
    each person's own token to it)."""
    running = start_server(security=SecurityConfig(
        tls_cert=str(keys.certs.server_cert), tls_key=str(keys.certs.server_key),
        tokens=str(people.folder)))
    yield running
    running.stop(grace=None)


def test_feeds_are_landscape_messages_in_canonical_json(people, server):
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
    run_with_page(server, body, people)


def test_the_lease_and_the_secret_stay_in_the_backend(people, server):
    async def body(page, dashboard):
        opened = await page.call(CONNECT, {"hello": {"clientName": "page-1"}})
        assert opened["reply"]["opened"]["sessionId"]
        assert opened["reply"]["opened"]["sessionSecret"] == ""
        locked = await page.call(DEVICE + "Lock")
        assert locked["reply"]["lease"] == ""
        assert (await page.call(DEVICE + "Activate"))["reply"]["retVal"]["retCode"] == "RETURN_CODE_CMD_EXEC_OK"
        assert server.device.state is State.RESTING   # the backend sent the lease
    run_with_page(server, body, people)


def test_a_refusal_is_the_servers_status_with_its_error_info(people, server):
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
    run_with_page(server, body, people)


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
def test_frames_the_backend_cannot_send_are_refused_and_change_nothing(people, server, frame, code):
    async def body(page, dashboard):
        call_id = await page.send(**{"device": "arm1", **frame})
        answer = await page.answer(call_id)
        assert answer["status"]["code"] == code, answer
        assert server.device.state is State.UNLOCKED
    run_with_page(server, body, people)


def test_a_second_hello_is_refused(people, server):
    async def body(page, dashboard):
        await page.call(CONNECT, {"hello": {"clientName": "page-1"}})
        assert (await page.call(CONNECT, {"hello": {"clientName": "again"}}))["status"]["code"] == 6
    run_with_page(server, body, people)


def test_closing_the_page_ends_its_session_and_the_device_releases(people, server):
    async def body(page, dashboard):
        await page.call(CONNECT, {"hello": {"clientName": "leaving"}})
        await page.call(DEVICE + "Lock")
        await page.call(DEVICE + "Activate")
        assert server.device.state is State.RESTING
        await page.ws.close()
    run_with_page(server, body, people)
    wait_until(lambda: server.device.state is State.UNLOCKED, timeout=20)


def test_a_blocked_backend_loop_keeps_the_pages_session_and_lock(people, server):
    """Issue 25 item 4: the backend's loop held past the device's keep-alive timeout (2 s):
    the session's keep-alives go from the client core's keeper threads all the same, so the
    page keeps its session and lock (the backend's own loop sent them before: it lost both)."""
    async def body(page, dashboard):
        session = await page.send(CONNECT, {"hello": {}})
        await page.answer(session)
        await page.call(DEVICE + "Lock")
        time.sleep(3)   # nothing on the loop runs: neither the backend nor the page's client
        assert "reply" in await page.call(DEVICE + "Activate")
        assert server.device.state is State.RESTING
        assert server.device.status().lock_holder == "olga"
        assert not [f for f in page.frames if f.get("id") == session and "status" in f]
    run_with_page(server, body, people)


def test_a_session_the_device_ends_is_reported_with_the_devices_reason(people, server):
    """Issue 25 item 4: the device ends the page's session as its keep-alive watchdog does;
    the page is told at once, in the device's words, and the lock is not taken back."""
    async def body(page, dashboard):
        session = await page.send(CONNECT, {"hello": {}})
        opened = await page.answer(session)
        await page.call(DEVICE + "Lock")
        registry = server.device.sessions
        registry.end(registry.get(opened["reply"]["opened"]["sessionId"]),
                     "no keep-alive for 2 s", "DEADLINE_EXCEEDED")
        ended = await page.until(lambda f: f.get("id") == session and "status" in f)
        assert ended["status"]["code"] == 4, ended   # DEADLINE_EXCEEDED
        assert ended["status"]["message"] == "your session ended: no keep-alive for 2 s"
        refused = await page.call(DEVICE + "Activate")   # the lock is gone, and says why
        assert refused["status"]["message"].startswith("your session ended: no keep-alive")
        assert not server.device.status().locked
    run_with_page(server, body, people)
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


def test_the_estop_rsvp_reaches_the_page_and_its_answer_the_device(people, server):
    async def body(page, dashboard):
        session, question = await _estop_question(page, server, "operator")
        request = question["reply"]["rsvpRequest"]
        assert set(request["choices"]) == {"reset", "stay"} and request["timeoutMs"] > 0
        await page.send(CONNECT, {"rsvpAnswer": {"rsvpId": request["rsvpId"], "choice": "reset"}},
                        call_id=session)
        await page.until(lambda f: f.get("reply", {}).get("event", {}).get("rsvpAnswer", {}).get("choice") == "reset")
        await asyncio.to_thread(wait_until, lambda: server.device.state is State.INACTIVE, 5)
    run_with_page(server, body, people)


def test_a_late_page_is_sent_the_kept_events_and_the_newest_state(people, server):
    async def body(page, dashboard):
        await page.call(CONNECT, {"hello": {"clientName": "first"}})
        await page.call(DEVICE + "Lock")
        http, ws = await open_page(dashboard.url, people.token("vera"))   # a viewer watches
        async with http, ws:
            late = PageClient(ws)
            await late.until(lambda f: "locked by olga" in json.dumps(f))
            holder = await late.until(lambda f: f["rpc"] == DEVICE + "GetDeviceState"
                                      and f["reply"]["lockHolder"] == "olga")
            assert holder["reply"]["locked"] is True
            await late.until(lambda f: "sample" in f.get("reply", {}))
    run_with_page(server, body, people)


def test_make_run_command_line_serves_the_page(server, people):
    """`python -m landscape.supervisor` as users start it: prints its address and where to
    find a sign-in token, serves the page to anyone and the API to the signed in, stops."""
    proc = subprocess.Popen([sys.executable, "-m", "landscape.supervisor", "--device",
                             f"arm1={server.target}", "--port", "0",
                             "--sign-in-tokens", str(people.folder)],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        line = proc.stdout.readline()
        assert line.startswith("web supervisor on http://127.0.0.1:"), line
        url = line.split()[-1]
        assert f"sign in with a token from {people.folder}" in proc.stdout.readline()
        with urllib.request.urlopen(url, timeout=10) as reply:
            assert b"LandScape supervisor" in reply.read()
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(url + "api/devices", timeout=10)
        assert refused.value.code == 401   # not signed in

        async def devices():
            async with await signed_in_http(url, people.token("vera")) as http:
                async with http.get(url + "api/devices") as reply:
                    return await reply.json()
        assert asyncio.run(devices()) == [{"name": "arm1", "target": server.target}]
    finally:
        proc.terminate()
        code = proc.wait(timeout=20)
    assert code == 0


def test_a_restarted_device_server_is_followed_from_its_first_event(people):
    first = start_server()
    port = first.port
    second = None

    async def body(page, dashboard):
        nonlocal second
        await page.call(CONNECT, {"hello": {"clientName": "before-restart"}})
        await page.call(DEVICE + "Lock")   # events 2 and on: the first run gets ahead
        await page.until(lambda f: "locked by olga" in json.dumps(f))
        await asyncio.to_thread(first.stop, None)
        second = await asyncio.to_thread(serve, ServerConfig(port=port, clock="lockstep"))
        page.frames.clear()
        restarted = await page.until(
            lambda f: f.get("reply", {}).get("event", {}).get("sequence") == "1", timeout=30)
        assert restarted["reply"]["event"]["stateChange"]["toState"] == "unlocked"

    try:
        run_with_page(first, body, people)
    finally:
        if second is not None:
            second.stop(grace=None)


def test_over_tls_a_persons_commands_go_with_their_own_token(people, secured_people, keys):
    """The supervisor's own token is a viewer's: the session, the lock and Activate work only
    because olga's operator token goes with them."""
    server = secured_people

    async def body(page, dashboard):
        state = await page.until(lambda f: f["rpc"] == DEVICE + "GetDeviceState")
        assert state["reply"]["state"] == "DEVICE_STATE_UNLOCKED"   # the feeds: its own token
        await page.call(CONNECT, {"hello": {}})
        assert "reply" in await page.call(DEVICE + "Lock")
        assert "reply" in await page.call(DEVICE + "Activate")
        assert server.device.state is State.RESTING
        assert server.device.status().lock_holder == "olga"
    run_with_page(server, body, people, tls=keys.tls(), token=people.token("supervisor"))


def test_an_admin_presses_the_estop_through_the_backend_with_their_token(people, secured_people,
                                                                          keys):
    server = secured_people

    async def body(page, dashboard):
        pressed = await page.call(DEVICE + "OperatePanel", {"action": "PANEL_ACTION_PRESS_ESTOP"})
        assert pressed["reply"]["estopPressed"] is True
        await asyncio.to_thread(wait_until, lambda: server.device.state is State.ERROR, 5)
        await page.call(DEVICE + "OperatePanel", {"action": "PANEL_ACTION_RELEASE_ESTOP"})
    run_with_page(server, body, people, person="ada", tls=keys.tls(),
                  token=people.token("supervisor"))


def test_without_a_token_every_read_is_refused_and_shown_so(people, secured_people, keys):
    async def body(page, dashboard):
        refused = await page.until(lambda f: f["rpc"] == DEVICE + "GetDeviceState")
        assert refused["status"]["code"] == 16   # UNAUTHENTICATED
    run_with_page(secured_people, body, people, tls=keys.tls())


def test_the_command_line_takes_the_client_credentials(keys, people):
    from landscape.supervisor.__main__ import parse_args
    config = parse_args(["--device", "a=127.0.0.1:1", "--tls-ca", str(keys.certs.ca),
                         "--token-file", str(people.folder / "viewer.tokens"),
                         "--sign-in-tokens", str(people.folder),
                         "--allowed-origin", "https://Panel.example:443"])
    assert config.tls.ca == str(keys.certs.ca) and config.token == people.token("vera")
    assert config.sign_in_tokens == str(people.folder)
    assert config.allowed_origins == ("https://panel.example",)


def _bodies(frame: dict) -> dict[str, dict]:
    return {body["name"]: body for body in frame["reply"]["bodies"]}


def test_each_device_describes_its_own_cell(people):
    first = start_server()
    second = start_server(cell=str(ROOT / "robot" / "cells" / "press_tending.toml"))

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
        run_with_page(None, body, people, devices=(DeviceTarget("arm1", first.target),
                                           DeviceTarget("arm2", second.target)))
    finally:
        first.stop(grace=None)
        second.stop(grace=None)


def test_the_world_follows_tool_changes_and_parts_taken_and_put(people, server):
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
    run_with_page(server, body, people)


def test_an_unanswered_question_times_out_on_the_device_and_the_backend_sends_nothing(
        people, server, caplog):
    """The device's own timer decides: the backend answers nothing when the page does not (a
    default sent for it would race that timer and be logged as an answer)."""
    server.device.rsvp_timeout = 0.5

    async def body(page, dashboard):
        await _estop_question(page, server, "silent")
        settled = await page.until(lambda f: "rsvpAnswer" in f.get("reply", {}).get("event", {}))
        answer = settled["reply"]["event"]["rsvpAnswer"]
        assert (answer["choice"], answer["timedOut"]) == ("stay", True)
        await asyncio.sleep(1.0)   # an answer the backend sent would have arrived by now

    with caplog.at_level(logging.WARNING, logger="landscape.server.api.servicers.session"):
        run_with_page(server, body, people)
    late = [r.getMessage() for r in caplog.records if "no such question waits" in r.getMessage()]
    assert not late
    assert server.device.state is State.ERROR   # "stay": the default kept it there


def test_a_server_stream_is_relayed_a_frame_a_reply_then_its_end(people, server):
    """GetPath, server-streaming: each of the device's replies a frame under the call's id,
    then status 0; an unknown path is the device's refusal, as it gave it."""
    with Robot(server.target, "script") as robot, robot.control(activate=False):
        robot.path_load("two", [TagPoint([0.1, 0, 1.5, 0, 1.5, 0], tag_name="a"),
                                TagPoint([0.2, 0, 1.5, 0, 1.5, 0])], Frame.JOINT)

    async def body(page, dashboard):
        call_id = await page.send(DEVICE + "GetPath", {"pathName": "two"})
        end = await page.until(lambda f: f.get("id") == call_id and "status" in f)
        assert end["status"]["code"] == 0
        replies = [f["reply"] for f in page.frames if f.get("id") == call_id and "reply" in f]
        assert replies[0]["path"]["numberOfPoints"] == 2
        points = [p for reply in replies for p in reply["points"]]
        assert [p["jointValues"][0] for p in points] == [0.1, 0.2]
        assert points[0]["tagName"] == "a"
        refused = await page.call(DEVICE + "GetPath", {"pathName": "none"})
        assert refused["status"]["code"] == 3, refused
        assert refused["status"]["details"][0]["reason"] == "NOT_FOUND"
    run_with_page(server, body, people)

"""The supervisor's own calls (supervisor_calls.py) through the backend's WebSocket on a real
device server: the control desk (handover.py) mediates only a lock held through this
supervisor, for an operator with a session; alarms are acknowledged on the device, and every
page, later ones too, sees who; what is refused changes nothing."""
from __future__ import annotations

import asyncio

from dashboard_support import CONNECT, DEVICE, PageClient, open_page, run_with_page
from landscape.client import Robot
from support import wait_until

ASK, ANSWER, CANCEL = ("supervisor/RequestControl", "supervisor/AnswerControl",
                       "supervisor/CancelControlRequest")
ACKNOWLEDGE = "landscape.v1.EventService/AcknowledgeAlarm"
SUBSCRIBE = "landscape.v1.EventService/Subscribe"


def test_the_desk_refuses_what_it_cannot_mediate(people, server):
    """Over the backend's WebSocket: nobody holds the lock, or a script holds it, or the asker
    has no session: refused with the reason, and nothing changes."""
    async def body(page, dashboard):
        refused = await page.call(ASK)
        assert refused["status"]["code"] == 9 and "not held through this supervisor" in refused["status"]["message"]
        with Robot(server.target, "script") as robot, robot.control(activate=False):
            refused = await page.call(ASK)
            assert "not held through this supervisor" in refused["status"]["message"]
            assert (await page.call(CANCEL))["status"]["code"] == 5
            assert (await page.call(ANSWER, {"give": True}))["status"]["code"] == 5
            assert server.device.status().lock_holder == "script"
        await page.call(CONNECT, {"hello": {}})
        assert "reply" in await page.call(DEVICE + "Lock")
        refused = await page.call(ASK)   # the holder asking itself
        assert refused["status"]["code"] == 6
        assert "reply" in await page.call(DEVICE + "Release")
        await asyncio.to_thread(wait_until, lambda: not server.device.status().locked, 5)
    run_with_page(server, body, people)


def test_a_viewer_may_not_ask(people, server):
    async def body(page, dashboard):
        refused = await page.call(ASK)
        assert refused["status"]["code"] == 7
        assert "needs the operator role" in refused["status"]["message"]
    run_with_page(server, body, people, person="vera")


def test_an_acknowledgement_is_the_devices_seen_by_every_page_and_a_bad_one_changes_nothing(
        people, server):
    """Issue 28: the page acknowledges an alarm on the device (EventService.AcknowledgeAlarm,
    as the signed-in person); every page, later ones too, sees the device's AlarmAcknowledged
    event naming who; an unknown alarm or a viewer's acknowledgement is refused."""
    def events(frame, kind):
        return frame["rpc"] == SUBSCRIBE and kind in frame.get("reply", {}).get("event", {})

    async def body(page, dashboard):
        await page.call(DEVICE + "OperatePanel", {"action": "PANEL_ACTION_PRESS_ESTOP"})
        alarm = (await page.until(lambda f: events(f, "alarm")))["reply"]["event"]
        refused = await page.call(ACKNOWLEDGE, {"sequence": "999999"})
        assert refused["status"]["code"] == 3, refused                  # INVALID_ARGUMENT
        assert not [f for f in page.frames if events(f, "alarmAcknowledged")]
        reply = (await page.call(ACKNOWLEDGE, {"sequence": alarm["sequence"]}))["reply"]
        assert reply["newly"] and reply["acknowledgement"]["onBehalfOf"] == "olga"
        told = (await page.until(lambda f: events(f, "alarmAcknowledged")))["reply"]["event"]
        assert told["alarmAcknowledged"]["alarmSequence"] == alarm["sequence"]
        assert told["alarmAcknowledged"]["client"] == "supervisor"
        http, ws = await open_page(dashboard.url, people.token("vera"))   # a page opened later
        async with http, ws:
            later = PageClient(ws, http)
            seen = await later.until(lambda f: events(f, "alarmAcknowledged"))
            assert seen["reply"]["event"]["sequence"] == told["sequence"]
            refused = await later.call(ACKNOWLEDGE, {"sequence": alarm["sequence"]})   # a viewer's
            assert refused["status"]["code"] == 7
        again = (await page.call(ACKNOWLEDGE, {"sequence": alarm["sequence"]}))["reply"]
        assert not again.get("newly") and again["eventSequence"] == told["sequence"]
    run_with_page(server, body, people)

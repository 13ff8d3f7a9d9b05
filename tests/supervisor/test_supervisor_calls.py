"""The supervisor's own calls (supervisor_calls.py) through the backend's WebSocket on a real
device server: the control desk (handover.py) mediates only a lock held through this
supervisor, for an operator with a session; acknowledgements (alarm_acks.py) reach every
page, later ones too; what is refused changes nothing."""
from __future__ import annotations

import asyncio

from dashboard_support import CONNECT, DEVICE, PageClient, open_page, run_with_page
from landscape.client import Robot
from support import wait_until

ASK, ANSWER, CANCEL = ("supervisor/RequestControl", "supervisor/AnswerControl",
                       "supervisor/CancelControlRequest")
ACKNOWLEDGE, ACKNOWLEDGED = "supervisor/AcknowledgeAlarms", "supervisor/Acknowledged"


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


def test_acknowledgements_reach_every_page_and_bad_ones_change_nothing(people, server):
    async def body(page, dashboard):
        for keys in (None, [], ["x" * 65], [3], ["ok", None]):
            refused = await page.call(ACKNOWLEDGE, {"keys": keys})
            assert refused["status"]["code"] == 3, keys          # INVALID_ARGUMENT
        reply = await page.call(ACKNOWLEDGE, {"keys": ["7@2026-01-01T00:00:00Z", "7@2026-01-01T00:00:00Z"]})
        assert reply["reply"] == {"acknowledged": 1}
        told = await page.until(lambda f: f["rpc"] == ACKNOWLEDGED)
        assert [(a["key"], a["by"]) for a in told["reply"]["acks"]] == [("7@2026-01-01T00:00:00Z", "olga")]
        http, ws = await open_page(dashboard.url, people.token("vera"))   # a page opened later
        async with http, ws:
            later = PageClient(ws, http)
            told = await later.until(lambda f: f["rpc"] == ACKNOWLEDGED)
            assert [a["key"] for a in told["reply"]["acks"]] == ["7@2026-01-01T00:00:00Z"]
            refused = await later.call(ACKNOWLEDGE, {"keys": ["8@x"]})   # a viewer's
            assert refused["status"]["code"] == 7
    run_with_page(server, body, people)

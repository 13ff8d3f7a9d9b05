"""A jog press through the backend, on a device server whose lock-step clock the test holds
and steps itself (issue 25 item 3): a page message still on its way after the device's
deadman cut the press's stream must never start the arm again; only a new press does."""
from __future__ import annotations

import asyncio

import pytest

from dashboard_support import CONNECT, DEVICE, PageClient, run_with_page
from landscape.server.device.states import State

JOG = DEVICE + "Jog"
DEADMAN_CYCLES = 50          # the device's default deadman: 200 ms of 4 ms cycles
PRESS = 40                   # the page's id for the press (larger than its calls before)
HOLD = {"deadman": True, "frame": "REFERENCE_FRAME_JOINT_FRAME", "velocity": [10, 0, 0, 0, 0, 0]}


def _statuses(page: PageClient, call_id: int) -> list[dict]:
    return [f["status"] for f in page.frames if f.get("id") == call_id and "status" in f]


async def _step(server, cycles: int) -> None:
    """`cycles` cycles of the held clock, stepped here (nothing else moves time)."""
    def step(controller):
        for _ in range(cycles):
            controller.step()
    await asyncio.to_thread(server.link.between_cycles, step, timeout=60)


async def _answered_or_sent_on(page: PageClient, server, call_id: int, statuses: int) -> None:
    """Until the backend answered the press's message (one more status for it) or passed
    something on to the device (a message waits for the held cycle)."""
    async with asyncio.timeout(30):
        while len(_statuses(page, call_id)) < statuses and not server.link.clock.pending:
            try:
                await page.until(lambda f: f.get("id") == call_id and "status" in f
                                 and len(_statuses(page, call_id)) >= statuses, timeout=0.05)
            except TimeoutError:
                pass


async def _stepped_until_jogging(page: PageClient, server) -> None:
    """A cycle at a time (the jog's start may wait for one) until the press is answered."""
    jogging = lambda f: f.get("id") == PRESS and "reply" in f   # noqa: E731
    async with asyncio.timeout(60):
        while not any(jogging(f) for f in page.frames):
            await _step(server, 1)
            try:
                await page.until(jogging, timeout=0.05)
            except TimeoutError:
                pass


def test_a_jog_message_arriving_after_the_deadman_moves_nothing(server, people):
    clock = server.link.clock

    async def body(page, dashboard):
        await page.call(CONNECT, {"hello": {}})
        await page.call(DEVICE + "Lock")
        await page.call(DEVICE + "Activate")
        await page.call(DEVICE + "ManualControl", {"type": "MANUAL_CONTROL_TYPE_TEACHPENDANT"})
        # Held from before the press: on a busy machine the free clock ran the deadman's 50
        # cycles before the device's first answer.
        clock.hold()
        try:
            await page.send(JOG, HOLD, call_id=PRESS)
            await _stepped_until_jogging(page, server)
            # The machine is busy: no message of the press comes for twice the deadman.
            await _step(server, 2 * DEADMAN_CYCLES)
            cut = await page.until(lambda f: f.get("id") == PRESS and "status" in f)
            assert "deadman" in cut["status"]["message"], cut
            await _step(server, DEADMAN_CYCLES)   # braked to rest
            at_rest = server.device.feedback().position.copy()

            # The page's message that was still on its way, then the same again.
            for late in (1, 2):
                await page.send(JOG, HOLD, call_id=PRESS)
                await _answered_or_sent_on(page, server, PRESS, statuses=1 + late)
                await _step(server, 3 * DEADMAN_CYCLES)
                assert server.device.feedback().position == pytest.approx(at_rest, abs=1e-6)
            refused = _statuses(page, PRESS)[-1]
            assert refused["code"] == 9 and "pressed again" in refused["message"], refused

            # An older press's first message after it: refused too.
            await page.send(JOG, HOLD, call_id=PRESS - 1)
            await _answered_or_sent_on(page, server, PRESS - 1, statuses=1)
            await _step(server, DEADMAN_CYCLES)
            assert server.device.feedback().position == pytest.approx(at_rest, abs=1e-6)

            # A new press moves the arm (so the test would have seen a move).
            await page.send(JOG, HOLD, call_id=PRESS + 1)
            await page.until(lambda f: f.get("id") == PRESS + 1 and "reply" in f)
            await _step(server, DEADMAN_CYCLES // 2)
            assert server.device.feedback().position[0] > at_rest[0] + 1e-4
            await page.send(JOG, None, call_id=PRESS + 1, cancel=True)   # let go
            await _step(server, 2 * DEADMAN_CYCLES)
        finally:
            clock.release()
    run_with_page(server, body, people)
    assert server.device.state in (State.RESTING, State.UNLOCKED)

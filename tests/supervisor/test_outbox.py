"""A browser's outbox: ordered frames all delivered in order, live feeds latest-wins, a browser
too far behind cut off."""
from __future__ import annotations

import asyncio

import pytest

from landscape.supervisor.outbox import Outbox, TooSlow


def take(outbox: Outbox) -> list[str]:
    return asyncio.run(asyncio.wait_for(outbox.take(), 5))


def test_ordered_frames_come_in_order_and_a_feed_only_its_newest():
    outbox = Outbox()
    for i in range(3):
        outbox.put(f"event {i}")
        outbox.put_latest(("arm1", "state"), f"sample {i}")
    outbox.put_latest(("arm2", "state"), "other sample")
    assert take(outbox) == ["event 0", "event 1", "event 2", "sample 2", "other sample"]


def test_take_waits_for_a_frame():
    async def main():
        outbox = Outbox()
        waiting = asyncio.create_task(outbox.take())
        await asyncio.sleep(0.01)
        assert not waiting.done()
        outbox.put("event")
        return await asyncio.wait_for(waiting, 5)
    assert asyncio.run(main()) == ["event"]


def test_a_closed_outbox_gives_nothing_more():
    outbox = Outbox()
    outbox.close()
    assert take(outbox) == []


def test_a_browser_too_far_behind_is_cut_off():
    outbox = Outbox(max_ordered=3)
    for i in range(4):
        outbox.put(f"event {i}")
    with pytest.raises(TooSlow):
        take(outbox)

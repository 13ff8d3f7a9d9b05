"""The cell around each arm, as its device knows it (DeviceService.GetCellDescription): read
when the link connects and again whenever the world may have changed, and sent to every
browser when it did.

The world changes with tool changes and with parts taken or put down. Each step of a tool
change is a motion of its own, so it comes with state changes on the event stream; a part
taken or let go (ActivateTool, DeactivateTool, at rest) comes with no event, but with a new
end effector state in the live state stream. Either one kicks a new read (device_link.py).
"""
from __future__ import annotations

import asyncio

from landscape.supervisor.feeds import Feed
from landscape.supervisor.rpc_table import RPCS, rpc_name

CELL_DESCRIPTION = rpc_name("DeviceService", "GetCellDescription")


class WorldFeed(Feed):
    rpc = CELL_DESCRIPTION

    def __init__(self, link):
        super().__init__(link)
        self._kick = asyncio.Event()
        self._seen: bytes | None = None

    def kick(self) -> None:
        self._kick.set()

    async def once(self) -> None:
        entry = RPCS[CELL_DESCRIPTION]
        self._seen = None   # a new connection: send it again
        while True:
            self._kick.clear()   # a kick during the read asks for one more
            reply = await entry.callable(self.link.channel)(entry.request_class(), timeout=10)
            self.working()
            key = reply.SerializeToString(deterministic=True)
            if key != self._seen:
                self._seen = key
                self.link.publish_latest(CELL_DESCRIPTION, CELL_DESCRIPTION, reply=reply)
            await self._kick.wait()

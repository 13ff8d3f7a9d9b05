"""Read-only calls whose answers every browser is shown (device_hub.py): a round of reads every
`period_s` and at once when kicked (a state change, a new end effector state), and a reply (or
a refusal) sent only when it differs from the last one sent.

Made through the supervisor's own AsyncRobot on the device's link (no session): a read the
device refuses (UNIMPLEMENTED, UNAUTHENTICATED) is sent as its status; a device that does not
answer (UNAVAILABLE, a deadline) fails the round, which is said once under the first read's
name and tried again.
"""
from __future__ import annotations

import asyncio

import grpc

from landscape.client import AsyncRobot
from landscape.client.commands import DEVICE
from landscape.client.errors import LandscapeError, RetryableTransportError, to_status
from landscape.supervisor.rpc_table import RPCS

RETRY_S = 1.0
READ_TIMEOUT_S = 10.0


class Reads:
    """`rpcs`: landscape.v1 DeviceService names, read each round; `once`: read at the start of
    each connection only; `period_s`: None reads only when kicked. `hub`: where the answers go
    (publish_latest, feed_status)."""

    def __init__(self, reader: AsyncRobot, hub, rpcs: tuple[str, ...], *,
                 period_s: float | None = None, once: tuple[str, ...] = ()):
        self.reader, self.hub = reader, hub
        self.rpcs, self.once, self.period_s = rpcs, once, period_s
        self._kick = asyncio.Event()
        self._seen: dict[str, bytes] = {}

    def kick(self) -> None:
        self._kick.set()

    async def run(self) -> None:
        while True:
            try:
                await self._follow()
            except RetryableTransportError as gone:
                self.hub.feed_status(self.rpcs[0], gone.code, gone.message)
            await asyncio.sleep(RETRY_S)

    async def _follow(self) -> None:
        self._seen.clear()   # a new connection (maybe a new server): send everything again
        for rpc in self.once:
            await self._read(rpc)
        while True:
            self._kick.clear()   # a kick during the round asks for one more
            for rpc in self.rpcs:
                await self._read(rpc)
            self.hub.feed_status(self.rpcs[0], grpc.StatusCode.OK, "")
            try:   # asyncio.timeout, not wait_for: 3.11's wait_for can lose the task's cancel
                async with asyncio.timeout(self.period_s):
                    await self._kick.wait()
            except TimeoutError:
                pass

    async def _read(self, rpc: str) -> None:
        entry = RPCS[rpc]
        reply = status = None
        try:
            reply = await self.reader.invoke(DEVICE, entry.method.name, entry.request_class(),
                                             timeout=READ_TIMEOUT_S)
        except RetryableTransportError:
            raise   # the device is gone: the round failed
        except LandscapeError as refused:
            status = to_status(refused)
        key = (reply.SerializeToString(deterministic=True) if reply is not None
               else b"status:" + status.SerializeToString(deterministic=True))
        if self._seen.get(rpc) != key:
            self._seen[rpc] = key
            self.hub.publish_latest(rpc, rpc, reply=reply, status=status)

"""The feeds a device link keeps for every browser: the event stream and the status reads.

Each feed runs until cancelled: when its call fails (the device server is down, restarting, or
refuses), every browser is told once with the call's status, and the feed tries again with a
growing pause.
"""
from __future__ import annotations

import asyncio
import logging

import grpc

from landscape.supervisor import wire
from landscape.supervisor.rpc_table import RPCS, SUBSCRIBE, rpc_name
from landscape.v1 import event_service_pb2

log = logging.getLogger(__name__)

RETRY_FIRST_S, RETRY_MAX_S = 0.25, 5.0


class Feed:
    """A call kept open (or repeated) for every browser; subclasses say what `once` does."""

    rpc: str

    def __init__(self, link):
        self.link = link
        self._failed: int | None = None   # the status code last reported, while failing

    async def once(self) -> None:
        raise NotImplementedError

    async def run(self) -> None:
        pause = RETRY_FIRST_S
        while True:
            try:
                await self.once()
                pause = RETRY_FIRST_S
            except grpc.aio.AioRpcError as error:
                self.failed(wire.status_of(error))
            await asyncio.sleep(pause)
            pause = min(2 * pause, RETRY_MAX_S)

    def failed(self, status) -> None:
        if status.code != self._failed:
            log.info("%s %s: %s", self.link.name, self.rpc, status.message)
            self._failed = status.code
            self.link.publish_latest(self.rpc + "#status", self.rpc, status=status, ordered=True)

    def working(self) -> None:
        if self._failed is not None:
            self._failed = None
            self.link.forget_latest(self.rpc + "#status")


class EventFeed(Feed):
    """EventService.Subscribe from the first kept event, resumed after the last one seen."""

    rpc = SUBSCRIBE

    def __init__(self, link, on_state_change):
        super().__init__(link)
        self.on_state_change = on_state_change
        self.last_sequence = 0

    async def once(self) -> None:
        call = RPCS[SUBSCRIBE].callable(self.link.channel)(
            event_service_pb2.SubscribeRequest(after_sequence=self.last_sequence))
        try:
            await self._read(call)
        except grpc.aio.AioRpcError as error:
            if error.code() is not grpc.StatusCode.OUT_OF_RANGE:
                raise
            # The device restarted (its sequence numbers start again at 1): from its first event.
            log.info("%s: %s", self.link.name, error.details())
            self.last_sequence = 0
            await self._read(RPCS[SUBSCRIBE].callable(self.link.channel)(
                event_service_pb2.SubscribeRequest(after_sequence=0)))

    async def _read(self, call) -> None:
        async for reply in call:
            self.working()
            event = reply.event
            self.last_sequence = max(self.last_sequence, event.sequence)
            self.link.publish_event(SUBSCRIBE, reply=reply)
            if event.HasField("state_change"):
                self.on_state_change()


# Read-only gets every browser shows: the lock holder and device state, and the settings a
# script may change behind the page's back. Sent when they change.
STATUS_READS = tuple(rpc_name("DeviceService", m) for m in (
    "GetDeviceState", "GetMotionControlState", "GetUnits", "GetVelocities", "GetAccelerations",
    "GetToolOffsets", "GetEndEffectorState", "GetTagId"))
# Read once per connection: the arm's limits do not change.
STATIC_READS = tuple(rpc_name("DeviceService", m) for m in (
    "GetMaxVelocities", "GetMaxAccelerations"))


class StatusPoll(Feed):
    """The status reads, twice a second and at once after every state change."""

    rpc = rpc_name("DeviceService", "GetDeviceState")
    PERIOD_S = 0.5

    def __init__(self, link):
        super().__init__(link)
        self._kick = asyncio.Event()
        self._seen: dict[str, bytes] = {}

    def kick(self) -> None:
        self._kick.set()

    async def once(self) -> None:
        self._seen.clear()   # a new connection: send everything again
        for rpc in STATIC_READS:
            await self._read(rpc)
        while True:
            self._kick.clear()
            for rpc in STATUS_READS:
                await self._read(rpc)
            self.working()
            try:   # asyncio.timeout, not wait_for: 3.11's wait_for can lose the task's cancel
                async with asyncio.timeout(self.PERIOD_S):
                    await self._kick.wait()
            except TimeoutError:
                pass

    async def _read(self, rpc: str) -> None:
        entry = RPCS[rpc]
        try:
            reply = await entry.callable(self.link.channel)(entry.request_class(), timeout=5)
        except grpc.aio.AioRpcError as error:
            if error.code() in (grpc.StatusCode.UNAVAILABLE, grpc.StatusCode.DEADLINE_EXCEEDED):
                raise   # the device is gone: the poll as a whole failed
            reply, status = None, wire.status_of(error)   # this read is refused (UNIMPLEMENTED)
        else:
            status = None
        key = (reply.SerializeToString(deterministic=True) if reply is not None
               else b"status:" + status.SerializeToString(deterministic=True))
        if self._seen.get(rpc) != key:
            self._seen[rpc] = key
            self.link.publish_latest(rpc, rpc, reply=reply, status=status)

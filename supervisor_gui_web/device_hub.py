"""One device server as the web supervisor shows it to every browser: the client core's link to
it, the reads every page shows, and the browsers watching.

The link (landscape.client.DeviceLink) holds what all the supervisor's people share of the
device: one event subscription (from the device's first kept event, so a page sees the
history), one live state stream at the display rate, and the keeper threads where every
person's session sends its keep-alives, whatever the supervisor's loop is doing. The core's
feeds reach every browser as frames (wire.py) under the contract's names: each event
(EventService/Subscribe; the newest `history` are replayed to a browser that joins), the state
stream's terms and samples (StateService/StreamState; a slow browser gets only the newest
sample), and a feed's failure (its status, once per change of its code, and to each browser
that joins while it lasts).

The state is asked for in meters and radians with the tool pose in the robot base frame, the
frames and units of the URDF the page draws (the page converts to the device's units for
display); the force sensor rides along where the device can stream it (the page says when it
has no readings).

The feeds and reads go as the supervisor, for every browser (with its own, viewer-level, token
where the devices use tokens); each person's calls go through their own AsyncRobot on this
link (`person`), with their token.
"""
from __future__ import annotations

import asyncio
import logging
from collections import deque

import grpc

from landscape.client import AsyncRobot, DeviceLink, Endpoint, Frame, Identity
from landscape.client.aio_streams import SI_UNITS, state_request
from landscape.client.aio_session import AsyncRsvpHandler
from landscape.client.credentials import ClientTLS
from landscape.client.errors import CommandRefused, TransportError
from landscape.client.state_feed import Sample
from landscape.supervisor import wire
from landscape.supervisor.config import DeviceTarget
from landscape.supervisor.device_reads import Reads
from landscape.supervisor.outbox import Outbox
from landscape.supervisor.rpc_table import STREAM_STATE, SUBSCRIBE, rpc_name
from landscape.v1 import event_service_pb2, state_service_pb2

log = logging.getLogger(__name__)

CLIENT = "supervisor"         # landscape-client on every call (identity.md)
FEEDS_FOR = "every browser"   # landscape-on-behalf-of of the shared feeds and reads
SENSORS = ("force_sensor",)
SENSOR_RETRY_S = 2.0
# Read-only gets every browser shows: the lock holder and device state, and the settings a
# script may change behind the page's back; sent when they change.
STATUS_READS = tuple(rpc_name("DeviceService", m) for m in (
    "GetDeviceState", "GetMotionControlState", "GetUnits", "GetVelocities", "GetAccelerations",
    "GetToolOffsets", "GetEndEffectorState", "GetTagId"))
STATIC_READS = tuple(rpc_name("DeviceService", m) for m in (   # the arm's limits: once
    "GetMaxVelocities", "GetMaxAccelerations"))
CELL_DESCRIPTION = rpc_name("DeviceService", "GetCellDescription")


class DeviceHub:
    def __init__(self, target: DeviceTarget, display_rate_hz: float,
                 tls: ClientTLS | None = None, token: str | None = None, history: int = 500):
        self.name = target.name
        self.target = target.address
        self.link = DeviceLink(Endpoint(target.address, tls), Identity(CLIENT, FEEDS_FOR),
                               token=token, replay_events=True,
                               state=state_request(display_rate_hz, Frame.BASE, SI_UNITS, ()))
        reader = AsyncRobot(self.link, CLIENT, token=token, identity=self.link.identity)
        # The status twice a second and after every state change; the cell around the arm
        # when it may have changed: a state change (a tool change's steps, a motion's start
        # and end) or a new end effector state (a part taken or let go, at rest).
        self.status = Reads(reader, self, STATUS_READS, period_s=0.5, once=STATIC_READS)
        self.cell = Reads(reader, self, (CELL_DESCRIPTION,))
        self._end_effector: tuple[str, str] | None = None
        self._watchers: set[Outbox] = set()
        self._history: deque[str] = deque(maxlen=history)   # the newest event frames, for joiners
        self._latest: dict[str, str] = {}                   # feed -> its newest frame, for joiners
        self._failed: dict[str, grpc.StatusCode] = {}       # feed -> the code it failed with
        self._tasks: list[asyncio.Task] = []

    async def start(self) -> None:
        """The link (its feeds keep trying until the device answers) and the reads."""
        await self.link.open(timeout=None)
        events, state = self.link.events, self.link.state
        events.listeners.append(self._event)
        events.status_listeners.append(lambda code, why: self.feed_status(SUBSCRIBE, code, why))
        state.listeners.append(self._sample)
        state.status_listeners.append(self._state_status)
        self._tasks = [asyncio.create_task(task, name=f"{self.name}-{name}") for name, task in (
            ("status", self.status.run()), ("cell", self.cell.run()),
            ("sensors", self._stream_sensors()))]

    async def close(self) -> None:
        for task in self._tasks:
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        await self.link.close()

    def person(self, name: str, token: str | None, on_rsvp: AsyncRsvpHandler) -> AsyncRobot:
        """A signed-in person's robot on this device: their calls (with their token, if the
        devices use tokens), and their session once opened, named for them."""
        return AsyncRobot(self.link, name, token=token, on_rsvp=on_rsvp,
                          identity=self.link.identity.acting_for(name))

    # ---- browsers
    def join(self, outbox: Outbox) -> None:
        """A browser starts watching: it gets the kept events, then the newest of each feed."""
        for text in self._history:
            outbox.put(text)
        for text in self._latest.values():
            outbox.put(text)
        self._watchers.add(outbox)

    def leave(self, outbox: Outbox) -> None:
        self._watchers.discard(outbox)

    def publish_latest(self, feed: str, rpc: str, reply=None, status=None,
                       ordered: bool = False) -> None:
        """The newest frame of a feed (state sample, a status read): a browser that is behind
        gets only the newest one. `ordered` frames (a stream's start, a failure) are delivered
        every one, in order."""
        text = wire.frame(self.name, rpc, reply=reply, status=status)
        self._latest[feed] = text
        for outbox in self._watchers:
            if ordered:
                outbox.put(text)
            else:
                outbox.put_latest((self.name, feed), text)

    @property
    def answering(self) -> bool:
        """No feed of the device's failing now (its state, events and reads)."""
        return not self._failed

    def feed_status(self, rpc: str, code: grpc.StatusCode, details: str) -> None:
        """A feed works (OK) or failed: its failure is told once per change of code."""
        if code is grpc.StatusCode.OK:
            if self._failed.pop(rpc, None) is not None:
                self._latest.pop(rpc + "#status", None)
            return
        if self._failed.get(rpc) != code:
            self._failed[rpc] = code
            log.info("%s %s: %s", self.name, rpc, details)
            self.publish_latest(rpc + "#status", rpc, status=wire.status(code, details),
                                ordered=True)

    # ---- from the core's feeds
    def _event(self, event: event_service_pb2.Event) -> None:
        text = wire.frame(self.name, SUBSCRIBE,
                          reply=event_service_pb2.SubscribeResponse(event=event))
        self._history.append(text)
        for outbox in self._watchers:
            outbox.put(text)
        if event.HasField("state_change"):
            self.status.kick()
            self.cell.kick()

    def _sample(self, sample: Sample) -> None:
        message = sample.message
        end_effector = (message.end_effector, message.end_effector_state)
        if end_effector != self._end_effector:
            self._end_effector = end_effector
            self.cell.kick()
        self.publish_latest("state.sample", STREAM_STATE,
                            reply=state_service_pb2.StreamStateResponse(sample=message))

    def _state_status(self, code: grpc.StatusCode, details: str) -> None:
        started = self.link.state.started
        if code is grpc.StatusCode.OK and started is not None:   # the stream's terms
            self.publish_latest("state.started", STREAM_STATE, ordered=True,
                                reply=state_service_pb2.StreamStateResponse(started=started))
        self.feed_status(STREAM_STATE, code, details)

    async def _stream_sensors(self) -> None:
        """The force sensor into the state stream, once the device answers; without it if the
        device cannot stream it."""
        while True:
            try:
                await self.link.state.watch(self, SENSORS)
                return
            except CommandRefused as refused:
                log.info("%s: the state stream goes without %s: %s", self.name,
                         ", ".join(SENSORS), refused)
                return
            except (TransportError, TimeoutError):
                await asyncio.sleep(SENSOR_RETRY_S)

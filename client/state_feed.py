"""A device's live state, read once for a whole program: one StateService.StreamState kept open,
its newest sample at hand and waitable.

Whoever answers from the state (a CRCL GetStatus, a page's display) reads `latest` rather than
asking the device each time. While the stream is down, `stale()` says why and how old the
last sample is, and the stream is opened again every RETRY_PERIOD. The sensors read into every
sample are those any owner asked for (`watch`); a set that grows is tried on a new stream
first, which replaces the running one only once the device has accepted it, so a sensor the
stream cannot carry is refused and the feed goes on as it was. Every sample also goes to the
`listeners`; the stream's terms are kept in `started`, and each time a stream starts or fails
the `status_listeners` hear (code, details): (OK, "") once a stream's terms arrived.
"""
from __future__ import annotations

import asyncio
import logging
import time
from dataclasses import dataclass
from typing import Callable

import grpc

from landscape.client.errors import CommandRefused, from_rpc_error
from landscape.client.feed import Feed
from landscape.v1 import state_service_pb2, state_service_pb2_grpc

log = logging.getLogger(__name__)

RETRY_PERIOD = 2.0          # s between attempts to (re)open the stream
OPEN_TIMEOUT = 5.0          # s for the device to accept a stream with new sensors
STALE_AFTER = 1.0           # s without a new sample: the state is old


@dataclass(frozen=True, eq=False)
class Sample:
    """One state sample as it arrived (each its own: compared and hashed by identity)."""

    message: state_service_pb2.StateSample
    received: float             # time.monotonic() when it arrived

    @property
    def time(self) -> float:
        """Unix s of the controller cycle it was taken in."""
        return self.message.time.ToNanoseconds() / 1e9


class StateFeed(Feed[Sample]):
    """`request` gives the rate, frame and units; its sensors are the feed's to set."""

    def __init__(self, channel: grpc.aio.Channel, request: state_service_pb2.StreamStateRequest,
                 metadata=()):
        super().__init__("landscape-state")
        self._stub = state_service_pb2_grpc.StateServiceStub(channel)
        self._request = request
        self._metadata = tuple(metadata)
        self.latest: Sample | None = None
        self.unavailable = "no state from the device yet"
        self.sensors: tuple[str, ...] = tuple(request.sensors)
        self.started: state_service_pb2.StreamStarted | None = None   # the running stream's terms
        self._wanted: dict[object, frozenset[str]] = {}     # owner -> its sensors
        self._changing = asyncio.Lock()                     # one change of sensors at a time
        self._changed = asyncio.Condition()

    async def watch(self, owner, names) -> None:
        """Read `owner`'s sensors (with every other owner's) into every sample from now on;
        the client's error (from_rpc_error), and nothing changed, if the device's stream
        cannot carry them."""
        async with self._changing:
            wanted = {**self._wanted, owner: frozenset(names)}
            if not wanted[owner]:
                del wanted[owner]
            sensors = tuple(sorted(frozenset().union(*wanted.values())))
            if sensors != self.sensors:
                first = None
                if not set(sensors) <= set(self.sensors):
                    first = await self._try(sensors)
                await self._restart(sensors, first)
            self._wanted = wanted

    # ---- how current the state is ------------------------------------------------------------

    def age(self) -> float | None:
        """Seconds since the newest sample arrived (None: there is none)."""
        return None if self.latest is None else time.monotonic() - self.latest.received

    def stale(self) -> str:
        """Why the newest sample cannot be taken for the present state ("" if it can)."""
        age = self.age()
        if age is None:
            return self.unavailable
        if age <= STALE_AFTER:
            return ""
        return f"the device's state is {age:.1f} s old ({self.unavailable or 'no new sample'})"

    async def present(self, timeout: float = 1.0) -> Sample | None:
        """The newest sample if it is not old, else the next to arrive within timeout; None if
        none does."""
        if not self.stale():
            return self.latest
        asked = time.monotonic()
        return await self.until(lambda s: s.received >= asked, timeout)

    async def taken_after(self, unix_s: float, timeout: float = 1.0) -> Sample | None:
        """The first sample of a cycle at or after `unix_s` (an event's time); None if none
        comes within timeout."""
        return await self.until(lambda s: s.time >= unix_s, timeout)

    async def until(self, condition: Callable[[Sample], bool],
                    timeout: float = 1.0) -> Sample | None:
        """The first sample (the newest included) for which condition(sample) holds; None if
        none comes within timeout."""
        async with self._changed:
            try:
                async with asyncio.timeout(timeout):
                    await self._changed.wait_for(
                        lambda: self.latest is not None and condition(self.latest))
            except TimeoutError:
                return None
        return self.latest

    # ---- the stream --------------------------------------------------------------------------

    def _request_for(self, sensors: tuple[str, ...]) -> state_service_pb2.StreamStateRequest:
        request = state_service_pb2.StreamStateRequest()
        request.CopyFrom(self._request)
        request.ClearField("sensors")
        request.sensors.extend(sensors)
        return request

    async def _try(self, sensors: tuple[str, ...]):
        """A stream of these sensors, once the device has accepted it: (call, first reply)."""
        call = self._stub.StreamState(self._request_for(sensors), metadata=self._metadata)
        try:
            async with asyncio.timeout(OPEN_TIMEOUT):
                first = await call.read()
        except grpc.aio.AioRpcError as error:
            raise from_rpc_error(error, "StreamState") from None
        except BaseException:
            call.cancel()
            raise
        if first is grpc.aio.EOF:
            raise CommandRefused("the device's state stream ended at once", await call.code(),
                                 rpc="StreamState")
        return call, first

    async def _restart(self, sensors: tuple[str, ...], first) -> None:
        old = self._task
        self.sensors = sensors
        self._task = asyncio.create_task(self._run(first), name=self._task_name)
        if old is not None:
            old.cancel()
            await asyncio.gather(old, return_exceptions=True)

    async def _publish(self, sample: Sample) -> None:
        self.latest, self.unavailable = sample, ""
        self._hand_on(sample)
        async with self._changed:
            self._changed.notify_all()

    async def _run(self, opened=None) -> None:
        """Stream samples, reopening the stream RETRY_PERIOD after it fails; only cancelling
        the task ends it. `opened`: a stream already open, and its first reply."""
        while True:
            call, message = opened or (self._stub.StreamState(
                self._request_for(self.sensors), metadata=self._metadata), None)
            opened = None
            code, details = grpc.StatusCode.UNAVAILABLE, "the device ended it"
            try:
                while True:
                    kind = message.WhichOneof("message") if message is not None else None
                    if kind == "sample":
                        await self._publish(Sample(message.sample, time.monotonic()))
                    elif kind == "started":
                        self.started = message.started
                        self._tell(grpc.StatusCode.OK, "")
                    message = await call.read()
                    if message is grpc.aio.EOF:
                        break
                self.unavailable = f"state stream: {details}"
            except grpc.aio.AioRpcError as error:
                code, details = error.code(), error.details()
                self.unavailable = f"state stream: {code.name}: {details}"
            except Exception as error:   # noqa: BLE001 - the feed must outlive any surprise
                code, details = grpc.StatusCode.UNKNOWN, repr(error)
                self.unavailable = f"state stream: {details}"
                log.exception("state stream")
            finally:
                call.cancel()
            log.warning("%s", self.unavailable)
            self._tell(code, details)
            await asyncio.sleep(RETRY_PERIOD)


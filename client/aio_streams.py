"""The device's server streams for asyncio callers: events and live state.

`AsyncEventStream` yields landscape.v1 Events (EventService.Subscribe); `AsyncStateStream`
yields StateSamples (StateService.StreamState) after reading the stream's terms into
`started`. Both end quietly when closed, and raise the client's exceptions (errors.py) when
the call fails. (The blocking twins are in streams.py; a program's one shared subscription,
which follows its commands, is event_feed.py.)
"""
from __future__ import annotations

import asyncio
from typing import AsyncIterator, Sequence

import grpc

from landscape.client.errors import from_rpc_error
from landscape.client.values import Frame
from landscape.v1 import event_service_pb2, state_service_pb2, types_pb2


class _AsyncStream:
    rpc = ""

    def __init__(self, call):
        self._call = call
        self._closed = False

    def close(self) -> None:
        self._closed = True
        self._call.cancel()

    async def __aenter__(self):
        return self

    async def __aexit__(self, *exc) -> None:
        self.close()

    async def _read(self):
        """The next message, or EOF; the client's error if the call fails (EOF once closed)."""
        try:
            return await self._call.read()
        except grpc.aio.AioRpcError as error:
            if self._closed:
                return grpc.aio.EOF
            raise from_rpc_error(error, self.rpc) from None
        except asyncio.CancelledError:   # grpc.aio's read of a call cancelled by close()
            if self._closed:
                return grpc.aio.EOF
            raise


class AsyncEventStream(_AsyncStream):
    """Events and alarms in order (seed 2.1); `last_sequence` is the newest one seen, to resume
    from after a reconnection."""

    rpc = "Subscribe"

    def __init__(self, call):
        super().__init__(call)
        self.last_sequence = 0

    async def __aiter__(self) -> AsyncIterator[event_service_pb2.Event]:
        while (reply := await self._read()) is not grpc.aio.EOF:
            self.last_sequence = reply.event.sequence
            yield reply.event


class AsyncStateStream(_AsyncStream):
    """Live state samples; `started` (StreamStarted: granted rate, frame, units) is read with
    the first sample, or by `wait_started()`."""

    rpc = "StreamState"

    def __init__(self, call):
        super().__init__(call)
        self.started: state_service_pb2.StreamStarted | None = None

    async def wait_started(self) -> state_service_pb2.StreamStarted:
        if self.started is None:
            first = await self._read()
            if first is grpc.aio.EOF:
                raise EOFError("the state stream ended before its terms")
            self.started = first.started
        return self.started

    async def __aiter__(self) -> AsyncIterator[state_service_pb2.StateSample]:
        await self.wait_started()
        while (message := await self._read()) is not grpc.aio.EOF:
            if message.WhichOneof("message") == "sample":
                yield message.sample


# Meters and radians: the units of a URDF, for a program that draws or plans with the state.
SI_UNITS = types_pb2.Units(linear=types_pb2.LINEAR_UNIT_METERS,
                           angular=types_pb2.ANGULAR_UNIT_RADIANS)


def subscribe_request(after_sequence: int | None) -> event_service_pb2.SubscribeRequest:
    return event_service_pb2.SubscribeRequest(after_sequence=after_sequence)


def state_request(rate_hz: float, frame: Frame | None, units: types_pb2.Units | None,
                  sensors: Sequence[str]) -> state_service_pb2.StreamStateRequest:
    """rate_hz: samples per second (0: every cycle); frame: BASE or WORLD (None: WORLD);
    units: None for the device's; sensors: names as GetSensorReading takes them."""
    return state_service_pb2.StreamStateRequest(
        rate_hz=rate_hz, frame=None if frame is None else Frame(frame), units=units,
        sensors=list(sensors))

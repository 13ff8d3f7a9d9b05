"""Iterators over the device's server streams, for the blocking client.

`EventStream` yields landscape.v1 Events (EventService.Subscribe); `StateStream` yields
StateSamples (StateService.StreamState) after reading the stream's terms into `started`.
Both end quietly when closed (`close()`, or leaving their `with`), and raise the client's
exceptions (errors.py) when the call fails.
"""
from __future__ import annotations

from typing import Iterator, Sequence

import grpc

from landscape.client.errors import from_rpc_error
from landscape.client.values import Frame
from landscape.v1 import event_service_pb2, state_service_pb2, types_pb2


class _Stream:
    def __init__(self, call):
        self._call = call
        self._closed = False

    def close(self) -> None:
        self._closed = True
        self._call.cancel()

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _messages(self) -> Iterator:
        try:
            yield from self._call
        except grpc.RpcError as error:
            if self._closed:   # cancelled by close()
                return
            raise from_rpc_error(error) from None


class EventStream(_Stream):
    """Events and alarms in order (seed 2.1); `last_sequence` is the newest one seen, to resume
    from after a reconnection (`robot.events(after_sequence=stream.last_sequence)`)."""

    def __init__(self, call):
        super().__init__(call)
        self.last_sequence = 0

    def __iter__(self) -> Iterator[event_service_pb2.Event]:
        for reply in self._messages():
            self.last_sequence = reply.event.sequence
            yield reply.event


def subscribe_request(after_sequence: int | None) -> event_service_pb2.SubscribeRequest:
    return event_service_pb2.SubscribeRequest(after_sequence=after_sequence)


class StateStream(_Stream):
    """Live state samples; `started` (StreamStarted: granted rate, frame, units) is read with
    the first sample, or by `wait_started()`."""

    def __init__(self, call):
        super().__init__(call)
        self._iterator = self._messages()
        self.started: state_service_pb2.StreamStarted | None = None

    def wait_started(self) -> state_service_pb2.StreamStarted:
        if self.started is None:
            first = next(self._iterator)
            self.started = first.started
        return self.started

    def __iter__(self) -> Iterator[state_service_pb2.StateSample]:
        self.wait_started()
        for message in self._iterator:
            if message.WhichOneof("message") == "sample":
                yield message.sample


def state_request(rate_hz: float, frame: Frame | None, units: types_pb2.Units | None,
                  sensors: Sequence[str]) -> state_service_pb2.StreamStateRequest:
    """rate_hz: samples per second (0: every cycle); frame: BASE or WORLD (None: WORLD);
    units: None for the device's; sensors: names as GetSensorReading takes them."""
    return state_service_pb2.StreamStateRequest(
        rate_hz=rate_hz, frame=None if frame is None else Frame(frame), units=units,
        sensors=list(sensors))

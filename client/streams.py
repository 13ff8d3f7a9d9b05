"""Iterators over the device's server streams, for the blocking client: the asyncio streams
(aio_streams.py) read on the Robot's loop thread.

`EventStream` yields landscape.v1 Events (EventService.Subscribe); `StateStream` yields
StateSamples (StateService.StreamState) after reading the stream's terms into `started`.
Both end quietly when closed (`close()`, or leaving their `with`), and raise the client's
exceptions (errors.py) when the call fails.
"""
from __future__ import annotations

from typing import Iterator

from landscape.client.aio_streams import AsyncEventStream, AsyncStateStream
from landscape.client.loop_thread import LoopThread
from landscape.v1 import event_service_pb2, state_service_pb2


class _Stream:
    def __init__(self, stream: AsyncEventStream | AsyncStateStream, thread: LoopThread):
        self._stream = stream
        self._thread = thread

    def close(self) -> None:
        self._thread.loop.call_soon_threadsafe(self._stream.close)

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class EventStream(_Stream):
    """Events and alarms in order (seed 2.1); `last_sequence` is the newest one seen, to resume
    from after a reconnection (`robot.events(after_sequence=stream.last_sequence)`)."""

    @property
    def last_sequence(self) -> int:
        return self._stream.last_sequence

    def __iter__(self) -> Iterator[event_service_pb2.Event]:
        return self._thread.iterate(self._stream)


class StateStream(_Stream):
    """Live state samples; `started` (StreamStarted: granted rate, frame, units) is read with
    the first sample, or by `wait_started()`."""

    @property
    def started(self) -> state_service_pb2.StreamStarted | None:
        return self._stream.started

    def wait_started(self) -> state_service_pb2.StreamStarted:
        return self._thread.run(self._stream.wait_started())

    def __iter__(self) -> Iterator[state_service_pb2.StateSample]:
        return self._thread.iterate(self._stream)

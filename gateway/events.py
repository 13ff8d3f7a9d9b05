"""Completion of the device's non-blocking commands, from EventService.Subscribe.

One subscription per gateway. A motion's started call returns a command id; its done, failed
or aborted event resolves the waiter for that id. An outcome that arrives before anyone waits
(a short move can finish before the caller resumes) is kept for a while, so none is missed.
"""
from __future__ import annotations

import asyncio
import collections
import logging
from dataclasses import dataclass

import grpc

from landscape.v1 import event_service_pb2, event_service_pb2_grpc

log = logging.getLogger(__name__)

Phase = event_service_pb2.CommandEvent.Phase
_FINAL = {Phase.PHASE_DONE: "done", Phase.PHASE_FAILED: "failed", Phase.PHASE_ABORTED: "aborted"}
KEEP_OUTCOMES = 1024        # finished commands remembered for late waiters
RETRY_PERIOD = 1.0


@dataclass(frozen=True)
class Outcome:
    """How a device command ended: "done", "failed" or "aborted", and the device's message."""

    result: str
    message: str = ""
    time: float = 0.0       # unix s the device published the end


class EventRouter:
    def __init__(self, channel):
        self.stub = event_service_pb2_grpc.EventServiceStub(channel)
        self._waiters: dict[str, asyncio.Future] = {}
        self._outcomes: collections.OrderedDict[str, Outcome] = collections.OrderedDict()
        self._task: asyncio.Task | None = None
        self.last_sequence: int | None = None

    async def start(self) -> None:
        self._task = asyncio.create_task(self._run(), name="crcl-events")

    async def stop(self) -> None:
        if self._task:
            self._task.cancel()
            await asyncio.gather(self._task, return_exceptions=True)

    async def outcome(self, command_id: str) -> Outcome:
        """Wait for the device command's end (cancel the wait to stop waiting)."""
        if command_id in self._outcomes:
            return self._outcomes[command_id]
        future = self._waiters.setdefault(command_id, asyncio.get_running_loop().create_future())
        return await asyncio.shield(future)   # a cancelled waiter leaves it for the others

    def _resolve(self, command_id: str, outcome: Outcome) -> None:
        self._outcomes[command_id] = outcome
        while len(self._outcomes) > KEEP_OUTCOMES:
            self._outcomes.popitem(last=False)
        future = self._waiters.pop(command_id, None)
        if future is not None and not future.done():
            future.set_result(outcome)

    async def _run(self) -> None:
        while True:
            # From the first kept event, then resuming: no outcome is lost between streams.
            request = event_service_pb2.SubscribeRequest(after_sequence=self.last_sequence or 0)
            try:
                async for reply in self.stub.Subscribe(request):
                    event = reply.event
                    if self.last_sequence is not None and event.sequence <= self.last_sequence:
                        self._outcomes.clear()   # a restarted device: its ids start again
                    self.last_sequence = event.sequence
                    if event.HasField("command") and event.command.phase in _FINAL:
                        self._resolve(event.command.command_id,
                                      Outcome(_FINAL[event.command.phase], event.command.message,
                                              event.time.ToNanoseconds() / 1e9))
            except grpc.aio.AioRpcError as error:
                log.warning("event stream ended: %s %s", error.code().name, error.details())
            await asyncio.sleep(RETRY_PERIOD)

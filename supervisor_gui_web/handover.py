"""Control handed over between two people signed in to this supervisor.

A device has one lock. When it is held through a page of this supervisor, another operator
here may ask for it: the holder's page shows the request, and the holder hands the lock over
or declines. Handing over stops nothing that runs: a motion in progress (Moving, Paused) must
be ended first, and the request is refused until then. The holder's side then powers down
(Deactivate, from Resting) and releases; the requester's session takes the lock at once and
powers nothing on. Nothing takes a lock without its holder's word, and a request nobody
answers lapses after REQUEST_S.

The desk knows which page (Console) holds each device's lock from the consoles themselves
(their Lock, Release, and sessions' ends). A lock held by any other client (a script, the
CLI, another supervisor) is not the desk's to mediate: asking is refused, saying so.

Every step is said to both pages on `supervisor/Control` frames:
  {"asked": {"by", "expires_in_ms"}}        to the holder
  {"waiting": {"holder", "expires_in_ms"}}  to the requester
  {"declined": {"by"}}, {"cancelled": {"by"}}, {"lapsed": {}}   to both
  {"given": {"to"}}                          to the holder: the lock is no longer theirs
  {"received": {"from"}}                     to the requester: the lock is theirs
  {"failed": {"why"}}                        to both: the hand-over stopped part way
"""
from __future__ import annotations

import asyncio
import logging
from dataclasses import dataclass
from typing import Protocol

import grpc

from landscape.client import LandscapeError

log = logging.getLogger(__name__)

REQUEST_S = 60.0
CONTROL = "supervisor/Control"
BUSY = {"DEVICE_STATE_MOVING", "DEVICE_STATE_PAUSED"}


class HandoverRefused(Exception):
    """A request the desk cannot take; nothing changed."""

    def __init__(self, code: grpc.StatusCode, message: str):
        super().__init__(message)
        self.code = code


class Page(Protocol):
    """What the desk needs of a page's console."""

    name: str                                       # who is signed in there

    def notify(self, device: str, body: dict) -> None: ...
    def has_session(self, device: str) -> bool: ...
    async def device_state(self, device: str) -> str: ...   # DeviceState name
    async def give_up_lock(self, device: str, deactivate: bool) -> None: ...
    async def take_lock(self, device: str) -> None: ...


@dataclass
class _Request:
    requester: Page
    timer: asyncio.TimerHandle


class ControlDesk:
    def __init__(self, request_s: float = REQUEST_S):
        self.request_s = request_s
        self._holders: dict[str, Page] = {}
        self._requests: dict[str, _Request] = {}

    # ---- what the consoles report
    def locked(self, device: str, page: Page) -> None:
        self._holders[device] = page

    def unlocked(self, device: str, page: Page) -> None:
        """The page's lock on `device` ended (released, its session ended, the page closed)."""
        if self._holders.get(device) is page:
            del self._holders[device]
            self._end(device, {"cancelled": {"by": page.name, "why": "the lock holder's lock ended"}})

    def gone(self, page: Page) -> None:
        """The page closed: its locks and its requests end."""
        for device in [d for d, holder in self._holders.items() if holder is page]:
            self.unlocked(device, page)
        for device in [d for d, r in self._requests.items() if r.requester is page]:
            self._end(device, {"cancelled": {"by": page.name, "why": "the page asking closed"}})

    # ---- what the pages ask
    def request(self, device: str, page: Page) -> None:
        holder = self._holders.get(device)
        if holder is None:
            raise HandoverRefused(grpc.StatusCode.FAILED_PRECONDITION,
                                  f"the lock of {device} is not held through this supervisor: "
                                  "take it if it is free, or ask whoever holds it")
        if holder is page:
            raise HandoverRefused(grpc.StatusCode.ALREADY_EXISTS, f"this page holds the lock of {device}")
        if not page.has_session(device):
            raise HandoverRefused(grpc.StatusCode.FAILED_PRECONDITION,
                                  "open a session first: the lock is handed to a session")
        waiting = self._requests.get(device)
        if waiting is not None:
            raise HandoverRefused(grpc.StatusCode.ALREADY_EXISTS,
                                  f"{waiting.requester.name} has asked for {device} already")
        timer = asyncio.get_running_loop().call_later(
            self.request_s, self._end, device, {"lapsed": {"after_s": self.request_s}})
        self._requests[device] = _Request(page, timer)
        expires = int(self.request_s * 1000)
        holder.notify(device, {"asked": {"by": page.name, "expires_in_ms": expires}})
        page.notify(device, {"waiting": {"holder": holder.name, "expires_in_ms": expires}})

    def cancel(self, device: str, page: Page) -> None:
        request = self._requests.get(device)
        if request is None or request.requester is not page:
            raise HandoverRefused(grpc.StatusCode.NOT_FOUND, f"this page has not asked for {device}")
        self._end(device, {"cancelled": {"by": page.name}})

    async def answer(self, device: str, page: Page, give: bool) -> None:
        request = self._requests.get(device)
        if self._holders.get(device) is not page or request is None:
            raise HandoverRefused(grpc.StatusCode.NOT_FOUND, f"nobody waits for this page's answer on {device}")
        if not give:
            self._end(device, {"declined": {"by": page.name}})
            return
        state = await page.device_state(device)
        if state in BUSY:
            raise HandoverRefused(grpc.StatusCode.FAILED_PRECONDITION,
                                  f"{device} is {state.removeprefix('DEVICE_STATE_').lower()}: stop "
                                  "and abort the motion before handing the lock over")
        if self._requests.get(device) is not request:   # lapsed or cancelled meanwhile
            raise HandoverRefused(grpc.StatusCode.NOT_FOUND, f"the request for {device} has ended")
        self._requests.pop(device).timer.cancel()
        requester = request.requester
        try:
            await page.give_up_lock(device, deactivate=state == "DEVICE_STATE_RESTING")
        except LandscapeError as error:
            self._tell((page, requester), device, {"failed": {"why": f"{page.name} kept the lock: {error}"}})
            raise
        self.unlocked(device, page)
        page.notify(device, {"given": {"to": requester.name}})
        try:
            await requester.take_lock(device)
        except LandscapeError as error:
            self._tell((page, requester), device, {"failed": {
                "why": f"{page.name} released the lock, and {requester.name}'s Lock was refused: {error}"}})
            return
        self.locked(device, requester)
        requester.notify(device, {"received": {"from": page.name}})
        log.info("%s: %s handed the lock to %s", device, page.name, requester.name)

    # ----
    def _end(self, device: str, body: dict) -> None:
        request = self._requests.pop(device, None)
        if request is None:
            return
        request.timer.cancel()
        self._tell((self._holders.get(device), request.requester), device, body)

    @staticmethod
    def _tell(pages, device: str, body: dict) -> None:
        for page in pages:
            if page is not None:
                page.notify(device, body)

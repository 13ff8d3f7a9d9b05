"""Alarms acknowledged, as the supervisor keeps them: who acknowledged which alarm of which
device, told to every page at once and to every page that opens later.

The device contract has no acknowledgement (docs/page.md says what it would need): the
supervisor keeps them for the people signed in to it, in memory, as long as it runs. An
alarm is named by the page as "<sequence>@<time>" of its event (a restarted device numbers
its events from 1 again).
"""
from __future__ import annotations

import time
from collections import OrderedDict

from landscape.supervisor import wire
from landscape.supervisor.outbox import Outbox

ACKNOWLEDGED = "supervisor/Acknowledged"
KEPT_PER_DEVICE = 2000     # the oldest acknowledgements go first
MAX_KEYS = 500             # per call
MAX_KEY_CHARS = 64


class AlarmAcks:
    def __init__(self):
        self._acks: dict[str, OrderedDict[str, dict]] = {}
        self._watchers: set[Outbox] = set()

    def join(self, outbox: Outbox) -> None:
        for device, acks in self._acks.items():
            outbox.put(wire.note(device, ACKNOWLEDGED, {"acks": list(acks.values())}))
        self._watchers.add(outbox)

    def leave(self, outbox: Outbox) -> None:
        self._watchers.discard(outbox)

    def acknowledge(self, device: str, keys, who: str) -> int:
        """Acknowledge the alarms `keys` of `device` as `who`; ValueError names what is wrong
        with `keys`, and nothing changes then. Returns how many were new."""
        if (not isinstance(keys, list) or not 0 < len(keys) <= MAX_KEYS
                or not all(isinstance(k, str) and 0 < len(k) <= MAX_KEY_CHARS for k in keys)):
            raise ValueError(f"keys: a list of 1 to {MAX_KEYS} alarm names "
                             f"(\"<sequence>@<time>\", at most {MAX_KEY_CHARS} characters each)")
        acks = self._acks.setdefault(device, OrderedDict())
        new = [{"key": key, "by": who, "at": time.time()} for key in dict.fromkeys(keys) if key not in acks]
        for ack in new:
            acks[ack["key"]] = ack
        while len(acks) > KEPT_PER_DEVICE:
            acks.popitem(last=False)
        if new:
            text = wire.note(device, ACKNOWLEDGED, {"acks": new})
            for outbox in self._watchers:
                outbox.put(text)
        return len(new)

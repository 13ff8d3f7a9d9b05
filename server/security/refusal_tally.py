"""Refused authentication, counted per address instead of written per try (issue 25.5).

A caller without a known token may try as often as it likes; one record each (600 bytes) let
29 calls a second rotate the audit's history away within the hour, and filled the server's
log the same. Per address, the first refusal of an interval is written at once (a client set
up wrong shows at once); the rest are counted and written as one line when the interval ends
(`flush`, which the caller schedules) or the server stops (`flush_all`).
"""
from __future__ import annotations

import time
from collections import Counter
from typing import Callable

INTERVAL = 10.0     # s each address's refusals are summed over


class RefusalTally:
    """`write(address, counts, seconds)` is given the refusals of `address` not written one by
    one (by status name) over the last `seconds`. Used on one thread (the event loop)."""

    def __init__(self, write: Callable[[str, Counter, float], None], interval: float = INTERVAL,
                 clock: Callable[[], float] = time.monotonic):
        self._write, self.interval, self._clock = write, interval, clock
        self._open: dict[str, tuple[float, Counter]] = {}    # address: (since, counts)

    def note(self, address: str, status: str) -> bool:
        """One more refusal of `address`; True if it opens an interval (write it yourself, and
        schedule `flush(address)` in `interval` s), False if it was counted."""
        if address not in self._open:
            self._open[address] = (self._clock(), Counter())
            return True
        self._open[address][1][status] += 1
        return False

    def flush(self, address: str) -> None:
        """End `address`'s interval: its counted refusals, if any, in one line."""
        since, counts = self._open.pop(address, (0.0, Counter()))
        if counts:
            self._write(address, counts, self._clock() - since)

    def flush_all(self) -> None:
        for address in list(self._open):
            self.flush(address)

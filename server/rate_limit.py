"""A rate limit per client: a token bucket each, refilled at `rate` calls per second up to
`burst`. Used on the event loop only (no lock needed); idle buckets are forgotten."""
from __future__ import annotations

import time
from dataclasses import dataclass


@dataclass
class _Bucket:
    level: float
    stamp: float


class RateLimiter:
    """`allow(key)` is True while `key` has made no more than `burst` calls at once and no
    more than `rate` per second on average."""

    FORGET_AFTER = 600.0      # s without a call: the bucket is full again anyway

    def __init__(self, rate: float, burst: int, clock=time.monotonic):
        if rate <= 0 or burst < 1:
            raise ValueError(f"a rate limit needs rate > 0 and burst >= 1; got {rate}, {burst}")
        self.rate, self.burst = float(rate), int(burst)
        self._clock = clock
        self._buckets: dict[str, _Bucket] = {}
        self._swept = clock()

    def allow(self, key: str) -> bool:
        now = self._clock()
        bucket = self._buckets.get(key)
        if bucket is None:
            bucket = self._buckets[key] = _Bucket(float(self.burst), now)
        bucket.level = min(self.burst, bucket.level + (now - bucket.stamp) * self.rate)
        bucket.stamp = now
        if now - self._swept > self.FORGET_AFTER:
            self._sweep(now)
        if bucket.level < 1.0:
            return False
        bucket.level -= 1.0
        return True

    def _sweep(self, now: float) -> None:
        self._swept = now
        for key in [k for k, b in self._buckets.items() if now - b.stamp > self.FORGET_AFTER]:
            del self._buckets[key]

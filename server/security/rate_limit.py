"""A rate limit per client: a token bucket each, refilled at `rate` calls per second up to
`burst`, or at the budget its name is given (`sized`: name -> calls per second, bursts of twice
that: the front ends' service identities, sized for their traffic). Used on the event loop only
(no lock needed); idle buckets are forgotten."""
from __future__ import annotations

import time
from dataclasses import dataclass


@dataclass
class _Bucket:
    level: float
    stamp: float
    rate: float
    burst: float


class RateLimiter:
    """`allow(key)` is True while `key` has made no more than `burst` calls at once and no
    more than `rate` per second on average."""

    FORGET_AFTER = 600.0      # s without a call: the bucket is full again anyway

    def __init__(self, rate: float, burst: int, sized: dict[str, float] | None = None,
                 clock=time.monotonic):
        if rate <= 0 or burst < 1:
            raise ValueError(f"a rate limit needs rate > 0 and burst >= 1; got {rate}, {burst}")
        if any(value <= 0 for value in (sized or {}).values()):
            raise ValueError(f"every sized rate must be above 0; got {sized}")
        self.rate, self.burst = float(rate), int(burst)
        self.sized = {name: float(value) for name, value in (sized or {}).items()}
        self._clock = clock
        self._buckets: dict[str, _Bucket] = {}
        self._swept = clock()

    def budget(self, name: str | None) -> tuple[float, float]:
        """(calls per second, burst) of a client named `name`."""
        rate = self.sized.get(name) if name is not None else None
        return (rate, 2.0 * rate) if rate is not None else (self.rate, float(self.burst))

    def allow(self, key: str, name: str | None = None) -> bool:
        """One call of client `key`, whose budget is its `name`'s (else the default)."""
        now = self._clock()
        bucket = self._buckets.get(key)
        if bucket is None:
            rate, burst = self.budget(name)
            bucket = self._buckets[key] = _Bucket(burst, now, rate, burst)
        bucket.level = min(bucket.burst, bucket.level + (now - bucket.stamp) * bucket.rate)
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

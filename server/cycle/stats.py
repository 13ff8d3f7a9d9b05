"""Timing statistics of a real-time cycle loop, kept in shared memory.

The cycle process writes one sample per cycle into ring buffers (no locks, no allocation); the
parent process reads them whenever it likes and does the sorting itself, so asking for figures
never costs the cycle anything. All times are in seconds.
"""
from __future__ import annotations

import multiprocessing
from dataclasses import dataclass

import numpy as np

# Counter slots.
_CYCLES, _OVERRUNS, _MISSED = range(3)
# Running-maximum slots (over the whole run, not only the window).
_PERIOD_MAX, _LATE_MAX, _EXEC_MAX = range(3)


@dataclass(frozen=True)
class CycleStats:
    """Figures of a cycle loop; times in s.

    cycles: cycles run. overruns: cycles that started more than one period after their deadline.
    missed: deadlines skipped because of overruns (the loop realigns to its grid, it does not
    catch up). period_*: interval between the starts of consecutive cycles. late_*: start of a
    cycle minus its deadline. exec_*: duration of the step (physics and cyclic function).
    Percentiles cover the last `window` cycles; maxima and counters cover the whole run.
    """

    cycle_time: float
    cycles: int
    overruns: int
    missed: int
    window: int
    period_p50: float
    period_p99: float
    period_min: float
    period_max: float
    late_p50: float
    late_p99: float
    late_max: float
    exec_p50: float
    exec_p99: float
    exec_max: float

    def summary(self, unit: float = 1e-3, label: str = "ms") -> str:
        """One line for humans; times in `label` (1e-3: ms)."""
        f = lambda x: f"{x / unit:.3f}"  # noqa: E731
        return (f"cycles={self.cycles} overruns={self.overruns} missed={self.missed} "
                f"period p50/p99/max={f(self.period_p50)}/{f(self.period_p99)}/"
                f"{f(self.period_max)} {label}  late p50/p99/max={f(self.late_p50)}/"
                f"{f(self.late_p99)}/{f(self.late_max)} {label}  exec p50/p99/max="
                f"{f(self.exec_p50)}/{f(self.exec_p99)}/{f(self.exec_max)} {label}")


class StatsRing:
    """Per-cycle period, lateness and execution time in shared-memory rings of `window` samples.

    Create it in the parent and pass it to the child as a Process argument (it pickles only
    then, like any multiprocessing shared array). One writer (the loop) and any readers.
    """

    def __init__(self, window: int = 1 << 16):
        ctx = multiprocessing.get_context("spawn")
        self.window = int(window)
        self._period = ctx.RawArray("d", self.window)
        self._late = ctx.RawArray("d", self.window)
        self._exec = ctx.RawArray("d", self.window)
        self._counts = ctx.RawArray("q", 3)
        self._maxima = ctx.RawArray("d", 3)
        self._views()

    def _views(self):
        self._p, self._l, self._e = (np.frombuffer(a, dtype=np.float64)
                                     for a in (self._period, self._late, self._exec))
        self._c = np.frombuffer(self._counts, dtype=np.int64)
        self._m = np.frombuffer(self._maxima, dtype=np.float64)

    def __getstate__(self):
        # The numpy views do not pickle; the child rebuilds them over the shared arrays.
        return {k: v for k, v in self.__dict__.items() if k not in ("_p", "_l", "_e", "_c", "_m")}

    def __setstate__(self, state):
        self.__dict__.update(state)
        self._views()

    # -- writer side, once per cycle
    def record(self, period: float, late: float, exec_s: float) -> None:
        """period: since the previous start (NaN for the first cycle); late: start - deadline;
        exec_s: step duration."""
        c, m = self._c, self._m
        i = int(c[_CYCLES]) % self.window
        self._p[i] = period
        self._l[i] = late
        self._e[i] = exec_s
        if period > m[_PERIOD_MAX]:  # False for NaN
            m[_PERIOD_MAX] = period
        if late > m[_LATE_MAX]:
            m[_LATE_MAX] = late
        if exec_s > m[_EXEC_MAX]:
            m[_EXEC_MAX] = exec_s
        c[_CYCLES] += 1

    def overrun(self, missed: int) -> None:
        self._c[_OVERRUNS] += 1
        self._c[_MISSED] += missed

    def reset(self) -> None:
        """Forget everything; only the writer may call it (the loop, between cycles)."""
        self._c[:] = 0
        self._m[:] = 0.0

    # -- reader side
    def since(self, seen: int) -> tuple[int, int, int, np.ndarray, np.ndarray]:
        """(cycles, overruns, missed, period, late): the counters now, and the periods and
        lateness of the cycles after the first `seen` that the window still holds (/metrics
        bins them, server/metrics.py)."""
        cycles, overruns, missed = (int(x) for x in self._c)
        first = max(seen, cycles - self.window)
        slots = np.arange(first, cycles) % self.window
        return cycles, overruns, missed, self._p[slots], self._l[slots]

    def snapshot(self, cycle_time: float) -> CycleStats:
        cycles, overruns, missed = (int(x) for x in self._c)
        n = min(cycles, self.window)
        # A sample being written while we copy is at worst one cycle stale: fine for statistics.
        period, late, exe = (a[:n].copy() for a in (self._p, self._l, self._e))
        period = period[np.isfinite(period)]

        def pct(a: np.ndarray, q: float) -> float:
            return float(np.percentile(a, q)) if a.size else float("nan")

        maxima = [float(x) if cycles else float("nan") for x in self._m]
        return CycleStats(
            cycle_time=cycle_time, cycles=cycles, overruns=overruns, missed=missed, window=n,
            period_p50=pct(period, 50), period_p99=pct(period, 99),
            period_min=float(period.min()) if period.size else float("nan"),
            period_max=maxima[_PERIOD_MAX],
            late_p50=pct(late, 50), late_p99=pct(late, 99), late_max=maxima[_LATE_MAX],
            exec_p50=pct(exe, 50), exec_p99=pct(exe, 99), exec_max=maxima[_EXEC_MAX],
        )

"""What the cycle reads besides the joints: the sensors, the I/O image and the I/O watches.

Runs in the cycle process, every cycle, inside the Executor (executor.py); costs stay small:
the sensors only in cycles that need them (a reader watches the ring, or a sensor loop runs),
the force/torque sensor then once per cycle, the range sensor once every RANGE_PERIOD cycles
(every cycle while a guarded move watches it), the I/O image only the bits the server asked
for, and a watch only its own bits at its own period.

Watches (seed 4.1 signalDigitalIO): a watch polls its unit's watched bits every `period`
cycles and fires once, on the first poll at which all of them are set (bits set when it
starts fire at its first poll), then ends; one not fired within `timeout` cycles (0: never)
ends with a timeout report. Edges are seen at the cycle they happen: a bit set between cycles
n - 1 and n is seen by cycle n's poll, whose report leaves at the end of that cycle.

Messages (executor.py routes them here):
  server -> cycle  {"op": "io_image", "units": [(unit, mask), ...]}  at most IO_UNITS
                   {"op": "watch", "id", "unit", "bits", "period": cycles >= 1,
                    "timeout": cycles, 0 for none}
                   {"op": "unwatch", "id"}
  cycle -> server  {"op": "io_signal", "id", "bits": the whole unit's, "sequence": the cycle}
                   {"op": "io_timeout", "id", "bits": the watched ones, "sequence"}
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from landscape.server.cycle.feedback import (FORCE_TORQUE, IO_UNITS, RANGE, RANGE_PERIOD,
                                       ring_sensors)


class CycleSensors:
    """The ring's sensors (feedback.ring_sensors), read into `values` (7,): force/torque in
    the flange frame (N, N*m) and range (m), NaN before the first read."""

    def __init__(self):
        self.values = np.full(7, math.nan)
        self.watch_range = False     # a guarded move needs the range every cycle
        self._force: str | None = None
        self._range: str | None = None
        self._known = False
        self._unread = True          # the last cycle skipped them (skip)

    def read(self, ctrl, cycle: int, wanted: bool = True) -> np.ndarray:
        """The readings of cycle `cycle`; NaN unless `wanted` (nobody needs them)."""
        if not wanted:
            return self._skip()
        fresh = self._unread   # the range too: the last value is not there to stay
        self._unread = False
        if not self._known:
            self._known = True
            for name, place in ring_sensors(ctrl.sensor_map()).items():
                if place == RANGE:
                    self._range = name
                else:
                    self._force = name
        if self._force is not None:
            self.values[FORCE_TORQUE] = ctrl.read_sensor(self._force)
        if self._range is not None and (self.watch_range or fresh or cycle % RANGE_PERIOD == 0):
            self.values[RANGE] = ctrl.read_sensor(self._range)[0]
        return self.values

    def _skip(self) -> np.ndarray:
        if not self._unread:
            self._unread = True
            self.values[:] = math.nan
        return self.values


@dataclass
class _Watch:
    id: str
    unit: int
    bits: int
    period: int
    timeout: int
    age: int = 0


class IoMonitor:
    """The I/O image (written into the ring's IO columns) and the signal watches."""

    def __init__(self):
        self.image = np.full(IO_UNITS, math.nan)
        self._units: list[tuple[int, int]] = []
        self._watches: dict[str, _Watch] = {}

    def handle(self, msg: dict) -> None:
        op = msg["op"]
        if op == "io_image":
            self._units = [(int(u), int(m)) for u, m in msg["units"]][:IO_UNITS]
            self.image[:] = math.nan
        elif op == "watch":
            self._watches[msg["id"]] = _Watch(msg["id"], int(msg["unit"]), int(msg["bits"]),
                                              max(1, int(msg["period"])), int(msg["timeout"]))
        elif op == "unwatch":
            self._watches.pop(msg["id"], None)

    def poll(self, ctrl, sequence: int, reports: list) -> None:
        for i, (unit, mask) in enumerate(self._units):
            self.image[i] = ctrl.read_io_unit(unit, mask)
        for watch in list(self._watches.values()):
            watch.age += 1
            timed_out = watch.timeout and watch.age >= watch.timeout
            if (watch.age - 1) % watch.period and not timed_out:
                continue
            bits = ctrl.read_io_unit(watch.unit, watch.bits)
            if bits == watch.bits:
                reports.append({"op": "io_signal", "id": watch.id,
                                "bits": ctrl.read_io_unit(watch.unit), "sequence": sequence})
            elif timed_out:
                reports.append({"op": "io_timeout", "id": watch.id, "bits": bits,
                                "sequence": sequence})
            else:
                continue
            del self._watches[watch.id]

"""Every cycle's feedback, from the cycle to the server, through a ring in shared memory.

The Executor (in the cycle process, or on the lock-step thread) writes one row per cycle; the
server reads the newest row whenever it needs the arm's state (never more than a cycle old),
or every row since the last one it saw (the state streams). Nothing is queued: a reader that
falls more than `rows` cycles behind finds those rows overwritten, which is what thinning a
slow reader means. Writing never waits for a reader.

A wake-up byte goes down a pipe after a row is written, at most once per `tick_period` of wall
time, so the server's event loop can sleep on the pipe instead of polling.

Row layout (float64): see the column constants below. Angles rad, velocities rad/s, torques
N*m, times s. The model torques are the arm model's (arm_dynamics.py): what the cycle's motion
takes with the payload the server declared; NaN when the cycle has no arm model. The sensor
columns hold the cell's first force/torque sensor (read every cycle) and its first range
sensor (read every RANGE_PERIOD cycles, every cycle while a guarded move watches it; between
two reads the last one stays); `ring_sensors` says which sensors those are.

Rows are whole (sensors and model torques in them) only while a reader watches them (`watch`:
a state stream, and always on the real-time clock, where the cycle has time to spare): on the
clocks that run cycles back to back, those columns were a quarter of what a cycle cost for
readers that were not there (issue 31 item 5). Otherwise they are NaN, and a reader asks the
controller (Sensors.reading).
The I/O columns mirror up to IO_UNITS units of digital I/O, each read every cycle through the
mask the server asked for (executor "io_image"): a bit field as a float, exact to 2**53.
"""
from __future__ import annotations

import multiprocessing
import os
import threading
import time
from dataclasses import dataclass

import numpy as np

from landscape.robot.controller import EnableState

SEQ, TIME, WALL = 0, 1, 2
Q = slice(3, 9)            # measured joint positions
QD = slice(9, 15)          # measured joint velocities
CMD = slice(15, 21)        # the setpoint of this cycle
TAU = slice(21, 27)        # measured joint torques
ENABLE, ESTOP = 27, 28     # EnableState value, 1.0 while the e-stop is pressed
SENSORS = slice(29, 36)    # force/torque (6: N, N*m) and range (1: m), NaN when not read
FORCE_TORQUE = slice(0, 6)  # ... within SENSORS: flange frame, about the flange origin, tared
RANGE = 6                  # ... m along the tool axis from the tip; NaN: nothing in range
IO = slice(36, 40)         # I/O image: one unit's masked bits per column, NaN when not mirrored
IO_UNITS = 4
MODEL_TAU = slice(40, 46)  # the arm model's joint torques for this cycle's motion (N*m)
WIDTH = 46
RANGE_PERIOD = 5           # cycles between two reads of the range sensor (20 ms at 4 ms)


@dataclass(frozen=True, eq=False)
class Sample:
    """One cycle as the server sees it (arrays (6,) unless said otherwise)."""

    sequence: int          # the controller's cycle count, +1 per cycle
    time: float            # controller time, s
    wall_time: float       # unix time of the cycle's tick (when it began), s
    position: np.ndarray   # rad
    velocity: np.ndarray   # rad/s
    command: np.ndarray    # rad: where the next motion starts
    torque: np.ndarray     # N*m
    enable: EnableState
    estop: bool
    sensors: np.ndarray    # (7,): fx, fy, fz (N), tx, ty, tz (N*m), range (m); NaN if unread
    io: np.ndarray         # (IO_UNITS,): the mirrored units' masked bits, NaN if not mirrored
    model_torque: np.ndarray   # N*m, the arm model's (arm_dynamics.py); NaN without a model

    @classmethod
    def of(cls, row: np.ndarray) -> "Sample":
        return cls(int(row[SEQ]), float(row[TIME]), float(row[WALL]), row[Q], row[QD],
                   row[CMD], row[TAU], EnableState(int(row[ENABLE])), bool(row[ESTOP]),
                   row[SENSORS], row[IO], row[MODEL_TAU])


def ring_sensors(sensors) -> dict[str, slice | int]:
    """Which of the cell's sensors (SensorInfo, in order) the ring carries, and where within
    SENSORS: the first force/torque sensor and the first range sensor."""
    places: dict[str, slice | int] = {}
    for kind, place in (("force_torque", FORCE_TORQUE), ("laser_range", RANGE)):
        first = next((s for s in sensors if s.kind == kind), None)
        if first is not None:
            places[first.name] = place
    return places


class FeedbackRing:
    """`rows` rows of feedback in shared memory (pickles into a spawned process at start)."""

    def __init__(self, rows: int = 1024):
        ctx = multiprocessing.get_context("spawn")
        self.rows = rows
        self._data = ctx.RawArray("d", rows * WIDTH)
        self._head = ctx.RawArray("q", 1)       # sequence of the newest row, -1 before any
        self._head[0] = -1
        self._watchers = ctx.RawArray("q", 2)   # readers that want whole rows; since which row
        self._watch_lock = threading.Lock()
        self._tick_read, self._tick_write = os.pipe()
        os.set_blocking(self._tick_read, False)
        os.set_blocking(self._tick_write, False)
        self.tick_period = 0.001
        self._views()

    def _views(self) -> None:
        self._table = np.frombuffer(self._data, dtype=np.float64).reshape(self.rows, WIDTH)
        self._last_tick = 0.0

    def __getstate__(self):
        # Into the cycle process: the shared arrays and the pipe's write end (as a duplicated
        # descriptor, which multiprocessing passes while spawning).
        from multiprocessing.reduction import DupFd
        state = {k: v for k, v in self.__dict__.items() if k not in (
            "_table", "_tick_read", "_tick_write", "_watch_lock")}
        state["_tick_write_dup"] = DupFd(self._tick_write)
        return state

    def __setstate__(self, state):
        self._tick_write = state.pop("_tick_write_dup").detach()
        self._tick_read = -1
        self._watch_lock = threading.Lock()
        self.__dict__.update(state)
        os.set_blocking(self._tick_write, False)
        self._views()

    # -- writer (the cycle), once per cycle
    def write(self, sequence: int, row: np.ndarray) -> None:
        """Store `row` (WIDTH,) as cycle `sequence`, then publish it."""
        self._table[sequence % self.rows] = row
        self.publish(sequence)

    def slot(self, sequence: int) -> np.ndarray:
        """The row (WIDTH,) where cycle `sequence` goes: written in place, then `publish`ed."""
        return self._table[sequence % self.rows]

    def publish(self, sequence: int) -> None:
        """Cycle `sequence`'s row is written: readers may take it."""
        self._head[0] = sequence
        now = time.monotonic()
        if now - self._last_tick >= self.tick_period:
            self._last_tick = now
            try:
                os.write(self._tick_write, b"\0")
            except (BlockingIOError, OSError):
                pass   # the reader is behind (pipe full) or gone: it reads the ring anyway

    @property
    def watched(self) -> bool:
        """Whether this cycle's row must be whole (read once per cycle by the writer)."""
        return self._watchers[0] > 0

    # -- readers (the server)
    def watch(self) -> int:
        """One more reader wants whole rows (undo with `unwatch`); returns the first sequence
        sure to be whole. The cycle looks at the count when it starts: the one running now may
        have looked before, the one after it cannot have."""
        with self._watch_lock:
            if self._watchers[0] == 0:
                self._watchers[1] = self.head + 2
            self._watchers[0] += 1
            return int(self._watchers[1])

    def unwatch(self) -> None:
        with self._watch_lock:
            self._watchers[0] = max(0, self._watchers[0] - 1)

    def whole(self, sequence: int) -> bool:
        """Whether row `sequence` carries the sensors and model torques."""
        return self._watchers[0] > 0 and sequence >= self._watchers[1]

    @property
    def head(self) -> int:
        """Sequence of the newest row, -1 before the first."""
        return int(self._head[0])

    @property
    def tick_fd(self) -> int:
        """Readable when rows were written since it was last drained (`drain_ticks`)."""
        return self._tick_read

    def drain_ticks(self) -> None:
        try:
            while os.read(self._tick_read, 4096):
                pass
        except BlockingIOError:
            pass

    def row(self, sequence: int) -> np.ndarray | None:
        """A copy of cycle `sequence`'s row, or None if it is not (or no longer) in the ring."""
        if sequence < 0 or sequence > self.head or sequence <= self.head - self.rows:
            return None
        row = self._table[sequence % self.rows].copy()
        return row if int(row[SEQ]) == sequence else None   # overwritten while copied

    def latest(self) -> Sample | None:
        while (head := self.head) >= 0:
            row = self.row(head)
            if row is not None:
                return Sample.of(row)
        return None

    def close(self) -> None:
        for fd in (self._tick_read, self._tick_write):
            if fd >= 0:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._tick_read = self._tick_write = -1

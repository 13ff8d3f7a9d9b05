"""Helpers of the reliability tests: every cycle's feedback, as the physics had it."""
from __future__ import annotations

import threading

import numpy as np

from landscape.server.cycle.feedback import CMD, ENABLE, QD, SEQ, TIME, Q, FeedbackRing


class RowLog:
    """Collects every cycle's feedback row (feedback.py) from `ring` on a thread of its own,
    from the next cycle on; the ring keeps 1,024 cycles, so the server's clock must be paced
    (or held) for none to be overwritten before it is read."""

    def __init__(self, ring: FeedbackRing, period: float = 0.01):
        self._ring, self._period = ring, period
        self._rows: list[np.ndarray] = []
        self._next = ring.head + 1
        self._stop = threading.Event()
        self.missed = 0
        self._thread = threading.Thread(target=self._run, name="row-log", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(self._period):
            self._collect()

    def _collect(self) -> None:
        head = self._ring.head
        while self._next <= head:
            row = self._ring.row(self._next)
            if row is None:
                self.missed += 1
            else:
                self._rows.append(row)
            self._next += 1

    def close(self) -> np.ndarray:
        """Every row collected, (n, WIDTH), in cycle order."""
        self._stop.set()
        self._thread.join(5)
        self._collect()
        assert self.missed == 0, f"{self.missed} cycles were overwritten before being read"
        return np.array(self._rows)


def columns(rows: np.ndarray) -> dict[str, np.ndarray]:
    """The rows' sequence, time (s), measured positions and velocities, commands, power."""
    return {"seq": rows[:, SEQ], "t": rows[:, TIME], "q": rows[:, Q], "qd": rows[:, QD],
            "cmd": rows[:, CMD], "enable": rows[:, ENABLE]}

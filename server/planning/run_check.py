"""A path run timed and checked against the cell in stretches, ahead of where the arm plays
it (issue 31 item 4): the run starts once its first rows are timed and checked, and the rest
is timed and checked while it plays (path_runs.py hands each stretch's pieces and end to
the cycle, which brakes along the path before rows not yet checked: playback.py).

How far ahead is enough: `brake_rows`, an upper bound on the rows the arm travels while it
brakes along the path from any row timed so far at the stop limits, so the first stretch is
that many rows plus LEAD (what the cycle plays while the next stretch is worked out).

`RunCheck` is the planning process's side (process.py's jobs), `follow` the server's: it has
the later stretches timed and checked one after the other and hands them on, or says that one
was refused (the cycle then brakes along the path and the motion fails with the refusal).
"""
from __future__ import annotations

import logging
import math
import threading
import time
from typing import Callable

import numpy as np

from landscape.server.errors import Collision, CommandError
from landscape.server.planning.collision import CollisionScene, check_motion
from landscape.server.planning.motion.trajectory import Trajectory

LEAD = 50       # rows (200 ms at 4 ms) played while the next stretch is checked
STRETCH = 500   # rows checked by each later job
# A stop ramp may be planned at reduced bounds (ramps.py: down to 0.36 of them) and late by a
# few cycles: the bound below is three times the braking time at full bounds, plus SPARE rows.
BRAKE_FACTOR = 3.0
SPARE = 8

log = logging.getLogger(__name__)


def brake_rows(speed: np.ndarray, dt: float, acceleration: np.ndarray, jerk: np.ndarray) -> int:
    """Rows (samples at rate 1) the play may advance while it brakes from any row whose joints
    move at most at `speed` (rad/s: the fastest of the rows timed so far, the only ones the
    arm plays): a joint at v rad/s stops within v / a + a / j s at acceleration a and jerk j,
    and the play moves at most one row per cycle meanwhile."""
    fastest = float(np.max(np.asarray(speed) / acceleration))
    seconds = fastest + float(np.max(acceleration / jerk))
    return int(math.ceil(BRAKE_FACTOR * seconds / dt)) + SPARE


class RunCheck:
    """The rows of a run (back-to-back trajectories, as played) checked stretch by stretch:
    `check(scene, start, stop)` raises Collision naming where in the whole run. A piece that
    comes again (the cycles of a path run) is checked once."""

    def __init__(self, trajectories: list, what: str):
        self.trajectories, self.what = trajectories, what
        self.rows = sum(len(t) for t in trajectories)
        self._done: dict[int, int] = {}   # id(piece) -> its rows checked so far

    def extend(self, trajectories: list) -> None:
        """Pieces timed later (a run timed as it plays), after the rows so far."""
        self.trajectories = [*self.trajectories, *trajectories]
        self.rows += sum(len(t) for t in trajectories)

    def check(self, scene: CollisionScene, start: int, stop: int, model=None) -> None:
        model = model or scene.model()
        first = 0
        for piece in self.trajectories:
            lo, hi = max(start - first, 0), min(stop - first, len(piece))
            done = self._done.get(id(piece), 0)
            if lo < hi and done < hi:
                self._check_piece(model, piece, max(lo, done - 1, 0), hi, first)
                self._done[id(piece)] = hi
            first += len(piece)

    def _check_piece(self, model, piece, lo: int, hi: int, first: int) -> None:
        marks = tuple((s - lo, label) for s, label in piece.marks if lo <= s < hi)
        # A stretch that continues a piece starts on its last checked row: a pair within the
        # margin there was refused already, so none may count as "leaving" (check_motion).
        result = check_motion(model, piece.positions[lo:hi], piece.dt, marks,
                              allow_leaving=lo == 0)
        if result.contact is not None:
            contact = result.contact.within(first + lo, self.rows, piece.dt)
            raise Collision(f"{self.what} would collide: {contact}", **contact.metadata())


def first_pass_timed(pieces: list, last_point: int) -> bool:
    """Whether a path run's `pieces` reach its last point (marks are labelled by point index):
    what is left to time then is the way back and cycles that reuse the pieces, if any."""
    return any(label == last_point for piece in pieces for _, label in piece.marks)


def joined(pieces: list, continues: list[bool]) -> tuple[list, bool]:
    """Pieces as the cycle plays them: each that continues the one before joined to it (one
    segment); and whether the first continues a piece sent before."""
    out: list = []
    for piece, joins in zip(pieces, continues):
        if joins and out:
            before = out[-1]
            out[-1] = Trajectory(before.dt, np.concatenate([before.positions, piece.positions]),
                                 np.concatenate([before.velocities, piece.velocities]),
                                 (*before.marks, *((s + len(before), label)
                                                   for s, label in piece.marks)))
        else:
            out.append(piece)
    return out, bool(continues and continues[0])


def following(*args) -> threading.Thread:
    """`follow(*args)` on a thread of its own, started."""
    thread = threading.Thread(target=follow, args=args, name=f"time {args[2]}", daemon=True)
    thread.start()
    return thread


def follow(planning, key: str, command_id: str,
           hand_on: Callable[[list, list, int, int, bool], bool],
           send: Callable[[dict], None], delay: Callable[[], float] = lambda: 0.0) -> None:
    """The server's side of a run timed as it plays: its next STRETCH rows checked, and the
    pieces timed for them, by `planning` (process.py's next_pieces) one stretch after the
    other, each handed to `hand_on(pieces, continues, rows checked, brake rows, all
    checked)`, which sends them to the cycle (False: the motion no longer runs, and this
    ends); a refusal goes to the cycle as {"op": "refused", "id", "message"} (it brakes
    along the path and the motion fails with it). `delay()`: seconds to wait before each
    stretch (0 in service; tests make a stretch late with it: PathRuns's
    check_ahead_delay)."""
    try:
        everything = False
        while not everything:
            time.sleep(delay())
            answer = planning.run("next_pieces", key, STRETCH)
            everything = answer[-1]
            if not hand_on(*answer):
                planning.run("drop_run", key)
                return
    except CommandError as refusal:   # a collision, a timing refused, the process lost
        _refuse(send, command_id, refusal.message)
    except Exception as error:   # never a silent end: the arm would wait at rest for rows
        log.exception("timing %s ahead of the arm failed", command_id)
        _refuse(send, command_id, f"internal error timing the path ahead: {error!r}")


def _refuse(send: Callable[[dict], None], command_id: str, message: str) -> None:
    try:
        send({"op": "refused", "id": command_id, "message": message})
    except CommandError as gone:   # the controller is gone: the motion failed already
        log.warning("refusal of %s not sent: %s", command_id, gone)

"""The cycle process's pipe to its server (child.py), on the fast clock: its reports go out in
batches (at most every FREE_FLUSH_PERIOD of wall time, each send waking the server), and still
in the order they were posted, before any reply that follows them."""
from __future__ import annotations

from landscape.server.link.realtime_clock import RealTimeClock
from landscape.sim.movegen import sample_controller


def post_report(controller, n: int) -> int:
    """Between two cycles: the cyclic function's mailbox gets report n, then the call returns."""
    controller.cyclic.mailbox.post({"op": "posted", "n": n})
    return n


def test_a_reply_comes_after_the_reports_posted_before_it():
    with RealTimeClock(sample_controller, free=True) as clock:
        for n in range(30):
            assert clock.between_cycles(post_report, n) == n
            # There already when the call returned: it went out before the reply.
            assert clock.recv(timeout=0) == {"op": "posted", "n": n}


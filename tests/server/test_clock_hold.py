"""The lock-step clock's hold, which tests use to make a race happen in a given order: once
`hold()` returns, no cycle runs until `release()` (a cycle under way when it was called has
ended by then). The suite on two workers once read the ring's head right after hold() and saw
it move on by one (test_read_cache)."""
from __future__ import annotations

import time

from support import start_server


def test_no_cycle_runs_once_hold_has_returned(backend):
    server = start_server(backend=backend)
    clock, ring = server.link.clock, server.link.feedback
    try:
        for _ in range(1000):
            clock.hold()
            head = ring.head
            time.sleep(0.005)          # a cycle of the flat-out clock takes well under this
            assert ring.head == head
            clock.release()
            while ring.head == head:   # it steps again
                time.sleep(0.0005)
    finally:
        clock.release()
        server.stop(grace=None)

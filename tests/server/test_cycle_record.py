"""Each cycle's row of the feedback ring (cycle_record.py writes it into its slot in one numpy
call, in the ring's column order): what the cycle read and commanded, in the right columns."""
from __future__ import annotations

import math

import numpy as np

from landscape.robot.controller import EnableState
from landscape.server.cycle.factory import build_controller
from landscape.server.cycle.feedback import FeedbackRing
from landscape.server.cycle.process import Mailbox


def test_a_cycles_row_holds_what_it_read_and_commanded():
    ring, mailbox = FeedbackRing(), Mailbox()
    controller = build_controller(None, ring, mailbox)
    try:
        controller.init()
        controller.enable()
        for _ in range(400):
            controller.step()
            if controller.state().enable is EnableState.ENABLED:
                break
        unit, mask = next((u.id, 0b11) for u in controller.io_map() if u.direction == "output")
        controller.write_io_unit(unit, 0b01, 0)
        mailbox.inbox.append({"op": "io_image", "units": [(unit, mask)]})
        first = ring.head + 1
        for _ in range(3):
            controller.step()
            fbk = controller.get()
            sample = ring.latest()
            assert sample.sequence == first and sample.time == controller.time
            assert sample.wall_time == controller.wall_time
            assert np.array_equal(sample.position, fbk.pos)
            assert np.array_equal(sample.velocity, fbk.vel)
            assert np.array_equal(sample.torque, fbk.torque)
            assert np.allclose(sample.command, fbk.pos, atol=1e-3)   # holding where it is
            assert sample.enable is EnableState.ENABLED and not sample.estop
            assert all(math.isnan(v) for v in sample.sensors)         # nobody watches
            assert all(math.isnan(v) for v in sample.model_torque)
            assert sample.io[0] == 0b01 and all(math.isnan(v) for v in sample.io[1:])
            first += 1
        ring.watch()
        for _ in range(3):
            controller.step()
        sample = ring.latest()
        assert all(math.isfinite(v) for v in sample.model_torque)
        assert all(math.isfinite(v) for v in sample.sensors[:6])
    finally:
        controller.destroy()

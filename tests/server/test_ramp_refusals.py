"""Ramps that cannot be planned are refused (RampPlanner.plan returns None: the play goes on as
planned and tries again next cycle), never an exception in the cycle: an exception there
disables the drives mid-motion (the cyclic function failed)."""
from __future__ import annotations

import numpy as np
import pytest

from landscape.server.cycle.ramps import RampPlanner

DT = 0.004
# A straight joint line: every joint 0.01 rad per sample, 50 samples.
POSITIONS = np.cumsum(np.full((50, 6), 0.01), axis=0)
LAST = len(POSITIONS) - 1
LIMITS = np.full(6, 50.0), np.full(6, 5000.0)   # rad/s^2, rad/s^3


def recent(sigma: float) -> np.ndarray:
    """The three positions played before sigma, newest first (the arm at its planned pace)."""
    k = min(int(sigma), LAST)
    return np.array([POSITIONS[max(k - j, 0)] for j in range(3)])


def test_a_resume_that_ruckig_cannot_time_is_refused():
    """Bounds so low that the ramp would last beyond what ruckig can compute: ruckig answers
    -101 (ErrorTrajectoryDuration), which its Python Result enum does not hold. Before, that
    escaped from the cycle as ValueError("-101 is not a valid Result")."""
    acceleration = np.full(6, 1e-6)
    ramp = RampPlanner(DT).plan(POSITIONS, recent(10), 10.0, 0.0, 0.0, 1.0, acceleration,
                                acceleration * 50)
    assert ramp is None


@pytest.mark.parametrize("target", [0.0, 1.0])
def test_a_ramp_from_past_the_segments_end_is_refused(target):
    """A play position past the last sample leaves no stretch to take the bounds from. Before,
    _planned took the maximum of an empty stretch (ValueError), or indexed an empty ramp."""
    for sigma in (LAST + 1.0, LAST + 1.5):
        ramp = RampPlanner(DT).plan(POSITIONS, recent(sigma), sigma, 1.0 - target, 0.0, target,
                                    *LIMITS)
        assert ramp is None


def test_a_stop_that_would_take_hours_is_refused(memory_capped):
    """A stop at bounds so low that it would last billions of cycles: refused, rather than
    sampled cycle by cycle. Before, sampling it asked numpy for terabytes (MemoryError; at
    bounds a little higher it took the cycle minutes and gigabytes)."""
    acceleration = np.full(6, 1e-9)
    ramp = RampPlanner(DT).plan(POSITIONS, recent(10), 10.0, 1.0, 0.0, 0.0, acceleration,
                                acceleration * 50)
    assert ramp is None


def test_ramps_within_reach_are_still_planned():
    """The refusals leave every ordinary ramp alone: a stop and a resume mid-segment."""
    stop = RampPlanner(DT).plan(POSITIONS, recent(10), 10.0, 1.0, 0.0, 0.0, *LIMITS)
    assert stop is not None and stop[1][-1] == 0.0 and stop[0][-1] <= LAST
    at_rest = np.tile(POSITIONS[10], (3, 1))
    resume = RampPlanner(DT).plan(POSITIONS, at_rest, 10.0, 0.0, 0.0, 1.0, *LIMITS)
    assert resume is not None and resume[1][-1] == 1.0

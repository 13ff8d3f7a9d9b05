"""A joint move's timing: the straight line in joint space from rest to rest, jerk-limited and
time-optimal, planned by ruckig in microseconds (issue 31 item 4: a joint MoveAbsolute's
planning was TOPP-RA's grid, passes and filter, 2-3 ms before the first cycle could move).

The line q(s) = q0 + s (q1 - q0), s from 0 to 1, is one degree of freedom: a joint moving
|q1_i - q0_i| rad per unit of s keeps its velocity, acceleration and jerk limits when s keeps
those limits divided by that distance, so the tightest joint sets each bound of s. ruckig's
profile for s under them is the time-optimal jerk-limited motion along the line (DESIGN 6:
point-to-point moves may use ruckig), with a whole number of cycles (its discrete duration).
Sampled at whole cycles, the positions' second and third differences are averages of the
profile's acceleration and jerk, so every sample keeps the limits the profile keeps.
"""
from __future__ import annotations

import math

import numpy as np
from ruckig import DurationDiscretization, InputParameter, Result, Ruckig, Trajectory as Profile

from landscape.server.cycle.ramps import sampled
from landscape.server.planning.motion.trajectory import Limits, PlanningError, Trajectory

MARGIN = 1e-7   # relative


def time_joint_line(q0: np.ndarray, q1: np.ndarray, limits: Limits, dt: float,
                    max_duration: float) -> Trajectory | None:
    """The timed line from q0 to q1 (rad, (6,)) at rest at both ends, every dt (s), marks
    (0, 0) and (last, 1) as timing.time_path's; None where this timing does not apply (no jerk
    limit, no motion, or too long for ruckig's range: time_path's answer then);
    PlanningError("TOO_LONG") past max_duration (s)."""
    q0, q1 = np.asarray(q0, dtype=float), np.asarray(q1, dtype=float)
    distance = np.abs(q1 - q0)
    if limits.jerk is None or distance.max() < 1e-9:
        return None
    moving = distance > 1e-12
    # Bounds of s per cycle (ruckig's time unit is one cycle), a hair inside the limits so
    # that rounding in the samples' differences never takes them past.
    velocity, acceleration, jerk = (float(np.min(bound[moving] / distance[moving]))
                                    * dt ** k * (1.0 - MARGIN)
                                    for k, bound in ((1, limits.velocity),
                                                     (2, limits.acceleration),
                                                     (3, limits.jerk)))
    otg, inp, profile = Ruckig(1, 1.0), InputParameter(1), Profile(1)
    inp.current_position, inp.target_position = [0.0], [1.0]
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = [velocity], [acceleration], [jerk]
    inp.duration_discretization = DurationDiscretization.Discrete
    try:
        if otg.calculate(inp, profile) not in (Result.Working, Result.Finished):
            return None
    except ValueError:   # a result the binding does not name: a duration past ruckig's range
        return None
    cycles = max(1, int(math.ceil(profile.duration - 1e-9)))
    if cycles * dt > max_duration:
        raise PlanningError("TOO_LONG", f"the motion would last {cycles * dt:.4g} s, longer "
                            f"than the {max(max_duration, 0.0):.4g} s allowed", index=0)
    states = sampled(profile, cycles)
    s, rate = states[:, 0], states[:, 1]
    s[0], s[-1], rate[0], rate[-1] = 0.0, 1.0, 0.0, 0.0   # exact ends, at rest
    positions = q0 + s[:, None] * (q1 - q0)
    velocities = (rate / dt)[:, None] * (q1 - q0)
    return Trajectory(dt, positions, velocities, ((0, 0), (cycles, 1)))

"""Playback's stop and restart along a trajectory (playback.py), without a controller."""
from __future__ import annotations

import numpy as np
import pytest

from landscape.server.cycle.playback import Motion
from landscape.server.planning.motion.timing import time_path
from landscape.server.planning.motion.trajectory import Limits
from landscape.robot.arm import arm_model

DT = 0.004
TOL = 1e-6   # relative: the acceleration limits hold to rounding
PATHS = {
    "one joint": [[0, 0, 1.5708, 0, 1.5708, 0], [2.5, 0, 1.5708, 0, 1.5708, 0]],
    "all joints": [[0, 0, 1.5708, 0, 1.5708, 0], [2.5, -0.5, 1.0, 1, 1.0, 2]],
    "blended": [[0, 0, 1.5708, 0, 1.5708, 0], [0.3, 0.2, 1.4, 0.5, 1.2, 0.3],
                [1, -0.3, 1.8, -1, 1.6, 1], [2, 0, 1.0, 0, 0.8, 0]],
    "issue 8": [[-1.2, -0.2, 1.9, 0.4, 1.1, -0.5], [1.3, 0.3, 1.4, -0.8, 0.7, 1.2]],
}


def motion(segments, limits: Limits) -> Motion:
    return Motion({"id": "m", "acceleration": limits.acceleration, "jerk": limits.jerk,
                   "segments": [{"positions": t.positions, "velocities": t.velocities}
                                for t in segments]}, DT)


def play(m: Motion, commands: dict[int, str], max_cycles: int):
    """The positions and velocities the executor commands, cycle by cycle, as Executor._play
    does (segments back to back, held at rest before and after); commands: cycle -> "stop",
    "resume" or "restart" (resume as soon as the rate reaches 0)."""
    positions = [m.position()] * 3                      # at rest before the start
    velocities = [np.zeros(6)] * 3
    restart = False
    for cycle in range(max_cycles):
        what = commands.get(cycle)
        if what == "stop":
            m.stop()
        elif what == "resume":
            m.resume()
        elif what == "restart":
            m.stop()
            restart = True
        if restart and m.rate == 0.0 and m.target_rate == 0.0:
            m.resume()
            restart = False
        m.advance()
        if m.s >= m.last and not m.next_segment():
            positions += [m.position()] * 3            # held at the end
            velocities += [np.zeros(6)] * 3
            return np.array(positions), np.array(velocities)
        positions.append(m.position())
        velocities.append(m.velocity())
    raise AssertionError("the motion did not end")


def assert_within(limits: Limits, positions, velocities, where):
    accel = np.abs(np.diff(positions, 2, axis=0)) / DT**2
    ratio = (accel / limits.acceleration).max(axis=0)
    assert np.all(ratio <= 1 + TOL), (where, "position second difference / limit", ratio)
    vel_accel = np.abs(np.diff(velocities, axis=0)) / DT
    assert np.all(vel_accel <= limits.acceleration * (1 + TOL)), (where, vel_accel.max(axis=0))
    jerk = np.abs(np.diff(positions, 3, axis=0)) / DT**3
    ratio = (jerk / limits.jerk).max(axis=0)
    assert np.all(ratio <= 1 + TOL), (where, "position third difference / jerk limit", ratio)


@pytest.mark.parametrize("name", PATHS)
@pytest.mark.parametrize("speed, accel", [(60, 50), (100, 100)])
def test_stopping_and_restarting_anywhere_stays_on_the_path_within_the_limits(name, speed, accel):
    limits = Limits.scaled(arm_model(), speed, accel)
    trajectory = time_path(np.array(PATHS[name], dtype=float), limits, DT)
    for stop_at in range(3, len(trajectory) - 3, 7):
        m = motion([trajectory], limits)
        positions, velocities = play(m, {stop_at: "restart"}, 20 * len(trajectory))
        assert_within(limits, positions, velocities, stop_at)
        assert np.allclose(positions[-1], trajectory.positions[-1])   # it went on to the end
        assert min(np.abs(velocities[2 + stop_at:]).sum(axis=1)) < 1e-9  # it did stop


@pytest.mark.parametrize("name", PATHS)
def test_stop_then_resume_later_keeps_every_cycle_within_the_limits(name):
    """Issue 8 item 6: StopMotion 0.1 s after the start, ResumeMotion 0.1 s later, at 100 %."""
    limits = Limits.scaled(arm_model(), 100, 100)
    trajectory = time_path(np.array(PATHS[name], dtype=float), limits, DT)
    for stop_at, resume_at in ((25, 50), (10, 30), (40, 47), (60, 61)):
        m = motion([trajectory], limits)
        positions, velocities = play(m, {stop_at: "stop", resume_at: "resume"},
                                     20 * len(trajectory))
        assert_within(limits, positions, velocities, (stop_at, resume_at))
        assert np.allclose(positions[-1], trajectory.positions[-1])


def test_segments_back_to_back_with_stops_keep_within_the_limits():
    """A run of several segments (as paths send them), stopped and restarted across their joins."""
    limits = Limits.scaled(arm_model(), 100, 100)
    points = np.array(PATHS["blended"], dtype=float)
    segments = [time_path(points[i:i + 2], limits, DT) for i in range(len(points) - 1)]
    total = sum(len(t) for t in segments)
    joins = np.cumsum([len(t) - 1 for t in segments])[:-1]
    for stop_at in [*range(3, total - 3, 13), *(joins - 2), *(joins - 1)]:
        m = motion(segments, limits)
        positions, velocities = play(m, {int(stop_at): "restart"}, 20 * total)
        assert_within(limits, positions, velocities, stop_at)
        assert np.allclose(positions[-1], points[-1])


def test_the_planned_trajectory_itself_keeps_the_position_second_difference_within_the_limits():
    """Played at rate 1 (no stop), the commanded positions are the samples themselves."""
    for name in PATHS:
        for speed, accel in ((60, 50), (100, 100), (100, 10)):
            limits = Limits.scaled(arm_model(), speed, accel)
            trajectory = time_path(np.array(PATHS[name], dtype=float), limits, DT)
            m = motion([trajectory], limits)
            positions, velocities = play(m, {}, 2 * len(trajectory))
            assert_within(limits, positions, velocities, (name, speed, accel))


def test_a_ramps_cycles_are_ruckigs_own_states():
    """ramps.sampled reads a one-DOF ruckig profile at whole cycles from its phases at once:
    the same states as ruckig's at_time, a brake phase and the time past the end included."""
    from ruckig import (ControlInterface, DurationDiscretization, InputParameter, Result,
                        Ruckig, Trajectory)

    from landscape.server.cycle.ramps import sampled
    rng = np.random.default_rng(3)
    otg, inp, trajectory = Ruckig(1, 1.0), InputParameter(1), Trajectory(1)
    braked = 0
    for k in range(400):
        inp.current_position = [rng.uniform(0, 100)]
        inp.current_velocity = [rng.uniform(-0.2, 1.5)]          # beyond 1: a brake phase
        inp.current_acceleration = [rng.uniform(-0.05, 0.05)]
        inp.max_velocity, inp.max_acceleration = [1.0], [rng.uniform(1e-3, 0.1)]
        inp.max_jerk = [rng.uniform(1e-4, 0.05)]
        inp.target_velocity, inp.target_acceleration = [float(rng.choice([0, 0.5, 1]))], [0.0]
        if k % 2:
            inp.control_interface = ControlInterface.Position
            inp.duration_discretization = DurationDiscretization.Discrete
            inp.target_position = [inp.current_position[0] + rng.uniform(1, 50)]
        else:
            inp.control_interface = ControlInterface.Velocity
            inp.duration_discretization = DurationDiscretization.Continuous
        assert otg.calculate(inp, trajectory) in (Result.Working, Result.Finished)
        braked += trajectory.profiles[0][0].brake.duration > 0
        cycles = int(np.ceil(trajectory.duration - 1e-9)) + 2
        theirs = np.array([[v[0] for v in trajectory.at_time(float(t))]
                           for t in range(cycles + 1)])
        assert np.allclose(sampled(trajectory, cycles), theirs, rtol=0, atol=1e-9)
    assert braked > 50

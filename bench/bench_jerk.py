"""Jerk-limited motion (issue 30): what bounded jerk costs in time, beside ruckig, what the
cycle pays for it, and how far a guarded move's force goes past its threshold.

    .venv/bin/python bench/bench_jerk.py [--quick]

Table 1, for a set of moves and paths at 100 % (the TX90's limits, jerk = acceleration /
20 ms): the jerk-limited duration (timing.time_path with limits.jerk) over the jerk-free
optimum (the same TOPP-RA timing without it; goal at most 1.05), and for the point-to-point
joint moves ruckig's time-optimal, time-synchronised duration for the same move and limits,
same run (ruckig leaves the straight joint line where it pays; ours keeps it). The peak jerk
of every sampled trajectory over its limit is printed too (at most 1).

Table 2, the cycle's share: a stop's ramp planned in the cycle (ramps.py: ruckig in the path
parameter and the check of every position it commands), the jog's and the force loops'
trackers (jerk_tracker.py), per call (CPU time), beside the 4 ms cycle.

Table 3 (pybullet on the lock-step clock, a server of its own per speed): a guarded move down
onto the table at 20, 100 and 300 mm/s (--quick: the issue's 100 and 300) with a -20 N
threshold: the peak force the done event reports, and how far past the threshold it went.

Prints the tables; no pass/fail.
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
import time
from pathlib import Path

import bench_planning
import numpy as np
from common import record
from landscape.robot.arm import arm_model
from landscape.robot.kinematics import Kinematics
from landscape.server.cycle.jerk_tracker import PositionTracker, VelocityTracker
from landscape.server.cycle.playback import Motion
from landscape.server.planning.motion.cartesian import arc, straight_line, tool_pose
from landscape.server.planning.motion.timing import time_path
from landscape.server.planning.motion.trajectory import Limits
from ruckig import InputParameter, Ruckig, Trajectory

DT = 0.004
HOME = bench_planning.HOME


def ruckig_time(start, goal, limits: Limits) -> float:
    inp = InputParameter(6)
    inp.current_position, inp.target_position = list(start), list(goal)
    inp.current_velocity = inp.current_acceleration = [0.0] * 6
    inp.target_velocity = inp.target_acceleration = [0.0] * 6
    inp.max_velocity, inp.max_acceleration = list(limits.velocity), list(limits.acceleration)
    inp.max_jerk = list(limits.jerk)
    trajectory = Trajectory(6)
    Ruckig(6).calculate(inp, trajectory)
    return trajectory.duration


def cases(arm):
    kin = Kinematics(arm)
    full = Limits.scaled(arm, 100, 100)
    rows = [("joint move, all joints", np.array([HOME, HOME + [2.0, -0.5, 0.6, 1.5, -0.8, 2.5]]),
             full, None),
            ("joint move, 1 joint 1.5 rad", np.array([HOME, HOME + [1.5, 0, 0, 0, 0, 0]]),
             full, None),
            ("joint move, short", np.array([HOME, HOME + [0.1, -0.05, 0.06, 0.15, -0.08, 0.25]]),
             full, None),
            ("joint move, 50 %", np.array([HOME, HOME + [2.0, -0.5, 0.6, 1.5, -0.8, 2.5]]),
             Limits.scaled(arm, 50, 50), None)]
    for n in (10, 20, 100):
        W, _ = bench_planning.reachable_walk(arm, n, full, 0)
        rows.append((f"blended path, {n} points", W, full, None))
    q0, goal, tcp = bench_planning.line_path(kin)
    line = straight_line(kin, q0, goal, tcp=tcp)
    for speed in (0.25, 2.0):
        rows.append((f"line 0.5 m, {speed:g} m/s", line,
                     Limits.scaled(arm, 100, 100, linear_velocity=speed), tool_pose(kin, tcp)))
    via, end = goal.copy(), goal.copy()
    via[:3, 3] += [-0.15, -0.15, 0.0]
    end[:3, 3] += [-0.3, 0.0, 0.0]
    rows.append(("arc r 0.15 m", arc(kin, line[-1], via, end, tcp=tcp), full,
                 tool_pose(kin, tcp)))
    return rows


def timing_table(arm) -> None:
    print(f"{'motion':<30} {'jerk-free s':>11} {'jerk s':>8} {'ratio':>7} {'ruckig s':>9} "
          f"{'vs ruckig':>9} {'peak jerk':>9} {'plan ms':>8}")
    for name, W, limits, tool in cases(arm):
        free = time_path(W, dataclasses.replace(limits, jerk=None), DT, tool_path=tool)
        start = time.thread_time()
        timed = time_path(W, limits, DT, tool_path=tool)
        planning = time.thread_time() - start
        held = np.concatenate([timed.positions[:1]] * 3 + [timed.positions]
                              + [timed.positions[-1:]] * 3)
        peak = float((np.abs(np.diff(held, 3, axis=0)).max(axis=0) / DT**3 / limits.jerk).max())
        ratio = timed.duration / free.duration
        extra = ""
        if name.startswith("joint move"):
            theirs = ruckig_time(W[0], W[-1], limits)
            extra = f"{theirs:>9.3f} {timed.duration / theirs:>9.3f}"
            record(f"jerk-limited time over ruckig's, {name}", timed.duration / theirs, "x",
                   baseline=theirs, baseline_name="ruckig, s")
        record(f"jerk-limited time over jerk-free, {name}", ratio, "x", goal=1.05)
        print(f"{name:<30} {free.duration:>11.3f} {timed.duration:>8.3f} {ratio:>7.3f} "
              f"{extra:>19} {peak:>9.4f} {planning * 1e3:>8.1f}")


def cycle_table(arm) -> None:
    limits = Limits.scaled(arm, 100, 100)
    timed = time_path(np.array([HOME, HOME + [2.0, -0.5, 0.6, 1.5, -0.8, 2.5]]), limits, DT)
    costs = []
    for at in range(20, len(timed) - 20, 7):
        motion = Motion({"id": "m", "acceleration": limits.acceleration, "jerk": limits.jerk,
                         "segments": [{"positions": timed.positions,
                                       "velocities": timed.velocities}]}, DT)
        for _ in range(at):
            motion.advance()
        motion.stop()
        start = time.thread_time()
        motion.advance()         # plans (and checks) the ramp, or tries again next cycle
        costs.append(time.thread_time() - start)
    a, j, v = (np.asarray(x) for x in (arm.max_acceleration, arm.max_jerk, arm.max_velocity))
    jog, follow = VelocityTracker(np.array(HOME), DT), PositionTracker(np.array(HOME), DT)
    jog_costs, follow_costs = [], []
    for k in range(500):
        start = time.thread_time()
        jog.step(np.full(6, 0.5 if k < 250 else 0.0), a, j)
        jog_costs.append(time.thread_time() - start)
        start = time.thread_time()
        follow.step(np.array(HOME) + 0.01 * np.sin(k * DT), np.zeros(6), v, a, j)
        follow_costs.append(time.thread_time() - start)
    print(f"\n{'in the cycle':<40} {'p50 us':>8} {'p99 us':>8}   (the cycle: 4,000 us)")
    for name, values in (("a stop's ramp, planned and checked", costs),
                         ("jog tracker, per cycle", jog_costs),
                         ("force loop tracker, per cycle", follow_costs)):
        p50, p99 = (float(np.percentile(values, q)) * 1e6 for q in (50, 99))
        record(f"cycle cost p99, {name}", p99, "us", baseline=4000, baseline_name="the cycle")
        print(f"{name:<40} {p50:>8.0f} {p99:>8.0f}")


def guarded_table(speeds) -> None:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from landscape.v1 import sensing_pb2, types_pb2
    from support import Arm  # the tests' harness: lock-step server, lock, events
    print(f"\n{'guarded move, -20 N':<24} {'peak fz N':>10} {'past threshold N':>17}")
    for mm_per_s in speeds:
        with tempfile.TemporaryDirectory() as folder:
            arm = Arm(Path(folder))
            try:
                arm.get_tool("vacuum")
                arm.move_down_to(0.65, 0.3, 0.26)
                reply = arm.device.MoveReact(sensing_pb2.MoveReactRequest(
                    sensor_type="force_sensor", motion=types_pb2.Vector3(z=0.1),
                    speed=mm_per_s / 20, thresholds=types_pb2.Vector3(z=-20.0)), timeout=30)
                message = arm.wait_command(reply.ret_val.command_id)[-1].command.message
            finally:
                arm.close()
        # The done event says it: "...; peak (fx, fy, fz) N".
        peak = float(message.split("peak (")[1].split(")")[0].split(", ")[2])
        record(f"guarded move peak force past -20 N, {mm_per_s} mm/s", -20.0 - peak, "N")
        print(f"{mm_per_s:>4} mm/s {'':<14} {peak:>10.1f} {-20.0 - peak:>17.1f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help="the guarded moves at 100 and 300 mm/s only")
    args = parser.parse_args()
    arm = arm_model()
    print(f"TX90 at 100 %: jerk limits {np.round(arm.max_jerk).tolist()} rad/s^3 "
          f"(acceleration / 20 ms)\n")
    timing_table(arm)
    cycle_table(arm)
    guarded_table((100, 300) if args.quick else (20, 100, 300))


if __name__ == "__main__":
    main()

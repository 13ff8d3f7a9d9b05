"""Kinematics figures: closed-form IK (one pose and batched), pinocchio DLS IK, forward kinematics.

    .venv/bin/python bench/bench_kinematics.py [--poses 1000] [--variant TX90] [--seed 0]

Random in-range joint vectors give the poses; every IK starts from the same q_near (the true
joints plus up to +-0.2 rad of noise per joint), so both IKs solve the same problems in the same
run. Prints a table beside the same-run baseline, pinocchio's forward kinematics; no pass/fail.
Times are this thread's CPU time, the best of a few repeats (the numeric IK: one run).
"""
from __future__ import annotations

import argparse
import time

import numpy as np
from common import record

from landscape.robot.arm import VARIANTS, arm_model
from landscape.robot.kinematics import Kinematics, ReversingResult, wrap_angle
from landscape.robot.pinocchio_model import PinocchioModel


def best_time(fn, repeat: int = 3) -> float:
    """Smallest CPU time of this thread (s) of `repeat` calls of fn(): on a machine shared with
    other work the wall time also counts the waits for a core."""
    times = []
    for _ in range(repeat):
        start = time.thread_time()
        fn()
        times.append(time.thread_time() - start)
    return min(times)


def dls_run(pin_model, poses, seeds, step):
    """(seconds, iterations (N,), converged (N,), solutions (N, 6)) of pinocchio's DLS IK."""
    results, iterations, converged = [], [], []
    start = time.thread_time()
    for pose, seed in zip(poses, seeds):
        q, ok, it = pin_model.ik_dls(pose, seed, tol=1e-10, step=step)
        results.append(q)
        iterations.append(it)
        converged.append(ok)
    return time.thread_time() - start, np.array(iterations), np.array(converged), np.array(results)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--poses", type=int, default=1000)
    parser.add_argument("--variant", default="TX90", choices=sorted(VARIANTS))
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    n = args.poses

    arm = arm_model(args.variant)
    kin, pin_model = Kinematics(arm), PinocchioModel(arm)
    rng = np.random.default_rng(args.seed)
    Q = rng.uniform(arm.lower, arm.upper, (n, 6))
    poses = kin.forward(Q)
    seeds = np.clip(Q + rng.uniform(-0.2, 0.2, (n, 6)), arm.lower, arm.upper)
    rows = []   # (what, microseconds per pose, note)

    # Closed form, one pose per call (the LLI_reverseKin path).
    closed = [kin.reverse(T, s) for T, s in zip(poses, seeds)]
    found = sum(code == ReversingResult.OK and np.allclose(q, q0, atol=1e-9)
                for (q, code), q0 in zip(closed, Q))
    t = best_time(lambda: [kin.reverse(T, s) for T, s in zip(poses, seeds)])
    rows.append(("closed-form reverse(), 1 pose/call", t / n,
                 f"{found}/{n} the original joints, the rest a solution nearer q_near"))
    t = best_time(lambda: [kin.solutions(T) for T in poses])
    rows.append(("closed-form solutions(), all 8", t / n, ""))

    # Pinocchio damped least squares from the same q_near, to |log6 error| < 1e-10.
    closed_q = np.array([q if q is not None else np.full(6, np.nan) for q, _ in closed])
    found_ok = ~np.isnan(closed_q[:, 0])
    for step, m in ((1.0, n), (0.1, min(n, 100))):
        t, its, ok, sols = dls_run(pin_model, poses[:m], seeds[:m], step)
        same = np.all(np.abs(wrap_angle(sols - closed_q[:m])) < 1e-8, axis=1)
        rows.append((f"pinocchio DLS IK, step {step:g}", t / m,
                     f"{ok.sum()}/{m} converged, {its[ok].mean():.1f} iterations on average, "
                     f"{same.sum()}/{m} same joints as closed form"))

    # Closed form, vectorised.
    t = best_time(lambda: kin.solve_batch(poses))
    rows.append((f"closed-form solve_batch(), {n} poses", t / n, "all 8 branches per pose"))

    # Forward kinematics.
    t = best_time(lambda: [kin.forward(q) for q in Q])
    rows.append(("forward(), 1 pose/call", t / n, ""))
    t = best_time(lambda: kin.forward(Q))
    rows.append((f"forward(), batch of {n}", t / n, ""))
    t = best_time(lambda: [pin_model.forward(q) for q in Q])
    rows.append(("pinocchio forward, 1 pose/call", t / n, "framesForwardKinematics"))

    # The same-run baseline: pinocchio's forward kinematics (C++), what a pose costs at best.
    baseline = rows[-1][1]
    print(f"{arm.name} kinematics, {n} random in-range poses (seed {args.seed}); CPU time of "
          f"this thread, best of 3\n")
    width = max(len(r[0]) for r in rows)
    print(f"{'':{width}}  {'us/pose':>10}  {'x pin FK':>8}  {'poses/s':>11}  notes")
    for what, seconds, note in rows:
        print(f"{what:{width}}  {seconds * 1e6:10.2f}  {seconds / baseline:8.2f}  "
              f"{1.0 / seconds:11,.0f}  {note}")
    record("IK, one pose (reverse)", rows[0][1] * 1e6, "us", baseline=baseline * 1e6,
           baseline_name="pinocchio FK", goal=15.0)
    batch = next(r for r in rows if "solve_batch" in r[0])
    record("IK, batched, per pose", batch[1] * 1e6, "us", baseline=baseline * 1e6,
           baseline_name="pinocchio FK", goal=4.0)
    errors = np.abs(kin.forward(closed_q[found_ok]) - poses[found_ok]).max()
    print(f"\nclosed form exact to {errors:.1e} (largest pose element error of reverse()'s "
          f"joints); goals (issue 18): reverse() <= 15 us, solve_batch() <= 4 us a pose")


if __name__ == "__main__":
    main()

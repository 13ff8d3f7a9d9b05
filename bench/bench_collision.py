"""Collision checking figures: whole trajectories against the default cell, beside their planning.

    .venv/bin/python bench/bench_collision.py [--repeat 7] [--seed 0] [--margin 0.005]

Motions (the default cell, TX90, the gripper mounted, dt = 4 ms), each planned by time_path
(server/motion/timing.py) as the server plans them:

- "cycle 10 s": a pick-and-place cycle of 14 waypoints above the table and the rack, stopping
  where the tool goes down to a part (fingers 2 cm above the table), at the speed that makes
  it last 10 s; clear, so every pair is checked to the end.
- "path 100": 100 random waypoints in the free space over the table and beside it (flange
  pointing down, 0.55 to 0.75 m high: the blended spline stays clear of the parts), blended,
  at 100 % speed; clear (the bench fails otherwise), so the whole path is checked.
- "through table": one joint move whose straight joint line sweeps the tool through the table:
  found, and how soon.
- "path 100 x 1000": that path loaded into a device server (lock-step clock, bare flange) and
  its PathMove of 1000 cycles checked as the server checks it (each distinct piece once,
  the part poses read from the world first), beside the same run of 1 cycle.

For each: samples, duration, the check time (best and median of --repeat) with its counts
(configurations placed and exact coal distances in the narrow phase; sphere/box bounds in the
broad phase; the exact distances are recorded too, beside the baseline's), and in the same run
the planning time of the same motion (time_path, best of --repeat) and a baseline check:
pinocchio's computeCollisions with every pair at every 4 ms sample (security margin = the
margin; it gives no guarantee between samples). Then clearance(q) at the motion's samples, per
call, and how long the scene takes to compile after a change.

Prints the table; no pass/fail.
"""
from __future__ import annotations

import argparse
import math
import statistics
import time

import grpc
import numpy as np
from common import record
import pinocchio as pin

from bench_planning import timed   # bench/ is on the path when a benchmark runs
from landscape.client import Session
from landscape.server.planning import path_planning
from landscape.server.app import serve
from landscape.server.planning.collision import CollisionScene, check_motion, clearance
from landscape.server.config import ServerConfig
from landscape.server.planning.motion.timing import time_path
from landscape.server.planning.motion.trajectory import Limits
from landscape.robot.units import pose_matrix
from landscape.robot.cell import load_cell
from landscape.robot.kinematics import Kinematics
from landscape.v1 import control_pb2, device_service_pb2_grpc, motion_pb2, types_pb2

DT = 0.004
DOWN = (np.pi, 0.0, 0.0)


class Cell:
    def __init__(self, margin: float):
        self.cell = load_cell()
        self.kin = Kinematics(self.cell.arm)
        self.scene = CollisionScene(self.cell, margin)
        self.scene.mount_tool("gripper")
        self.q0 = np.array(self.cell.controller.initial_position)

    def ik(self, xyz, near) -> np.ndarray:
        """Joints putting the flange at xyz (m), pointing down, nearest `near`."""
        q, result = self.kin.reverse(pose_matrix(xyz, DOWN), near)
        if q is None:
            raise RuntimeError(f"{xyz} unreachable: {result.name}")
        return q

    def chain(self, points) -> np.ndarray:
        out = [self.q0]
        for p in points:
            out.append(self.ik(p, out[-1]))
        return np.array(out)


def cycle(c: Cell) -> tuple[np.ndarray, np.ndarray]:
    """A pick-and-place cycle: waypoints (M, 6) and stops (M,)."""
    above, low = 0.55, 0.2 + 0.02 + 0.16     # flange heights: clear / fingers 2 cm up
    pts = [(0.5, -0.15, above), (0.5, -0.15, low), (0.5, -0.15, above),
           (0.73, 0.1, above), (0.73, 0.1, low + 0.02), (0.73, 0.1, above),
           (0.3, -0.45, 0.7), (0.0, -0.45, 0.75), (0.3, -0.45, 0.7),
           (0.5, 0.15, above), (0.5, 0.15, low), (0.5, 0.15, above), (0.45, 0.0, 0.7)]
    W = c.chain(pts)
    stops = np.zeros(len(W), dtype=bool)
    stops[[0, 2, 5, 11, len(W) - 1]] = True
    return W, stops


def free_path(c: Cell, n: int, rng) -> np.ndarray:
    """n waypoints over and beside the table, flange down, each reachable from the last; high
    enough that the blended spline between them stays clear of the parts on the table."""
    out = [c.q0]
    while len(out) < n:
        xyz = (rng.uniform(0.3, 0.7), rng.uniform(-0.4, 0.4), rng.uniform(0.55, 0.75))
        q, _ = c.kin.reverse(pose_matrix(xyz, DOWN), out[-1])
        if q is not None:
            out.append(q)
    return np.array(out)


def ten_seconds(c: Cell, W: np.ndarray, stops: np.ndarray) -> Limits:
    """The limits (percent speed, 100 % acceleration) under which the cycle lasts 10 s."""
    lo, hi = 1.0, 100.0
    for _ in range(30):
        mid = (lo + hi) / 2
        if time_path(W, Limits.scaled(c.cell.arm, mid, 100), DT, stops=stops).duration > 10.0:
            lo = mid
        else:
            hi = mid
    return Limits.scaled(c.cell.arm, hi, 100)


def compile_times(c: Cell) -> list[tuple[str, float]]:
    """(change, ms to compile the scene's model after it): the scene follows the world."""
    scene = c.scene
    changes = [("unmount", scene.unmount_tool), ("mount", lambda: scene.mount_tool("gripper")),
               ("attach", lambda: scene.attach_part("block_1", q=c.q0)),
               ("release", lambda: scene.release_part(c.q0))]
    out = []
    for name, change in changes:
        change()
        start = time.perf_counter()
        scene.model()
        out.append((name, (time.perf_counter() - start) * 1e3))
    return out


def path_run(W: np.ndarray, margin: float, repeat: int) -> dict[int, tuple[list[float], object]]:
    """The check a device server makes before PathMove runs the path through W, for 1000
    cycles and for 1: {cycles: (CPU times of `repeat` checks, the last one's counts)}."""
    server = serve(ServerConfig(port=0, clock="lockstep", collision_margin=margin))
    try:
        with grpc.insecure_channel(server.target) as channel, \
                Session(channel, "bench") as session:
            session.lock()
            device = device_service_pb2_grpc.DeviceServiceStub(session.channel)
            device.Activate(control_pb2.ActivateRequest(), timeout=10)
            header = motion_pb2.PathHeader(
                path_name="p", frame=types_pb2.REFERENCE_FRAME_JOINT_FRAME,
                motion_type=types_pb2.MOTION_TYPE_JOINT_MOTION,
                offset_type=types_pb2.OFFSET_TYPE_ABSOLUTE_DATA)
            tags = [types_pb2.TagStruct(joint_values=list(q), transition_speed=50) for q in W]
            device.PathLoad(iter([motion_pb2.PathLoadRequest(header=header, tags=tags)]),
                            timeout=60)
            motions, paths, out = server.device.motions, server.device.path_runs.paths, {}
            for cycles in (1000, 1):
                run = path_planning.plan_run(motions.planner, paths.get("p"),
                                             motions.planning_start(), server.device.settings,
                                             cycles)
                out[cycles] = timed(lambda: motions.check_collisions(run), repeat)
            device.Deactivate(control_pb2.DeactivateRequest(), timeout=10)
    finally:
        server.stop(grace=None)
    return out


def baseline(model, Q: np.ndarray, margin: float) -> int:
    """Every sample, every pair, in pinocchio (C++); the number of samples within the margin."""
    data, gdata = model.pin_model.createData(), pin.GeometryData(model.geom_model)
    for request in gdata.collisionRequests:
        request.security_margin = margin
    return sum(pin.computeCollisions(model.pin_model, data, model.geom_model, gdata, q, True)
               for q in Q)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=7)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--margin", type=float, default=0.005)
    args = parser.parse_args()

    c = Cell(args.margin)
    model = c.scene.model()
    W, stops = cycle(c)
    full = Limits.scaled(c.cell.arm, 100, 100)
    cases = [("cycle 10 s", W, stops, ten_seconds(c, W, stops)),
             ("path 100", free_path(c, 100, np.random.default_rng(args.seed)), None, full),
             ("through table", np.array([c.ik((0.6, -0.55, 0.3), c.q0),
                                         c.ik((0.6, 0.55, 0.3), c.q0)]), None, full)]

    rows, clearance_times = [], []
    for name, W, stops, limits in cases:
        plan, traj = timed(lambda: time_path(W, limits, DT, stops=stops), args.repeat)
        Q = traj.positions
        check, result = timed(lambda: check_motion(model, Q, DT, traj.marks), args.repeat)
        base, within = timed(lambda: baseline(model, Q, args.margin), 1)
        rows.append({"motion": name, "M": len(W), "samples": len(Q), "dur s": traj.duration,
                     "check": min(check) * 1e3, "median": statistics.median(check) * 1e3,
                     "configs": result.configurations, "exact": result.pair_checks,
                     "bounds": result.bound_checks, "plan": min(plan) * 1e3,
                     "baseline": min(base) * 1e3,
                     "found": f"{result.contact or 'clear'}; baseline: {within} samples "
                              "within the margin"})
        record(f"collision check, {name}", min(check) * 1e3, "ms", baseline=min(plan) * 1e3,
               baseline_name="planning it", goal=20.0 if name.startswith("cycle 10") else None)
        record(f"collision check, {name}: exact distances", result.pair_checks, "pair checks",
               baseline=len(Q) * len(model.pairs), baseline_name="every pair at every sample")
        if name != "through table" and not result.clear:
            raise SystemExit(f"{name} is meant to be clear: {result.contact}")
        sample = Q[:: max(1, len(Q) // 200)]
        per_call = []
        for limit in (math.inf, 0.05):
            start = time.perf_counter()
            for q in sample:
                clearance(model, q, limit=limit)
            per_call.append((time.perf_counter() - start) / len(sample) * 1e6)
        clearance_times.append(f"{name} {per_call[0]:.0f} ({per_call[1]:.0f} within 5 cm)")

    runs = path_run(cases[1][1], args.margin, args.repeat)
    (many, many_result), (one, one_result) = runs[1000], runs[1]
    record("collision check, path 100 x 1000 cycles", min(many) * 1e3, "ms",
           baseline=min(one) * 1e3, baseline_name="1 cycle")
    record("collision check, path 100 x 1000 cycles: exact distances", many_result.pair_checks,
           "pair checks", baseline=one_result.pair_checks, baseline_name="1 cycle")

    print(f"Collision checks, default cell, gripper mounted, margin {args.margin * 1e3:.1f} mm, "
          f"{len(model.geometries)} shapes, {len(model.pairs)} pairs, dt = {DT * 1e3:.0f} ms\n")
    columns = [("motion", "<14", ""), ("M", ">4", ""), ("samples", ">7", ""),
               ("dur s", ">6", ".2f"), ("check", ">7", ".2f"), ("median", ">7", ".2f"),
               ("configs", ">7", ""), ("exact", ">6", ""), ("bounds", ">7", ""),
               ("plan", ">7", ".2f"), ("baseline", ">9", ".1f")]
    head = " ".join(format(key, align) for key, align, _ in columns)
    print(head + "\n" + "-" * len(head) + "   (ms)")
    for row in rows:
        print(" ".join(format(format(row[key], fmt), align) for key, align, fmt in columns))
    print()
    for row in rows:
        print(f"{row['motion']:<14} {row['found']}")
    print(f"\npath 100 run by a device server (bare flange), PathMove's check: 1000 cycles "
          f"{min(many) * 1e3:.2f} ms ({many_result.pair_checks} exact), 1 cycle "
          f"{min(one) * 1e3:.2f} ms ({one_result.pair_checks} exact)")
    print("clearance(q), us per call: " + ", ".join(clearance_times))
    print("model compile after a change, ms: " + ", ".join(
        f"{name} {ms:.1f}" for name, ms in compile_times(c)))
    print("\ncheck: check_motion; exact: coal distances; bounds: broad-phase bounds; plan: "
          "time_path of the same\nwaypoints; baseline: computeCollisions at every sample "
          "with all pairs (no guarantee between samples).")


if __name__ == "__main__":
    main()

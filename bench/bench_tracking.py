"""How closely the simulated arm follows what the device server commands.

Runs moves through a real device server (gRPC on loopback, lock-step clock, pybullet arm) at
full set speed, records every cycle with the controller's recorder, and prints the worst joint
following error and tool-tip tracking error (commanded vs measured tip), next to the baseline
of the same run: how far the commanded tip itself strays from the ideal line (planning error).

    python bench/bench_tracking.py
"""
from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from common import record

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from support import Arm  # noqa: E402  (the tests' harness: server, lock, recorder)

from landscape.v1 import motion_pb2, settings_pb2, types_pb2  # noqa: E402

BASE = types_pb2.REFERENCE_FRAME_BASE_CARTESIAN_FRAME
JOINT = types_pb2.REFERENCE_FRAME_JOINT_FRAME


def run(arm: Arm, start_call) -> dict:
    arm.record_start()
    t0 = time.perf_counter()
    reply = start_call()
    arm.wait_command(reply.ret_val.command_id)
    wall = time.perf_counter() - t0
    _, data = arm.recorded_tips()
    cmd_tip = arm.kin.forward(data["cmd_pos"])[:, :3, 3]
    fbk_tip = arm.kin.forward(data["fbk_pos"])[:, :3, 3]
    return {"cycles": len(data["t"]), "wall": wall, "cmd_tip": cmd_tip, "fbk_tip": fbk_tip,
            "joint_error": np.abs(data["cmd_pos"] - data["fbk_pos"]).max(),
            "tip_error": np.linalg.norm(cmd_tip - fbk_tip, axis=1).max()}


def line_deviation(points, a, b) -> float:
    d = (b - a) / np.linalg.norm(b - a)
    rel = points - a
    return float(np.linalg.norm(rel - np.outer(rel @ d, d), axis=1).max())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="accepted for the report; the "
                        "run is short already (lock-step clock)")
    parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        arm = Arm(Path(tmp))
        try:
            arm.device.SetSpeed(settings_pb2.SetSpeedRequest(
                speed=100, attribute=types_pb2.SPEED_TYPE_PERCENT_SPEED))
            arm.device.SetAcceleration(settings_pb2.SetAccelerationRequest(
                accel=100, attribute=types_pb2.ACCEL_TYPE_PERCENT_ACCEL))
            rows = []
            joint = run(arm, lambda: arm.device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
                frame=JOINT, values=[1.2, 0.3, 1.2, 0.5, 1.0, -0.8])))
            rows.append(("joint move, 100 %", joint, None))
            arm.device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
                frame=JOINT, values=[0, 0, math.pi / 2, 0, math.pi / 2, 0]))
            time.sleep(0.5)
            start = arm.tip()[:3, 3]
            line = run(arm, lambda: arm.device.MoveRelative(motion_pb2.MoveRelativeRequest(
                frame=BASE, values=[0, 0.5, 0, 0, 0, 0],
                motion_type=types_pb2.MOTION_TYPE_STRAIGHT_MOTION)))
            goal = start + [0, 0.5, 0]
            rows.append(("straight 0.5 m, 2 m/s cap", line,
                         (line_deviation(line["cmd_tip"], start, goal),
                          line_deviation(line["fbk_tip"], start, goal))))
        finally:
            arm.close()
    print(f"{'motion':28} {'cycles':>7} {'wall s':>7} {'joint err rad':>14} {'tip err mm':>11} "
          f"{'line dev cmd mm':>16} {'line dev meas mm':>17}")
    for name, r, dev in rows:
        cmd, meas = (f"{dev[0] * 1000:.4f}", f"{dev[1] * 1000:.4f}") if dev else ("-", "-")
        print(f"{name:28} {r['cycles']:7d} {r['wall']:7.2f} {r['joint_error']:14.2e} "
              f"{r['tip_error'] * 1000:11.4f} {cmd:>16} {meas:>17}")
        record(f"tracking: tip error, {name}", r["tip_error"] * 1000, "mm")
    record("straight line: measured deviation", rows[1][2][1] * 1000, "mm",
           baseline=rows[1][2][0] * 1000, baseline_name="commanded")
    print("tip err: commanded vs measured tool tip, worst cycle; line dev cmd: the planner's own "
          "deviation (baseline); line dev meas: the arm's.")


if __name__ == "__main__":
    main()

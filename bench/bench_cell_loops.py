"""What issue 10's per-cycle work costs the cycle: the Executor's time per cycle in each mode.

    python bench/bench_cell_loops.py [--cycles 2000]

The real BulletController (default cell, vacuum cup on the flange) stepped in a plain loop;
the time of the cyclic function alone (the Executor: messages, sensors, I/O, setpoint, ring
row) is measured with perf_counter, and the whole step (physics included) beside it:

  bare executor       the Executor with sensor and I/O reading and the model torques taken
                      out: the cost before issue 10 (same-run baseline)
  holding             what every cycle pays while a reader watches the rows (a state stream;
                      always on the real-time clock): the force/torque sensor, the range
                      sensor every 5th cycle, the I/O image of the end effector's signals,
                      the model torques (pinocchio's RNEA with the payload)
  holding, unwatched  the same with nobody watching the rows: no sensor, no model torques
                      (what the fast clock pays running a program, issue 31 item 5)
  + guarded move      a moveReact's threshold monitor on a straight move
  + comply            the admittance loop (pinocchio Jacobian and pose, a damped solve)
  + Cartesian jog     jog integration with its reference pose (pinocchio, a damped solve)
  + I/O watch         a signalDigitalIO watch polling unit 1 (zones: a look at the world)

and, alone, the model torques' share of every cycle (the Executor's acceleration and RNEA, on
the same controller's feedback, in a tight loop: less disturbed by a busy machine).

Prints figures (microseconds, p50 / p99 / max), decides nothing; the 4 ms cycle is the budget.
"""
from __future__ import annotations

import argparse
import math
import time

import numpy as np
from common import record

from landscape.server.cycle.arm_dynamics import ArmDynamics, tool_payload
from landscape.server.cycle.cycle_record import CycleRecord
from landscape.server.cycle.executor import Executor
from landscape.server.cycle.run_arrays import pack_run
from landscape.server.cycle.feedback import FeedbackRing
from landscape.server.cycle.force_loops import ComplySpec, GuardSpec
from landscape.server.cycle.jog_integrator import MANUAL_TIP_SPEED, JogLimits
from landscape.server.planning.moves import Planner
from landscape.server.device.motion_settings import MotionSettings
from landscape.server.planning.targets import Frame
from landscape.sim.bullet_controller import BulletController
from landscape.robot.cell import load_cell
from landscape.robot.controller import EnableState, JointFbk
from landscape.server.cycle.process import Mailbox
from landscape.robot.kinematics import Kinematics
from landscape.server.cycle.shared_array import SharedArrays

CUP = np.eye(4)
CUP[2, 3] = 0.12


class _Nothing:
    """Stands in for the sensor and I/O readers: the executor before issue 10."""

    values = np.full(7, math.nan)
    image = np.full(4, math.nan)
    watch_range = False

    def read(self, *args):
        return self.values

    def poll(self, *args):
        pass

    def handle(self, msg):
        pass


def _controller(bare: bool, watched: bool = True):
    cell = load_cell()
    mailbox = Mailbox()
    parts = {"sensors": _Nothing(), "io": _Nothing(), "model_torques": False} if bare else {}
    ring = FeedbackRing()
    if watched:
        ring.watch()
    executor = Executor(mailbox, cell.controller.cycle_time, ring, cell.arm, **parts)
    timed = []

    def cyclic(ctrl):
        start = time.perf_counter()
        ok = executor(ctrl)
        timed.append(time.perf_counter() - start)
        return ok
    ctrl = BulletController(cell, cyclic)
    ctrl.init()
    ctrl.enable()
    while ctrl.state().enable is not EnableState.ENABLED:
        ctrl.step()
    ctrl.dio.write("toolchanger_lock", True)   # nothing at the flange: the lock closes on air
    mailbox.outbox.clear()
    return ctrl, mailbox, timed


def _run(ctrl, timed, cycles: int, each=None) -> tuple[np.ndarray, np.ndarray]:
    timed.clear()
    steps = []
    for k in range(cycles):
        if each is not None:
            each(k)
        start = time.perf_counter()
        ctrl.step()
        steps.append(time.perf_counter() - start)
    return np.array(timed) * 1e6, np.array(steps) * 1e6


def _move(ctrl, mailbox, loops: dict) -> None:
    cell = ctrl.cell
    planner = Planner(Kinematics(cell.arm), cell.controller.cycle_time)
    q = ctrl.get().pos
    trajectory = planner.move(q, MotionSettings(cell.arm).with_tool_offset(CUP), Frame.TOOL,
                              np.array([0.2, 0.0, 0.0, 0, 0, 0]), True, True, 0.5)
    arrays = SharedArrays.create(pack_run([trajectory], planner.dt), shared=False)
    mailbox.inbox.append({"op": "run", "id": "m", "arrays": arrays,
                          "acceleration": np.array(cell.arm.max_acceleration) * 0.5,
                          "stop_acceleration": np.array(cell.arm.max_acceleration), **loops})


def _figures(label: str, executor_us: np.ndarray, step_us: np.ndarray) -> None:
    p = lambda a: f"{np.percentile(a, 50):7.1f} {np.percentile(a, 99):7.1f} {a.max():8.1f}"  # noqa
    print(f"{label:20s} executor p50/p99/max {p(executor_us)} us   whole step {p(step_us)} us")
    record(f"cycle step p99, {label.lstrip('+ ')}", float(np.percentile(step_us, 99)), "us",
           baseline=4000.0, baseline_name="the cycle")


def _model_torques(cycles: int) -> np.ndarray:
    cell = load_cell()
    cycle = CycleRecord(None, cell.controller.cycle_time, ArmDynamics(cell.arm))
    cycle.set_payload(tool_payload(cell.world.tools[0]))
    q = np.array(cell.controller.initial_position)
    fbk = JointFbk(q, np.full(6, 0.5), np.zeros(6), np.zeros(6))
    out = []
    for k in range(cycles):
        start = time.perf_counter()
        cycle.model_torques(fbk, q + 1e-3 * (k % 7))
        out.append(time.perf_counter() - start)
    return np.array(out) * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=2000)
    n = parser.parse_args().cycles
    print(f"{n} cycles per mode; the cycle is 4000 us")

    ctrl, mailbox, timed = _controller(bare=True)
    _figures("bare executor", *_run(ctrl, timed, n))

    ctrl, mailbox, timed = _controller(bare=False)
    mailbox.inbox.append({"op": "io_image", "units": [(1, 0b1100111), (2, 0b111)]})
    _figures("holding", *_run(ctrl, timed, n))

    unwatched, unwatched_box, unwatched_timed = _controller(bare=False, watched=False)
    unwatched_box.inbox.append({"op": "io_image", "units": [(1, 0b1100111), (2, 0b111)]})
    _figures("holding, unwatched", *_run(unwatched, unwatched_timed, n))

    _move(ctrl, mailbox, {"guard": GuardSpec("force_torque", (0.0, 0.0, -1e6), (0, 0, 0),
                                             1.0, CUP)})
    _figures("+ guarded move", *_run(ctrl, timed, n))

    ctrl, mailbox, timed = _controller(bare=False)
    mailbox.inbox.append({"op": "io_image", "units": [(1, 0b1100111), (2, 0b111)]})
    _move(ctrl, mailbox, {"comply": ComplySpec(
        axes=(False, True, False), setpoint=(0, -1e-3, 0), kp=(0, 1e-6, 0), kd=(0, 0, 0),
        reach=(0, 0.5, 0), envelope=(0, 0, 0), travel=(0, 0, 0), speed=0.01, acceleration=1.0,
        timeout=0, hold_only=False, panic=0, tool_offset=CUP)})
    _figures("+ comply", *_run(ctrl, timed, n))

    ctrl, mailbox, timed = _controller(bare=False)
    arm = ctrl.cell.arm
    a = np.array(arm.max_acceleration)
    cartesian = np.array([arm.max_linear_acceleration, arm.max_angular_acceleration])
    limits = JogLimits(np.array(arm.max_velocity) * 0.25, a * 0.5, a, arm.lower, arm.upper,
                       cartesian * 0.5, cartesian, MANUAL_TIP_SPEED, 10 ** 9,
                       np.array(arm.max_jerk) * 0.5, np.array(arm.max_jerk))
    mailbox.inbox.append({"op": "jog", "id": "j", "limits": limits, "tool_offset": CUP})
    velocity = {"op": "jog_velocity", "frame": "tool", "deadman": True,
                "velocity": np.array([0.02, 0.0, 0.0, 0.0, 0.0, 0.05])}
    _figures("+ Cartesian jog", *_run(ctrl, timed, n,
                                      lambda k: k % 20 or mailbox.inbox.append(velocity)))

    ctrl, mailbox, timed = _controller(bare=False)
    mailbox.inbox.append({"op": "io_image", "units": [(1, 0b1100111), (2, 0b111)]})
    mailbox.inbox.append({"op": "watch", "id": "w", "unit": 1, "bits": 1 << 4, "period": 1,
                          "timeout": 0})
    _figures("+ I/O watch", *_run(ctrl, timed, n))

    alone = _model_torques(n)
    print(f"{'model torques alone':20s} p50/p99/max {np.percentile(alone, 50):7.1f} "
          f"{np.percentile(alone, 99):7.1f} {alone.max():8.1f} us")


if __name__ == "__main__":
    main()

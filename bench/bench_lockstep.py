"""Lock-step simulation speed (issue 18 item 2, issue 17): how many times faster than real time
the whole stack runs a program, beside what its parts allow, measured in the same run.

- whole stack: a device server, a client on gRPC loopback loading and running a blended
  joint path (about 11 simulated seconds), the event stream open; simulated time from the
  controller's clock, wall time from the call to the done event; once with the controller on
  `--clock fast` (its cycle process running cycles back to back: what users run long programs
  on) and once on the lock-step thread inside the server (as the tests start it);
- bare controller: the same cell's BulletController stepped by the lock-step clock with a
  shuttling arm, no server (bench_cycle's run);
- pybullet alone: the same world's stepSimulation, as many steps as the controller's cycles
  take (two 2 ms steps a 4 ms cycle).

Prints simulated s per wall s and the time per cycle of each, the load averages, and the whole
stack's speed as a share of the bare controller's, each whole-stack run beside a bare one run
right after it (the machine may be shared: the two see the same load). Goals: the whole stack
at 50 times real time or more (issue 18), and at least 0.8 times the bare controller on the
fast clock (issue 31 item 5), marked met or not.
Run: .venv/bin/python bench/bench_lockstep.py [--quick]
"""
from __future__ import annotations

import argparse
import functools
import math
import os
import sys
import time
from pathlib import Path

import grpc
import pybullet
from common import record

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from bench_cycle import run_lock_step  # noqa: E402
from support import locked_session  # noqa: E402

from landscape.server.app import serve  # noqa: E402
from landscape.server.config import ServerConfig  # noqa: E402

from landscape.sim.bullet_controller import BulletController  # noqa: E402
from landscape.robot.cell import load_cell  # noqa: E402
from landscape.v1 import (control_pb2, device_service_pb2_grpc, event_service_pb2,  # noqa: E402
                          event_service_pb2_grpc, motion_pb2, types_pb2)

GOAL = 50.0
SHARE_GOAL = 0.8   # of the bare controller's speed, on the fast clock (issue 31 item 5)
PATH_POINTS = 40
LOOPS = 3   # of the path (about 3.7 s each at the default speed)


def whole_stack(runs: int, clock: str = "lockstep") -> tuple[float, float, float, float]:
    """(simulated s, wall s, CPU s of the cycle process, CPU s of this process: the server
    and its client) of `runs` runs of a blended ~10 s joint path through gRPC, the server's
    controller on `clock` ("lockstep": a thread of the server, as the tests run it, cycle
    process CPU NaN; "fast": its own cycle process, as `--clock fast` runs it)."""
    server = serve(ServerConfig(port=0, clock=clock))
    session = locked_session(server, "bench")
    device = device_service_pb2_grpc.DeviceServiceStub(session.channel)
    events = event_service_pb2_grpc.EventServiceStub(session.channel).Subscribe(
        event_service_pb2.SubscribeRequest())
    try:
        device.Activate(control_pb2.ActivateRequest(), timeout=30)
        points = [types_pb2.TagStruct(joint_values=[
            0.9 * math.sin(2 * math.pi * i / PATH_POINTS), 0.3 * math.sin(4 * math.pi * i / PATH_POINTS),
            1.5708 + 0.3 * math.cos(2 * math.pi * i / PATH_POINTS), 0.5 * math.sin(2 * math.pi * i / PATH_POINTS),
            1.5708, math.cos(2 * math.pi * i / PATH_POINTS)], tag_name=f"t{i}", transition_speed=50)
            for i in range(PATH_POINTS + 1)]
        header = motion_pb2.PathHeader(path_name="lockstep", frame=types_pb2.REFERENCE_FRAME_JOINT_FRAME,
                                       motion_type=types_pb2.MOTION_TYPE_JOINT_MOTION,
                                       offset_type=types_pb2.OFFSET_TYPE_ABSOLUTE_DATA)
        device.PathLoad(iter([motion_pb2.PathLoadRequest(header=header, tags=points)]), timeout=60)
        def now() -> float:   # the controller's time, from its newest feedback row
            return server.link.feedback.latest().time
        simulated = wall = cpu = own = 0.0
        for _ in range(runs):
            cpu -= _cpu_seconds(server.link.cycle_pid)
            own -= time.process_time()
            began, began_sim = time.perf_counter(), now()
            command = device.PathMove(motion_pb2.PathMoveRequest(
                path_name="lockstep", number_of_cycles=LOOPS), timeout=60).ret_val.command_id
            for reply in events:
                event = reply.event
                if event.HasField("command") and event.command.command_id == command and \
                        event.event_id in ("command_done", "command_failed"):
                    break
            wall += time.perf_counter() - began
            simulated += now() - began_sim
            cpu += _cpu_seconds(server.link.cycle_pid)
            own += time.process_time()
            if event.event_id != "command_done":
                raise RuntimeError(f"the path did not complete: {event.command.message}")
        return simulated, wall, cpu, own
    finally:
        events.cancel()
        try:
            device.Deactivate(control_pb2.DeactivateRequest(), timeout=30)
        except grpc.RpcError:
            pass
        session.close()
        server.stop(grace=None)


def _cpu_seconds(pid: int | None) -> float:
    """CPU time (user and system) process `pid` used so far (Linux); NaN for no process."""
    if pid is None:
        return math.nan
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def bare_controller(simulated: float) -> tuple[float, float]:
    """(wall s, CPU s) of the bare controller for `simulated` s."""
    began = time.process_time()
    wall, _ = run_lock_step(simulated)
    return wall, time.process_time() - began


def pybullet_alone(cycles: int) -> tuple[float, float]:
    """(simulated s, wall s) of the default world's physics for `cycles` controller cycles."""
    cell = load_cell(None)
    ctrl = BulletController(cell)
    steps = cycles * cell.controller.substeps
    # the same bound stepSimulation the drives' cycle calls (sim/bullet_drives.py)
    step = functools.partial(pybullet.stepSimulation, physicsClientId=ctrl.world.bc.client_id)
    began = time.perf_counter()
    for _ in range(steps):
        step()
    wall = time.perf_counter() - began
    ctrl.destroy()
    return cycles * cell.controller.cycle_time, wall


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="one path run, for CI")
    args = parser.parse_args()
    cycle = load_cell(None).controller.cycle_time
    runs = 1 if args.quick else 3
    load_before = os.getloadavg()
    fast_sim, fast_wall, fast_cpu, fast_server_cpu = whole_stack(runs, "fast")
    fast_bare_wall, fast_bare_cpu = bare_controller(fast_sim)   # the same simulated time
    simulated, wall, _, _ = whole_stack(runs, "lockstep")
    bare_wall, _ = bare_controller(simulated)
    physics_sim, physics_wall = pybullet_alone(round(simulated / cycle))
    print(f"lock-step speed, {simulated:.1f} simulated s of a {PATH_POINTS}-point blended path "
          f"run {LOOPS} times "
          f"(simulated s per wall s; wall time per 4 ms cycle):")
    rows = (("whole stack, --clock fast", fast_sim, fast_wall),
            ("  bare controller, run after it", fast_sim, fast_bare_wall),
            ("whole stack, lock-step thread", simulated, wall),
            ("  bare controller, run after it", simulated, bare_wall),
            ("pybullet alone (baseline)", physics_sim, physics_wall))
    for name, sim_s, wall_s in rows:
        print(f"  {name:32s} {sim_s / wall_s:7.1f} x real time   "
              f"{wall_s / (sim_s / cycle) * 1e6:7.1f} us/cycle")
    fast_share, thread_share = fast_bare_wall / fast_wall, bare_wall / wall
    print(f"  whole stack / bare controller: --clock fast {fast_share:.2f} "
          f"(goal >= {SHARE_GOAL:g}: {'met' if fast_share >= SHARE_GOAL else 'NOT met'}), "
          f"lock-step thread {thread_share:.2f}")
    fast_cycles = fast_sim / cycle
    print(f"  CPU per cycle, --clock fast: the cycle process {fast_cpu / fast_cycles * 1e6:.1f} us, "
          f"the bare controller {fast_bare_cpu / fast_cycles * 1e6:.1f} us "
          f"(a busy machine takes wall time from both, not CPU time); the server and its "
          f"client {fast_server_cpu / fast_cycles * 1e6:.1f} us")
    print(f"  goal (issue 18): whole stack >= {GOAL:g} x real time")
    print(f"  load averages (1, 5, 15 min): before {_load(load_before)}, "
          f"after {_load(os.getloadavg())}")
    record("lock-step speed, whole stack (--clock fast)", fast_sim / fast_wall, "x real time",
           baseline=fast_sim / fast_bare_wall, baseline_name="bare controller", goal=GOAL,
           better="higher")
    record("lock-step speed, whole stack (--clock fast) / bare controller", fast_share,
           "x the bare controller", goal=SHARE_GOAL, better="higher")
    record("lock-step speed, whole stack (lock-step thread)", simulated / wall, "x real time",
           baseline=simulated / bare_wall, baseline_name="bare controller", better="higher")
    record("lock-step speed, pybullet alone", physics_sim / physics_wall, "x real time")


def _load(averages) -> str:
    return ", ".join(f"{x:.2f}" for x in averages)


if __name__ == "__main__":
    main()

"""The clocks: lock-step (deterministic, in process) and real time (a cycle process).

No timing assertions here: timing figures belong to bench/bench_cycle.py. The generous wall
time bounds below only keep a hang from blocking the suite. Tests that claim physics use the
real BulletController on the default cell; the pure clock logic uses stand-ins.
"""
from __future__ import annotations

import dataclasses
import functools
import operator
import os
import signal
import struct
import subprocess
import sys
import textwrap
import threading
import time
from multiprocessing.reduction import ForkingPickler
from pathlib import Path

import numpy as np
import pytest

from landscape.sim.bullet_controller import BulletController
from landscape.robot.cell import load_cell
from landscape.server.link.clock import CycleProcessError, LockStepClock, RealTimeClock
from landscape.robot.controller import (Controller, DioStatus, DoutValue, EnableState, InitState,
                                      IoctrlCode, IoType, JointCmd, Status)
from landscape.server.cycle import process as cycle_process
from landscape.server.cycle.process import check_cycle_time
from landscape.sim.movegen import JointMove, sample_controller
from landscape.sim.recorder import read_recording

sys.path.insert(0, str(Path(__file__).parent))
from cycle_standins import (StandIn, make_broken, make_echo, make_slow_store,  # noqa: E402
                            make_stand_in, steps_of)

# Joint offsets (rad) of the test moves from the default cell's initial position: well inside
# the ranges and speeds, away from the table.
SWING = np.array([0.6, 0.35, -0.4, 0.8, 0.5, 1.0])


def alive(pid: int) -> bool:
    """True while `pid` runs (a zombie waiting for its reaper counts as gone)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (FileNotFoundError, ProcessLookupError):
        return False


def wait_gone(pid: int, timeout: float = 10.0) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if not alive(pid):
            return True
        time.sleep(0.02)
    return False


# -- lock-step clock, pure logic
def test_lock_step_counts_simulated_time():
    clock = LockStepClock(StandIn())
    clock.step()
    clock.step(9)
    assert clock.controller.steps == 10
    assert clock.run_for(1.0) == 250
    assert clock.time == pytest.approx(260 * 0.004)


def test_lock_step_run_until_uses_simulated_timeout():
    clock = LockStepClock(StandIn())
    assert clock.run_until(lambda: clock.controller.steps >= 30, timeout_s=1.0)
    assert clock.controller.steps == 30
    assert not clock.run_until(lambda: False, timeout_s=3600.0)  # an hour, simulated
    assert clock.controller.steps == 30 + 900_000


def wait_for(predicate, timeout: float = 10.0) -> bool:
    end = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > end:
            return False
        time.sleep(0.01)
    return True


# -- lock-step clock, the real arm
def ten_second_motion(record_path: Path) -> tuple:
    """The default cell's arm, moved by JointMove over 10 s of simulated time on the lock-step
    clock while the recorder runs; returns (final feedback, recording, wall s of the motion)."""
    cell = load_cell()
    cell = dataclasses.replace(cell, recorder=dataclasses.replace(cell.recorder,
                                                                  path=str(record_path)))
    move = JointMove(cell.controller.cycle_time)
    with BulletController(cell, move) as ctrl:
        clock = LockStepClock(ctrl)
        assert ctrl.init() == Status.OK and ctrl.enable() == Status.OK
        assert clock.run_until(lambda: ctrl.state().enable == EnableState.ENABLED, 1.0)
        assert ctrl.rec_init() == Status.OK and ctrl.rec_start() == Status.OK
        target = ctrl.get().pos + SWING
        move.start(target, 10.0)
        started = time.perf_counter()
        assert clock.run_until(lambda: not move.moving, timeout_s=10.5)
        clock.run_for(0.2)  # let it settle
        wall = time.perf_counter() - started
        assert ctrl.rec_store() == Status.OK
        final = ctrl.get()
        assert ctrl.state().enable == EnableState.ENABLED  # no command was refused
        np.testing.assert_allclose(final.pos, target, atol=1e-4)
    return final, read_recording(str(record_path)), wall


def test_lock_step_motion_is_deterministic(tmp_path):
    first, rec1, wall1 = ten_second_motion(tmp_path / "first.mcap")
    second, rec2, wall2 = ten_second_motion(tmp_path / "second.mcap")
    print(f"\n10 s of simulated motion on the lock-step clock: {wall1:.2f} s and "
          f"{wall2:.2f} s of wall time")
    for name in ("pos", "vel", "pos_err", "torque"):
        assert np.array_equal(getattr(first, name), getattr(second, name)), name
    assert len(rec1["t"]) > round(10.0 / 0.004)  # every cycle of the motion (100 %)
    for name in rec1:
        assert np.array_equal(rec1[name], rec2[name]), name


def test_cycle_time_must_be_a_multiple_of_0_2_ms():
    assert check_cycle_time(0.004) == 0.004
    assert check_cycle_time(0.0002) == 0.0002
    for bad in (0.0041, 0.0, -0.004, 0.0001):
        with pytest.raises(ValueError):
            check_cycle_time(bad)
    with pytest.raises(ValueError):
        RealTimeClock(make_stand_in, cycle_time=0.0031)


# -- real-time clock with the stand-in: process life cycle
def test_real_time_clock_runs_and_stops_its_process():
    with RealTimeClock(make_stand_in) as clock:
        pid = clock.pid
        assert clock.cycle_time == 0.004
        deadline = time.monotonic() + 10.0
        while clock.stats().cycles < 50 and time.monotonic() < deadline:
            time.sleep(0.01)
        stats = clock.stats()
        assert stats.cycles >= 50
        assert stats.window == min(stats.cycles, 1 << 16)
        for value in (stats.period_p50, stats.period_p99, stats.period_max, stats.late_p99,
                      stats.exec_max):
            assert np.isfinite(value)
        assert clock.sim_time() > 0.0
        clock.reset_stats()
    assert not clock.alive and clock._process.exitcode == 0
    assert wait_gone(pid)
    with pytest.raises(CycleProcessError):
        clock.sim_time()


def test_clock_cycle_time_must_match_the_controller():
    clock = RealTimeClock(functools.partial(make_stand_in, cycle_time=0.002), cycle_time=0.004)
    with pytest.raises(CycleProcessError, match="differs"):
        clock.start()
    assert not clock.alive


def test_factory_failure_reports_the_traceback():
    clock = RealTimeClock(make_broken)
    with pytest.raises(CycleProcessError, match="no controller today"):
        clock.start()
    assert not clock.alive


def test_failing_cycle_ends_the_process_and_fails_calls():
    failures: list[str] = []
    clock = RealTimeClock(functools.partial(make_stand_in, fail_at=20),
                          on_failure=failures.append).start()
    try:
        assert wait_for(lambda: failures)
        assert "cycle failed on purpose" in failures[0]
        assert clock._process.exitcode == 1
        with pytest.raises(CycleProcessError, match="cycle failed on purpose"):
            clock.sim_time()
        assert "cycle failed on purpose" in clock.error
    finally:
        clock.stop()
    assert len(failures) == 1


def test_killed_child_is_reported_and_a_stop_is_not():
    failures: list[str] = []
    with RealTimeClock(make_stand_in, on_failure=failures.append):
        pass
    assert failures == []  # stop() asked for it
    clock = RealTimeClock(make_stand_in, on_failure=failures.append).start()
    clock._process.kill()
    assert wait_for(lambda: failures)
    assert "code -9" in failures[0]
    with pytest.raises(CycleProcessError):
        clock.proxy.state()
    clock.stop()


def test_an_urgent_call_is_answered_while_a_slow_call_runs():
    """The operator panel's lane: a call marked urgent is not held back behind a call on the
    asynchronous task (storing a recording), as the calls after that one are."""
    with RealTimeClock(make_slow_store) as clock:
        stored = []
        storing = threading.Thread(target=lambda: stored.append(clock.call("rec_store")))
        storing.start()
        time.sleep(0.1)   # the store has begun
        assert clock.between_cycles(steps_of, urgent=True, timeout=1.0) > 0
        assert not stored
        storing.join(10)
        assert stored == ["stored"]


def test_unknown_call_is_refused():
    with RealTimeClock(make_stand_in) as clock:
        with pytest.raises(AttributeError):
            clock.call("step")  # the cycle's own business, not a remote call
        with pytest.raises(AttributeError):
            clock.call("no_such_call")


# -- real-time clock with the real arm
def test_real_time_clock_drives_the_arm(tmp_path):
    cell_file = tmp_path / "cell.toml"
    default = (Path(load_cell.__code__.co_filename).parent / "cells" / "default.toml").read_text()
    record = tmp_path / "records" / "rt.mcap"
    cell_file.write_text(default.replace('path = "var/records/cs8.mcap"', f'path = "{record}"'))
    events: list[str] = []
    with RealTimeClock(functools.partial(sample_controller, cell_path=str(cell_file))) as clock:
        arm = clock.proxy
        assert isinstance(arm, Controller)
        assert clock.cycle_time == 0.004
        assert arm.ioctrl(IoctrlCode.GET_CYCLE_TIME) == 0.004
        assert arm.state().init == InitState.INITIALIZED
        with pytest.raises(RuntimeError):
            arm.get()  # the synchronous calls stay in the cycle process
        with pytest.raises(RuntimeError):
            arm.set(JointCmd(np.zeros(6), np.zeros(6)))

        # enable: non-blocking, progress through state()
        assert arm.plug_event_func(events.append) == Status.OK
        assert arm.enable() == Status.OK
        assert wait_for(lambda: arm.state().enable == EnableState.ENABLED)

        # I/O by name, answered between cycles
        lamp = arm.get_dout_id("lamp_green")
        assert lamp.type == IoType.D_OUTPUT
        assert arm.read_dio(lamp) == DioStatus.ZERO
        assert arm.write_dout(lamp, DoutValue.ONE) == Status.OK
        assert arm.read_dio(lamp) == DioStatus.ONE
        assert arm.get_din_id("door_closed").type == IoType.D_INPUT
        assert arm.get_din_id("no_such_input").type == IoType.UNDEFINED
        # a refused call raises an event, delivered to this process
        door = arm.get_din_id("door_closed")
        assert arm.write_dout(door, DoutValue.ONE) == Status.ERROR
        assert wait_for(lambda: any("write_dout refused" in e for e in events))

        # kinematics run in the child, results come back as arrays
        pose, _config = arm.forward_kin(np.zeros(6))
        assert pose.shape == (4, 4)
        # what the LLI has no call for: a picklable function run between cycles
        wrench = clock.between_cycles(operator.methodcaller("read_sensor", "force_sensor"))
        assert np.asarray(wrench).shape == (6,)

        # messages both ways: a move down, feedback up; recorder through the proxy
        assert arm.rec_init() == Status.OK and arm.rec_start() == Status.OK
        clock.send({"op": "where"})
        start = np.array(clock.recv(timeout=5.0)["position"])
        clock.send({"op": "move", "target": (start + SWING).tolist(), "duration": 0.5, "id": 7})
        done = clock.recv(timeout=10.0)
        assert done["op"] == "done" and done["id"] == 7
        np.testing.assert_allclose(done["position"], start + SWING)
        assert arm.rec_stop() == Status.OK and arm.rec_store() == Status.OK
        assert arm.state().enable == EnableState.ENABLED  # no command was refused

        stats = clock.stats()
        assert stats.cycles > 0 and np.isfinite(stats.period_p99) and stats.exec_max > 0
        print(f"\nreal-time clock with the TX90: {stats.summary()}")
        pid = clock.pid
    assert clock._process.exitcode == 0
    assert wait_gone(pid)
    recording = read_recording(str(record))
    assert len(recording["t"]) >= 0.5 / 0.004
    np.testing.assert_allclose(recording["cmd_pos"][-1], start + SWING)


def test_messages_keep_their_order_and_size():
    received = []
    with RealTimeClock(make_echo, on_message=received.append) as clock:
        trajectory = np.random.default_rng(1).normal(size=(20_000, 6))  # ~80 s at 4 ms
        for i in range(50):
            clock.send(i)
        clock.send(trajectory)
        assert wait_for(lambda: len(received) == 51)
    assert [msg for _, msg in received[:50]] == list(range(50))
    assert np.array_equal(received[50][1], trajectory)
    steps = [step for step, _ in received]
    assert steps == sorted(steps)
    with pytest.raises(RuntimeError):
        clock.recv(0.1)  # with on_message, messages go there



def test_a_message_written_slowly_holds_no_cycle_up():
    """The parent writes a large message in several writes, and a busy server may take its
    time between them (the bench saw a 43 ms step while the server planned): the cycle keeps
    its pace on what has arrived and takes the message once it is whole."""
    received = []
    with RealTimeClock(make_echo, on_message=received.append) as clock:
        payload = np.random.default_rng(2).normal(size=(40_000, 6))   # ~1.9 MB
        data = bytes(ForkingPickler.dumps((cycle_process.MSG, payload)))
        frame = struct.pack("!i", len(data)) + data
        fd = clock._conn.fileno()
        with clock._send_lock:   # the clock's own writes wait until this message is whole
            os.write(fd, frame[:4096])
            before = clock.stats().cycles
            time.sleep(0.3)
            during = clock.stats().cycles - before
            view = memoryview(frame)[4096:]
            while view:
                view = view[os.write(fd, view):]
        assert wait_for(lambda: len(received) == 1)
        clock.send("after")
        assert wait_for(lambda: len(received) == 2)
    assert during >= 30   # 75 cycles in 0.3 s; none while a cycle waits for the rest
    assert np.array_equal(received[0][1], payload)
    assert received[1][1] == "after"


PARENT_SCRIPT = textwrap.dedent("""
    import sys, time
    sys.path.insert(0, {test_dir!r})
    from landscape.server.link.clock import RealTimeClock
    from {module} import {factory} as factory
    if __name__ == "__main__":
        clock = RealTimeClock(factory).start()
        print("cycle process", clock.pid, flush=True)
        if {linger}:
            time.sleep(600)
""")


def child_pid(parent: subprocess.Popen) -> int:
    for line in parent.stdout:  # pybullet prints to stdout too
        if line.startswith("cycle process"):
            return int(line.split()[-1])
    raise AssertionError("the parent did not start its cycle process")


@pytest.mark.parametrize("how, module, factory", [
    ("SIGKILL", "landscape.sim.movegen", "sample_controller"),  # the real arm
    ("SIGTERM", "cycle_standins", "make_stand_in"),
    ("exit", "cycle_standins", "make_stand_in"),  # returns without stop()
])
def test_child_exits_when_its_parent_dies(tmp_path, how, module, factory):
    script = tmp_path / "parent.py"
    script.write_text(PARENT_SCRIPT.format(test_dir=str(Path(__file__).parent), module=module,
                                           factory=factory, linger=how != "exit"))
    parent = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True)
    try:
        child = child_pid(parent)
        if how != "exit":
            assert alive(child)
            parent.send_signal(getattr(signal, how))
        parent.wait(10.0)
        assert wait_gone(child), "the cycle process outlived its parent"
    finally:
        parent.kill()
        parent.wait()

"""Issue 8.1: the cycle process dies or hangs, on the real-time clock as `make run` has it.

The loss is noticed within a few cycles (its pipe closes at once when it dies; its feedback
stops when it hangs), the device goes to Error with an alarm naming the cause, health says
NOT_SERVING, a motion in flight fails with its command id, the lock stays with its holder
(the documented rule), and Reset starts a fresh cycle process that works like the first.
"""
from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
import time
from pathlib import Path

import grpc
import pytest
from grpc_health.v1 import health_pb2, health_pb2_grpc

from landscape.server.app import serve
from landscape.server.config import ServerConfig
from landscape.server.link.controller_link import FAST_SILENCE
from landscape.server.device.states import State
from landscape.v1 import control_pb2, event_service_pb2, motion_pb2, sensing_pb2, types_pb2

from support import activate, bus_history, error_info, locked_session, stubs, wait_until

JOINT = types_pb2.REFERENCE_FRAME_JOINT_FRAME


@pytest.fixture
def realtime():
    server = serve(ServerConfig(port=0, clock="realtime"))
    yield server
    server.stop(grace=None)


def _lost_alarm(events, after: float):
    """The controller-lost alarm and the Error state change, from the event stream."""
    alarm = state = None
    for reply in events:
        event = reply.event
        if event.HasField("alarm") and event.alarm.code == 105 and alarm is None:
            alarm = event
        if event.HasField("state_change") and event.state_change.to_state == "error":
            state = event
        if alarm and state:
            return alarm, state
    raise AssertionError("no controller-lost alarm")


# Where a server thread waits on the controller or on a motion's end.
WAITS = {("clock.py", "call"), ("device.py", "_wait_controller"), ("motion_control.py", "_wait")}


def _blocked_threads() -> list[str]:
    """The threads of this process waiting in one of WAITS, by name."""
    names = {thread.ident: thread.name for thread in threading.enumerate()}
    blocked = []
    for ident, frame in sys._current_frames().items():
        while frame is not None:
            if (Path(frame.f_code.co_filename).name, frame.f_code.co_name) in WAITS:
                blocked.append(names.get(ident, str(ident)))
                break
            frame = frame.f_back
    return blocked


def _health(channel) -> int:
    return health_pb2_grpc.HealthStub(channel).Check(
        health_pb2.HealthCheckRequest(service="landscape.v1.DeviceService"), timeout=5).status


@pytest.mark.parametrize("when", ["moving", "resting", "enabling"])
def test_a_killed_cycle_process_is_an_error_and_reset_brings_a_working_one(realtime, when):
    server = realtime
    holder = locked_session(server, "holder")
    device, _, events = stubs(holder.channel)
    stream = events.Subscribe(event_service_pb2.SubscribeRequest())
    try:
        command_id = ""
        if when in ("moving", "resting"):
            activate(holder)
        if when == "moving":
            reply = device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
                frame=JOINT, values=[1.5, 0, 1.5708, 0, 1.5708, 0], speed=20), timeout=5)
            command_id = reply.ret_val.command_id
        if when == "enabling":
            server.device.enable_timeout = 30.0
            activating = device.Activate.future(control_pb2.ActivateRequest(), timeout=30)
            time.sleep(0.02)   # enabling takes 0.1 s of the cell's controller
        killed = time.time()
        os.kill(server.link.clock.pid, signal.SIGKILL)
        alarm, error = _lost_alarm(stream, killed)
        latency = alarm.time.ToNanoseconds() / 1e9 - killed
        print(f"{when}: Error and alarm {latency * 1000:.1f} ms after SIGKILL: "
              f"{alarm.alarm.message}")   # the figure: bench/bench_faults.py
        assert "cycle process" in alarm.alarm.message and latency >= 0.0
        assert server.device.state is State.ERROR
        assert server.device.status().lock_holder == "holder"   # the rule: the lock stays
        assert _health(holder.channel) == health_pb2.HealthCheckResponse.NOT_SERVING
        if when == "moving":
            failed = next(r.event for r in stream if r.event.event_id == "command_failed")
            assert failed.command.command_id == command_id
            assert "controller lost" in failed.command.message
        if when == "enabling":
            with pytest.raises(grpc.RpcError) as refused:
                activating.result()
            assert refused.value.code() is grpc.StatusCode.ABORTED
        # Nothing is left hanging: no thread waits on the dead controller, every pool runs,
        # calls answer, and Reset starts a fresh cycle process.
        wait_until(lambda: not _blocked_threads(), timeout=5)
        for pool in ("commands", "immediate", "reads", "panel"):
            assert getattr(server.dispatch, pool).submit(lambda: True).result(5)
        assert server.device.safety.wait_idle(5)
        status = device.GetDeviceState(control_pb2.GetDeviceStateRequest(), timeout=2)
        assert status.state == types_pb2.DEVICE_STATE_ERROR and "cycle process" in status.error
        reply = device.Reset(control_pb2.ResetRequest(), timeout=60)
        assert reply.state == types_pb2.DEVICE_STATE_INACTIVE
        assert _health(holder.channel) == health_pb2.HealthCheckResponse.SERVING
        activate(holder)
        reply = device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
            frame=JOINT, values=[0.2, 0, 1.5708, 0, 1.5708, 0], speed=50), timeout=5)
        done = next(r.event for r in stream if r.event.HasField("command")
                    and r.event.command.command_id == reply.ret_val.command_id
                    and r.event.event_id in ("command_done", "command_failed"))
        assert done.event_id == "command_done"
    finally:
        stream.cancel()
        holder.close()


def test_a_hung_cycle_process_is_noticed_by_its_silence(realtime):
    server = realtime
    holder = locked_session(server, "holder")
    _, _, events = stubs(holder.channel)
    stream = events.Subscribe(event_service_pb2.SubscribeRequest())
    pid = server.link.clock.pid
    try:
        activate(holder)
        stopped = time.time()
        os.kill(pid, signal.SIGSTOP)
        alarm, _ = _lost_alarm(stream, stopped)
        latency = alarm.time.ToNanoseconds() / 1e9 - stopped
        print(f"silence noticed after {latency * 1000:.1f} ms: {alarm.alarm.message}")
        assert "no feedback" in alarm.alarm.message and latency >= 0.0   # bench_faults.py
        assert server.device.state is State.ERROR
        wait_until(lambda: not _alive(pid), timeout=5)   # killed when found silent
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGCONT)
        stream.cancel()
        holder.close()
    # The holder left; anyone may reset: a fresh cycle process is started.
    wait_until(lambda: server.device.status().lock_holder == "", timeout=5)
    with grpc.insecure_channel(server.target) as channel:
        device, _, _ = stubs(channel)
        reply = device.Reset(control_pb2.ResetRequest(), timeout=60)
    assert reply.state == types_pb2.DEVICE_STATE_UNLOCKED
    assert server.link.clock.pid != pid


def _voluntary_switches(thread: threading.Thread) -> int:
    with open(f"/proc/self/task/{thread.native_id}/status") as status:
        return next(int(line.split()[1]) for line in status
                    if line.startswith("voluntary_ctxt_switches"))


def test_the_watchdog_looks_about_once_per_silence_limit_not_every_cycle(realtime):
    """The watchdog looked at the ring every cycle: 250 wake-ups a second, each taking the
    interpreter from the event loop for a moment (issue 31 item 1). It looks when the newest
    row it saw would be 10 cycles old by that row's time stamp: 25 or so a second."""
    watchdog = next(t for t in threading.enumerate() if t.name == "controller-watchdog")
    before = _voluntary_switches(watchdog)
    time.sleep(1.0)
    woken = _voluntary_switches(watchdog) - before
    print(f"the watchdog woke {woken} times in 1 s")
    assert woken < 100
    assert realtime.link.lost is None


def test_a_cycle_process_hung_and_reset_again_and_again_comes_back_each_time(realtime):
    """Hung, killed and reset at once, again and again (bench_faults did that, and failed in
    CI): a restarted cycle process collects its garbage and tunes itself after saying it is
    ready, and on a busy machine its first row came over 40 ms later: the watchdog, counting
    from the old process's silence, killed the new one as hung and Reset failed with "the
    cycle process exited". And the killed process's exit, read after the restart, marked
    the new controller lost. Now a new process's silence counts from its first row (before
    it, START_SILENCE), and news of a replaced process is ignored. Both races need a busy
    machine: on an idle one this passes on the old code too."""
    server = realtime
    with grpc.insecure_channel(server.target) as channel:
        device, _, _ = stubs(channel)
        for _ in range(12):
            os.kill(server.link.clock.pid, signal.SIGSTOP)   # killed when found silent
            wait_until(lambda: server.device.state is State.ERROR, timeout=5, period=0.001)
            reply = device.Reset(control_pb2.ResetRequest(), timeout=60)
            assert reply.state == types_pb2.DEVICE_STATE_UNLOCKED
            assert server.link.lost is None, server.link.lost


def test_on_the_fast_clock_a_cycle_process_held_off_the_cpu_is_not_a_hung_one():
    """The fast clock's cycle process runs in the normal policy (free-running under SCHED_FIFO
    it would starve the machine), so a busy machine may hold it off the cores for tens of ms:
    before, 10 cycles (40 ms) of silence killed it as hung (test_fast_clock failed under
    load). Silent for FAST_SILENCE it is one."""
    server = serve(ServerConfig(port=0, clock="fast"))
    pid = server.link.clock.pid
    try:
        os.kill(pid, signal.SIGSTOP)
        time.sleep(0.15)
        os.kill(pid, signal.SIGCONT)
        head = server.link.feedback.head
        wait_until(lambda: server.link.feedback.head > head + 100, timeout=5)
        assert server.link.lost is None and _alive(pid)
        os.kill(pid, signal.SIGSTOP)
        last_row = server.link.feedback.latest().wall_time   # silence counts from it
        wait_until(lambda: server.link.lost is not None, timeout=5)
        noticed = time.time() - last_row
        print(f"fast clock: silence noticed after {noticed * 1000:.0f} ms")
        assert "no feedback" in server.link.lost and noticed >= FAST_SILENCE
        wait_until(lambda: server.device.state is State.ERROR, timeout=5)   # told after lost
        wait_until(lambda: not _alive(pid), timeout=5)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGCONT)
        server.stop(grace=None)


def _alive(pid: int) -> bool:
    try:   # it may be reaped between the two looks: gone then too
        os.kill(pid, 0)
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().split()[2] != "Z"
    except (ProcessLookupError, FileNotFoundError):
        return False


def test_a_cycle_process_that_resumes_after_its_silence_never_commands_the_arm_again(realtime):
    """A cycle process stalled long enough to be declared lost (SIGSTOP), then resumed
    (SIGCONT), must not go on playing its motion: the README says nothing commands the arm."""
    server = realtime
    holder = locked_session(server, "holder")
    device, _, _ = stubs(holder.channel)
    pid = server.link.clock.pid
    try:
        activate(holder)
        device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
            frame=JOINT, values=[2.5, 0, 1.5708, 0, 1.5708, 0], speed=10), timeout=5)
        wait_until(lambda: abs(server.device.feedback().velocity[0]) > 0.05, timeout=10)
        os.kill(pid, signal.SIGSTOP)
        wait_until(lambda: server.link.lost is not None, timeout=5)
        # The server kills a lost cycle process: on a busy machine it may be gone already.
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGCONT)
        wait_until(lambda: not _alive(pid), timeout=5)
        head = server.link.feedback.head
        time.sleep(0.3)   # 75 cycles: a live process would have written rows
        assert server.link.feedback.head == head
        assert server.device.state is State.ERROR
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGCONT)
        holder.close()


def test_the_estop_on_the_real_time_clock_is_an_estop_and_the_cycle_imports_nothing(realtime):
    """The operator panel runs in the cycle process between two cycles; nothing sent there may
    make it import a module on its loop thread (that cost 117 ms once, tripping the silence
    watchdog: the e-stop was reported as a lost controller, alarm 105 instead of 102)."""
    server = realtime
    holder = locked_session(server, "holder")
    device, _, _ = stubs(holder.channel)
    try:
        activate(holder)
        reply = device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
            frame=JOINT, values=[1.0, 0, 1.5708, 0, 1.5708, 0], speed=20), timeout=5)
        device.GetSensorReading(sensing_pb2.GetSensorReadingRequest(sensor_type="force_sensor"),
                                timeout=5)
        device.OperatePanel(control_pb2.OperatePanelRequest(
            action=control_pb2.PANEL_ACTION_PRESS_ESTOP), timeout=5)
        wait_until(lambda: server.device.state is State.ERROR, timeout=5)
        time.sleep(0.2)
        alarms = [e.detail.code for e in bus_history(server) if e.event_id == "alarm"]
        assert 102 in alarms and 105 not in alarms, alarms
        assert server.link.lost is None and "e-stop" in server.device.error
        assert server.link.clock.late_imports() == []
        assert reply.ret_val.command_id
    finally:
        holder.close()


def test_a_controller_lost_during_an_estop_is_alarmed_and_the_estop_outlives_it(realtime):
    """In Error already (e-stop), the cycle process dies: alarm 105 all the same, and the
    error names the loss. The e-stop is a latch in the cell, not in the process: Reset starts
    a fresh controller but is refused while it stays pressed (no "e-stop released?" question
    either); released, the holder is asked, and Reset works."""
    server = realtime
    holder = locked_session(server, "holder")
    device, _, _ = stubs(holder.channel)
    try:
        activate(holder)
        server.device.operate_panel("press_estop")
        assert server.device.state is State.ERROR
        pid = server.link.clock.pid
        os.kill(pid, signal.SIGKILL)
        wait_until(lambda: server.link.lost is not None, timeout=5)
        wait_until(lambda: 105 in [e.detail.code for e in bus_history(server)
                                   if e.event_id == "alarm"], timeout=5)
        assert "controller lost" in server.device.error
        with pytest.raises(grpc.RpcError) as refused:
            device.Reset(control_pb2.ResetRequest(), timeout=60)
        assert error_info(refused.value).reason == "ESTOP_ACTIVE"
        assert server.link.clock.pid != pid and server.link.lost is None
        status = device.GetDeviceState(control_pb2.GetDeviceStateRequest(), timeout=2)
        assert status.state == types_pb2.DEVICE_STATE_ERROR and status.estop
        time.sleep(0.2)
        assert not [e for e in bus_history(server) if e.event_id == "rsvp_request"]
        server.device.operate_panel("release_estop")
        wait_until(lambda: [e for e in bus_history(server) if e.event_id == "rsvp_request"])
        reply = device.Reset(control_pb2.ResetRequest(), timeout=60)
        assert reply.state == types_pb2.DEVICE_STATE_INACTIVE
    finally:
        holder.close()

"""Issue 8.8: SIGINT, SIGTERM (once or twice) and SIGHUP each stop the server the safe way: the
motion stops along its path, the drives go off, the lock is released, and it exits 0."""
from __future__ import annotations

import signal
import subprocess
import sys
import time

import grpc
import pytest

from landscape.client import Session
from landscape.v1 import control_pb2, event_service_pb2, motion_pb2, types_pb2

from support import stubs


@pytest.mark.parametrize("signals", [[signal.SIGINT], [signal.SIGTERM],
                                     [signal.SIGTERM, signal.SIGTERM], [signal.SIGHUP]],
                         ids=["INT", "TERM", "TERM-TERM", "HUP"])
def test_a_signal_stops_the_arm_safely_and_exits_0(tmp_path, signals):
    proc = subprocess.Popen([sys.executable, "-m", "landscape.server", "--port", "0",
                             "--paths", str(tmp_path / "paths.sqlite3")],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        target = next(line for line in proc.stdout if "listening on" in line).split()[-1]
        with grpc.insecure_channel(target) as channel:
            session = Session(channel, "operator").open()
            device, _, events = stubs(session.channel)
            stream = events.Subscribe(event_service_pb2.SubscribeRequest(after_sequence=0))
            session.lock()
            device.Activate(control_pb2.ActivateRequest(), timeout=10)
            device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
                frame=types_pb2.REFERENCE_FRAME_JOINT_FRAME,
                values=[2.5, 0, 1.5708, 0, 1.5708, 0], speed=20), timeout=5)
            time.sleep(0.5)
            began = time.monotonic()
            for number in signals:
                proc.send_signal(number)
                time.sleep(0.01)
            code = proc.wait(timeout=15)
            took = time.monotonic() - began
            seen = []
            try:
                for reply in stream:
                    seen.append(reply.event)
            except grpc.RpcError:
                pass   # the server went away once it had said everything
            session.close()
    finally:
        proc.kill()
    print(f"{'+'.join(signal.Signals(s).name for s in signals)}: exit {code} after "
          f"{took:.2f} s")
    assert code == 0
    phases = [e.event_id for e in seen if e.HasField("command")]
    assert phases[-1] == "command_aborted"   # stopped along its path, then dropped
    states = [e.state_change.to_state for e in seen if e.HasField("state_change")]
    assert states[-2:] == ["inactive", "unlocked"]

"""The gateway never loses its lock silently (issue 25 item 4), against a real device server:
its keep-alives go out whatever its event loop computes; a lock lost all the same (the
gateway stopped past the device's keep-alive timeout) ends the running CRCL command in
CRCL_Error naming the loss and the device's reason, every later status says so until the
next InitCanon, and EndCanon has nothing to release; a MoveScrew's helix is computed off the
loop, so another connection's GetStatus is answered meanwhile; every call says whom the
gateway acts for."""
from __future__ import annotations

import asyncio
import concurrent.futures
import os
import signal
import threading
import time
import urllib.parse

import pytest

from landscape.server.device.states import State

from support import start_server, wait_until

from crcl_support import RawClient, command, field, pose
from test_gateway import MOVE
from test_restart import GatewayProcess, _free_port

SLOW = '<TransSpeed xsi:type="TransSpeedRelativeType"><Fraction>0.02</Fraction></TransSpeed>'


def starve_until_unlocked(gateway, server) -> None:
    """The gateway's process stopped (no keep-alive goes out) until the device has ended its
    session and freed the lock."""
    os.kill(gateway.process.pid, signal.SIGSTOP)
    try:
        wait_until(lambda: not server.device.status().locked, timeout=20)
    finally:
        os.kill(gateway.process.pid, signal.SIGCONT)


@pytest.fixture
def paced():
    """Motions last as long as on the arm (lock-step at real-time pace)."""
    running = start_server(lockstep_pace=1.0)
    yield running
    running.stop(grace=None)


def test_a_blocked_gateway_loop_keeps_its_lock(server, gateway, client):
    """The gateway's loop does nothing for 3 s (past the device's 2 s keep-alive timeout):
    the keep-alives go out from the core's keeper threads all the same."""
    holder = server.device.status().lock_holder
    gateway.loop.call_soon_threadsafe(time.sleep, 3.0)
    time.sleep(3.5)
    assert server.device.status().lock_holder == holder
    posted = client.run("Message", 2, "<Message>still here</Message>")   # needs the lease
    assert field(posted, "CommandState") == "CRCL_Done", posted


def test_a_lost_lock_is_an_error_until_init_canon_takes_it_again(paced):
    port = _free_port()
    gateway = GatewayProcess(paced.target, port)
    client = RawClient(port, timeout=30)
    try:
        assert field(client.run("InitCanon", 1), "CommandState") == "CRCL_Done"
        client.run("SetTransSpeed", 2, SLOW)
        client.send(command("MoveTo", 3, MOVE.format("true") + pose(0.5, 0.3, 0.5)))
        wait_until(lambda: paced.device.state is State.MOVING, timeout=20)
        starve_until_unlocked(gateway, paced)
        ended = client.wait_done(3)
        assert field(ended, "CommandState") == "CRCL_Error"
        lost = field(ended, "StateDescription")
        assert "the lock is lost" in lost and "no keep-alive for 2 s" in lost, lost
        lost = lost.split("; the device's state is")[0]     # (the state stream may lag)
        again = client.status()                             # and so says every status
        assert field(again, "CommandState") == "CRCL_Error"
        assert field(again, "StateDescription").startswith(lost)
        later = client.run("Dwell", 4, "<DwellTime>0</DwellTime>")
        assert field(later, "CommandState") == "CRCL_Error"
        assert field(later, "StateDescription").startswith(lost)
        assert not paced.device.status().locked             # nothing took it back
        assert field(client.run("EndCanon", 5), "CommandState") == "CRCL_Done"
        assert field(client.run("InitCanon", 6), "CommandState") == "CRCL_Done"
        assert paced.device.status().locked
        done = client.run("MoveTo", 7, MOVE.format("false") + pose(0.5, 0.1, 0.6))
        assert field(done, "CommandState") == "CRCL_Done", done
    finally:
        client.close()
        gateway.stop()


def test_a_lock_lost_during_init_canon_is_its_error_and_the_next_takes_it(paced):
    """InitCanon fetching the cell's gripper (a tool change: motions of seconds) loses the
    lock on the way: it ends in CRCL_Error naming the loss, never as a gateway error (it
    was "AttributeError: 'NoneType' object has no attribute 'prepare'" when the loss came
    between its steps), and the next InitCanon, sent at once, takes the lock again once the
    device has stopped the arm (it was refused: "Lock is not valid in state moving")."""
    port = _free_port()
    gateway = GatewayProcess(paced.target, port, "--end-effector", "gripper")
    client = RawClient(port, timeout=60)
    try:
        client.send(command("InitCanon", 1))
        wait_until(lambda: paced.device.state is State.MOVING, timeout=30)
        starve_until_unlocked(gateway, paced)
        ended = client.wait_done(1)
        assert field(ended, "CommandState") == "CRCL_Error", ended
        why = field(ended, "StateDescription")
        assert "gateway error" not in why and "no keep-alive for 2 s" in why, why
        again = client.run("InitCanon", 2, timeout=120)
        assert field(again, "CommandState") == "CRCL_Done", again
        assert paced.device.status().locked
    finally:
        client.close()
        gateway.stop()


def test_get_status_is_answered_while_a_move_screw_is_computed(server, gateway, client):
    """The helix waits for a worker thread the test holds: meanwhile another connection's
    GetStatus is answered, and the screw does not start; released, it completes."""
    gate = threading.Event()
    workers = concurrent.futures.ThreadPoolExecutor(max_workers=1)
    workers.submit(gate.wait)
    asyncio.run_coroutine_threadsafe(_use(workers), gateway.loop).result(5)
    try:
        client.send(command("MoveScrew", 2, "<AxialDistanceScrew>0.01</AxialDistanceScrew>"
                                            "<Turn>1.5</Turn>"))
        other = RawClient(gateway.port)
        for _ in range(100):                                # a second's worth of polls
            assert field(other.status(), "CommandState")
            assert server.device.state is State.RESTING     # the screw has not started
            time.sleep(0.01)
        other.close()
        assert field(client.status(), "CommandState") == "CRCL_Working"
    finally:
        gate.set()
    done = client.wait_done(2)
    assert field(done, "CommandState") == "CRCL_Done", done


async def _use(workers: concurrent.futures.Executor) -> None:
    asyncio.get_running_loop().set_default_executor(workers)


def test_a_screw_past_the_point_bound_is_refused_before_anything_is_computed(client):
    refused = client.run("MoveScrew", 2, "<AxialDistanceScrew>0</AxialDistanceScrew>"
                                         "<Turn>1000</Turn>")
    assert field(refused, "CommandState") == "CRCL_Error"
    assert "at most 2000" in field(refused, "StateDescription")


def test_every_device_call_names_the_gateway_and_the_crcl_peer(proxied):
    proxy, _, client = proxied
    peer = "crcl 127.0.0.1:%d" % client.sock.getsockname()[1]
    by_method = {}
    for method, metadata in proxy.metadata:
        by_method.setdefault(method, []).append(metadata)
    for method in ("Connect", "Lock", "Activate", "GetUnits"):
        for metadata in by_method[method]:
            assert metadata.get("landscape-client") == "crcl-gateway", method
            assert urllib.parse.unquote(metadata["landscape-on-behalf-of"]) == peer, method
    for method in ("Subscribe", "StreamState"):               # the gateway's own feeds
        assert by_method[method][0].get("landscape-client") == "crcl-gateway", method

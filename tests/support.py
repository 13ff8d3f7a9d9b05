"""Helpers shared by the tests: servers, sessions, stubs, waiting."""
from __future__ import annotations

import contextlib
import math
import queue
import subprocess
import sys
import textwrap
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import grpc
from google.rpc import error_details_pb2
from grpc_status import rpc_status

import numpy as np
import pytest

from landscape.cell.certs import CertFiles, make_certificates
from landscape.cell.tokens import make_tokens
from landscape.client import ClientTLS, Session, read_token
from landscape.robot.kinematics import Kinematics
from landscape.sim.recorder import read_recording
from landscape.server.app import RunningServer, serve
from landscape.server.config import SecurityConfig, ServerConfig
from landscape.v1 import (control_pb2, device_service_pb2_grpc, digital_io_service_pb2_grpc,
                          end_effector_pb2, event_service_pb2, event_service_pb2_grpc, motion_pb2,
                          sensing_pb2, types_pb2)


ROOT = Path(__file__).resolve().parents[1]


def installed(path: Path, target: str, what: str) -> Path:
    """`path`, which `make <target>` builds (the downloads are the Makefile's, never a
    test's); skips the test, naming the command, when it is not built."""
    if not path.exists():
        pytest.skip(f"{what} is not built here: `make {target}` builds it "
                    f"({path.relative_to(ROOT)})")
    return path


# A lock holder in a process of its own (`python -c HOLDER_SCRIPT TARGET`), to be killed or
# frozen: "doomed" locks, activates, says "active" and waits.
HOLDER_SCRIPT = textwrap.dedent("""
    import sys, time, grpc
    from landscape.client import Session
    from landscape.v1 import control_pb2, device_service_pb2_grpc
    session = Session(grpc.insecure_channel(sys.argv[1]), "doomed").open()
    session.lock()
    device_service_pb2_grpc.DeviceServiceStub(session.channel).Activate(
        control_pb2.ActivateRequest(), timeout=10)
    print("active", flush=True)
    time.sleep(600)
""")


def start_server(**config) -> RunningServer:
    """A device server on a free loopback port, its simulated arm on the lock-step clock."""
    return serve(ServerConfig(port=0, clock="lockstep", **config))


@dataclass
class Keys:
    """A development CA and server certificate, and one token file per role."""
    certs: CertFiles
    tokens: Path                  # the folder of <role>.tokens

    def token(self, role: str) -> str:
        return read_token(self.tokens / f"{role}.tokens")

    def token_file(self, role: str) -> Path:
        return self.tokens / f"{role}.tokens"

    def tls(self) -> ClientTLS:
        return ClientTLS(ca=str(self.certs.ca))


def make_keys(folder: Path, hosts=(), opcua: bool = False) -> Keys:
    certs = make_certificates(folder / "certs", hosts=hosts, opcua=opcua)
    make_tokens(folder / "tokens")
    return Keys(certs, folder / "tokens")


def start_secured_server(keys: Keys, **config) -> RunningServer:
    """start_server with TLS (the keys' server certificate) and the keys' role tokens."""
    return start_server(security=SecurityConfig(
        tls_cert=str(keys.certs.server_cert), tls_key=str(keys.certs.server_key),
        tokens=str(keys.tokens)), **config)


@contextlib.contextmanager
def spawned_server(*args: str):
    """The device server as users start it (`python -m landscape.server`, real-time clock) on
    a free port; yields its target and checks that it stops cleanly (exit code 0)."""
    proc = subprocess.Popen([sys.executable, "-m", "landscape.server", "--port", "0", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        for line in proc.stdout:   # pybullet prints its own lines on stdout first
            if "listening on" in line:
                break
        else:
            raise AssertionError("the server exited without listening")
        yield line.rsplit(" ", 1)[-1].strip()
    finally:
        proc.terminate()
        code = proc.wait(timeout=20)
    assert code == 0, f"the server exited with {code}"


@contextlib.contextmanager
def memory_cap(headroom: int = 3 << 30):
    """This process's address space capped at what it maps now plus `headroom` bytes while the
    block runs (RLIMIT_AS, Linux): a runaway allocation in an in-process server fails with
    MemoryError, which a test sees as a wrong status, instead of exhausting the machine."""
    import resource
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    with open("/proc/self/statm") as statm:
        mapped = int(statm.read().split()[0]) * resource.getpagesize()
    cap = mapped + headroom if hard == resource.RLIM_INFINITY else min(mapped + headroom, hard)
    resource.setrlimit(resource.RLIMIT_AS, (cap, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


def child_pids(pid: int) -> list[int]:
    """The children of process `pid`, whichever of its threads started them (Linux /proc)."""
    found = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            found += [int(child) for child in (task / "children").read_text().split()]
        except FileNotFoundError:   # a thread that ended meanwhile
            pass
    return found


def assert_serving(channel) -> None:
    """The server behind `channel` answers its health check SERVING."""
    from grpc_health.v1 import health_pb2, health_pb2_grpc
    health = health_pb2_grpc.HealthStub(channel).Check(health_pb2.HealthCheckRequest(),
                                                       timeout=5)
    assert health.status == health_pb2.HealthCheckResponse.SERVING


def cell_file(directory, replacements: dict[str, str]) -> str:
    """A copy of the default cell file with some of its text replaced; returns its path."""
    from importlib import resources
    text = resources.files("landscape.robot").joinpath("cells/default.toml").read_text()
    for old, new in replacements.items():
        assert old in text, old
        text = text.replace(old, new)
    path = directory / "cell.toml"
    path.write_text(text)
    return str(path)


def distance_to_line(points, a, b) -> np.ndarray:
    direction = (b - a) / np.linalg.norm(b - a)
    rel = points - a
    return np.linalg.norm(rel - np.outer(rel @ direction, direction), axis=1)


def stubs(channel):
    return (device_service_pb2_grpc.DeviceServiceStub(channel),
            digital_io_service_pb2_grpc.DigitalIOServiceStub(channel),
            event_service_pb2_grpc.EventServiceStub(channel))


def error_info(error: grpc.RpcError) -> error_details_pb2.ErrorInfo:
    status = rpc_status.from_call(error)
    info = error_details_pb2.ErrorInfo()
    assert status.details[0].Unpack(info)
    return info


def wait_until(predicate, timeout: float = 5.0, period: float = 0.005) -> float:
    """Seconds it took for predicate() to hold; AssertionError after `timeout`."""
    start = time.monotonic()
    while not predicate():
        if time.monotonic() - start > timeout:
            raise AssertionError(f"not true within {timeout} s")
        time.sleep(period)
    return time.monotonic() - start


def locked_session(server, name: str = "supervisor") -> Session:
    channel = grpc.insecure_channel(server.target)
    session = Session(channel, name).open()
    session.lock()
    return session


def bus_history(server) -> list:
    """Every event a server's bus still keeps, oldest first (domain events)."""
    subscription = server.bus.subscribe(after_sequence=0)
    events = []
    while (event := subscription.get(timeout=0.1)) is not None:
        events.append(event)
    subscription.close()
    return events


def activate(session: Session) -> None:
    device_service_pb2_grpc.DeviceServiceStub(session.channel).Activate(
        control_pb2.ActivateRequest(), timeout=10)


class Arm:
    """An active arm: server (lock-step, `pace` and `config` as in ServerConfig), lock holder,
    stubs, an event subscription from the first event, and the recorder writing into
    tmp_path."""

    def __init__(self, tmp_path, pace=None, **config):
        self.record = tmp_path / "record.mcap"
        cell = cell_file(tmp_path, {'path = "var/records/cs8.mcap"': f'path = "{self.record}"'})
        self.server = start_server(cell=cell, lockstep_pace=pace, **config)
        self.session = locked_session(self.server)
        activate(self.session)
        self.device, _, events = stubs(self.session.channel)
        self.events = events.Subscribe(event_service_pb2.SubscribeRequest(after_sequence=0))
        self._received: queue.Queue = queue.Queue()
        threading.Thread(target=self._read_events, daemon=True, name="arm-events").start()
        self.kin = Kinematics(self.server.device.arm)
        self.link = self.server.link
        self.link.between_cycles(lambda c: c.rec_init())

    def close(self):
        self.events.cancel()
        self.session.close()
        self.server.stop(grace=None)

    def _read_events(self):
        try:
            for reply in self.events:
                self._received.put(reply.event)
        except grpc.RpcError:
            pass
        self._received.put(None)

    def next_event(self, timeout: float = 60.0):
        """The next event of the subscription (landscape.v1 Event); AssertionError after
        `timeout` or if the stream ended."""
        try:
            event = self._received.get(timeout=timeout)
        except queue.Empty:
            raise AssertionError(f"no event within {timeout} s") from None
        if event is None:
            raise AssertionError("event stream ended")
        return event

    def wait_command(self, command_id, phases=("command_done", "command_failed"),
                     timeout: float = 120.0) -> list:
        """The events of `command_id` up to one of `phases`; AssertionError after `timeout`."""
        seen, deadline = [], time.monotonic() + timeout
        while True:
            try:
                event = self._received.get(timeout=max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                raise AssertionError(f"no {'/'.join(phases)} for {command_id} within "
                                     f"{timeout} s; saw {[e.event_id for e in seen]}") from None
            if event is None:
                raise AssertionError("event stream ended")
            if event.HasField("command") and event.command.command_id == command_id:
                seen.append(event)
                if event.event_id in phases:
                    return seen

    def record_start(self):
        self.link.between_cycles(lambda c: c.rec_start())

    def recorded_tips(self) -> np.ndarray:
        self.link.between_cycles(lambda c: (c.rec_stop(), c.rec_store()))
        data = read_recording(str(self.record))
        return self.kin.forward(data["fbk_pos"])[:, :3, 3], data

    def joints(self) -> np.ndarray:
        return self.server.device.feedback().position

    def tip(self) -> np.ndarray:
        return self.kin.forward(self.joints())

    def tool_tip(self) -> np.ndarray:
        """The tool tip (4x4, m) in the base frame, through the present tool offset."""
        return self.tip() @ self.server.device.settings.tool_offset

    def move_down_to(self, x: float, y: float, z: float) -> list:
        """A joint move putting the tool tip at (x, y, z) (m, world), pointing down; its
        events."""
        reply = self.device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
            frame=types_pb2.REFERENCE_FRAME_WORLD_CARTESIAN_FRAME,
            values=[x, y, z, math.pi, 0, 0]), timeout=30)
        events = self.wait_command(reply.ret_val.command_id)
        assert events[-1].event_id == "command_done", events[-1]
        return events

    def reading(self, sensor: str = "force_sensor") -> np.ndarray:
        return np.array(self.device.GetSensorReading(
            sensing_pb2.GetSensorReadingRequest(sensor_type=sensor), timeout=10).current_data)

    def get_tool(self, name: str) -> None:
        self.device.GetTool(end_effector_pb2.GetToolRequest(tool_id=name), timeout=120)

    def history(self) -> list:
        """Every event the bus still keeps, oldest first."""
        return bus_history(self.server)


def random_walk(arm, start: np.ndarray, n: int, seed: int, step: float) -> np.ndarray:
    """n waypoints (n, 6) of a seeded random walk from `start`, each joint kept inside 80 % of
    the arm's range: the paths the timing tests draw."""
    rng = np.random.default_rng(seed)
    W = [np.asarray(start, dtype=float)]
    for _ in range(n - 1):
        W.append(np.clip(W[-1] + rng.normal(0.0, step, 6), 0.8 * arm.lower, 0.8 * arm.upper))
    return np.array(W)


def tool_line(arm, start_xyz, dy: float, near: np.ndarray):
    """(dense joint waypoints, tool_path) of a straight line of a 15 cm tool pointing down from
    `start_xyz` (m, base frame), `dy` m along y, its first configuration nearest `near`: the
    Cartesian path the timing tests time."""
    from landscape.robot.units import pose_matrix
    from landscape.server.planning.motion.cartesian import straight_line, tool_pose
    kin = Kinematics(arm)
    tcp = pose_matrix([0.0, 0.0, 0.15], [0.0, 0.0, 0.0])
    start = pose_matrix(list(start_xyz), [np.pi, 0.0, 0.0])
    q0, _ = kin.reverse(start @ np.linalg.inv(tcp), near)
    goal = start.copy()
    goal[:3, 3] += [0.0, dy, 0.0]
    return straight_line(kin, q0, goal, tcp=tcp), tool_pose(kin, tcp)

"""The real gateway in a thread of the test process (its own event loop), before a real device
server, and a CRCL client written from the specification (raw sockets, not gateway code)."""
from __future__ import annotations

import asyncio
import functools
import re
import socket
import threading
import time
from pathlib import Path

import grpc
import numpy as np
import pytest
from lxml import etree
from scipy.spatial.transform import Rotation

from landscape.gateway.device import CrclDevice
from landscape.client import Endpoint
from landscape.gateway.schemas import INSTALL_HINT, SchemaSet, default_directory
from landscape.gateway.server import Gateway
from landscape.gateway.session import GatewayOptions
from landscape.v1 import state_service_pb2, state_service_pb2_grpc, types_pb2

# NIST's schemas as `make install` installs them (crcl4java-base 1.8: the 2018 revision), the
# gateway's default; every status a test reads is checked against them when they are there.
XSD = default_directory()
needs_xsd = pytest.mark.skipif(XSD is None, reason=f"NIST's CRCL schemas are not installed: "
                                                   f"{INSTALL_HINT}")
# The project's reference copy of NIST's 2021 revision and NIST's examples, beside the
# checkout (../shared/crcl), never copied in: the tests that use them skip without them.
SHARED = Path(__file__).resolve().parents[3] / "shared" / "crcl"
XSD_2021 = SHARED / "xsd" if (SHARED / "xsd" / "CRCLCommands.xsd").is_file() else None
EXAMPLES = SHARED / "examples"
needs_examples = pytest.mark.skipif(not EXAMPLES.is_dir(),
                                    reason="NIST's CRCL examples (../shared/crcl/examples) are absent")


class RunningGateway:
    """The gateway serving on a free loopback port, stopped by close()."""

    def __init__(self, device_target: str, state_rate_hz: float = 100.0,
                 schemas: Path | None = XSD, **options):
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True,
                                       name="crcl-gateway")
        self.thread.start()
        self.schemas = schemas
        schemas = SchemaSet(schemas) if schemas else None
        self.options = GatewayOptions(schemas=schemas, **options)
        self.link, self.gateway = self.run(self._start(device_target, state_rate_hz))
        self.port = self.gateway.port

    async def _start(self, target: str, state_rate_hz: float):
        link = CrclDevice(Endpoint(target), state_rate_hz)
        await link.start()
        gateway = await Gateway(link, self.options).serve("127.0.0.1", 0)
        return link, gateway

    def run(self, coroutine, timeout: float = 30.0):
        return asyncio.run_coroutine_threadsafe(coroutine, self.loop).result(timeout)

    def close(self) -> None:
        async def stop():
            await self.gateway.close()
            await self.link.close()
        self.run(stop())
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(timeout=10)


class ToolWatch:
    """The device's tool pose every few controller cycles (a state stream of its own, opened
    at the present), with the controller's (simulated) time. Open one just before the motion
    to watch, and call moved() after it, so the samples cover all of it."""

    def __init__(self, target: str, rate_hz: float = 100.0):
        self.channel = grpc.insecure_channel(target)
        self.samples: list[tuple[float, np.ndarray]] = []
        self.call = state_service_pb2_grpc.StateServiceStub(self.channel).StreamState(
            state_service_pb2.StreamStateRequest(
                rate_hz=rate_hz, frame=types_pb2.REFERENCE_FRAME_WORLD_CARTESIAN_FRAME,
                units=types_pb2.Units(linear=types_pb2.LINEAR_UNIT_METERS,
                                      angular=types_pb2.ANGULAR_UNIT_RADIANS)))
        threading.Thread(target=self._read, daemon=True).start()
        self._until(lambda: len(self.samples) >= 3, "no samples")

    def _read(self):
        try:
            for reply in self.call:
                if reply.WhichOneof("message") == "sample":
                    p = reply.sample.tool_pose
                    self.samples.append((reply.sample.controller_time,
                                         np.array([p.x, p.y, p.z, p.roll, p.pitch, p.yaw])))
        except grpc.RpcError:
            pass

    def _until(self, predicate, what: str, timeout: float = 30.0) -> None:
        deadline = time.monotonic() + timeout
        while not predicate():
            assert time.monotonic() < deadline, what
            time.sleep(0.01)

    def moved(self) -> tuple[np.ndarray, np.ndarray]:
        """Once the samples show the tool moved and at rest again: (controller times (K,),
        tool poses (K, 6))."""
        def at_rest_elsewhere():
            last = [p for _, p in self.samples[-5:]]
            return (len(last) == 5 and np.ptp(np.array(last), axis=0).max() < 1e-9
                    and np.abs(last[-1] - self.samples[0][1]).max() > 1e-6)
        self._until(at_rest_elsewhere, "the tool did not move and come to rest")
        self.call.cancel()
        self.channel.close()
        return np.array([t for t, _ in self.samples]), np.array([p for _, p in self.samples])

    def peak_turn_rate(self, window: int = 5) -> float:
        """The fastest the tool turned (rad/s of controller time) over `window` samples."""
        times, tool = self.moved()
        rotations = Rotation.from_euler("xyz", tool[:, 3:])
        angles = (rotations[window:] * rotations[:-window].inv()).magnitude()
        return float(np.max(angles / (times[window:] - times[:-window])))


# ---- a CRCL client from the specification ------------------------------------------------------

XSI = 'xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"'


def command(kind: str, command_id: int, body: str = "") -> bytes:
    return (f'<?xml version="1.0" encoding="UTF-8"?>\n<CRCLCommandInstance {XSI}>'
            f'<CRCLCommand xsi:type="{kind}Type"><CommandID>{command_id}</CommandID>{body}'
            f'</CRCLCommand></CRCLCommandInstance>').encode()


def pose(x, y, z, xaxis=(1, 0, 0), zaxis=(0, 0, -1), tag="EndPosition") -> str:
    return (f"<{tag}><Point><X>{x}</X><Y>{y}</Y><Z>{z}</Z></Point>"
            f"<XAxis><I>{xaxis[0]}</I><J>{xaxis[1]}</J><K>{xaxis[2]}</K></XAxis>"
            f"<ZAxis><I>{zaxis[0]}</I><J>{zaxis[1]}</J><K>{zaxis[2]}</K></ZAxis></{tag}>")


class RawClient:
    """Sends bytes; reads CRCLStatus documents back, found by their closing tag, each checked
    against CRCLStatus.xsd of `schemas` (default: the installed ones; None: unchecked)."""

    def __init__(self, port: int, timeout: float = 30.0, schemas: Path | None = XSD):
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=timeout)
        self.buffer = b""
        self.next_id = 1000
        self.schemas = schemas

    def send(self, data: bytes) -> None:
        self.sock.sendall(data)

    def read_status(self) -> str:
        end = b"</CRCLStatus>"
        while end not in self.buffer:
            chunk = self.sock.recv(65536)
            if not chunk:
                raise ConnectionError("the gateway closed the connection")
            self.buffer += chunk
        i = self.buffer.index(end) + len(end)
        raw, self.buffer = self.buffer[:i], self.buffer[i:]
        check_status(raw, self.schemas)
        return raw.decode().strip()

    def status(self) -> str:
        self.next_id += 1
        self.send(command("GetStatus", self.next_id))
        return self.read_status()

    def wait_done(self, command_id: int, timeout: float = 60.0) -> str:
        """Poll until the command is Done or Error; returns that status."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            text = self.status()
            if field(text, "CommandID") == str(command_id) and \
                    field(text, "CommandState") in ("CRCL_Done", "CRCL_Error"):
                return text
            time.sleep(0.01)
        raise AssertionError(f"command {command_id} not finished in {timeout} s: {text}")

    def run(self, kind: str, command_id: int, body: str = "", timeout: float = 60.0) -> str:
        self.send(command(kind, command_id, body))
        return self.wait_done(command_id, timeout)

    def close(self) -> None:
        self.sock.close()


@functools.cache
def _status_schema(directory: Path) -> etree.XMLSchema:
    return etree.XMLSchema(etree.parse(str(directory / "CRCLStatus.xsd"),
                                       etree.XMLParser(no_network=True)))


def check_status(raw: bytes, schemas: Path | None = XSD) -> None:
    """Every status the gateway writes must validate against CRCLStatus.xsd (of `schemas`)."""
    if schemas is None:
        return
    schema = _status_schema(schemas)
    document = etree.fromstring(raw.strip())
    assert schema.validate(document), (schema.error_log, raw)


def field(status: str, tag: str) -> str | None:
    match = re.search(rf"<{tag}>(.*?)</{tag}>", status, re.S)
    return match.group(1) if match else None


def program(commands: list[tuple[str, str]]) -> bytes:
    """A CRCLProgram: InitCanon, (kind, body) middle commands, EndCanon; CommandIDs 1, 2, ..."""
    middle = "".join(f'<MiddleCommand xsi:type="{kind}Type"><CommandID>{i}</CommandID>{body}'
                     f"</MiddleCommand>" for i, (kind, body) in enumerate(commands, start=2))
    return (f'<?xml version="1.0" encoding="UTF-8"?>\n<CRCLProgram {XSI}><InitCanon><CommandID>1'
            f"</CommandID></InitCanon>{middle}<EndCanon><CommandID>{len(commands) + 2}</CommandID>"
            f"</EndCanon></CRCLProgram>").encode()


def reachable_program() -> bytes:
    """Moves, waypoints and settings the TX90 can do, in millimetres and degrees."""
    return program([
        ("SetLengthUnits", "<UnitName>millimeter</UnitName>"),
        ("SetAngleUnits", "<UnitName>degree</UnitName>"),
        ("SetTransSpeed", '<TransSpeed xsi:type="TransSpeedAbsoluteType"><Setting>500</Setting>'
                          "</TransSpeed>"),
        ("SetEndPoseTolerance", "<Tolerance><XPointTolerance>1</XPointTolerance><YPointTolerance>1"
                                "</YPointTolerance><ZPointTolerance>1</ZPointTolerance><XAxisTolerance>1"
                                "</XAxisTolerance><ZAxisTolerance>1</ZAxisTolerance></Tolerance>"),
        ("MoveTo", "<MoveStraight>false</MoveStraight>" + pose(500, 100, 600)),
        ("MoveTo", "<MoveStraight>true</MoveStraight>" + pose(500, -100, 600)),
        ("MoveThroughTo", "<MoveStraight>false</MoveStraight>" + pose(550, 0, 500, tag="Waypoint")
         + pose(500, 150, 550, tag="Waypoint") + "<NumPositions>2</NumPositions>"),
        ("Dwell", "<DwellTime>0.05</DwellTime>"),
        ("Message", "<Message>program half done</Message>"),
        ("ActuateJoints", '<ActuateJoint><JointNumber>1</JointNumber><JointPosition>10'
                          '</JointPosition><JointDetails xsi:type="JointSpeedAccelType">'
                          "<JointSpeed>30</JointSpeed></JointDetails></ActuateJoint>"),
        ("MoveTo", "<MoveStraight>true</MoveStraight>" + pose(450, 0, 550)),
    ])

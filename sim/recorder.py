"""The controller's recorder (LLI s7.4 section 5.5), writing MCAP.

The cycle calls `Recorder.append` once per cycle while recording; it only copies into buffers
allocated up front (sized from `max_seconds`), keeps every `every_nth` cycle (the LLI's "record
frequency in percent of the cycle frequency": 1 is 100 %, 2 is 50 %, ...), and stops silently
when the buffers are full. `store` runs on the asynchronous side and does all the I/O.

File layout (readable by Foxglove and other MCAP viewers): JSON messages with JSON schemas on

- `/joint_command`: `{timestamp: {sec, nsec}, name: [str], position: [rad], velocity: [rad/s]}`
- `/joint_state`:   `{timestamp: {sec, nsec}, name: [str], position: [rad], velocity: [rad/s],
  effort: [N*m]}`

one message of each per recorded cycle, log_time = publish_time = the cycle's time stamp in ns
(simulated time for the simulator, so the file starts near t = 0), and a metadata record
"landscape.recorder" with joint_count, joint_names, every_nth, cycle_time.

Given the arm, the file is also what Foxglove draws in 3D, in its own well-known schemas
(protobuf, from foxglove-sdk: the same the live bridge serves, bridges/foxglove/):

- `/tf`: `foxglove.FrameTransforms`, every link in its parent (robot/link_frames.py) from
  the measured joints, at most 50 a second (what a 3D view shows; the plots have every cycle);
- `/robot_description`: the arm's URDF once, at the first cycle, as `{data: str}` (the shape
  Foxglove's URDF layer reads from a topic).
"""
from __future__ import annotations

import json
import math
import os
import tempfile
from pathlib import Path

import numpy as np

COMMAND_TOPIC = "/joint_command"
STATE_TOPIC = "/joint_state"
TF_TOPIC = "/tf"
DESCRIPTION_TOPIC = "/robot_description"
TF_PERIOD_NS = 20_000_000   # /tf at most every 20 ms of the recording
METADATA_NAME = "landscape.recorder"

_FIELDS = ("cmd_pos", "cmd_vel", "fbk_pos", "fbk_vel", "fbk_torque")
# Storing works in small pieces (samples converted at a time, bytes compressed at a time) so
# that it never holds the GIL for long when it runs beside a cycle (cycle_process.SLOW_CALLS).
_BLOCK = 256
_CHUNK_BYTES = 128 * 1024


def _array(unit: str) -> dict:
    return {"type": "array", "items": {"type": "number"}, "description": unit}


_HEADER = {
    "timestamp": {"type": "object", "description": "cycle time stamp",
                  "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}},
    "name": {"type": "array", "items": {"type": "string"}, "description": "joint names"},
}
_COMMAND_SCHEMA = {
    "title": "landscape.JointCommand", "type": "object",
    "properties": {**_HEADER, "position": _array("rad"), "velocity": _array("rad/s")},
}
DESCRIPTION_SCHEMA = {
    "title": "landscape.RobotDescription", "type": "object",
    "properties": {"data": {"type": "string", "description": "the arm as URDF"}},
}
_STATE_SCHEMA = {
    "title": "landscape.JointState", "type": "object",
    "properties": {**_HEADER, "position": _array("rad"), "velocity": _array("rad/s"),
                   "effort": _array("N*m")},
}


class Recorder:
    """Records joint commands and feedback per cycle; stores them as one MCAP file.

    path: the file `store` writes. every_nth: keep one cycle in N (N >= 1), starting with the
    first cycle after `start`. max_seconds: longest recording, in seconds of cycle time; the
    buffers hold ceil(max_seconds / (cycle_time * every_nth)) samples. joint_count: n, the
    length of every joint array passed to `append`. cycle_time (s) only sizes the buffers and
    is written to the file's metadata; joint_names default to joint_1 .. joint_n. arm (an
    ArmModel): also write its links' transforms and URDF (module docstring).

    Life cycle: `start` clears and starts a recording, `stop` ends it, `store` writes what the
    last recording holds (also while it is still running, or empty if none was ever started).
    Not thread-safe: `append` and `store` must not run at the same time (in the LLI they live
    in the synchronous and asynchronous contexts of one controller, which never overlap here).
    """

    def __init__(self, path: str, every_nth: int = 1, max_seconds: float = 60.0,
                 joint_count: int = 6, *, cycle_time: float = 0.004,
                 joint_names: list[str] | None = None, arm=None):
        if every_nth < 1:
            raise ValueError("every_nth must be >= 1")
        if max_seconds <= 0 or cycle_time <= 0:
            raise ValueError("max_seconds and cycle_time must be positive")
        self.path = str(path)
        self.every_nth = int(every_nth)
        self.max_seconds = float(max_seconds)
        self.cycle_time = float(cycle_time)
        self.arm = arm
        self.joint_names = list(joint_names) if joint_names else [
            f"joint_{i + 1}" for i in range(joint_count)]
        if len(self.joint_names) != joint_count:
            raise ValueError("joint_names needs joint_count names")
        # A tiny epsilon keeps 60 s / 4 ms at 15000 samples, not 15001, despite rounding.
        self.capacity = max(1, math.ceil(max_seconds / (cycle_time * every_nth) - 1e-9))
        self._t = np.zeros(self.capacity)
        self._buf = {name: np.zeros((self.capacity, joint_count)) for name in _FIELDS}
        # Direct references: the per-cycle path does no dictionary look-ups.
        self._cmd_pos, self._cmd_vel, self._fbk_pos, self._fbk_vel, self._fbk_torque = (
            self._buf[name] for name in _FIELDS)
        self._count = 0
        self._skip = 0
        self._recording = False
        self._full = False

    # -- state
    @property
    def recording(self) -> bool:
        """True between `start` and `stop` (or until the buffers filled up)."""
        return self._recording

    @property
    def full(self) -> bool:
        """True once the last recording filled its buffers and stopped by itself."""
        return self._full

    def __len__(self) -> int:
        """Samples held by the last recording."""
        return self._count

    # -- control (either context)
    def start(self) -> None:
        """Start a new recording (the previous one is dropped); no-op while recording."""
        if self._recording:
            return
        self._count = 0
        self._skip = 0
        self._full = False
        self._recording = True

    def stop(self) -> None:
        """Stop recording; what was recorded stays until the next `start`."""
        self._recording = False

    # -- the synchronous context, every cycle
    def append(self, t: float, cmd_pos, cmd_vel, fbk_pos, fbk_vel, fbk_torque) -> None:
        """Record one cycle: t in s; the others are arrays of shape (joint_count,) in rad, rad/s,
        N*m. Does nothing when not recording or when this cycle is not one to keep."""
        if not self._recording:
            return
        if self._skip:
            self._skip -= 1
            return
        self._skip = self.every_nth - 1
        i = self._count
        self._t[i] = t
        self._cmd_pos[i] = cmd_pos
        self._cmd_vel[i] = cmd_vel
        self._fbk_pos[i] = fbk_pos
        self._fbk_vel[i] = fbk_vel
        self._fbk_torque[i] = fbk_torque
        self._count = i + 1
        if self._count == self.capacity:
            self._recording = False
            self._full = True

    # -- the asynchronous context
    def data(self) -> dict[str, np.ndarray]:
        """A copy of the last recording, in the shapes `read_recording` returns."""
        n = self._count
        out = {"t": self._t[:n].copy()}
        out.update((name, buf[:n].copy()) for name, buf in self._buf.items())
        return out

    def store(self) -> str:
        """Write the last recording to `path` atomically (temporary file, then rename); return
        the path. Storing again rewrites the same file with what the recording holds then."""
        from mcap.writer import Writer  # only the asynchronous side pays for the import

        target = Path(self.path)
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp")
        try:
            with os.fdopen(fd, "wb") as stream:
                writer = Writer(stream, chunk_size=_CHUNK_BYTES)
                writer.start(profile="", library="landscape.sim.recorder")
                self._write(writer)
                writer.finish()
                stream.flush()
                os.fsync(stream.fileno())
            os.replace(tmp, target)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        return str(target)

    def _write(self, writer) -> None:
        def channel(topic: str, schema: dict) -> int:
            schema_id = writer.register_schema(name=schema["title"], encoding="jsonschema",
                                               data=json.dumps(schema).encode())
            return writer.register_channel(topic=topic, message_encoding="json",
                                           schema_id=schema_id)

        cmd_channel = channel(COMMAND_TOPIC, _COMMAND_SCHEMA)
        state_channel = channel(STATE_TOPIC, _STATE_SCHEMA)
        scene = _Scene(writer, self.arm, channel) if self.arm is not None else None
        writer.add_metadata(METADATA_NAME, {
            "joint_count": str(len(self.joint_names)),
            "joint_names": json.dumps(self.joint_names),
            "every_nth": str(self.every_nth),
            "cycle_time": repr(self.cycle_time),
        })
        d = self.data()  # a copy: the cycle may go on recording while we write
        names = self.joint_names
        for seq, (t, cmd_pos, cmd_vel, fbk_pos, fbk_vel, fbk_torque) in enumerate(_rows(d)):
            ns = round(t * 1e9)
            stamp = {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}
            # json writes floats with repr, so values read back bit-identical.
            cmd = {"timestamp": stamp, "name": names, "position": cmd_pos, "velocity": cmd_vel}
            state = {"timestamp": stamp, "name": names, "position": fbk_pos,
                     "velocity": fbk_vel, "effort": fbk_torque}
            writer.add_message(channel_id=cmd_channel, log_time=ns, publish_time=ns,
                               sequence=seq, data=json.dumps(cmd).encode())
            writer.add_message(channel_id=state_channel, log_time=ns, publish_time=ns,
                               sequence=seq, data=json.dumps(state).encode())
            if scene is not None:
                scene.add(seq, ns, fbk_pos)


class _Scene:
    """The 3D side of a recording: the URDF once, then every link's transform per cycle."""

    def __init__(self, writer, arm, channel):
        from foxglove.messages import FrameTransforms   # only a store with an arm pays for it

        from landscape.robot.arm import urdf
        from landscape.robot.link_frames import LinkFrames
        self.writer, self.frames, self.urdf = writer, LinkFrames.for_arm(arm), urdf(arm)
        schema = FrameTransforms.get_schema()
        schema_id = writer.register_schema(name=schema.name, encoding=schema.encoding,
                                           data=bytes(schema.data))
        self.tf = writer.register_channel(topic=TF_TOPIC, message_encoding=schema.encoding,
                                          schema_id=schema_id)
        self.description = channel(DESCRIPTION_TOPIC, DESCRIPTION_SCHEMA)
        self.due = None    # the time of the next /tf, ns
        self.count = 0

    def add(self, seq: int, ns: int, joints: list[float]) -> None:
        if seq == 0:
            self.writer.add_message(channel_id=self.description, log_time=ns, publish_time=ns,
                                    sequence=0, data=json.dumps({"data": self.urdf}).encode())
        if self.due is not None and ns < self.due:
            return
        self.due = ns + TF_PERIOD_NS
        self.writer.add_message(channel_id=self.tf, log_time=ns, publish_time=ns,
                                sequence=self.count, data=self.frames.messages(joints, ns).encode())
        self.count += 1


def _rows(data: dict[str, np.ndarray]):
    """(t, cmd_pos, cmd_vel, fbk_pos, fbk_vel, fbk_torque) per sample, as Python floats and
    lists, converted a block at a time: storing may run on a thread beside the cycle, and no
    single call here may hold the GIL for long."""
    for first in range(0, len(data["t"]), _BLOCK):
        block = slice(first, first + _BLOCK)
        yield from zip(data["t"][block].tolist(), *(data[name][block].tolist() for name in _FIELDS))


def read_recording(path: str) -> dict[str, np.ndarray]:
    """Read a file written by `Recorder.store`.

    Returns t (k,) in s (from the ns time stamps) and cmd_pos, cmd_vel, fbk_pos, fbk_vel,
    fbk_torque of shape (k, n), k the number of recorded cycles and n the joint count.
    """
    from mcap.reader import make_reader

    columns: dict[str, list] = {"t": [], **{name: [] for name in _FIELDS}}
    joint_count = 0
    with open(path, "rb") as stream:
        reader = make_reader(stream)
        for meta in reader.iter_metadata():
            if meta.name == METADATA_NAME:
                joint_count = int(meta.metadata["joint_count"])
        # File order is write order: one command then one state per cycle.
        for _, channel, message in reader.iter_messages(topics=[COMMAND_TOPIC, STATE_TOPIC],
                                                        log_time_order=False):
            msg = json.loads(message.data)
            if channel.topic == COMMAND_TOPIC:
                columns["t"].append(message.log_time / 1e9)
                columns["cmd_pos"].append(msg["position"])
                columns["cmd_vel"].append(msg["velocity"])
            else:
                columns["fbk_pos"].append(msg["position"])
                columns["fbk_vel"].append(msg["velocity"])
                columns["fbk_torque"].append(msg["effort"])
    if columns["cmd_pos"]:
        joint_count = len(columns["cmd_pos"][0])
    out = {"t": np.array(columns["t"], dtype=float)}
    for name in _FIELDS:
        out[name] = np.array(columns[name], dtype=float).reshape(len(columns[name]), joint_count)
    if any(len(out[name]) != len(out["t"]) for name in _FIELDS):
        raise ValueError(f"{path}: {COMMAND_TOPIC} and {STATE_TOPIC} counts differ")
    return out

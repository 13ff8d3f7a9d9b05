"""Live state: the feedback ring (feedback.py) fanned out to any number of watchers.

Runs on the server's event loop. The ring's wake-up pipe tells `StateHub` that cycles were
written; every waiting stream then takes what it is due:

- A stream asks for every n-th cycle (n from its rate). While it keeps up it gets exactly the
  cycles it is due, with no gaps, even when several arrive at once.
- A stream that falls more than `max_lag` cycles behind (a slow reader: its writes wait on
  flow control) jumps to the newest cycle and says how many it skipped: latest sample wins,
  nothing is queued for it, and nobody else waits for it. On the real-time clock `max_lag`
  (250 cycles, 1 s) lets a reader that stalls for a moment (a busy machine) catch up without a
  gap; on the lock-step clock, whose cycles outrun any reader, it is a few cycles, so a reader
  always sees the arm as it is now. (What a stalled reader finds queued in the transport
  besides is bounded by its own HTTP/2 flow-control window.)

Watchers cost no thread: they wait on one shared future that each wake-up replaces. The hub
listens to the pipe only while a stream is open: with nobody watching, the cycles' wake-ups
(one a millisecond on the fast clock) cost the event loop nothing (issue 31 item 5).
"""
from __future__ import annotations

import asyncio
from dataclasses import dataclass

import numpy as np

from landscape.server.api import convert
from landscape.server.errors import ParamError
from landscape.server.cycle.feedback import CMD, IO, MODEL_TAU, QD, SENSORS, SEQ, TAU, TIME, WALL, Q
from landscape.server.planning.targets import Frame
from landscape.robot.units import Units
from landscape.robot.pinocchio_model import PinocchioModel
from landscape.v1 import state_service_pb2 as pb

# rad: joints within this of where the arm stood are where it stands. An arm at rest still
# reads a new position every cycle (the simulation's round-off: 1e-23 rad), which would
# rebuild a position read's reply every 4 ms for nothing.
STILL = 1e-9


@dataclass(frozen=True)
class View:
    """How one stream wants its samples: every `period` cycles, the tool pose in `frame`
    (BASE or WORLD), lengths and angles in `units`, the readings of `sensors` (names)."""

    period: int
    frame: Frame
    units: Units
    sensors: tuple[str, ...] = ()


class StateHub:
    def __init__(self, device, workcell=None, max_lag: int = 250, conversions: int = 64):
        """workcell: sensors and the end effector (workcell.py), if any. max_lag: cycles a
        stream may fall behind before it jumps to the newest."""
        self.device = device
        self.workcell = workcell
        self.ring = device.link.feedback
        self.max_lag = max_lag
        self._loop: asyncio.AbstractEventLoop | None = None
        self._tick: asyncio.Future | None = None
        self._closed = False
        self._streams = 0              # open streams: the pipe is listened to while any is
        self._messages: dict = {}      # (sequence, view) -> StateSample, the newest few
        self._conversions = conversions
        self._poses: dict[int, np.ndarray] = {}   # sequence -> flange pose (4, 4), newest few
        self._model = PinocchioModel(device.arm)  # one pose in ~5 us (the numpy FK: ~60 us)
        self._looked = -1                  # the newest cycle position_since looked at
        self._since, self._stands = -1, None   # where the arm stands, since which cycle

    @property
    def cycle(self) -> int:
        """The newest cycle's sequence number (-1 before the first)."""
        return self.ring.head

    def position_since(self) -> int:
        """The cycle since which the arm has stood where it stands now (every joint within
        STILL), the newest while it moves: a reply built from the joints alone stays right
        while this does (GetRobotPosition). One ring read per new cycle, on the loop."""
        head = self.ring.head
        if head != self._looked:
            row = self.ring.row(head)
            if row is not None:
                joints = row[Q]
                if self._stands is None or np.abs(joints - self._stands).max() > STILL:
                    self._since, self._stands = head, joints
                self._looked = head
        return self._since

    def attach(self, loop: asyncio.AbstractEventLoop) -> None:
        """Serve streams on `loop` (the server's), listening to the ring's wake-ups while
        any is open."""
        self._loop = loop
        self._tick = loop.create_future()

    async def aclose(self) -> None:
        """End every stream and stop listening to the ring (on the loop, before the ring's
        pipe closes)."""
        self._closed = True
        if self._loop is not None:
            self._loop.remove_reader(self.ring.tick_fd)
            self._wake()

    def _opened(self) -> None:
        self._streams += 1
        if self._streams == 1 and not self._closed:
            self.ring.drain_ticks()     # what came while nobody listened
            self._loop.add_reader(self.ring.tick_fd, self._on_tick)

    def _ended(self) -> None:
        self._streams -= 1
        if self._streams == 0:
            self._loop.remove_reader(self.ring.tick_fd)

    def _on_tick(self) -> None:
        self.ring.drain_ticks()
        self._wake()

    def _wake(self) -> None:
        tick, self._tick = self._tick, self._loop.create_future()
        if not tick.done():
            tick.set_result(None)

    async def _wait_for(self, sequence: int) -> bool:
        """Until the ring holds cycle `sequence`; False once the hub is closed."""
        while self.ring.head < sequence:
            if self._closed:
                return False
            await asyncio.shield(self._tick)
        return not self._closed

    def view(self, rate_hz: float, frame: Frame | None, units: Units,
             sensors: tuple[str, ...] = ()) -> tuple[View, str]:
        """The view a request asks for, and a note if the rate granted is not the one asked."""
        for name in sensors:
            self.workcell.sensors.info(name)   # ParamError naming the known ones
            if not self.workcell.sensors.in_ring(name):
                raise ParamError(f"{name} is not read every cycle: GetSensorReading reads it")
        cycle = self.device.link.cycle_time
        if not np.isfinite(rate_hz) or rate_hz < 0:
            raise ParamError(f"rate_hz must be 0 (every cycle) or a positive number, got {rate_hz}")
        if frame not in (None, Frame.BASE, Frame.WORLD):
            raise ParamError("the tool pose of a state stream is in BASE_CARTESIAN_FRAME or "
                             "WORLD_CARTESIAN_FRAME")
        period = 1 if rate_hz == 0 else max(1, round(1.0 / (rate_hz * cycle)))
        granted = 1.0 / (period * cycle)
        note = ""
        if rate_hz > 1.0 / cycle * (1 + 1e-9):
            note = f"{rate_hz:g} Hz is above the controller's cycle rate; every cycle it is"
        elif rate_hz and abs(granted - rate_hz) > 1e-6 * rate_hz:
            note = f"samples come every {period} cycles of {cycle * 1000:g} ms"
        return View(period, frame or Frame.WORLD, units, tuple(sensors)), note

    async def stream(self, view: View):
        """The samples of one stream: (sequence, skipped) pairs, forever (until closed)."""
        self._opened()
        whole = self.ring.watch()   # sensors and model torques in the rows (feedback.py)
        try:
            async for sample in self._samples(view, whole):
                yield sample
        finally:
            self.ring.unwatch()
            self._ended()

    async def _samples(self, view: View, whole: int):
        head = self.ring.head
        due = max(head, whole, 0)
        previous = None
        while await self._wait_for(due):
            head = self.ring.head
            sequence = due if head - due <= self.max_lag else head
            row = self.ring.row(sequence)
            if row is None:   # overwritten meanwhile: take the newest
                sequence = self.ring.head
                row = self.ring.row(sequence)
                if row is None:
                    continue
            skipped = 0 if previous is None else max(0, sequence - previous - view.period)
            yield self.sample(row, view, skipped)
            previous, due = sequence, sequence + view.period

    def sample(self, row: np.ndarray, view: View, skipped: int = 0) -> pb.StreamStateResponse:
        """The stream message of a feedback row, converted once per view (then shared)."""
        sequence = int(row[SEQ])
        key = (sequence, view)
        message = self._messages.get(key)
        if message is None:
            message = self._convert(row, view)
            if len(self._messages) >= self._conversions:
                self._messages.pop(next(iter(self._messages)))
            self._messages[key] = message
        if skipped:
            copy = pb.StreamStateResponse()
            copy.CopyFrom(message)
            copy.sample.skipped = skipped
            return copy
        return message

    def tool_pose(self, sequence: int, joints: np.ndarray, frame: Frame) -> np.ndarray:
        """The tool tip (4x4, m) in `frame` (BASE or WORLD) at cycle `sequence`'s joints.
        Forward kinematics runs once per cycle, whoever asks (streams and position reads)."""
        flange = self._poses.get(sequence)
        if flange is None:
            flange = self._model.forward(joints)
            if len(self._poses) >= 8:
                self._poses.pop(next(iter(self._poses)))
            self._poses[sequence] = flange
        settings = self.device.settings
        tip = flange @ settings.tool_offset
        return settings.base_in_world @ tip if frame is Frame.WORLD else tip

    def _convert(self, row: np.ndarray, view: View) -> pb.StreamStateResponse:
        device, units = self.device, view.units
        tip = self.tool_pose(int(row[SEQ]), row[Q], view.frame)
        status = device.status()
        motion, mode = device.motion_control_state()
        running = device.motions.running   # read once: the motion may end meanwhile
        sample = pb.StateSample(
            sequence=int(row[SEQ]), controller_time=float(row[TIME]),
            skipped=0, joint_positions=units.angle_from_si(row[Q]).tolist(),
            joint_velocities=units.angle_from_si(row[QD]).tolist(),
            commanded_positions=units.angle_from_si(row[CMD]).tolist(),
            joint_torques=row[TAU].tolist(), tool_pose=convert.matrix_to_pose(tip, units),
            device_state=convert.DEVICE_STATE_PB[status.state], motion_control_state=motion,
            control_mode=mode, command_id=status.command_id,
            point_name=running.point_name if running else "",
            tag_name=device.path_runs.last_tag[1], estop=status.estop,
            units=convert.units_to_pb(units))
        if self.workcell is not None:
            sample.end_effector, sample.end_effector_state = self.workcell.tools.state(row[IO])
            sensors = self.workcell.sensors
            for name in view.sensors:
                values = sensors.from_row(name, row[SENSORS])
                sample.sensors.add(name=name, values=convert.sensor_to_pb(
                    sensors.info(name).kind, values, units))
        if not np.isnan(row[MODEL_TAU]).any():
            sample.model_torques.extend(row[MODEL_TAU].tolist())
        sample.time.FromNanoseconds(round(float(row[WALL]) * 1e9))
        return pb.StreamStateResponse(sample=sample)

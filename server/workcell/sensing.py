"""The cell's sensors as clients see them (seed 3.7.1 getSensorReading, state streams).

The sensors are the controller's (Controller.sensor_map): a force/torque sensor at the
flange and a laser standoff (range) sensor along the tool axis in the default cell, and any
other the cell file declares. The ring carries the first of each kind every cycle while its
rows are watched (feedback.ring_sensors, FeedbackRing.watch); others, and those while nobody
watches, are read from the controller when asked.

What a reading is, in SI (convert.py gives it in the client's units):
- force_torque: (fx, fy, fz, tx, ty, tz) at the tool tip in the tool frame (the tool offset's
  frame): forces in N, torques about the tip in N*m. The sensor measures the load the tool side
  puts on the flange, so a tool hanging down reads +m*g along its z and pressing the tip into
  a surface reads fz < 0. Zeroed by a tare (SendCommand "tare force_sensor"; MoveReact tares
  it when it starts; Comply does not: it usually starts in contact, guarded.py).
- laser_range: (distance,) in m from the tool tip along its z to the first surface; NaN when
  nothing is within the sensor's range.
"""
from __future__ import annotations

import numpy as np

from landscape.robot.controller import SensorInfo, Status
from landscape.server.cycle.feedback import SENSORS, ring_sensors
from landscape.server.cycle.tip_model import wrench_map
from landscape.server.device.stored_settings import SettingsKeeper
from landscape.server.errors import ControllerFailure, ParamError
from landscape.server.link.controller_link import ControllerLink

class Sensors:
    def __init__(self, link: ControllerLink, settings: SettingsKeeper):
        self.link, self.settings = link, settings
        self._known: dict[str, SensorInfo] = {}
        self._ring: dict[str, slice | int] = {}
        self._tip_map: tuple[np.ndarray | None, np.ndarray] = (None, np.eye(6))

    def controller_started(self) -> None:
        sensors = self.link.proxy.sensor_map()
        self._known = {s.name: s for s in sensors}
        self._ring = ring_sensors(sensors)

    @property
    def names(self) -> list[str]:
        return list(self._known)

    def info(self, name: str) -> SensorInfo:
        try:
            return self._known[name]
        except KeyError:
            raise ParamError(f"no sensor {name!r} (sensors: {', '.join(self._known)})",
                             sensor=name) from None

    def in_ring(self, name: str) -> bool:
        return name in self._ring

    def reading(self, name: str) -> np.ndarray:
        """The sensor's present reading in SI (module docstring): from the newest row if it
        carries it (`held_cycle`), else asked of the controller (blocking)."""
        cycle = self.held_cycle(name)
        if cycle is not None:
            return self.reading_at(name, cycle)
        info = self.info(name)
        return self._tool_frame(info, np.asarray(self.link.proxy.read_sensor(name)))

    def held_cycle(self, name: str) -> int | None:
        """The newest cycle, if its row carries `name` (a ring sensor, rows whole:
        FeedbackRing.watch), at most a cycle old; else None: the controller has to be asked.
        Two reads of shared memory: no wait."""
        if name not in self._ring:
            return None
        ring = self.link.feedback
        head = ring.head
        return head if head >= 0 and ring.whole(head) else None

    def reading_at(self, name: str, cycle: int) -> np.ndarray:
        """A ring sensor's reading in cycle `cycle`'s row (one `held_cycle` gave)."""
        row = self.link.feedback.row(cycle)
        if row is None:   # 1,024 cycles later: not from a cycle held_cycle just gave
            raise ControllerFailure(f"cycle {cycle}'s feedback is no longer in the ring")
        return self.from_row(name, row[SENSORS])

    def from_row(self, name: str, sensors: np.ndarray) -> np.ndarray:
        """A ring sensor's reading from a feedback row's sensor columns (7,)."""
        raw = np.atleast_1d(sensors[self._ring[name]])
        return self._tool_frame(self._known[name], raw)

    def tare(self, name: str) -> None:
        self.info(name)
        if self.link.proxy.tare_sensor(name) is not Status.OK:
            raise ControllerFailure(f"the controller did not tare {name}")

    def _tool_frame(self, info: SensorInfo, raw: np.ndarray) -> np.ndarray:
        if info.kind == "force_torque":
            return self._to_tip(self.settings.current.tool_offset) @ raw
        return raw.astype(float)

    def _to_tip(self, tool_offset: np.ndarray) -> np.ndarray:
        """wrench_map of the tool offset, made once per offset (a new array per change, as
        the settings are replaced, never changed): a product per reading, not a pinocchio
        transform."""
        offset, matrix = self._tip_map
        if offset is not tool_offset:
            matrix = wrench_map(tool_offset)
            self._tip_map = (tool_offset, matrix)
        return matrix

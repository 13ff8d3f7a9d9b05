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
from landscape.server.cycle.tip_model import wrench_at_tip
from landscape.server.device.stored_settings import SettingsKeeper
from landscape.server.errors import ControllerFailure, ParamError
from landscape.server.link.controller_link import ControllerLink

class Sensors:
    def __init__(self, link: ControllerLink, settings: SettingsKeeper):
        self.link, self.settings = link, settings
        self._known: dict[str, SensorInfo] = {}
        self._ring: dict[str, slice | int] = {}

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
        """The sensor's present reading in SI (module docstring): from the ring if it carries
        it (`held`), else asked of the controller (blocking)."""
        info = self.info(name)
        raw = self.held(name)
        if raw is None:
            raw = np.asarray(self.link.proxy.read_sensor(name))
        return self._tool_frame(info, raw)

    def held(self, name: str) -> np.ndarray | None:
        """`name`'s raw columns (flange frame) in the newest cycle's row, at most a cycle old:
        None unless the ring carries the sensor and that row is whole (FeedbackRing.watch);
        then `reading` asks the controller. A read of memory: no wait, no conversion."""
        place = self._ring.get(name)
        if place is None:
            return None
        ring = self.link.feedback
        head = ring.head
        row = ring.row(head)
        if row is None or not ring.whole(head):
            return None
        return np.atleast_1d(row[SENSORS][place])

    def in_tool_frame(self, name: str, raw: np.ndarray) -> np.ndarray:
        """`held`'s raw columns as `reading` gives them (SI, the tool frame)."""
        return self._tool_frame(self.info(name), raw)

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
            return wrench_at_tip(raw, self.settings.current.tool_offset)
        return raw.astype(float)

"""The parent's handle on a controller that runs in a cycle process (see clock.RealTimeClock).

`ControllerProxy` implements the same `Controller` interface as the backend, so code above it
works with a local controller (lock-step) or a remote one (real time) alike. Each asynchronous
LLI call travels down the pipe, runs between two cycles, and its result (or exception) comes
back; the caller blocks until then, at most `clock.call_timeout` s (TimeoutError).
The synchronous calls, `get` and `set`, belong to the cyclic function inside the cycle process.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from landscape.robot.configurations import Config, ReversingResult
from landscape.robot.controller import (Capability, Controller, DioStatus, DoutValue, EventFunc,
                                        IoctrlCode, IoId, IoUnit, JointCmd, JointFbk, SensorInfo,
                                        State, Status)

if TYPE_CHECKING:
    from landscape.server.link.clock import RealTimeClock


class ControllerProxy(Controller):
    """The asynchronous LLI calls of a controller in a cycle process."""

    def __init__(self, clock: "RealTimeClock"):
        self._clock = clock
        self._call = clock.call

    # -- life cycle: the child owns construction; destroy ends the cycle process
    def init(self) -> Status:
        return self._call("init")

    def home(self) -> Status:
        return self._call("home")

    def destroy(self) -> Status:
        """Stop the cycle process, which disables and destroys the controller."""
        self._clock.stop()
        return Status.OK

    def enable(self) -> Status:
        return self._call("enable")

    def disable(self) -> Status:
        return self._call("disable")

    # -- the synchronous task is not reachable from here
    def get(self) -> JointFbk:
        raise RuntimeError("get() belongs to the cyclic function in the cycle process")

    def set(self, cmd: JointCmd) -> Status:
        raise RuntimeError("set() belongs to the cyclic function in the cycle process")

    def state(self) -> State:
        return self._call("state")

    def ioctrl(self, code: IoctrlCode, data: Any = None) -> Any:
        return self._call("ioctrl", code, data)

    def plug_event_func(self, func: EventFunc | None) -> Status:
        """`func(text)` is called in this process, on the clock's dispatch thread."""
        self._clock.set_event_func(func)
        return self._call("plug_event_func", func is not None)

    # -- I/O by name
    def get_din_id(self, name: str) -> IoId:
        return self._call("get_din_id", name)

    def get_dout_id(self, name: str) -> IoId:
        return self._call("get_dout_id", name)

    def read_dio(self, io: IoId) -> DioStatus:
        return self._call("read_dio", io)

    def write_dout(self, io: IoId, value: DoutValue) -> Status:
        return self._call("write_dout", io, value)

    # -- cell: I/O by unit, sensors
    def io_map(self) -> tuple[IoUnit, ...]:
        return self._call("io_map")

    def read_io_unit(self, unit: int, mask: int = -1) -> int:
        return self._call("read_io_unit", unit, mask)

    def write_io_unit(self, unit: int, bits_on: int, bits_off: int) -> Status:
        return self._call("write_io_unit", unit, bits_on, bits_off)

    def sensor_map(self) -> tuple[SensorInfo, ...]:
        return self._call("sensor_map")

    def read_sensor(self, name: str) -> np.ndarray:
        return self._call("read_sensor", name)

    def tare_sensor(self, name: str) -> Status:
        return self._call("tare_sensor", name)

    # -- kinematics (the child's model, so both sides agree to the bit)
    def forward_kin(self, joints: np.ndarray) -> tuple[np.ndarray, Config]:
        return self._call("forward_kin", np.asarray(joints, dtype=float))

    def reverse_kin(self, joints_in: np.ndarray, target: np.ndarray, config: Config,
                    joint_range: tuple[np.ndarray, np.ndarray] | None = None
                    ) -> tuple[np.ndarray | None, ReversingResult]:
        return self._call("reverse_kin", np.asarray(joints_in, dtype=float),
                          np.asarray(target, dtype=float), config, joint_range)

    # -- beyond the LLI: what the backend offers (its panel and world are reached between
    # cycles: robot/controller.py's operate_panel, read_part_states)
    def capabilities(self) -> frozenset[Capability]:
        return self._call("capabilities")

    # -- recorder
    def rec_init(self) -> Status:
        return self._call("rec_init")

    def rec_start(self) -> Status:
        return self._call("rec_start")

    def rec_stop(self) -> Status:
        return self._call("rec_stop")

    def rec_store(self) -> Status:
        return self._call("rec_store")

"""The simulated CS8: the LLI-shaped `Controller` on pybullet (DIRECT mode, a client of its own).

`step()` is the drive interrupt: it advances the physics by one cycle, then calls the cyclic
function (which calls `get()` then `set()`). Clocks call `step()`; nothing here depends on wall
time. `time` is simulated seconds since construction; `wall_time` stamps each cycle's tick (the
start of step(), when a real controller would run the cyclic function) for its records.

The arm's drives and brakes, their physics and the feedback they measure (what `get()`
returns) are bullet_drives.py's; this module is the controller's LLI side.

Power (LLI 5.3.3, 5.3.4, 5.3.10). DISABLED means brakes on. ENABLING (enable_time) and
DISABLING (disable_time) hold the measured position with the drives; once ENABLED the held
command is the measured position. An invalid set(), a failing cyclic function (an exception or
False) or the e-stop disable at once, with an error event. While not ENABLED, set() is accepted
and ignored: there is nothing to command.

Single-threaded: call everything from the thread that steps (the cycle process).
"""
from __future__ import annotations

import logging
import math
import time
from typing import Any

import numpy as np

from landscape.sim.bullet_drives import Drives, connect
from landscape.robot.cell import PANEL_WIRES, Cell
from landscape.robot.controller import (
    CalibState, Controller, CyclicFunction, DioStatus, DoutValue, EnableState, EstopState,
    EventFunc, InitState, IoctrlCode, IoId, IoType, IoUnit, JointCmd, JointFbk, SensorInfo,
    State, Status)
from landscape.sim.dio import DigitalIO
from landscape.robot.kinematics import Config, Kinematics, ReversingResult
from landscape.sim.panel import Panel
from landscape.sim.sensors import SENSOR_CLASSES
from landscape.sim.world import World

log = logging.getLogger(__name__)

SOFTWARE_VERSION = "landscape-sim CS8 LLI s7.4 0.1"
SYNCHRO_TASK_PRIORITY = 10     # VxWorks-style, 0 is highest; fixed, as on a CS8
_SLACK = 1e-9                  # rad, rad/s: rounding allowance of the command checks


class BulletController(Controller):
    """The CS8 of `cell` on pybullet; `cyclic` is called at the end of every `step()`.

    Besides the LLI calls: `cycle_time` (s), `time` (simulated s), `step()`, `cyclic` (the cyclic
    function; may be replaced between cycles), `world`, `panel`
    (e-stop, door, parts by hand), `dio` (the I/O by name and by unit), `last_record_path`.
    """

    def __init__(self, cell: Cell, cyclic: CyclicFunction | None = None):
        self.cell = cell
        spec, arm = cell.controller, cell.arm
        self.cycle_time = spec.cycle_time
        self.cycles = 0
        self.time = 0.0
        self.wall_time = 0.0   # unix s at which the latest cycle began (its tick)
        self.cyclic = cyclic
        self._event_func: EventFunc | None = None

        self._bc = connect(spec.cycle_time, spec.substeps)
        self.world = World(self._bc, cell)
        self.panel = Panel(self.world, self._on_estop)
        self.dio = DigitalIO(cell.io, self._read_wire, self.world.set_output)
        self._sensors = {s.name: SENSOR_CLASSES[s.kind](self.world, s) for s in cell.sensors}
        self._io_map = tuple(
            IoUnit(u.id, u.name, u.direction,
                   tuple(sorted((s.bit, s.name) for s in cell.io.signals if s.unit == u.id)))
            for u in cell.io.units)
        self._kin = Kinematics(arm)
        self._recorder = None
        self.last_record_path: str | None = None
        self._drives = Drives(self._bc, self.world, arm, spec)   # braked

        # Limits, (6,) arrays.
        self._lower, self._upper = arm.lower, arm.upper
        self._vmax = np.array(arm.max_velocity)
        self._max_step = self._vmax * self.cycle_time
        self._max_dvel = spec.acceleration_factor * np.array(arm.max_acceleration) * self.cycle_time
        # The per-joint limits of the command checks, as plain lists (numpy is slow on 6
        # values): (min, max, max |vel|, max |pos step|, max |vel step|, max |torque|), with the
        # rounding allowance the checks grant.
        self._limits = list(zip(self._lower.tolist(), self._upper.tolist(),
                                (self._vmax + _SLACK).tolist(), (self._max_step + _SLACK).tolist(),
                                (self._max_dvel + _SLACK).tolist(), self._drives.effort))
        self._enable_cycles = max(1, round(spec.enable_time / self.cycle_time))
        self._disable_cycles = max(1, round(spec.disable_time / self.cycle_time))
        self._user_marks = np.array(spec.user_marks)

        # LLI state.
        self._init = InitState.NOT_INITIALIZED
        self._calib = CalibState.NOT_CALIBRATED
        self._enable = EnableState.DISABLED
        self._countdown = 0
        self._torque_mode = False
        self._cyclic_failing = False
        self._destroyed = False

    # ---- the cycle ----------------------------------------------------------------------------

    def step(self) -> None:
        """One cycle: power procedures, cycle_time of physics and its feedback, world, recorder,
        then the cyclic function."""
        if self._destroyed:
            raise RuntimeError("the controller was destroyed")
        self.wall_time = time.time()
        if self._countdown:
            self._procedure()
        drives = self._drives
        drives.cycle()
        self.world.update()
        self.cycles += 1
        self.time = self.cycles * self.cycle_time
        if self._recorder is not None:
            fbk = drives.fbk
            self._recorder.append(self.time, *drives.reference(), fbk.pos, fbk.vel, fbk.torque)
        if self.cyclic is not None:
            self._run_cyclic()

    def _run_cyclic(self) -> None:
        try:
            ok = self.cyclic(self)
            why = "the cyclic function returned an error"
        except Exception as exc:  # noqa: BLE001 - any failure of user code disables the drives
            ok = False
            why = f"the cyclic function raised {type(exc).__name__}: {exc}"
        if ok is False:
            if self._enable is not EnableState.DISABLED or not self._cyclic_failing:
                self._event(f"{why}; drives disabled")
            self._cyclic_failing = True
            self._power_off()
        else:
            self._cyclic_failing = False

    def _procedure(self) -> None:
        """Advance enabling or disabling by one cycle."""
        self._countdown -= 1
        if self._countdown:
            return
        if self._enable is EnableState.ENABLING:
            self._enable = EnableState.ENABLED
            self._drives.engage(self._torque_mode)
        elif self._enable is EnableState.DISABLING:
            self._power_off()

    def _power_off(self) -> None:
        self._countdown = 0
        self._enable = EnableState.DISABLED
        if not self._drives.braked:
            self._drives.brake()

    # ---- LLI: life cycle and power ------------------------------------------------------------

    def _event(self, text: str) -> None:
        log.warning("%s", text)
        if self._event_func is not None:
            try:
                self._event_func(text)
            except Exception:  # noqa: BLE001 - a broken listener must not break the controller
                log.exception("the event function raised")

    def _refuse(self, text: str) -> Status:
        self._event(text)
        return Status.ERROR

    def plug_event_func(self, func: EventFunc | None) -> Status:
        self._event_func = func
        return Status.OK

    def init(self) -> Status:
        if self._destroyed:
            return Status.ERROR
        if self._init is InitState.INITIALIZED:
            return self._refuse("init refused: already initialised (once per construction)")
        self._init = InitState.INITIALIZED
        return self.home()

    def home(self) -> Status:
        if self._init is not InitState.INITIALIZED:
            return self._refuse("home refused: not initialised")
        self._calib = CalibState.CALIBRATED
        return Status.OK

    def destroy(self) -> Status:
        if not self._destroyed:
            self._power_off()
            self._bc.disconnect()
            self._destroyed = True
            self._init = InitState.NOT_INITIALIZED
            self._recorder = None
        return Status.OK

    def __enter__(self) -> "BulletController":
        return self

    def __exit__(self, *exc) -> None:
        self.destroy()

    def enable(self) -> Status:
        if self._init is not InitState.INITIALIZED or self._calib is not CalibState.CALIBRATED:
            return self._refuse("enable refused: the controller is not initialised")
        if self.panel.estop_pressed:
            return self._refuse("enable refused: the emergency stop is pressed; release it first")
        if self._enable is EnableState.DISABLING:
            return self._refuse("enable refused: the drives are disabling")
        if self._enable is EnableState.DISABLED:
            self._enable = EnableState.ENABLING
            self._countdown = self._enable_cycles
            self._drives.power_on()
        return Status.OK

    def disable(self) -> Status:
        if self._init is not InitState.INITIALIZED:
            return self._refuse("disable refused: the controller is not initialised")
        if self._enable in (EnableState.ENABLED, EnableState.ENABLING):
            self._enable = EnableState.DISABLING
            self._countdown = self._disable_cycles
            self._drives.hold()
        return Status.OK

    def _on_estop(self, pressed: bool) -> None:
        if not pressed:
            self._event("emergency stop released")
        elif self._enable is EnableState.DISABLED:
            self._event("emergency stop pressed")
        else:
            self._power_off()
            self._event("emergency stop pressed: drives disabled")

    def state(self) -> State:
        return State(self._init, self._enable, self._calib, self._drives.settle,
                     EstopState.ESTOP if self.panel.estop_pressed else EstopState.NO_ESTOP)

    # ---- LLI: the synchronous calls -----------------------------------------------------------

    def get(self) -> JointFbk:
        f = self._drives.fbk
        return JointFbk(f.pos.copy(), f.vel.copy(), f.pos_err.copy(), f.torque.copy())

    def set(self, cmd: JointCmd) -> Status:
        if self._enable is not EnableState.ENABLED:
            return Status.OK
        pos, vel, tau = cmd.pos, cmd.vel, cmd.torque_ffw
        if pos.shape != (6,) or vel.shape != (6,) or tau.shape != (6,):
            return self._reject(f"a command needs 6 values per field, got {pos.shape}, "
                                f"{vel.shape}, {tau.shape}")
        pos, vel, tau = pos.tolist(), vel.tolist(), tau.tolist()
        drives = self._drives
        last_pos, last_vel = drives.cmd_pos, drives.cmd_vel
        clipped = []
        # NaN fails every comparison, so these checks reject it too.
        for i, (lo, hi, vmax, step, dvel, effort) in enumerate(self._limits):
            p, v, t = pos[i], vel[i], tau[i]
            if not (lo <= p <= hi and -vmax <= v <= vmax and -step <= p - last_pos[i] <= step
                    and -dvel <= v - last_vel[i] <= dvel and -math.inf < t < math.inf):
                return self._reject(self._explain(i, p, v, t))
            clipped.append(-effort if t < -effort else effort if t > effort else t)
        drives.command(pos, vel, clipped)
        return Status.OK

    def _reject(self, problem: str) -> Status:
        """LLI 5.3.6: an invalid command is never applied; the drives are disabled."""
        self._power_off()
        self._event(f"set refused: {problem}; drives disabled")
        return Status.ERROR

    def _explain(self, i: int, p: float, v: float, t: float) -> str:
        """What is wrong with joint i's command (position p, velocity v, torque t)."""
        j, lo, hi = i + 1, self._lower[i], self._upper[i]
        if not (math.isfinite(p) and math.isfinite(v) and math.isfinite(t)):
            return f"joint {j} command holds NaN or infinite values"
        if not lo <= p <= hi:
            return f"joint {j} position {p:.6f} rad is outside its range [{lo:.6f}, {hi:.6f}] rad"
        if abs(v) > self._vmax[i] + _SLACK:
            return (f"joint {j} velocity {v:.6f} rad/s exceeds its maximum "
                    f"{self._vmax[i]:.6f} rad/s")
        step = abs(p - self._drives.cmd_pos[i])
        if step > self._max_step[i] + _SLACK:
            return (f"joint {j} position changes by {step:.6f} rad in one cycle, more than its "
                    f"maximum velocity allows ({self._max_step[i]:.6f} rad)")
        change = abs(v - self._drives.cmd_vel[i])
        return (f"joint {j} velocity changes by {change:.6f} rad/s in one cycle, more than a "
                f"drive can follow ({self._max_dvel[i]:.6f} rad/s)")

    # ---- LLI: ioctrl --------------------------------------------------------------------------

    def ioctrl(self, code: IoctrlCode, data: Any = None) -> Any:
        """GET_* return their value (str, int, float s, user marks (6,) rad, joint range as
        (min (6,), max (6,)) rad); SET_* return a Status."""
        try:
            code = IoctrlCode(code)
        except ValueError:
            return self._refuse(f"ioctrl refused: unknown code {code!r}")
        arm = self.cell.arm
        if code is IoctrlCode.GET_SOFTWARE_VERSION:
            return SOFTWARE_VERSION
        if code is IoctrlCode.GET_ROBOT_TYPE:
            return arm.name
        if code is IoctrlCode.GET_JNT_NUMBER:
            return 6
        if code is IoctrlCode.GET_CYCLE_TIME:
            return self.cycle_time
        if code is IoctrlCode.GET_SYNCHRO_TASK_PRIORITY:
            return SYNCHRO_TASK_PRIORITY
        if code is IoctrlCode.GET_JNT_RANGE:
            return self._lower.copy(), self._upper.copy()
        if code is IoctrlCode.GET_USER_MARKS:
            return self._user_marks.copy()
        if code is IoctrlCode.SET_USER_MARKS:
            marks = np.asarray(data, dtype=float) if data is not None else np.empty(0)
            if marks.shape != (6,) or not np.all(np.isfinite(marks)):
                return self._refuse("ioctrl SET_USER_MARKS refused: needs 6 finite values (rad)")
            self._user_marks = marks.copy()
            return Status.OK
        if code is IoctrlCode.SET_TORQUE_MODE or code is IoctrlCode.SET_POS_VEL_MODE:
            torque = code is IoctrlCode.SET_TORQUE_MODE
            if torque != self._torque_mode:
                self._torque_mode = torque
                if self._enable is EnableState.ENABLED:
                    self._drives.engage(torque, bumpless=True)
            return Status.OK
        # SET_ABS_JNT_POS, RECOVER_ABS_JNT_POS: a simulated arm never loses its calibration.
        return self._refuse(f"ioctrl {code.name} refused: not supported by the simulated CS8")

    # ---- LLI: digital I/O by name -------------------------------------------------------------

    def _read_wire(self, wire: str) -> bool:
        return self.panel.read(wire) if wire in PANEL_WIRES else self.world.read_input(wire)

    def get_din_id(self, name: str) -> IoId:
        s = self.dio.lookup(name)
        found = s is not None and s.direction == "input"
        return IoId(IoType.D_INPUT, name) if found else IoId(IoType.UNDEFINED)

    def get_dout_id(self, name: str) -> IoId:
        s = self.dio.lookup(name)
        found = s is not None and s.direction == "output"
        return IoId(IoType.D_OUTPUT, name) if found else IoId(IoType.UNDEFINED)

    def read_dio(self, io: IoId) -> DioStatus:
        if io.type not in (IoType.D_INPUT, IoType.D_OUTPUT) or self.dio.lookup(io.name) is None:
            return DioStatus.UNDEFINED
        return DioStatus.ONE if self.dio.read(io.name) else DioStatus.ZERO

    def write_dout(self, io: IoId, value: DoutValue) -> Status:
        s = self.dio.lookup(io.name) if io.type is IoType.D_OUTPUT else None
        if s is None or s.direction != "output":
            return self._refuse(f"write_dout refused: {io.name!r} is not a digital output")
        self.dio.write(io.name, value == DoutValue.ONE)
        return Status.OK

    # ---- cell: I/O by unit, sensors ------------------------------------------------------------

    def io_map(self) -> tuple[IoUnit, ...]:
        return self._io_map

    def read_io_unit(self, unit: int, mask: int = -1) -> int:
        return self.dio.read_unit(unit, mask)

    def write_io_unit(self, unit: int, bits_on: int, bits_off: int) -> Status:
        try:
            self.dio.write_unit(unit, bits_on, bits_off)
        except (KeyError, ValueError) as exc:
            return self._refuse(f"write_io_unit refused: {exc.args[0]}")
        return Status.OK

    def sensor_map(self) -> tuple[SensorInfo, ...]:
        return tuple(SensorInfo(s.name, s.kind) for s in self.cell.sensors)

    def _sensor(self, name: str):
        try:
            return self._sensors[name]
        except KeyError:
            raise KeyError(f"no sensor {name!r} (sensors: {', '.join(self._sensors)})") from None

    def read_sensor(self, name: str) -> np.ndarray:
        """The present reading of a sensor of the cell (shape and units: sim/sensors.py)."""
        return self._sensor(name).read()

    def tare_sensor(self, name: str) -> Status:
        """Zero a sensor at its present reading."""
        self._sensor(name).tare()
        return Status.OK

    # ---- LLI: kinematics (flange in the base_link frame) --------------------------------------

    def forward_kin(self, joints: np.ndarray) -> tuple[np.ndarray, Config]:
        """LLI_forwardKin: the flange pose (4, 4) in base_link and the configuration of q (6,)."""
        return self._kin.forward(joints), self._kin.configuration(joints)

    def reverse_kin(self, joints_in: np.ndarray, target: np.ndarray, config: Config,
                    joint_range: tuple[np.ndarray, np.ndarray] | None = None
                    ) -> tuple[np.ndarray | None, ReversingResult]:
        """LLI_reverseKin: joints reaching `target` (flange (4, 4) in base_link) in `config`,
        nearest `joints_in`, within `joint_range` (min (6,), max (6,); default: the cell's)."""
        lower, upper = joint_range if joint_range is not None else (None, None)
        return self._kin.reverse(target, joints_in, config, lower, upper)

    # ---- LLI: recorder ------------------------------------------------------------------------

    def rec_init(self) -> Status:
        from landscape.sim.recorder import Recorder   # the recorder and mcap load on first use

        spec = self.cell.recorder
        self._recorder = Recorder(spec.path, spec.every_nth, spec.max_seconds, 6,
                                  cycle_time=self.cycle_time)
        return Status.OK

    def rec_start(self) -> Status:
        if self._recorder is None:
            return self._refuse("rec_start refused: call rec_init first")
        self._recorder.start()
        return Status.OK

    def rec_stop(self) -> Status:
        if self._recorder is None:
            return self._refuse("rec_stop refused: call rec_init first")
        self._recorder.stop()
        return Status.OK

    def rec_store(self) -> Status:
        if self._recorder is None:
            return self._refuse("rec_store refused: call rec_init first")
        try:
            self.last_record_path = self._recorder.store()
        except OSError as exc:
            return self._refuse(f"rec_store failed: {exc}")
        return Status.OK

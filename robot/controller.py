"""The controller interface, shaped like the Staubli LLI s7.4 (../shared/spec/staubli-lli-s7.4.md).

One method per LLI call (section 5 of the manual; Python names in snake_case). The simulated
CS8 (`landscape.sim.bullet_controller`) implements it now; a binding to a real CS8 would be a
second implementation, and nothing above this interface knows which one it talks to.

Context rules (LLI section 5.3.1): `get` and `set` belong to the synchronous task and are called
once per cycle, `get` first, from the cyclic function; `init`, `home`, `destroy`, the I/O calls
and the recorder's `rec_init`/`rec_store` belong to the asynchronous side; `enable`, `disable`,
`state` and `ioctrl` may be called from either.

Beyond the LLI (section "cell" below): what a supervisory cell needs from its controller and
the LLI has no call for, shaped so that a CS8 binding could offer them from its fieldbus image
and its sensor drivers: the I/O map and whole units by bit field (LandScape's DIGITAL_IO,
seed 4), and the cell's sensors by name (F/T, range) with tare. These read the latest image,
never wait, and may be called from either context (the cyclic function reads sensors every
cycle); writing outputs belongs to the asynchronous side, as LLI_writeDout does.

Beyond both, optional capabilities a backend may offer and declares (`capabilities()`): the
server asks before it uses one (`Capability`): an operator panel (the e-stop button and the
door, as a person at the cell works them), part tracking (where the cell's loose parts are),
and sensors that measure the world (without: a force reads zero, a range nothing).
`operate_panel` and `read_part_states` below are how the server reaches the first two of a
controller in a cycle process (run between two cycles, pickled by name; this module is loaded
there before the loop starts).

Units: joint positions in rad, velocities in rad/s, torques in N*m, Cartesian positions in m,
forces in N. Joint arrays have shape (n_joints,), joint 1 first.
"""
from __future__ import annotations

import abc
import enum
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from landscape.robot.configurations import Config, ReversingResult


def check_cycle_time(cycle_time: float) -> float:
    """The LLI's rule (3.5.1): a positive multiple of 0.2 ms. Returns it as float, in s."""
    ticks = round(cycle_time / 0.0002)
    if ticks < 1 or abs(ticks * 0.0002 - cycle_time) > 1e-9:
        raise ValueError(f"cycle time {cycle_time!r} s is not a positive multiple of 0.2 ms")
    return float(cycle_time)


class Capability(enum.Enum):
    """What a backend offers beyond the LLI, each optional."""

    PANEL = "panel"       # operate_panel: the e-stop button and the door
    WORLD = "world"       # part_states: where the loose parts are (and parts moved by hand)
    SENSING = "sensing"   # the sensors measure the world


# What a person at the cell does at the panel (Capability.PANEL).
PANEL_ACTIONS = ("press_estop", "release_estop", "open_door", "close_door")


class Status(enum.IntEnum):
    OK = 0
    ERROR = 1


class InitState(enum.IntEnum):
    NO_LICENCE = 0
    NOT_INITIALIZED = 1
    INITIALIZED = 2


class EnableState(enum.IntEnum):
    DISABLED = 0
    ENABLING = 1
    ENABLED = 2
    DISABLING = 3


class CalibState(enum.IntEnum):
    CALIBRATED = 0
    NOT_CALIBRATED = 1


class SettleState(enum.IntEnum):
    NOT_SETTLED = 0
    SETTLED = 1


class EstopState(enum.IntEnum):
    ESTOP = 0
    NO_ESTOP = 1


@dataclass(frozen=True)
class State:
    """LLI_State: what `state()` reports."""

    init: InitState = InitState.NOT_INITIALIZED
    enable: EnableState = EnableState.DISABLED
    calib: CalibState = CalibState.NOT_CALIBRATED
    settle: SettleState = SettleState.NOT_SETTLED
    estop: EstopState = EstopState.NO_ESTOP


class IoctrlCode(enum.IntEnum):
    GET_SOFTWARE_VERSION = 0
    GET_ROBOT_TYPE = 1
    GET_JNT_NUMBER = 2
    GET_CYCLE_TIME = 3
    GET_SYNCHRO_TASK_PRIORITY = 4
    SET_ABS_JNT_POS = 5
    RECOVER_ABS_JNT_POS = 6
    GET_USER_MARKS = 7
    SET_USER_MARKS = 8
    SET_TORQUE_MODE = 9
    SET_POS_VEL_MODE = 10
    GET_JNT_RANGE = 11


class IoType(enum.IntEnum):
    D_INPUT = 0
    D_OUTPUT = 1
    A_INPUT = 2
    A_OUTPUT = 3
    UNDEFINED = 4


class DioStatus(enum.IntEnum):
    ONE = 0
    ZERO = 1
    UNDEFINED = 2


class DoutValue(enum.IntEnum):
    ONE = 0
    ZERO = 1


@dataclass(frozen=True)
class IoId:
    """LLI_IoId: what `get_din_id`/`get_dout_id` return; `type` is UNDEFINED if not found."""

    type: IoType
    name: str = ""


@dataclass
class JointCmd:
    """LLI_JointCmd for all joints: position (rad), velocity (rad/s), torque feed-forward (N*m)."""

    pos: np.ndarray
    vel: np.ndarray
    torque_ffw: np.ndarray = field(default=None)  # type: ignore[assignment]

    def __post_init__(self):
        self.pos = np.asarray(self.pos, dtype=float)
        self.vel = np.asarray(self.vel, dtype=float)
        self.torque_ffw = (np.zeros_like(self.pos) if self.torque_ffw is None
                           else np.asarray(self.torque_ffw, dtype=float))


@dataclass
class JointFbk:
    """LLI_JointFbk for all joints: position (rad), velocity (rad/s), following error (rad), torque (N*m)."""

    pos: np.ndarray
    vel: np.ndarray
    pos_err: np.ndarray
    torque: np.ndarray


@dataclass(frozen=True)
class IoUnit:
    """One unit of the cell's digital I/O (the CS8's cell.cf): `id`, `name`, `direction`
    ("input" or "output": a unit is all one or the other) and its named bits as (bit, name)
    pairs, bit 0 being the value 1 of the unit's bit field."""

    id: int
    name: str
    direction: str
    bits: tuple[tuple[int, str], ...]

    @property
    def mask(self) -> int:
        """The declared bits as a bit field."""
        mask = 0
        for bit, _ in self.bits:
            mask |= 1 << bit
        return mask

    def bit_of(self, name: str) -> int | None:
        return next((bit for bit, n in self.bits if n == name), None)


@dataclass(frozen=True)
class SensorInfo:
    """A sensor of the cell: its `name` and `kind`, "force_torque" (reads (6,): fx, fy, fz in N,
    tx, ty, tz in N*m, in the flange frame, about its origin: the load the tool side puts on
    the flange) or "laser_range" (reads (1,): distance in m along the tool axis from the tool
    tip to the first surface, NaN with nothing in range)."""

    name: str
    kind: str

    @property
    def size(self) -> int:
        return 6 if self.kind == "force_torque" else 1


# LLI_EventFunc: receives the event description.
EventFunc = Callable[[str], None]
# The cyclic function of LLI_construct; it returns False (an error) to have the drives disabled.
CyclicFunction = Callable[["Controller"], bool]


class Controller(abc.ABC):
    """The LLI robot-control and kinematics programming interface (LLI sections 5.2 to 5.5).

    Construction is the constructor (LLI_construct); `destroy` ends it. Methods that the LLI
    declares as returning LLI_Status return `Status`; the others return their data.
    """

    # -- 5.1, 5.3.2, 5.3.8: life cycle
    @abc.abstractmethod
    def init(self) -> Status:
        """Initialise the hardware and calibrate (calls `home` at the end); once per construction."""

    @abc.abstractmethod
    def home(self) -> Status: ...

    @abc.abstractmethod
    def destroy(self) -> Status:
        """Free everything; the robot is left disabled and safe."""

    # -- 5.3.3, 5.3.4: non-blocking power procedures; `state()` reports their progress
    @abc.abstractmethod
    def enable(self) -> Status: ...

    @abc.abstractmethod
    def disable(self) -> Status: ...

    # -- 5.3.5, 5.3.6: the synchronous task, once per cycle, get before set
    @abc.abstractmethod
    def get(self) -> JointFbk: ...

    @abc.abstractmethod
    def set(self, cmd: JointCmd) -> Status:
        """Command this cycle. An out-of-range command is never applied: the controller raises
        an error event and disables (LLI 5.3.6)."""

    # -- 5.3.7, 5.2.2/5.3.9, 5.2.1
    @abc.abstractmethod
    def state(self) -> State: ...

    @abc.abstractmethod
    def ioctrl(self, code: IoctrlCode, data: Any = None) -> Any: ...

    @abc.abstractmethod
    def plug_event_func(self, func: EventFunc | None) -> Status: ...

    # -- 5.3.11: digital I/O by name (names from the cell file)
    @abc.abstractmethod
    def get_din_id(self, name: str) -> IoId: ...

    @abc.abstractmethod
    def get_dout_id(self, name: str) -> IoId: ...

    @abc.abstractmethod
    def read_dio(self, io: IoId) -> DioStatus: ...

    @abc.abstractmethod
    def write_dout(self, io: IoId, value: DoutValue) -> Status: ...

    # -- 5.4: kinematics; Cartesian frames are 4x4 homogeneous matrices of the flange in the base
    @abc.abstractmethod
    def forward_kin(self, joints: np.ndarray) -> tuple[np.ndarray, Config]: ...

    @abc.abstractmethod
    def reverse_kin(self, joints_in: np.ndarray, target: np.ndarray, config: Config,
                    joint_range: tuple[np.ndarray, np.ndarray] | None = None
                    ) -> tuple[np.ndarray | None, ReversingResult]: ...

    # -- cell: I/O by unit and bit field, sensors (see the module docstring)
    @abc.abstractmethod
    def io_map(self) -> tuple[IoUnit, ...]:
        """Every unit of the cell's digital I/O."""

    @abc.abstractmethod
    def read_io_unit(self, unit: int, mask: int = -1) -> int:
        """The unit's bits as a bit field, only those of `mask` read (the others 0); an unknown
        unit raises KeyError."""

    @abc.abstractmethod
    def write_io_unit(self, unit: int, bits_on: int, bits_off: int) -> Status:
        """Set the bits of `bits_on` and clear those of `bits_off` of an output unit; a bit not
        declared, in both fields, or an input unit: an error event and Status.ERROR, nothing
        written."""

    @abc.abstractmethod
    def sensor_map(self) -> tuple[SensorInfo, ...]:
        """The cell's sensors."""

    @abc.abstractmethod
    def read_sensor(self, name: str) -> np.ndarray:
        """The sensor's present reading (shape and units: SensorInfo); KeyError if unknown."""

    @abc.abstractmethod
    def tare_sensor(self, name: str) -> Status:
        """Zero the sensor at its present reading (a range sensor has nothing to zero)."""

    # -- 5.5: recorder
    @abc.abstractmethod
    def rec_init(self) -> Status: ...

    @abc.abstractmethod
    def rec_start(self) -> Status: ...

    @abc.abstractmethod
    def rec_stop(self) -> Status: ...

    @abc.abstractmethod
    def rec_store(self) -> Status: ...

    # -- beyond the LLI: optional capabilities (see the module docstring)
    def capabilities(self) -> frozenset[Capability]:
        """The capabilities this backend offers; none unless it says so."""
        return frozenset()

    def operate_panel(self, action: str) -> tuple[bool, bool]:
        """PANEL: one of PANEL_ACTIONS, as a person at the cell would; returns (e-stop pressed,
        door open)."""
        raise NotImplementedError(f"{type(self).__name__} has no operator panel")

    def part_states(self) -> dict[str, tuple]:
        """WORLD: the cell's parts, name -> (position (3,) m, quaternion xyzw, speed m/s, held
        by the mounted tool)."""
        raise NotImplementedError(f"{type(self).__name__} does not track parts")


def operate_panel(controller: Controller, action: str) -> tuple[bool, bool]:
    """Controller.operate_panel, run between two cycles (ControllerLink.between_cycles)."""
    return controller.operate_panel(action)


def read_part_states(controller: Controller) -> dict[str, tuple]:
    """Controller.part_states, run between two cycles (ControllerLink.between_cycles)."""
    return controller.part_states()

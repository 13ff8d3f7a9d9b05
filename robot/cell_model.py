"""The parsed cell (cell.py reads the file): frozen dataclasses of the arm, its controller, the
world (floor, fixtures, tools, parts, zones), the I/O and the sensors, with the wiring vocabulary
the simulator understands. Units as in cell.py: metres, kilograms, seconds, newtons, radians.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from landscape.robot.arm import ArmModel

_DEG = math.pi / 180.0

TOOL_KINDS = ("parallel_gripper", "vacuum_cup")
SENSOR_KINDS = ("force_torque", "laser_range")
# What an input or output can be wired to (dio.py, world.py, panel.py).
PANEL_WIRES = ("estop", "door_closed")
WORLD_INPUT_WIRES = ("gripper_closed", "vacuum_ok", "tool_present")
INPUT_WIRES = PANEL_WIRES + WORLD_INPUT_WIRES + ("none",)   # plus "zone:<zone name>"
# and "tool_id:<bit>": bit <bit> of the coupled tool's id (0 with no tool), as a tool changer's
# coded identification pins give it.
MAX_TOOL_ID_BITS = 8
OUTPUT_WIRES = ("toolchanger_lock", "gripper_close", "vacuum_on", "none")
MAX_BITS = 32   # a LandScape bit field is a long


# ---- the parsed cell --------------------------------------------------------------------------

@dataclass(frozen=True)
class Pose:
    """A frame: position xyz (m) and fixed-axis X-Y-Z angles rpy (rad)."""

    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class ControllerSpec:
    """The simulated CS8: cycle, drive and brake figures.

    cycle_time: s, a positive multiple of 0.2 ms (LLI 3.5.1). physics_step: longest pybullet
    step, s; each cycle runs `substeps` equal steps and the drives micro-interpolate the command
    over them. enable_time / disable_time: s, duration of the power procedures. The drives
    reject a command whose velocity changes by more than acceleration_factor * max_acceleration
    * cycle_time. effort_factor: drive peak torque / the published max effort. brake_factor:
    brake holding torque / the published max effort. initial_position: rad (6,), where the arm
    stands at construction. user_marks: rad (6,), LLI user mark positions. backend: the
    controller's (robot/backends.py): "pybullet", or "kinematic" (no physics).
    """

    cycle_time: float = 0.004
    physics_step: float = 0.002
    enable_time: float = 0.1
    disable_time: float = 0.05
    acceleration_factor: float = 3.0
    effort_factor: float = 2.0
    brake_factor: float = 2.0
    initial_position: tuple[float, ...] = (0.0, 0.0, math.pi / 2, 0.0, math.pi / 2, 0.0)
    user_marks: tuple[float, ...] = (0.0,) * 6
    backend: str = "pybullet"

    @property
    def substeps(self) -> int:
        return max(1, math.ceil(self.cycle_time / self.physics_step - 1e-9))


@dataclass(frozen=True)
class BoxSpec:
    """A box: fixture (mass 0: fixed in the world) or part. size: full extents (m), pose of its
    centre; colour RGBA in 0..1."""

    name: str
    pose: Pose
    size: tuple[float, float, float]
    mass: float = 0.0
    color: tuple[float, float, float, float] = (0.6, 0.6, 0.6, 1.0)


@dataclass(frozen=True)
class ToolSpec:
    """A tool in the rack. Its frame is the mounting plate: z along the tool axis, away from the
    flange; mounted, it coincides with the flange frame (tool0). slot: the plate's pose when the
    tool sits in the rack. length: plate to tool tip along z (m); the tip frame is the plate
    frame moved by `length` along z. Gripper: stroke = finger gap when open (m), finger_speed
    (m/s of each finger). Vacuum cup: cup_radius (m). contact_stiffness (N/m) and
    contact_damping (N*s/m): the compliance of the tool's contacts (pybullet's soft contact,
    per contact point: a flat finger face on a flat surface has about four, the cup's lip one),
    so that pressing
    on something gives a force that grows with the depth instead of saturating the drives.
    id: the number its identification pins code (1 .. 2**MAX_TOOL_ID_BITS - 1), unique."""

    name: str
    kind: str
    slot: Pose
    mass: float
    length: float
    id: int = 1
    stroke: float = 0.08
    finger_speed: float = 0.2
    cup_radius: float = 0.02
    contact_stiffness: float = 5000.0
    contact_damping: float = 300.0


@dataclass(frozen=True)
class ZoneSpec:
    """An axis-aligned box of the world (centre xyz, full size, m); wired to an input that is 1
    while the centre of some part lies inside."""

    name: str
    center: tuple[float, float, float]
    size: tuple[float, float, float]

    def contains(self, point) -> bool:
        d = np.abs(np.asarray(point, dtype=float) - self.center)
        return bool(np.all(d <= np.asarray(self.size) / 2))


@dataclass(frozen=True)
class WorldSpec:
    """The pybullet world. lock_distance (m) and lock_angle (rad): how close a tool's plate must
    be to the flange for the tool changer to take it, and to its slot for the rack to."""

    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    floor: bool = True
    fixtures: tuple[BoxSpec, ...] = ()
    tools: tuple[ToolSpec, ...] = ()
    parts: tuple[BoxSpec, ...] = ()
    zones: tuple[ZoneSpec, ...] = ()
    lock_distance: float = 0.005
    lock_angle: float = 3.0 * _DEG


@dataclass(frozen=True)
class IoUnitSpec:
    """A unit of digital I/O: up to 32 bits, all inputs or all outputs (LLI cell.cf)."""

    id: int
    name: str
    direction: str   # "input" or "output"


@dataclass(frozen=True)
class IoSignalSpec:
    """One named bit. wire: what drives an input or what an output drives (INPUT_WIRES,
    "zone:<name>", OUTPUT_WIRES); "none" is a plain bit (an output that only stores its value,
    an input that reads 0)."""

    name: str
    unit: int
    bit: int
    wire: str
    direction: str


@dataclass(frozen=True)
class IoSpec:
    units: tuple[IoUnitSpec, ...] = ()
    signals: tuple[IoSignalSpec, ...] = ()


@dataclass(frozen=True)
class SensorSpec:
    """A sensor read through `Controller.read_sensor(name)`. Laser: range from min_range to
    max_range (m), from the tool tip moved by `offset` (m, tool frame), along the tool's z."""

    name: str
    kind: str
    max_range: float = 1.0
    min_range: float = 0.005
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class RecorderSpec:
    """LLI records.cfx. path: MCAP file (relative paths: to the working directory).
    frequency_percent: of the cycle frequency, 100 = every cycle, 50 = every other one.
    max_seconds: longest recording."""

    path: str = "var/records/cs8.mcap"
    frequency_percent: float = 100.0
    max_seconds: float = 60.0

    @property
    def every_nth(self) -> int:
        """Record one cycle in N: 100 / frequency_percent, rounded to whole cycles."""
        return max(1, round(100.0 / self.frequency_percent))


@dataclass(frozen=True)
class Cell:
    name: str
    arm: ArmModel
    base: Pose            # base_link in the world
    controller: ControllerSpec
    world: WorldSpec
    io: IoSpec
    sensors: tuple[SensorSpec, ...]
    recorder: RecorderSpec
    source: str = "<string>"
    # Where base_link stands in a cell shared with other arms (the launcher's cell file, not
    # this world file: [[devices]] placement_xyz, placement_rpy_deg), and that cell's name;
    # None: the arm is placed nowhere beyond its own world.
    placement: Pose | None = None
    shared_cell: str = ""

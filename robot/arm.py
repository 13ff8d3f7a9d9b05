"""The TX90-class arm: its published parameters, and a URDF written from them.

Every number comes from ../shared/robot/tx90.md (manufacturer data D28082904C). Lengths in
metres, angles in radians, velocities in rad/s, accelerations in rad/s^2, efforts in N*m,
masses in kg. Joint arrays have shape (6,), joint 1 first.

Acceleration and jerk limits are not published; we choose them (see `_ACCEL_PER_VELOCITY` and
`JERK_RAMP`) and make them configuration: a cell file may override `max_acceleration` and
`max_jerk`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from xml.sax.saxutils import quoteattr

import numpy as np

_DEG = math.pi / 180.0

# Main axes reach full speed in 1/3 s, wrist axes in 1/5 s: a plausible, conservative choice
# for a 50 kg-class arm with a 6 kg payload (the TX90's nominal load).
_ACCEL_PER_VELOCITY = (3.0, 3.0, 3.0, 5.0, 5.0, 5.0)

# The jerk limit: each joint ramps its acceleration from zero to its maximum in 20 ms, so
# max_jerk = max_acceleration / JERK_RAMP (50 times the acceleration limit per second). No jerk
# figure is published (tx90.md); industrial controllers ramp acceleration over tens of
# milliseconds, and 20 ms is the shortest of those that keeps a rest-to-rest joint move within
# about 3 % of its jerk-free time (ruckig measured it at 1.028 x; 50 ms ramps cost 7 %), while
# each 4 ms cycle changes the acceleration by a fifth of its limit at most, not all of it.
JERK_RAMP = 0.020   # s

JOINT_AXES = ("z", "y", "y", "z", "y", "z")


@dataclass(frozen=True)
class ArmModel:
    """Geometry and limits of an ortho-parallel 6R arm with a spherical wrist.

    Geometry in the notation of Brandstoetter, Angerer, Hofbaur (2014): a1 (J2 ahead of the
    J1 axis), a2 (elbow offset, zero here), b (lateral offset of the forearm), c1 (J2 above
    the base), c2 (upper arm), c3 (forearm, J3 to wrist centre), c4 (wrist centre to flange).
    Zero joint offsets: at q = 0 the arm stands straight up.
    """

    name: str = "TX90"
    a1: float = 0.050
    a2: float = 0.0
    b: float = 0.050
    c1: float = 0.478
    c2: float = 0.425
    c3: float = 0.425
    c4: float = 0.100
    joint_min: tuple[float, ...] = tuple(d * _DEG for d in (-180, -130, -145, -270, -115, -270))
    joint_max: tuple[float, ...] = tuple(d * _DEG for d in (180, 147.5, 145, 270, 140, 270))
    max_velocity: tuple[float, ...] = tuple(d * _DEG for d in (400, 400, 430, 540, 475, 760))
    max_acceleration: tuple[float, ...] = field(default=())
    max_jerk: tuple[float, ...] = field(default=())   # rad/s^3; default: see JERK_RAMP
    max_effort: tuple[float, ...] = (318.0, 166.0, 76.0, 34.0, 29.0, 11.0)
    # Tool-tip Cartesian limits (m/s, rad/s, m/s^2, rad/s^2): not published either; our choice,
    # well inside what the joint limits allow near the middle of the workspace.
    max_linear_velocity: float = 2.0
    max_angular_velocity: float = 2 * math.pi
    max_linear_acceleration: float = 10.0
    max_angular_acceleration: float = 8 * math.pi
    # base, link1 .. link6
    link_masses: tuple[float, ...] = (10.73, 16.93, 12.99, 7.50, 4.54, 0.569, 0.031)

    def __post_init__(self):
        if not self.max_acceleration:
            accel = tuple(k * v for k, v in zip(_ACCEL_PER_VELOCITY, self.max_velocity))
            object.__setattr__(self, "max_acceleration", accel)
        if not self.max_jerk:
            jerk = tuple(a / JERK_RAMP for a in self.max_acceleration)
            object.__setattr__(self, "max_jerk", jerk)
        for name in ("joint_min", "joint_max", "max_velocity", "max_acceleration", "max_jerk",
                     "max_effort"):
            if len(getattr(self, name)) != 6:
                raise ValueError(f"{name} needs 6 values")
        if any(lo >= hi for lo, hi in zip(self.joint_min, self.joint_max)):
            raise ValueError("every joint_min must be below its joint_max")
        if min(min(self.max_velocity), min(self.max_acceleration), min(self.max_jerk)) <= 0:
            raise ValueError("velocity, acceleration and jerk limits must be positive")

    @property
    def lower(self) -> np.ndarray:
        return np.array(self.joint_min)

    @property
    def upper(self) -> np.ndarray:
        return np.array(self.joint_max)

    @property
    def joint_origins(self) -> tuple[tuple[float, float, float], ...]:
        """Origin of each joint in its parent link's frame at q = 0 (tx90.md table)."""
        # a2 sits at the elbow (J4's origin in link 3), so it turns with q2 + q3 as in the paper.
        return ((0.0, 0.0, self.c1), (self.a1, 0.0, 0.0), (0.0, self.b, self.c2),
                (self.a2, 0.0, 0.0), (0.0, 0.0, self.c3), (0.0, 0.0, self.c4))

    def with_overrides(self, **values) -> "ArmModel":
        if "max_acceleration" in values and "max_jerk" not in values:
            values["max_jerk"] = ()     # ramps of JERK_RAMP at the new accelerations
        return replace(self, **values)


# The three published variants share everything but the arm lengths.
VARIANTS = {
    "TX90": ArmModel(),
    "TX90L": ArmModel(name="TX90L", c2=0.500, c3=0.550),
    "TX90XL": ArmModel(name="TX90XL", c2=0.650, c3=0.650),
}


def arm_model(variant: str = "TX90", **overrides) -> ArmModel:
    try:
        base = VARIANTS[variant]
    except KeyError:
        raise ValueError(f"unknown arm variant {variant!r}; known: {', '.join(VARIANTS)}") from None
    return base.with_overrides(**overrides) if overrides else base


# ---- URDF ------------------------------------------------------------------------------------

# Display and collision shapes: (radius, length, centre z in the link frame) of one cylinder per
# link, sized to roughly fill the real arm's envelope. They are ours, not the manufacturer's.
def _link_shapes(arm: ArmModel):
    return (
        (0.13, arm.c1 - 0.10, (arm.c1 - 0.10) / 2),   # base column, up to just below J2
        (0.12, 0.22, -0.03),                          # shoulder housing around J2
        (0.08, arm.c2, arm.c2 / 2),                   # upper arm
        (0.075, 0.16, 0.0),                           # elbow housing around J3
        (0.055, arm.c3 - 0.06, (arm.c3 - 0.06) / 2),  # forearm up to the wrist
        (0.05, 0.10, 0.0),                            # wrist housing around J5
        (0.04, 0.02, -0.01),                          # flange disk
    )


def _cylinder_inertia(mass: float, radius: float, length: float) -> tuple[float, float, float]:
    side = mass * (3 * radius**2 + length**2) / 12.0
    return side, side, mass * radius**2 / 2.0


def _link_xml(name: str, mass: float, radius: float, length: float, z: float) -> str:
    ixx, iyy, izz = _cylinder_inertia(mass, radius, length)
    shape = f'<cylinder radius="{radius:.4f}" length="{length:.4f}"/>'
    origin = f'<origin xyz="0 0 {z:.4f}" rpy="0 0 0"/>'
    return (
        f'  <link name="{name}">\n'
        f'    <inertial>{origin}<mass value="{mass}"/>'
        f'<inertia ixx="{ixx:.6g}" iyy="{iyy:.6g}" izz="{izz:.6g}" ixy="0" ixz="0" iyz="0"/></inertial>\n'
        f'    <visual>{origin}<geometry>{shape}</geometry>'
        f'<material name="staubli_yellow"><color rgba="0.95 0.75 0.1 1"/></material></visual>\n'
        f'    <collision>{origin}<geometry>{shape}</geometry></collision>\n'
        f'  </link>\n'
    )


def urdf(arm: ArmModel) -> str:
    """The arm as URDF: links base_link, link1..link6, the flange frame tool0."""
    axes = {"x": "1 0 0", "y": "0 1 0", "z": "0 0 1"}
    links = ["base_link"] + [f"link{i}" for i in range(1, 7)]
    parts = [f'<?xml version="1.0"?>\n<robot name={quoteattr(arm.name.lower())}>\n']
    for link, mass, (radius, length, z) in zip(links, arm.link_masses, _link_shapes(arm)):
        parts.append(_link_xml(link, mass, radius, length, z))
    for i in range(6):
        x, y, z = arm.joint_origins[i]
        parts.append(
            f'  <joint name="joint_{i + 1}" type="revolute">'
            f'<parent link="{links[i]}"/><child link="{links[i + 1]}"/>'
            f'<origin xyz="{x} {y} {z}" rpy="0 0 0"/><axis xyz="{axes[JOINT_AXES[i]]}"/>'
            f'<limit lower="{arm.joint_min[i]!r}" upper="{arm.joint_max[i]!r}" '
            f'velocity="{arm.max_velocity[i]!r}" effort="{arm.max_effort[i]}"/></joint>\n'
        )
    # tool0 carries a token mass: pybullet would give a link without inertia 1 kg.
    parts.append('  <link name="tool0"><inertial><mass value="1e-6"/>'
                 '<inertia ixx="1e-9" iyy="1e-9" izz="1e-9" ixy="0" ixz="0" iyz="0"/></inertial></link>\n'
                 '  <joint name="flange" type="fixed"><parent link="link6"/><child link="tool0"/>'
                 '<origin xyz="0 0 0" rpy="0 0 0"/></joint>\n</robot>\n')
    return "".join(parts)

"""The tools' shapes as URDF (simple boxes and cylinders), with no physics engine attached.

A tool's frame is its mounting plate: z along the tool axis, away from the flange; the tip is
`length` along z. The simulator loads these URDFs into pybullet (sim/world.py, sim/tools.py);
the server's collision model reads the same text with pinocchio (server/collision/), so the two
always agree on the shapes. Lengths in metres, masses in kg.
"""
from __future__ import annotations

from landscape.robot.cell import ToolSpec

PLATE_T = 0.015          # m, plate thickness
GRIPPER_BODY = 0.06      # m, gripper housing height below the plate
FINGER = (0.01, 0.02)    # m, finger thickness (along the stroke) and width
FINGER_MASS = 0.1        # kg, each
FINGER_FORCE = 200.0     # N, finger drive


# ---- URDF -------------------------------------------------------------------------------------

def _box(size, xyz, rgba) -> str:
    geo = f'<geometry><box size="{size[0]} {size[1]} {size[2]}"/></geometry>'
    org = f'<origin xyz="{xyz[0]} {xyz[1]} {xyz[2]}"/>'
    return (f'<visual>{org}{geo}<material name="m"><color rgba="{rgba}"/></material></visual>'
            f'<collision>{org}{geo}</collision>')


def _cyl(radius, length, z, rgba, collide: bool = True) -> str:
    geo = f'<geometry><cylinder radius="{radius}" length="{length}"/></geometry>'
    org = f'<origin xyz="0 0 {z}"/>'
    return (f'<visual>{org}{geo}<material name="m"><color rgba="{rgba}"/></material></visual>'
            + (f'<collision>{org}{geo}</collision>' if collide else ''))


def _inertial(mass, xyz, r) -> str:
    i = mass * r * r / 2.0   # a rough, well-conditioned inertia: the tool is not a study object
    return (f'<inertial><origin xyz="{xyz[0]} {xyz[1]} {xyz[2]}"/><mass value="{mass}"/>'
            f'<inertia ixx="{i}" iyy="{i}" izz="{i}" ixy="0" ixz="0" iyz="0"/></inertial>')


_GREY, _DARK, _BLACK = "0.7 0.7 0.72 1", "0.25 0.25 0.28 1", "0.1 0.1 0.1 1"


def tool_urdf(spec: ToolSpec) -> str:
    """The tool as URDF; its root link `plate` is the tool frame."""
    if spec.kind == "parallel_gripper":
        return _gripper_urdf(spec)
    return _cup_urdf(spec)


def _gripper_urdf(s: ToolSpec) -> str:
    body_end = PLATE_T + GRIPPER_BODY
    if s.length <= body_end + 0.01:
        raise ValueError(f"tool {s.name!r}: a gripper needs length > {body_end + 0.01} m")
    finger_len = s.length - body_end
    width = s.stroke + 2 * FINGER[0] + 0.02
    plate = (_cyl(0.045, PLATE_T, PLATE_T / 2, _GREY)
             + _box((width, 0.05, GRIPPER_BODY), (0, 0, PLATE_T + GRIPPER_BODY / 2), _DARK)
             + _inertial(max(s.mass - 2 * FINGER_MASS, 0.05), (0, 0, body_end / 2), 0.05))
    parts = [f'<?xml version="1.0"?>\n<robot name="{s.name}">\n<link name="plate">{plate}</link>\n']
    for side, sign in (("left", -1), ("right", 1)):
        # Joint value d = half the finger gap: 0 closed, stroke / 2 open.
        x = sign * FINGER[0] / 2
        finger = (_box((FINGER[0], FINGER[1], finger_len), (x, 0, 0), _BLACK)
                  + _inertial(FINGER_MASS, (x, 0, 0), 0.01))
        parts.append(
            f'<link name="finger_{side}">{finger}</link>\n'
            f'<joint name="finger_{side}" type="prismatic"><parent link="plate"/>'
            f'<child link="finger_{side}"/><origin xyz="0 0 {body_end + finger_len / 2}"/>'
            f'<axis xyz="{sign} 0 0"/><limit lower="0" upper="{s.stroke / 2}" '
            f'effort="{FINGER_FORCE}" velocity="{s.finger_speed}"/></joint>\n')
    parts.append("</robot>\n")
    return "".join(parts)


def _cup_urdf(s: ToolSpec) -> str:
    cup_h = 0.02
    stem = s.length - PLATE_T - cup_h
    if stem <= 0:
        raise ValueError(f"tool {s.name!r}: a vacuum cup needs length > {PLATE_T + cup_h} m")
    # The rubber lip touches as a dome (a sphere of the cup's radius, its lowest point the tip):
    # one contact point, so the force depends on how deep it is pressed, not on how many
    # points a flat face happens to touch with as it slides.
    lip = (f'<collision><origin xyz="0 0 {s.length - s.cup_radius}"/><geometry>'
           f'<sphere radius="{s.cup_radius}"/></geometry></collision>')
    plate = (_cyl(0.04, PLATE_T, PLATE_T / 2, _GREY)
             + _cyl(0.012, stem, PLATE_T + stem / 2, _DARK)
             + _cyl(s.cup_radius, cup_h, s.length - cup_h / 2, _BLACK, collide=False) + lip
             + _inertial(s.mass, (0, 0, s.length / 3), 0.04))
    return (f'<?xml version="1.0"?>\n<robot name="{s.name}">\n<link name="plate">{plate}</link>\n'
            '</robot>\n')

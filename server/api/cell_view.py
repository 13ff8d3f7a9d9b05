"""The cell around the arm as the device knows it (GetCellDescription): the fixtures and zones
of the cell file, and the tools and parts where the collision scene, which follows every tool
change, grasp and put-down the device commands, says they are. Poses (4, 4) in the world, m."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from landscape.server.planning.collision import CollisionScene
from landscape.robot.units import pose_matrix
from landscape.robot.tool_shapes import tool_urdf


@dataclass(frozen=True)
class Body:
    name: str
    kind: str                         # "fixture", "tool", "part" or "zone"
    pose: np.ndarray | None           # (4, 4) in the world; None while attached
    size: tuple[float, float, float] | None = None
    color: tuple[float, ...] = ()
    urdf: str = ""
    attached_to: str = ""             # "flange" (a mounted tool), "tool" (a held part)


def bodies(scene: CollisionScene) -> list[Body]:
    world = scene.cell.world
    out = [Body(f.name, "fixture", pose_matrix(f.pose.xyz, f.pose.rpy), f.size, f.color)
           for f in world.fixtures]
    for tool in world.tools:
        mounted = scene.mounted == tool.name
        out.append(Body(tool.name, "tool", None if mounted else scene.tool_pose(tool.name),
                        urdf=tool_urdf(tool), attached_to="flange" if mounted else ""))
    for part in world.parts:
        held = scene.held == part.name
        pose = None if held else scene.part_pose(part.name)
        if pose is None and not held:
            continue   # taken out of the cell
        out.append(Body(part.name, "part", pose, part.size, part.color,
                        attached_to="tool" if held else ""))
    out += [Body(z.name, "zone", pose_matrix(z.center, (0.0, 0.0, 0.0)), z.size)
            for z in world.zones]
    return out

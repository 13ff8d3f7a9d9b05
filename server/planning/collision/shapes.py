"""The collision shapes of the cell's bodies, read from the same descriptions the simulator uses.

The arm's links come from its URDF (sim/arm.py: one cylinder per link), the tools from theirs
(sim/tool_shapes.py: plate, housing, fingers or cup), both read by pinocchio, so the checker and
the pybullet world agree on every shape; fixtures and parts are the cell file's boxes, and the
floor is a half-space (z <= 0 in the world is solid).

Units: metres. Poses are (4, 4) homogeneous matrices.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import coal
import numpy as np
import pinocchio as pin

from landscape.robot.arm import ArmModel, urdf
from landscape.robot.cell import BoxSpec, ToolSpec
from landscape.robot.tool_shapes import tool_urdf

ARM_LINKS = ("base_link", "link1", "link2", "link3", "link4", "link5", "link6")
FLANGE_LINK = 6    # the link tools and held parts move with (tool0 coincides with its frame)
FLOOR = "floor"


@dataclass(frozen=True, eq=False)
class Geometry:
    """One collision shape of a body.

    name: the body's name, or "<body>/<shape>" for bodies of several shapes (a tool);
    body: the body it belongs to ("table", "link3", "gripper", "block_1", "floor");
    shape: a coal geometry, in its own frame; link: what it moves with -- 0 for base_link and
    everything fixed in the cell, 1..6 for link1..link6 (a mounted tool and a held part move
    with link6); placement (4, 4): its frame in the link's frame (link 0: the base_link frame).
    """

    name: str
    body: str
    shape: object
    link: int
    placement: np.ndarray


@lru_cache(maxsize=8)
def arm_description(arm: ArmModel) -> tuple[pin.Model, tuple[Geometry, ...]]:
    """The arm's kinematic model in pinocchio (from its URDF; universe = base_link) and its
    links, one geometry each (ARM_LINKS order) in their link frames. Shared: read only."""
    text = urdf(arm)
    model = pin.buildModelFromXML(text)
    geoms = pin.buildGeomFromUrdfString(model, text, pin.COLLISION)
    out = []
    for g in geoms.geometryObjects:
        body = model.frames[g.parentFrame].name
        out.append(Geometry(body, body, g.geometry, g.parentJoint, g.placement.homogeneous))
    if tuple(g.body for g in out) != ARM_LINKS:
        raise ValueError(f"unexpected arm links in the URDF: {[g.body for g in out]}")
    return model, tuple(out)


@lru_cache(maxsize=32)
def _tool_shapes(spec: ToolSpec, gap: float) -> tuple[tuple[str, object, np.ndarray], ...]:
    """(shape name, coal shape, placement (4, 4) in the tool's plate frame) of a tool whose
    fingers (if any) stand `gap` apart (m)."""
    text = tool_urdf(spec)
    model = pin.buildModelFromXML(text)
    geoms = pin.buildGeomFromUrdfString(model, text, pin.COLLISION)
    data, gdata = model.createData(), pin.GeometryData(geoms)
    # The finger joints are each one half of the gap (0 closed, stroke / 2 open).
    pin.updateGeometryPlacements(model, data, geoms, gdata, np.full(model.nq, gap / 2.0))
    return tuple((g.name.removesuffix("_0"), g.geometry, gdata.oMg[i].homogeneous.copy())
                 for i, g in enumerate(geoms.geometryObjects))


def tool_geometries(spec: ToolSpec, gap: float, link: int, frame: np.ndarray
                    ) -> list[Geometry]:
    """A tool's shapes with its plate frame at `frame` (4, 4) in the frame of `link` (0: the
    base_link frame, standing in the rack; FLANGE_LINK: mounted). gap: finger gap (m),
    clipped to the gripper's stroke; ignored for a cup."""
    gap = min(max(gap, 0.0), spec.stroke)
    return [Geometry(f"{spec.name}/{name}", spec.name, shape, link, frame @ placement)
            for name, shape, placement in _tool_shapes(spec, float(gap))]


def box_geometry(spec: BoxSpec, link: int, placement: np.ndarray) -> Geometry:
    """A fixture or part: a box of spec.size (full extents, m) whose centre is at `placement`."""
    return Geometry(spec.name, spec.name, coal.Box(*spec.size), link, placement)


def floor_geometry(world_in_base: np.ndarray) -> Geometry:
    """The floor: everything below z = 0 of the world is solid."""
    shape = coal.Halfspace(np.array([0.0, 0.0, 1.0]), 0.0)
    return Geometry(FLOOR, FLOOR, shape, 0, world_in_base)

"""Every link of the arm relative to its parent, as a viewer draws the URDF (arm.urdf): the
live Foxglove bridge and the recorder's MCAP files publish them as Foxglove FrameTransforms.

The URDF's joints are revolute about a fixed axis with their origin's rotation zero, so the
transform from a link to the next is the joint's origin (a constant translation) then a
rotation of q about the joint's axis: a quaternion (axis * sin(q / 2), cos(q / 2)), computed
for any number of samples at once. tool0 is fixed to link6 (the flange).
"""
from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np

from landscape.robot.arm import JOINT_AXES, ArmModel

LINKS = ("base_link", "link1", "link2", "link3", "link4", "link5", "link6", "tool0")
_AXIS = {"x": 0, "y": 1, "z": 2}


class LinkFrames:
    """The parent -> child transforms of an arm's links (LINKS), frame ids prefixed with
    `prefix` ("arm1/" names arm1's links in a cell of several arms). origins: (6, 3) m, each
    joint's origin in its parent link; axes: each joint's axis, "x", "y" or "z"."""

    def __init__(self, origins, axes, prefix: str = ""):
        self.prefix = prefix
        self.pairs = [(prefix + LINKS[i], prefix + LINKS[i + 1]) for i in range(7)]
        self.origins = np.array([*np.asarray(origins, dtype=float), (0.0, 0.0, 0.0)])   # (7, 3)
        self._axes = [_AXIS[axis] for axis in axes]

    @classmethod
    def for_arm(cls, arm: ArmModel, prefix: str = "") -> "LinkFrames":
        return cls(arm.joint_origins, JOINT_AXES, prefix)

    @classmethod
    def from_urdf(cls, text: str, prefix: str = "") -> "LinkFrames":
        """From the URDF of arm.urdf (GetRobotDescription's): its six revolute joints."""
        robot = ET.fromstring(text)
        joints = [j for j in robot.iter("joint") if j.get("type") == "revolute"]
        origins = [[float(v) for v in j.find("origin").get("xyz").split()] for j in joints]
        axes = ["xyz"[[float(v) for v in j.find("axis").get("xyz").split()].index(1.0)]
                for j in joints]
        if len(joints) != 6:
            raise ValueError(f"expected the six revolute joints of a TX90-class arm, got "
                             f"{len(joints)}")
        return cls(origins, axes, prefix)

    def quaternions(self, q) -> np.ndarray:
        """(..., 7, 4) quaternions x, y, z, w of each link in its parent, for joints q (..., 6)
        in radians; the last, tool0 in link6, is the identity."""
        q = np.asarray(q, dtype=float)
        out = np.zeros((*q.shape[:-1], 7, 4))
        half = q / 2.0
        for joint, axis in enumerate(self._axes):
            out[..., joint, axis] = np.sin(half[..., joint])
            out[..., joint, 3] = np.cos(half[..., joint])
        out[..., 6, 3] = 1.0
        return out

    def messages(self, q, stamp_ns: int):
        """A foxglove.messages.FrameTransforms of every link at joints q (6,), stamped."""
        from foxglove.messages import (FrameTransform, FrameTransforms, Quaternion, Timestamp,
                                       Vector3)
        stamp = Timestamp(sec=stamp_ns // 1_000_000_000, nsec=stamp_ns % 1_000_000_000)
        transforms = []
        for (parent, child), origin, quat in zip(self.pairs, self.origins.tolist(),
                                                 self.quaternions(q).tolist()):
            transforms.append(FrameTransform(
                timestamp=stamp, parent_frame_id=parent, child_frame_id=child,
                translation=Vector3(x=origin[0], y=origin[1], z=origin[2]),
                rotation=Quaternion(x=quat[0], y=quat[1], z=quat[2], w=quat[3])))
        return FrameTransforms(transforms=transforms)


def pose_message(matrix: np.ndarray, frame_id: str, stamp_ns: int):
    """A foxglove.messages.PoseInFrame of a (4, 4) pose in `frame_id`, stamped."""
    import pinocchio as pin
    from foxglove.messages import Pose, PoseInFrame, Quaternion, Timestamp, Vector3
    x, y, z, w = pin.Quaternion(np.asarray(matrix[:3, :3], dtype=float)).coeffs().tolist()
    t = matrix[:3, 3].tolist()
    return PoseInFrame(timestamp=Timestamp(sec=stamp_ns // 1_000_000_000,
                                           nsec=stamp_ns % 1_000_000_000),
                       frame_id=frame_id,
                       pose=Pose(position=Vector3(x=t[0], y=t[1], z=t[2]),
                                 orientation=Quaternion(x=x, y=y, z=z, w=w)))

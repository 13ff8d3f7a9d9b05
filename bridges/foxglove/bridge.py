"""One arm in Foxglove: its channels, filled from its device's state and event streams.

Topics under the arm's name (`/arm1/...`): `tf` (foxglove.FrameTransforms: every link),
`tool_pose` (foxglove.PoseInFrame in `arm1/base_link`), `joint_states` (foxglove.JointStates),
`wrench` (the force/torque sensor), `digital_io`, `log` (foxglove.Log: events and alarms) and
`robot_description` (the URDF, every DESCRIPTION_PERIOD seconds: the protocol keeps no last
message for a late subscriber, and this one only goes to a channel's subscribers).
"""
from __future__ import annotations

import logging
import time
import xml.etree.ElementTree as ET

import foxglove
from foxglove.channels import (FrameTransformsChannel, JointStatesChannel, LogChannel,
                               PoseInFrameChannel)

from landscape.bridges.device_feed import Callbacks, Description
from landscape.bridges.foxglove import messages
from landscape.robot.link_frames import LinkFrames

log = logging.getLogger(__name__)

DESCRIPTION_PERIOD = 2.0   # s


def prefixed_urdf(urdf: str, prefix: str) -> str:
    """The URDF with every link named `prefix` + its name, as the transforms name them."""
    robot = ET.fromstring(urdf)
    for link in robot.iter("link"):
        link.set("name", prefix + link.get("name"))
    for joint in robot.iter("joint"):
        for end in ("parent", "child"):
            element = joint.find(end)
            element.set("link", prefix + element.get("link"))
    return ET.tostring(robot, encoding="unicode")


class ArmBridge:
    """The Foxglove side of device `name`; `callbacks()` is what its DeviceFeed calls."""

    def __init__(self, name: str, context: foxglove.Context):
        self.name, self.prefix = name, f"{name}/"
        topic = f"/{name}"
        self.tf = FrameTransformsChannel(f"{topic}/tf", context=context)
        self.pose = PoseInFrameChannel(f"{topic}/tool_pose", context=context)
        self.joints = JointStatesChannel(f"{topic}/joint_states", context=context)
        self.log = LogChannel(f"{topic}/log", context=context)
        self.wrench = foxglove.Channel(f"{topic}/wrench", schema=messages.WRENCH_SCHEMA,
                                       context=context)
        self.io = foxglove.Channel(f"{topic}/digital_io", schema=messages.IO_SCHEMA,
                                   context=context)
        self.description_channel = foxglove.Channel(
            f"{topic}/robot_description", schema=messages.DESCRIPTION_SCHEMA, context=context)
        self.urdf = ""            # prefixed, once the device said it
        self.joint_names: tuple[str, ...] = ()
        self.frames: LinkFrames | None = None
        self._described = 0.0      # when the URDF was last sent (monotonic s)

    def callbacks(self) -> Callbacks:
        return Callbacks(self.connected, self.sample, self.event, self.digital_io, self.lost)

    def connected(self, description: Description) -> None:
        self.urdf = prefixed_urdf(description.urdf, self.prefix)
        self.joint_names = description.joint_names
        self.frames = LinkFrames.from_urdf(description.urdf, self.prefix)
        self.send_description()
        log.info("%s: %s connected", self.name, description.robot_type)

    def send_description(self) -> None:
        if self.urdf:
            self._described = time.monotonic()
            self.description_channel.log({"data": self.urdf})

    def sample(self, sample) -> None:
        if time.monotonic() - self._described > DESCRIPTION_PERIOD:
            self.send_description()
        ns = messages.stamp_ns(sample)
        self.tf.log(self.frames.messages(sample.joint_positions, ns), log_time=ns)
        self.pose.log(messages.tool_pose(sample, f"{self.prefix}base_link", ns), log_time=ns)
        self.joints.log(messages.joint_states(sample, self.joint_names, ns), log_time=ns)
        wrench = messages.wrench(sample, ns)
        if wrench is not None:
            self.wrench.log(wrench, log_time=ns)

    def event(self, event) -> None:
        self.log.log(messages.log(event, self.name), log_time=messages.stamp_ns(event))

    def digital_io(self, values) -> None:
        self.io.log(messages.digital_io(values))

    def lost(self, why: str) -> None:
        log.warning("lost %s; connecting again", why)
        self.log.log(foxglove.messages.Log(level=foxglove.messages.LogLevel.Error,
                                           message=f"bridge: lost {why}", name=self.name))

"""The live state every browser shows: StateService.StreamState at the display rate.

The stream is asked for in meters and radians and the tool pose in the robot base frame, the
frames and units of the URDF the page draws (the page converts to the device's units for
display). The force sensor rides along for the force plot; a device that cannot put sensors in
the stream (UNIMPLEMENTED) is asked again without them, and the page says it has no readings.

TEMPORARY (config.poll_state_if_unimplemented): a device server that answers StreamState with
UNIMPLEMENTED is polled instead; the samples then carry only what the gets say, in the device's
units and the world frame, and the StreamStarted message says so in its note.
"""
from __future__ import annotations

import asyncio
import logging
import time

import grpc

from landscape.supervisor.feeds import Feed
from landscape.supervisor.rpc_table import RPCS, STREAM_STATE
from landscape.v1 import (control_pb2, settings_pb2, state_service_pb2 as pb, types_pb2,
                          device_service_pb2_grpc)

log = logging.getLogger(__name__)

SENSORS = ("force_sensor",)
SI_UNITS = types_pb2.Units(linear=types_pb2.LINEAR_UNIT_METERS, angular=types_pb2.ANGULAR_UNIT_RADIANS)


class StateFeed(Feed):
    rpc = STREAM_STATE

    def __init__(self, link, rate_hz: float, poll_if_unimplemented: bool):
        super().__init__(link)
        self.rate_hz = rate_hz
        self.poll_if_unimplemented = poll_if_unimplemented
        self.sensors = SENSORS

    def request(self) -> pb.StreamStateRequest:
        return pb.StreamStateRequest(rate_hz=self.rate_hz, units=SI_UNITS, sensors=self.sensors,
                                     frame=types_pb2.REFERENCE_FRAME_BASE_CARTESIAN_FRAME)

    async def once(self) -> None:
        self.sensors = SENSORS   # a new attempt may be a new server: ask for everything again
        while True:
            try:
                await self._stream()
                return
            except grpc.aio.AioRpcError as error:
                if error.code() is not grpc.StatusCode.UNIMPLEMENTED:
                    raise
                if self.sensors:
                    log.info("%s: state stream without sensors: %s", self.link.name, error.details())
                    self.sensors = ()
                elif self.poll_if_unimplemented:
                    await self._poll(error.details())
                else:
                    raise

    async def _stream(self) -> None:
        async for reply in RPCS[STREAM_STATE].callable(self.link.channel)(self.request()):
            self.working()
            self._publish(reply)

    def _publish(self, reply: pb.StreamStateResponse) -> None:
        kind = reply.WhichOneof("message")
        # The stream's terms reach every browser; samples are latest-wins.
        self.link.publish_latest(f"state.{kind}", STREAM_STATE, reply=reply, ordered=kind == "started")

    # ---- TEMPORARY: polling while StreamState is not served ------------------------------
    async def _poll(self, why: str) -> None:
        """Until a get fails: one sample per display period from the gets (world frame, the
        device's units); the failure ends the feed's attempt and the stream is tried again."""
        device = device_service_pb2_grpc.DeviceServiceStub(self.link.channel)
        self._publish(pb.StreamStateResponse(started=pb.StreamStarted(
            granted_rate_hz=self.rate_hz, frame=types_pb2.REFERENCE_FRAME_WORLD_CARTESIAN_FRAME,
            note=f"TEMPORARY polling of GetRobotPosition: StreamState answered UNIMPLEMENTED "
                 f"({why}); no cycle number, cycle time, velocities, setpoints or sensors")))
        period = 1.0 / self.rate_hz
        while True:
            started = time.monotonic()
            position, state, motion, tag = await asyncio.gather(
                device.GetRobotPosition(settings_pb2.GetRobotPositionRequest(), timeout=5),
                device.GetDeviceState(control_pb2.GetDeviceStateRequest(), timeout=5),
                device.GetMotionControlState(settings_pb2.GetMotionControlStateRequest(), timeout=5),
                device.GetTagId(settings_pb2.GetTagIdRequest(), timeout=5))
            self._publish(pb.StreamStateResponse(sample=pb.StateSample(
                joint_positions=position.joint_position, tool_pose=position.world_position,
                units=position.units, device_state=state.state, estop=state.estop,
                command_id=state.command_id, motion_control_state=motion.motion_control_state,
                control_mode=motion.control_mode, point_name=tag.path_name, tag_name=tag.tag_id)))
            await asyncio.sleep(max(0.0, period - (time.monotonic() - started)))

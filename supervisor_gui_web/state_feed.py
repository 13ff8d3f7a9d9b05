"""The live state every browser shows: StateService.StreamState at the display rate.

The stream is asked for in meters and radians and the tool pose in the robot base frame, the
frames and units of the URDF the page draws (the page converts to the device's units for
display). The force sensor rides along for the force plot; a device that cannot put sensors in
the stream (UNIMPLEMENTED) is asked again without them, and the page says it has no readings.
A new end effector or end effector state (a tool coupled, a part taken or let go) is told to
`on_end_effector`: the cell around the arm may have changed.
"""
from __future__ import annotations

import logging

import grpc

from landscape.supervisor.feeds import Feed
from landscape.supervisor.rpc_table import RPCS, STREAM_STATE
from landscape.v1 import state_service_pb2 as pb, types_pb2

log = logging.getLogger(__name__)

SENSORS = ("force_sensor",)
SI_UNITS = types_pb2.Units(linear=types_pb2.LINEAR_UNIT_METERS, angular=types_pb2.ANGULAR_UNIT_RADIANS)


class StateFeed(Feed):
    rpc = STREAM_STATE

    def __init__(self, link, rate_hz: float, on_end_effector=lambda: None):
        super().__init__(link)
        self.rate_hz = rate_hz
        self.sensors = SENSORS
        self.on_end_effector = on_end_effector
        self._end_effector: tuple[str, str] | None = None

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
                if error.code() is not grpc.StatusCode.UNIMPLEMENTED or not self.sensors:
                    raise
                log.info("%s: state stream without sensors: %s", self.link.name, error.details())
                self.sensors = ()

    async def _stream(self) -> None:
        async for reply in RPCS[STREAM_STATE].callable(self.link.channel)(self.request()):
            self.working()
            self._publish(reply)

    def _publish(self, reply: pb.StreamStateResponse) -> None:
        kind = reply.WhichOneof("message")
        if kind == "sample":
            end_effector = (reply.sample.end_effector, reply.sample.end_effector_state)
            if end_effector != self._end_effector:
                self._end_effector = end_effector
                self.on_end_effector()
        # The stream's terms reach every browser; samples are latest-wins.
        self.link.publish_latest(f"state.{kind}", STREAM_STATE, reply=reply, ordered=kind == "started")

"""DeviceService.SolvePose: a move to a goal planned and checked as MoveAbsolute would, not
made; the refusal the move would get is an answer, not an error.

A mixin of DeviceServicer (device.py): the guard finds this body through it.
"""
from __future__ import annotations

import grpc

from landscape.server.api import convert
from landscape.server.api.guard import blocking
from landscape.server.errors import CommandError, info_metadata
from landscape.v1 import pose_solving_pb2 as pb


class PoseSolving:
    """SolvePose; `self.device` is DeviceServicer's."""

    @blocking   # planning and the collision check take milliseconds: off the event loop
    def SolvePose(self, request, context):
        device = self.device
        units = device.settings.units
        try:
            settings = convert.move_settings(device.settings, request)
            frame = convert.enum_value(convert.FRAMES, request.frame, "frame")
            trajectory = device.motions.plan_move(
                frame, convert.move_values(frame, request.values, units), False,
                convert.motion_type(request), convert.optional_speed(request), settings,
                "the move to this pose")
        except CommandError as error:
            if error.status is grpc.StatusCode.INVALID_ARGUMENT:
                raise   # a malformed goal: refused as MoveAbsolute refuses it
            return pb.SolvePoseResponse(ret_val=convert.ok("MoveAbsolute would be refused"),
                                        refusal=refusal(error), units=convert.units_to_pb(units))
        goal = trajectory.positions[-1]
        tip = device.kinematics.forward(goal) @ settings.tool_offset
        return pb.SolvePoseResponse(
            ret_val=convert.ok("reachable"), reachable=True,
            joints=units.angle_from_si(goal).tolist(), base_pose=convert.matrix_to_pose(tip, units),
            world_pose=convert.matrix_to_pose(settings.base_in_world @ tip, units),
            duration=trajectory.duration, units=convert.units_to_pb(units))


def refusal(error: CommandError) -> pb.MoveRefusal:
    """What the refused call's status and ErrorInfo would say (errors.to_status)."""
    return pb.MoveRefusal(status=error.status.name, reason=error.reason, message=error.message,
                          metadata=info_metadata(error))

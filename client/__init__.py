"""Python client for a LandScape device server (landscape.v1 over gRPC).

    from landscape.client import Frame, Robot

    with Robot("127.0.0.1:50051", "me") as robot, robot.control():
        robot.move_absolute([0.5, 0, 1.57, 0, 1.57, 0], Frame.JOINT).wait(timeout=30)

`Robot` (blocking) and `AsyncRobot` (asyncio) have a method per command of the contract;
errors are the exceptions below (module errors). `Session` and `AsyncSession` are the
session alone, for programs that use the generated stubs directly. A device server that
wants TLS or a role token: `Robot(target, tls=ClientTLS(ca="ca.pem"), token=read_token(path))`
(the same for AsyncRobot), or a channel from `open_channel` / `open_aio_channel` (module
credentials).
"""
from landscape.client.aio import AsyncCommand, AsyncRobot
from landscape.client.aio_session import AsyncSession
from landscape.client.command import Command
from landscape.client.credentials import ClientTLS, open_aio_channel, open_channel, read_token
from landscape.client.errors import (CommandAborted, CommandFailed, CommandRefused,
                                     CommandTimeout, LandscapeError, NotImplementedByServer,
                                     NotAllowed, NotLockHolder, TransportError, WrongState)
from landscape.client.robot import Robot, connect
from landscape.client.session import Session
from landscape.client.values import (AccelType, AngularUnit, DeviceState, Frame, LinearUnit,
                                     Motion, Offset, Pose, SpeedType, TagPoint)

__all__ = [
    "Robot", "AsyncRobot", "connect", "Command", "AsyncCommand", "Session", "AsyncSession",
    "Frame", "Motion", "Offset", "SpeedType", "AccelType", "LinearUnit", "AngularUnit",
    "DeviceState", "Pose", "TagPoint",
    "LandscapeError", "CommandRefused", "WrongState", "NotLockHolder", "NotAllowed",
    "NotImplementedByServer",
    "TransportError", "CommandFailed", "CommandAborted", "CommandTimeout",
    "ClientTLS", "open_channel", "open_aio_channel", "read_token",
]

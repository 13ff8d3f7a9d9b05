"""Python client for a LandScape device server (landscape.v1 over gRPC).

    from landscape.client import Frame, Robot

    with Robot("127.0.0.1:50051", "me") as robot, robot.control():
        robot.move_absolute([0.5, 0, 1.57, 0, 1.57, 0], Frame.JOINT).wait(timeout=30)

`Robot` (blocking) and `AsyncRobot` (asyncio) have a method per command of the contract;
errors are the exceptions below (module errors). They are one client core: AsyncRobot is a
session (AsyncSession) on a DeviceLink (a device's channel, the keeper threads where session
keep-alives run, one shared event subscription and state stream), and Robot runs it on a
loop thread. A program that serves many people on one device (a gateway, a supervisor) opens
one DeviceLink and an AsyncRobot or AsyncSession per person on it, each with its Identity
(module identity). `Session` is a session alone on a synchronous channel, for programs that
use the generated stubs directly. A device server that wants TLS or a role token:
`Robot(target, tls=ClientTLS(ca="ca.pem"), token=read_token(path))` (the same for AsyncRobot),
or an `Endpoint`.
"""
from landscape.client.aio import AsyncCommand, AsyncRobot
from landscape.client.aio_session import AsyncSession
from landscape.client.command import Command
from landscape.client.credentials import (ClientTLS, Endpoint, open_aio_channel, open_channel,
                                          read_token)
from landscape.client.errors import (CommandAborted, CommandFailed, CommandRefused,
                                     CommandTimeout, LandscapeError, NotImplementedByServer,
                                     NotAllowed, NotLockHolder, SessionEnded, TransportError,
                                     WrongState)
from landscape.client.identity import Identity
from landscape.client.link import DeviceLink
from landscape.client.robot import Robot, connect
from landscape.client.session import Session
from landscape.client.values import (AccelType, AngularUnit, DeviceState, Frame, LinearUnit,
                                     Motion, Offset, Pose, SpeedType, TagPoint)

__all__ = [
    "Robot", "AsyncRobot", "connect", "Command", "AsyncCommand", "Session", "AsyncSession",
    "DeviceLink", "Endpoint", "Identity",
    "Frame", "Motion", "Offset", "SpeedType", "AccelType", "LinearUnit", "AngularUnit",
    "DeviceState", "Pose", "TagPoint",
    "LandscapeError", "CommandRefused", "WrongState", "NotLockHolder", "NotAllowed",
    "NotImplementedByServer",
    "TransportError", "CommandFailed", "CommandAborted", "CommandTimeout", "SessionEnded",
    "ClientTLS", "open_channel", "open_aio_channel", "read_token",
]

"""The supervisor's own calls, beside the landscape.v1 contract: what the backend does among
the people signed in to it and the device contract does not offer (docs/page.md). Alarms
are acknowledged on the device (EventService.AcknowledgeAlarm), like any call of the page.

    supervisor/RequestControl     {}        ask this supervisor's lock holder for the lock
    supervisor/AnswerControl      {"give": true | false}   the holder hands over or declines
    supervisor/CancelControlRequest {}                                     handover.py

They travel as the RPCs do (wire.py): a frame with the device, the name, an id and a plain JSON
request; the answer is a plain JSON reply, or a google.rpc.Status saying why not, and then
nothing changed. Each needs the operator role.
"""
from __future__ import annotations

import grpc

from landscape.server.security.auth import Role
from landscape.supervisor import wire
from landscape.supervisor.handover import CONTROL, ControlDesk, HandoverRefused
from landscape.supervisor.wire import Refused
from landscape.v1 import types_pb2

PREFIX = "supervisor/"


class ConsolePage:
    """A console (one browser page) as the control desk sees it: handover.Page. Its calls are
    the person's, through their robot on the device (console.Console.robot_of)."""

    def __init__(self, console):
        self.console = console
        self.name = console.person.name

    def notify(self, device: str, body: dict) -> None:
        self.console.outbox.put(wire.note(device, CONTROL, body))

    def has_session(self, device: str) -> bool:
        session = self.console.robot_of(device).session
        return session is not None and not session.ended.is_set()

    async def device_state(self, device: str) -> str:
        reply = await self.console.robot_of(device).get_device_state()
        return types_pb2.DeviceState.Name(reply.state)

    async def give_up_lock(self, device: str, deactivate: bool) -> None:
        robot = self.console.robot_of(device)
        if deactivate:
            await robot.deactivate()
        await robot.release()

    async def take_lock(self, device: str) -> None:
        await self.console.robot_of(device).lock()


class SupervisorCalls:
    """The supervisor's own calls for every page of one app."""

    def __init__(self):
        self.desk = ControlDesk()

    @staticmethod
    def handles(name) -> bool:
        return isinstance(name, str) and name.startswith(PREFIX)

    async def call(self, page: ConsolePage, role: Role, device: str, name: str, request) -> dict:
        """The reply to one call of `page`; Refused says why not."""
        method = name.removeprefix(PREFIX)
        if method not in ("RequestControl", "AnswerControl", "CancelControlRequest"):
            raise Refused(grpc.StatusCode.UNIMPLEMENTED, f"{name!r} is not a call of the supervisor")
        if role < Role.OPERATOR:
            raise Refused(grpc.StatusCode.PERMISSION_DENIED,
                          f"{method} needs the operator role; you are signed in as {role.label}")
        request = request if isinstance(request, dict) else {}
        try:
            if method == "RequestControl":
                self.desk.request(device, page)
            elif method == "CancelControlRequest":
                self.desk.cancel(device, page)
            else:
                give = request.get("give")
                if not isinstance(give, bool):
                    raise ValueError("give: true (hand the lock over) or false (decline)")
                await self.desk.answer(device, page, give)
        except HandoverRefused as refused:
            raise Refused(refused.code, str(refused)) from None
        except ValueError as error:
            raise Refused(grpc.StatusCode.INVALID_ARGUMENT, str(error)) from None
        return {}

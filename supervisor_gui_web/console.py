"""One browser's commands, made as its signed-in person through their AsyncRobot on each device
(the client core: their calls, their session and its lock, their jog streams).

The browser belongs to a signed-in person (sign_in.py). Each frame is first checked against
the person's role (roles.py: a viewer watches and may press the e-stop; commanding needs an
operator): a frame the role does not allow is refused here with the reason, and nothing is
sent. Otherwise the call goes to the device server as the browser asked, through the person's
robot (device_hub.DeviceHub.person: their own token where the devices use tokens, and who it
is for), with the lease of the browser's own session when it holds the lock; the server's
answer (reply, or google.rpc.Status with its ErrorInfo) goes back as it came. The session's
secret and the lease stay in the robot; the page never sees them. A session the device ends is
reported to the page with the device's reason ("no keep-alive for 2 s"); a new hello opens a
new session (a new robot: nothing takes a lock back by itself).

Jogging is one device Jog stream per button press: the page gives each press a fresh id,
larger than every earlier one on its connection (its call numbering does). The first message
of a new press opens the stream; a message of a press whose stream has ended (released, cut
by the device's deadman, aborted, failed) or of a press older than the newest is refused and
never reaches the device: a late or repeated message cannot start the arm again.

The supervisor's own calls ("supervisor/...": control handed over between people signed in
here) go to supervisor_calls.py; the console tells its control desk when
its lock starts and ends.

Every call runs in its own task, so a StopMotion never waits behind an Activate in progress.
Closing the console (the page closed or lost its connection) ends its sessions: the device's
disconnect handler then stops, deactivates and releases, as for any client.
"""
from __future__ import annotations

import asyncio
import logging
from dataclasses import dataclass, field

import grpc
from google.protobuf import json_format

from landscape.client import AsyncRobot, LandscapeError, SessionEnded
from landscape.client.aio import AUDIT, RECORDING
from landscape.client.commands import DEVICE, EVENTS, IO
from landscape.client.errors import to_status
from landscape.supervisor import wire
from landscape.supervisor.device_hub import DeviceHub
from landscape.supervisor.outbox import Outbox
from landscape.supervisor.roles import OPERATE_PANEL, needed_role, refusal
from landscape.supervisor.rpc_table import (CONNECT, JOG, LOCK, RELEASE, RPCS, STREAM_STATE,
                                            SUBSCRIBE, Rpc)
from landscape.supervisor.sign_in import SignIn
from landscape.supervisor.supervisor_calls import ConsolePage, SupervisorCalls
from landscape.supervisor.wire import Refused
from landscape.v1 import control_pb2, session_service_pb2, types_pb2

log = logging.getLogger(__name__)

FED = {STREAM_STATE, SUBSCRIBE}   # fed to every browser by its hub; a browser does not open them
SERVICES = {"DeviceService": DEVICE, "DigitalIOService": IO, "EventService": EVENTS,
            "RecordingService": RECORDING, "AuditService": AUDIT}
CALL_TIMEOUT_S = 120.0   # a blocking call's longest wait (an Activate, a long PathLoad)


@dataclass
class _DeviceSide:
    """What this browser has open on one device."""
    robot: AsyncRobot                      # the person's calls; their session once opened
    session_call_id: int | None = None
    rsvp_answers: dict[str, asyncio.Future] = field(default_factory=dict)
    jog: "_Stream | None" = None
    last_press: int = 0                    # the newest jog press id seen


class _Stream:
    """A jog press's messages from the browser, as the device's Jog stream reads them."""

    def __init__(self, call_id: int):
        self.call_id = call_id
        self.queue: asyncio.Queue = asyncio.Queue()
        self.task: asyncio.Task | None = None

    async def requests(self):
        while (item := await self.queue.get()) is not None:
            yield item


class Console:
    def __init__(self, hubs: dict[str, DeviceHub], outbox: Outbox, person: SignIn,
                 calls: SupervisorCalls):
        self.hubs = hubs
        self.outbox = outbox
        self.person = person
        self._calls = calls
        self._page = ConsolePage(self)   # this page, as the control desk knows it
        self._sides = {name: _DeviceSide(self._robot(hub)) for name, hub in hubs.items()}
        self._tasks: set[asyncio.Task] = set()

    def _robot(self, hub: DeviceHub) -> AsyncRobot:
        return hub.person(self.person.name, self.person.token,
                          on_rsvp=lambda request: self._ask_page(hub.name, request))

    # ---- frames from the browser
    def receive(self, body: dict) -> None:
        """Start handling one browser frame; its answer arrives later in the outbox."""
        device, rpc_name, call_id = body.get("device"), body.get("rpc"), body.get("id")
        self._spawn(self._handle(device, rpc_name, call_id, body))

    def _spawn(self, coroutine) -> asyncio.Task:
        task = asyncio.create_task(coroutine)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)
        return task

    async def _handle(self, device, rpc_name, call_id, body) -> None:
        try:
            hub = self.hubs.get(device)
            if hub is None:
                raise Refused(grpc.StatusCode.NOT_FOUND, f"no device named {device!r} here")
            if self._calls.handles(rpc_name):
                reply = await self._calls.call(self._page, self.person.role, hub.name, rpc_name,
                                               body.get("request"))
                self.outbox.put(wire.note(hub.name, rpc_name, reply, call_id))
                return
            rpc = RPCS.get(rpc_name)
            if rpc is None or rpc_name in FED:
                raise Refused(grpc.StatusCode.UNIMPLEMENTED,
                              f"{rpc_name!r} is not a landscape.v1 call the page can make")
            self._check_role(rpc, body)
            if rpc_name == CONNECT:
                await self._session(hub, call_id, body)
            elif rpc_name == JOG:
                await self._jog(hub, rpc, call_id, body)
            else:
                await self._call(hub, rpc, call_id, body)
        except Refused as refused:
            self._send(device, rpc_name, call_id, status=refused.status)
        except json_format.ParseError as error:
            self._send(device, rpc_name, call_id,
                       status=wire.status(grpc.StatusCode.INVALID_ARGUMENT, f"bad request: {error}"))
        except LandscapeError as error:
            self._send(device, rpc_name, call_id, status=to_status(error))

    def _check_role(self, rpc: Rpc, body: dict) -> None:
        """Refused unless the person's role allows the call (OperatePanel: its action)."""
        request = (wire.parse_request(rpc.request_class, body.get("request"))
                   if rpc.name == OPERATE_PANEL else None)
        needed = needed_role(rpc.name, request)
        if self.person.role < needed:
            raise Refused(grpc.StatusCode.PERMISSION_DENIED,
                          refusal(rpc.name, needed, self.person.role))

    def _send(self, device, rpc, call_id, reply=None, status=None) -> None:
        self.outbox.put(wire.frame(str(device), str(rpc), reply=reply, status=status, call_id=call_id))

    # ---- plain calls
    async def _call(self, hub: DeviceHub, rpc: Rpc, call_id, body) -> None:
        side = self._sides[hub.name]
        if rpc.kind == "unary":
            request = wire.parse_request(rpc.request_class, body.get("request"))
        elif rpc.kind == "client_stream":
            request = iter([wire.parse_request(rpc.request_class, r)
                            for r in body.get("requests", ())])
        elif rpc.kind == "server_stream":   # each reply a frame, then the end's status
            request = wire.parse_request(rpc.request_class, body.get("request"))
            async for reply in side.robot.invoke_stream(SERVICES[rpc.service], rpc.method.name,
                                                        request, timeout=CALL_TIMEOUT_S):
                self._send(hub.name, rpc.name, call_id, reply=reply)
            self._send(hub.name, rpc.name, call_id,
                       status=wire.status(grpc.StatusCode.OK, "stream ended"))
            return
        else:
            raise Refused(grpc.StatusCode.UNIMPLEMENTED, f"{rpc.name} is a stream the page cannot open")
        if rpc.name == LOCK:
            await side.robot.lock()
            self._calls.desk.locked(hub.name, self._page)
            # The lease stays in the robot: the page learns only that the lock is its own.
            self._send(hub.name, LOCK, call_id, reply=control_pb2.LockResponse(ret_val=types_pb2.RetVal()))
            return
        reply = await side.robot.invoke(SERVICES[rpc.service], rpc.method.name, request,
                                        timeout=CALL_TIMEOUT_S)
        if rpc.name == RELEASE:
            self._calls.desk.unlocked(hub.name, self._page)
        self._send(hub.name, rpc.name, call_id, reply=reply)

    # ---- the session: hello opens it, rsvp_answer answers, cancel closes it
    async def _session(self, hub: DeviceHub, call_id, body) -> None:
        side = self._sides[hub.name]
        session = side.robot.session
        if body.get("cancel"):
            await side.robot.close()
            return
        message = wire.parse_request(session_service_pb2.ConnectRequest, body.get("request"))
        kind = message.WhichOneof("message")
        if kind == "rsvp_answer":
            answer = message.rsvp_answer
            future = side.rsvp_answers.get(answer.rsvp_id)
            if future is None or future.done():
                raise Refused(grpc.StatusCode.NOT_FOUND,
                              f"no question {answer.rsvp_id!r} waits for this page's answer")
            future.set_result((answer.choice, list(answer.data)))
        elif kind == "hello":
            if session is not None and not session.ended.is_set():
                raise Refused(grpc.StatusCode.ALREADY_EXISTS,
                              f"this page already has session {session.session_id}")
            if session is not None:   # the one before ended: a new session, a new robot
                side.robot = self._robot(hub)
            # The session bears the person's name (the device shows it as the lock holder),
            # whatever name the page asked for.
            await side.robot.open()
            session = side.robot.session
            if session is None:
                raise Refused(grpc.StatusCode.PERMISSION_DENIED,
                              f"the device lets {self.person.name} watch, not open a session")
            side.session_call_id = call_id
            # The secret proves ownership to Lock: it stays in the robot.
            self._send(hub.name, CONNECT, call_id, reply=session_service_pb2.ConnectResponse(
                opened=session_service_pb2.SessionOpened(session_id=session.session_id)))
            session.add_end_listener(lambda lost: self._session_ended(hub.name, call_id, lost))
        else:
            raise Refused(grpc.StatusCode.INVALID_ARGUMENT,
                          "the page sends hello or rsvp_answer; the backend keeps the session alive")

    def _session_ended(self, device: str, call_id, lost: SessionEnded | None) -> None:
        self._calls.desk.unlocked(device, self._page)
        if lost is None:   # closed from here: the page asked, or went away
            self._send(device, CONNECT, call_id, status=wire.status(grpc.StatusCode.OK, "session closed"))
            return
        self._send(device, CONNECT, call_id, status=wire.status(
            lost.code or grpc.StatusCode.UNKNOWN, f"your session ended: {lost.reason}"))

    async def _ask_page(self, device: str, request):
        """An RSVP for this page's session: the page shows it and answers in time, or nothing
        is sent and the device's own timer gives the default (its event says timed out)."""
        side = self._sides[device]
        future = asyncio.get_running_loop().create_future()
        side.rsvp_answers[request.rsvp_id] = future
        self._send(device, CONNECT, side.session_call_id,
                   reply=session_service_pb2.ConnectResponse(rsvp_request=request))
        try:
            async with asyncio.timeout(request.timeout_ms / 1000.0):
                return await future
        except TimeoutError:
            return None
        finally:
            side.rsvp_answers.pop(request.rsvp_id, None)

    # ---- jogging: one device stream per button press; its messages feed the deadman
    async def _jog(self, hub: DeviceHub, rpc: Rpc, call_id, body) -> None:
        side = self._sides[hub.name]
        stream = side.jog
        if stream is not None and stream.call_id == call_id:   # the press going on
            stream.queue.put_nowait(None if body.get("cancel") else
                                    wire.parse_request(rpc.request_class, body.get("request")))
            return   # (after a cancel the stream reads nothing more)
        if body.get("cancel"):
            return   # a press with no stream open: nothing to end
        if isinstance(call_id, bool) or not isinstance(call_id, int) or call_id <= side.last_press:
            raise Refused(grpc.StatusCode.FAILED_PRECONDITION,
                          f"jog press {call_id} is over (or older than press {side.last_press}):"
                          f" nothing moves until the button is pressed again")
        request = wire.parse_request(rpc.request_class, body.get("request"))
        side.last_press = call_id
        if stream is not None:
            stream.queue.put_nowait(None)   # a new press ends the one before
        stream = side.jog = _Stream(call_id)
        stream.task = self._spawn(self._run_jog(hub.name, side, stream))
        stream.queue.put_nowait(request)

    async def _run_jog(self, device: str, side: _DeviceSide, stream: _Stream) -> None:
        try:
            async for reply in side.robot.jog_stream(stream.requests()):
                self._send(device, JOG, stream.call_id, reply=reply)
            self._send(device, JOG, stream.call_id, status=wire.status(grpc.StatusCode.OK, "jog ended"))
        except LandscapeError as error:
            self._send(device, JOG, stream.call_id, status=to_status(error))
        finally:
            if side.jog is stream:
                side.jog = None

    # ---- what the control desk uses (supervisor_calls.ConsolePage)
    def robot_of(self, device: str) -> AsyncRobot:
        return self._sides[device].robot

    # ---- the page went away
    async def close(self) -> None:
        self._calls.desk.gone(self._page)
        for side in self._sides.values():
            if side.jog is not None:
                side.jog.queue.put_nowait(None)
            await side.robot.close()
        for task in list(self._tasks):
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)

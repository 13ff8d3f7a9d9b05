"""`Robot`: one device server, for blocking Python programs.

    from landscape.client import Frame, Robot

    with Robot("127.0.0.1:50051", "my-program") as robot:   # a session (no lock yet)
        print(robot.get_robot_position().joint_position)
        with robot.control():                               # lock + activate ... and back
            robot.move_absolute([0.5, 0, 1.57, 0, 1.57, 0], Frame.JOINT).wait(timeout=30)

Leaving `control()` — normally or by an exception — stops any motion, deactivates and releases.
Leaving the `Robot` ends the session; if it still held the lock, the device does the same
(seed 2.2). Every failure is one of the exceptions in errors.py; a session the device ended
raises SessionEnded with its reason.

A Robot is the asyncio core (AsyncRobot, aio.py) run on a loop thread of its own: each method
waits there for the coroutine it starts; the session's keep-alives run on the core's keeper
thread, whatever this program's threads do.
"""
from __future__ import annotations

import asyncio
import contextlib
from typing import Iterable, Iterator, Sequence

from landscape.client.aio import AsyncRobot
from landscape.client.aio_session import AsyncSession
from landscape.client.command import Command
from landscape.client.commands import DeviceCommands
from landscape.client.credentials import ClientTLS, Endpoint
from landscape.client.errors import SessionEnded
from landscape.client.identity import Identity
from landscape.client.loop_thread import LoopThread, pump
from landscape.client.session import RsvpHandler
from landscape.client.streams import EventStream, StateStream
from landscape.client.values import DeviceState, Frame
from landscape.v1 import types_pb2


class Robot(DeviceCommands):
    """A session with one device server, and every command of the contract as a method.

    target: "host:port" (with tls and token: TLS, the CA to trust and a client certificate,
    and the role token to present, credentials.py; plaintext and no token when unset), or an
    Endpoint.
    client_name: shown to other clients as the lock holder.
    identity: who calls, for the device's records (identity.py; default: client_name).
    on_rsvp: answers the device's RSVP questions (seed 2.2): called with a landscape.v1
    RsvpRequest on a thread of its own, returns (choice, data). Unset: the device waits out
    its timeout and takes its default.
    """

    def __init__(self, target: str | Endpoint, client_name: str = "landscape-client", *,
                 on_rsvp: RsvpHandler | None = None, tls: ClientTLS | None = None,
                 token: str | None = None, identity: Identity | None = None):
        if not isinstance(target, (str, Endpoint)):
            raise ValueError("TLS and the token belong to the channel: give Robot a "
                             "\"host:port\" (with tls= and token=) or an Endpoint")
        self.client_name = client_name
        self._thread = LoopThread(f"landscape-{client_name}")
        answer = None if on_rsvp is None else (
            lambda request: asyncio.to_thread(on_rsvp, request))   # off the loop: it may block
        self._robot = AsyncRobot(target, client_name, on_rsvp=answer, tls=tls, token=token,
                                 identity=identity)

    # ---- life cycle ----

    def open(self, timeout: float = 10.0) -> "Robot":
        """Open the session (ServerUnavailable if no device answers within `timeout` s); once
        open, opening again does nothing."""
        try:
            self._thread.run(self._robot.open(timeout))
        except BaseException:
            self._thread.stop()
            raise
        return self

    def close(self) -> None:
        """End the session (the device releases the lock if it was held) and the streams."""
        try:
            self._thread.run(self._robot.close())
        finally:
            self._thread.stop()

    def __enter__(self) -> "Robot":
        return self.open()

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def session(self) -> AsyncSession | None:
        """The underlying session: session_id, lease, lost; None when the role token may not
        open one (a viewer's: reads and streams only)."""
        return self._robot.session

    @property
    def lost(self) -> SessionEnded | None:
        """Why the device ended this robot's session, if it did."""
        return self._robot.lost

    def when_lost(self, callback) -> None:
        """`callback(lost)` on a thread of the client's as soon as the device ends the session
        (not when this program closes it); never without a session (a viewer's)."""
        def listener(lost):
            if lost is not None:
                self._thread.loop.run_in_executor(None, callback, lost)
        if self._robot.session is not None:
            self._thread.loop.call_soon_threadsafe(self._robot.session.add_end_listener,
                                                   listener)

    # ---- the lock ----

    def lock(self, timeout: float = 10.0) -> str:
        """Seed 3.1.1: take the lock for this session; returns the lease, which every later
        call of this Robot carries."""
        return self._thread.run(self._robot.lock(timeout))

    @contextlib.contextmanager
    def control(self, activate: bool = True) -> Iterator["Robot"]:
        """Lock (and activate) for the body; afterwards, however it ends, stop any motion,
        deactivate and release."""
        self.lock()
        try:
            if activate:
                self.activate()
            yield self
        finally:
            self.relinquish()

    def relinquish(self) -> DeviceState:
        """Stop, abort, deactivate and release as the state needs; returns the state reached."""
        return self._thread.run(self._robot.relinquish())

    # ---- streams ----

    def events(self, after_sequence: int | None = None,
               timeout: float | None = None) -> EventStream:
        """Events and alarms (seed 2.1): live only, or the kept ones after `after_sequence`
        first. Iterate it; close it (or use `with`) to stop. With `timeout` (seconds), the
        stream ends by raising RpcTimeout when that time is up."""
        return EventStream(self._thread.run(self._stream(self._robot.event_stream,
                                                         after_sequence, timeout)), self._thread)

    def live_state(self, rate_hz: float = 10.0, frame: Frame | None = None,
                   units: types_pb2.Units | None = None, sensors: Sequence[str] = (),
                   timeout: float | None = None) -> StateStream:
        """The device's state at `rate_hz` samples per second (0: every 4 ms cycle); see
        state_service.proto. Iterate it; close it (or use `with`) to stop; `timeout` as for
        events()."""
        return StateStream(self._thread.run(self._stream(
            self._robot.state_stream, rate_hz, frame, units, sensors, timeout)), self._thread)

    def jog(self, velocities: Iterable[Sequence[float]], frame: Frame) -> Iterator:
        """Jog with the deadman held while `velocities` (percent of each axis maximum) lasts;
        the iterable paces the stream (the deadman stops the arm if it pauses too long).
        Yields a JogResponse (joints, pose) per message. Needs manual_control(TEACHPENDANT)."""
        return self._thread.iterate(self._robot.jog(pump(velocities), frame))

    @staticmethod
    async def _stream(open_stream, *args):
        return open_stream(*args)   # a grpc.aio call is made on the loop it runs on

    # ---- every command goes through here ----

    def _call(self, service: str, rpc: str, request, *, started: bool = False,
              timeout: float | None = None):
        reply = self._thread.run(self._robot.invoke(service, rpc, request, started, timeout))
        return Command(reply, self._thread) if started else reply


def connect(target: str | Endpoint, client_name: str = "landscape-client",
            **options) -> Robot:
    """An open Robot; use it in a `with` block (or call close())."""
    return Robot(target, client_name, **options).open()

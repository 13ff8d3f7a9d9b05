"""`Robot`: one device server, for blocking Python programs.

    from landscape.client import Frame, Robot

    with Robot("127.0.0.1:50051", "my-program") as robot:   # a session (no lock yet)
        print(robot.get_robot_position().joint_position)
        with robot.control():                               # lock + activate ... and back
            robot.move_absolute([0.5, 0, 1.57, 0, 1.57, 0], Frame.JOINT).wait(timeout=30)

Leaving `control()` — normally or by an exception — stops any motion, deactivates and releases.
Leaving the `Robot` ends the session; if it still held the lock, the device does the same
(seed 2.2). Every failure is one of the exceptions in errors.py.
"""
from __future__ import annotations

import contextlib
import logging
from typing import Iterable, Iterator, Sequence

import grpc

from landscape.client.command import Command, CommandTracker
from landscape.client.commands import (DEVICE, EVENTS, IO, RELINQUISH_MAX_STEPS,
                                       RELINQUISH_STEP, DeviceCommands, jog_requests)
from landscape.client.credentials import ClientTLS, open_channel
from landscape.client.errors import (CommandRefused, NotAllowed, NotLockHolder,
                                     ServerUnavailable, from_rpc_error)
from landscape.client.session import RsvpHandler, Session
from landscape.client.streams import EventStream, StateStream, state_request, subscribe_request
from landscape.client.values import DeviceState, Frame
from landscape.v1 import (control_pb2, device_service_pb2_grpc, digital_io_service_pb2_grpc,
                          event_service_pb2_grpc, state_service_pb2_grpc, types_pb2)

log = logging.getLogger(__name__)

DEFAULT_TIMEOUT = 30.0   # seconds, for a blocking call that names none
FENCE_TIMEOUT = 2.0      # seconds for the command subscription to prove live (tracking.py)


class Robot(DeviceCommands):
    """A session with one device server, and every command of the contract as a method.

    target: "host:port", or an open grpc.Channel (then the caller closes it).
    tls, token: with a "host:port", TLS (the CA to trust, a client certificate) and the role
    token to present (credentials.py); plaintext and no token when unset.
    client_name: shown to other clients as the lock holder.
    on_rsvp: answers the device's RSVP questions (seed 2.2): called with a landscape.v1
    RsvpRequest on a background thread, returns (choice, data). Unset: the device waits out
    its timeout and takes its default.
    """

    def __init__(self, target: str | grpc.Channel, client_name: str = "landscape-client", *,
                 on_rsvp: RsvpHandler | None = None, tls: ClientTLS | None = None,
                 token: str | None = None):
        self._own_channel = isinstance(target, str)
        if not self._own_channel and (tls is not None or token):
            raise ValueError("TLS and the token belong to the channel: give them to "
                             "open_channel, or give Robot a \"host:port\"")
        self._raw = open_channel(target, tls, token) if self._own_channel else target
        self.client_name = client_name
        self._on_rsvp = on_rsvp
        self._session: Session | None = None
        self._no_session: NotAllowed | None = None   # why there is no session, if refused
        self._tracker: CommandTracker | None = None

    # ---- life cycle ----

    def open(self, timeout: float = 10.0) -> "Robot":
        """Open the session and the event subscription that follows this client's commands."""
        # A first call that waits for the connection (not channel_ready_future: its polling
        # thread outlives a quick close and prints a traceback).
        probe = device_service_pb2_grpc.DeviceServiceStub(self._raw)
        try:
            probe.GetDeviceState(control_pb2.GetDeviceStateRequest(), timeout=timeout,
                                 wait_for_ready=True)
        except grpc.RpcError as error:
            if error.code() is grpc.StatusCode.DEADLINE_EXCEEDED:
                raise ServerUnavailable(f"no device server answered within {timeout} s",
                                        grpc.StatusCode.UNAVAILABLE) from None
            raise from_rpc_error(error) from None
        channel = self._raw
        events = event_service_pb2_grpc.EventServiceStub(channel)
        try:
            self._session = Session(channel, self.client_name, self._on_rsvp).open()
        except grpc.RpcError as error:
            refused = from_rpc_error(error)
            if not isinstance(refused, NotAllowed):
                self.close()
                raise refused from None
            self._no_session = refused   # a viewer's token: reads and streams only
        # Carries the lease once locked.
        lease_channel = self._session.channel if self._session else channel
        self._stubs = {DEVICE: device_service_pb2_grpc.DeviceServiceStub(lease_channel),
                       IO: digital_io_service_pb2_grpc.DigitalIOServiceStub(lease_channel),
                       EVENTS: event_service_pb2_grpc.EventServiceStub(lease_channel)}
        self._events = events
        self._state = state_service_pb2_grpc.StateServiceStub(channel)
        return self

    def _track_commands(self, after_sequence: int | None = None) -> CommandTracker:
        """The live subscription that follows this client's commands, opened before its first
        lock or command (read-only clients need none); see tracking.py."""
        if self._tracker is None:
            self._tracker = CommandTracker(EventStream(self._events.Subscribe(
                subscribe_request(after_sequence))))
        return self._tracker

    def _live_tracker(self) -> CommandTracker:
        """The tracker, proved live before a command starts (else replaying, to be sure)."""
        tracker = self._track_commands()
        if not tracker.wait_live(FENCE_TIMEOUT):
            log.warning("no event arrived on the command subscription; replaying the device's")
            tracker.close()
            self._tracker = None
            tracker = self._track_commands(after_sequence=0)
        return tracker

    def close(self) -> None:
        """End the session (the device releases the lock if it was held) and the streams."""
        if self._tracker is not None:
            self._tracker.close()
        if self._session is not None:
            self._session.close()
        if self._own_channel:
            self._raw.close()

    def __enter__(self) -> "Robot":
        return self.open()

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def session(self) -> Session | None:
        """The underlying session: session_id, lease, rsvp_requests (every question asked);
        None when the role token may not open one (a viewer's: reads and streams only)."""
        return self._session

    # ---- the lock ----

    def lock(self, timeout: float = 10.0) -> str:
        """Seed 3.1.1: take the lock for this session; returns the lease, which every later
        call of this Robot carries."""
        if self._session is None:
            raise self._no_session
        self._track_commands()   # before the lock, whose event then proves it live
        try:
            return self._session.lock(timeout)
        except grpc.RpcError as error:
            raise from_rpc_error(error) from None

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
        state = DeviceState.UNLOCKED
        for _ in range(RELINQUISH_MAX_STEPS):
            state = DeviceState(self.get_device_state().state)
            step = RELINQUISH_STEP.get(state)
            if step is None:
                return state
            try:
                getattr(self, step)()
            except (NotLockHolder, NotAllowed):   # not (or no longer) ours to hand back
                return state
            except CommandRefused as refused:   # the state moved on by itself: look again
                log.debug("relinquish: %s refused: %s", step, refused)
        return state

    # ---- streams ----

    def events(self, after_sequence: int | None = None,
               timeout: float | None = None) -> EventStream:
        """Events and alarms (seed 2.1): live only, or the kept ones after `after_sequence`
        first. Iterate it; close it (or use `with`) to stop. With `timeout` (seconds), the
        stream ends by raising RpcTimeout when that time is up."""
        return EventStream(self._events.Subscribe(subscribe_request(after_sequence),
                                                  timeout=timeout))

    def live_state(self, rate_hz: float = 10.0, frame: Frame | None = None,
                   units: types_pb2.Units | None = None, sensors: Sequence[str] = (),
                   timeout: float | None = None) -> StateStream:
        """The device's state at `rate_hz` samples per second (0: every 4 ms cycle); see
        state_service.proto. Iterate it; close it (or use `with`) to stop; `timeout` as for
        events()."""
        return StateStream(self._state.StreamState(
            state_request(rate_hz, frame, units, sensors), timeout=timeout))

    def jog(self, velocities: Iterable[Sequence[float]], frame: Frame) -> Iterator:
        """Jog with the deadman held while `velocities` (percent of each axis maximum) lasts;
        the iterable paces the stream (the deadman stops the arm if it pauses too long).
        Yields a JogResponse (joints, pose) per message. Needs manual_control(TEACHPENDANT)."""
        try:
            yield from self._stubs[DEVICE].Jog(jog_requests(velocities, frame))
        except grpc.RpcError as error:
            raise from_rpc_error(error) from None

    # ---- every command goes through here ----

    def _call(self, service: str, rpc: str, request, *, started: bool = False,
              timeout: float | None = None):
        tracker = self._live_tracker() if started else None
        try:
            reply = getattr(self._stubs[service], rpc)(request, timeout=timeout or DEFAULT_TIMEOUT)
        except grpc.RpcError as error:
            raise from_rpc_error(error) from None
        if started:
            return Command(reply.ret_val.command_id, rpc, reply.ret_val, tracker)
        return reply


def connect(target: str | grpc.Channel, client_name: str = "landscape-client",
            **options) -> Robot:
    """An open Robot; use it in a `with` block (or call close())."""
    return Robot(target, client_name, **options).open()

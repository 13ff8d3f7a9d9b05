"""What every CLI command shares: where the device is, how to print, and how it gets the lock.

A lock lives as long as its session, and a session as long as its process. So a single
`landscape move ...` takes the lock for itself: session, lock, activate, the command, and then
stop, deactivate, release. Inside `landscape session` one session and its lock span many
commands, and `lock`, `activate`, `deactivate` and `release` are the user's to give.
"""
from __future__ import annotations

import contextlib
from dataclasses import dataclass
from typing import Iterator

import click

from landscape.client.cli.output import Output
from landscape.client.credentials import ClientTLS
from landscape.client.errors import (CommandAborted, CommandFailed, CommandRefused,
                                     CommandTimeout, LandscapeError, NotImplementedByServer,
                                     RpcTimeout, SessionEnded, TransportError)
from landscape.client.identity import Identity, user_at_host
from landscape.client.robot import Robot

DEFAULT_TARGET = "127.0.0.1:50051"
PROGRAM = "landscape-cli"     # landscape-client on every call (identity.py)

# Exit codes (documented in `landscape --help` and the README), most specific class first.
EXIT_OK = 0
EXIT_REFUSED = 1          # the device refused the command, or the motion failed / was aborted
EXIT_USAGE = 2            # bad arguments or file (click's own code for usage errors)
EXIT_UNREACHABLE = 3      # no answer from the device server
EXIT_TIMEOUT = 4          # a command did not finish within --timeout
EXIT_UNIMPLEMENTED = 5    # this device server does not carry the command out yet
EXIT_SESSION_LOST = 6     # the device ended the session (its reason is printed): it stopped
                          # the arm and released the lock; nothing takes it back
EXIT_INTERRUPTED = 130    # Ctrl-C: motion stopped, lock released
EXIT_CODES: tuple[tuple[type[LandscapeError], int], ...] = (
    (SessionEnded, EXIT_SESSION_LOST),
    (NotImplementedByServer, EXIT_UNIMPLEMENTED),
    (CommandTimeout, EXIT_TIMEOUT),
    (RpcTimeout, EXIT_TIMEOUT),
    (TransportError, EXIT_UNREACHABLE),
    (CommandAborted, EXIT_REFUSED),
    (CommandFailed, EXIT_REFUSED),
    (CommandRefused, EXIT_REFUSED),
    (LandscapeError, EXIT_REFUSED),
)


def exit_code_for(error: LandscapeError) -> int:
    return next(code for cls, code in EXIT_CODES if isinstance(error, cls))


@dataclass
class CliState:
    target: str
    as_json: bool
    client_name: str
    timeout: float                  # seconds to wait for a started command to finish
    connect_timeout: float          # seconds to wait for the device server to answer
    tls: ClientTLS | None = None    # TLS to the device server (credentials.py), if any
    token: str | None = None        # the role token to present, if any
    robot: Robot | None = None      # the session's, inside `landscape session`

    @property
    def out(self) -> Output:
        return Output(self.as_json)

    @property
    def in_session(self) -> bool:
        return self.robot is not None

    @contextlib.contextmanager
    def reader(self) -> Iterator[Robot]:
        """A Robot for read-only calls: the session's, or a short session of its own."""
        if self.robot is not None:
            yield self.robot
        else:
            with self.open_robot() as robot:
                yield robot

    @contextlib.contextmanager
    def commander(self, activate: bool = True) -> Iterator[Robot]:
        """A Robot that may command: inside a session, as its lock stands; alone, locked (and
        activated) for this command only, handed back however the command ends."""
        if self.robot is not None:
            yield self.robot
            return
        with self.open_robot() as robot, robot.control(activate=activate):
            yield robot

    def open_robot(self) -> Robot:
        return Robot(self.target, self.client_name, tls=self.tls, token=self.token,
                     identity=Identity(PROGRAM, user_at_host())).open(self.connect_timeout)


pass_state = click.make_pass_decorator(CliState)

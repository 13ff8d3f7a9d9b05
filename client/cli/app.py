"""The `landscape` command: talk to a LandScape device server from a shell or a script.

Exit codes: 0 done; 1 the device refused the command (its message is printed), or the motion
failed or was aborted; 2 bad arguments or file; 3 no answer from the device server; 4 a
command did not finish within --timeout; 5 not implemented by this device server yet;
6 the device ended the session (its reason is printed, e.g. "your session ended: no
keep-alive for 2 s"): it stopped the arm and released the lock; 130 interrupted (Ctrl-C: the
motion is stopped and the lock released).
"""
from __future__ import annotations

import click

from landscape.client.cli import control, crcl_run, hardware, motion, status
from landscape.client.cli.context import (DEFAULT_TARGET, EXIT_INTERRUPTED, CliState,
                                          exit_code_for)
from landscape.client.cli.output import show_error
from landscape.client.credentials import FLAGS, from_values
from landscape.client.errors import CommandRefused, LandscapeError


class Failure(click.ClickException):
    """A LandscapeError as the CLI reports it: the server's message and an exit code."""

    def __init__(self, error: LandscapeError | None, as_json: bool, message: str = "",
                 exit_code: int | None = None):
        super().__init__(message or str(error))
        self.error, self.as_json = error, as_json
        self.exit_code = exit_code if exit_code is not None else exit_code_for(error)

    def show(self, file=None) -> None:
        payload = {"type": type(self.error).__name__ if self.error else "Interrupted",
                   "message": getattr(self.error, "message", self.message),
                   "exit_code": self.exit_code}
        if isinstance(self.error, CommandRefused):
            payload.update(code=self.error.code.name, reason=self.error.reason,
                           ret_code=self.error.ret_code)
        show_error(payload, self.message, self.as_json)


class LandscapeGroup(click.Group):
    """Turns the client's exceptions into messages and exit codes, in one place."""

    def invoke(self, ctx: click.Context):
        try:
            return super().invoke(ctx)
        except LandscapeError as error:
            raise Failure(error, _as_json(ctx)) from None
        except KeyboardInterrupt:
            state = ctx.find_object(CliState)
            if state is not None and state.in_session:   # the session stays: stop the arm
                try:
                    state.robot.stop_motion()
                except LandscapeError:
                    pass
            raise Failure(None, _as_json(ctx), "interrupted: motion stopped",
                          EXIT_INTERRUPTED) from None


def _as_json(ctx: click.Context) -> bool:
    state = ctx.find_object(CliState)
    return bool(state and state.as_json)


@click.group(cls=LandscapeGroup, epilog=__doc__.split("\n\n", 1)[1])
@click.option("--target", "-t", envvar="LANDSCAPE_TARGET", default=DEFAULT_TARGET,
              show_default=True, help="HOST:PORT of the device server (env LANDSCAPE_TARGET).")
@click.option("--json", "as_json", is_flag=True, help="Print JSON for scripts.")
@click.option("--name", "client_name", default="landscape-cli", show_default=True,
              help="Client name, shown to others as the lock holder.")
@click.option("--timeout", type=float, default=120.0, show_default=True,
              help="Seconds to wait for a motion to finish.")
@click.option("--connect-timeout", type=float, default=5.0, show_default=True,
              help="Seconds to wait for the device server to answer.")
@click.version_option(package_name="landscape-grpc", prog_name="landscape")
@click.pass_context
def cli(ctx: click.Context, target: str, as_json: bool, client_name: str, timeout: float,
        connect_timeout: float, **credentials) -> None:
    """Talk to a LandScape device server: status, watch, move, paths, I/O, tools, CRCL."""
    if ctx.obj is None:   # inside `landscape session` the session's state is given
        try:
            tls, token = from_values(**credentials)
        except (OSError, ValueError) as error:
            raise click.BadParameter(str(error), param_hint="--token-file") from None
        ctx.obj = CliState(target, as_json, client_name, timeout, connect_timeout, tls, token)


# TLS and the role token, as every client program takes them (credentials.FLAGS), each also
# from the environment: --tls-ca or LANDSCAPE_TLS_CA, --token-file or LANDSCAPE_TOKEN_FILE, ...
for _flag, _help in FLAGS:
    _env = "LANDSCAPE_" + _flag[2:].replace("-", "_").upper()
    cli = click.option(_flag, envvar=_env, default=None, help=f"{_help[0].upper()}{_help[1:]} "
                       f"(env {_env}).")(cli)


for command in (status.status, status.watch, motion.move, motion.path, hardware.io,
                hardware.sensor, hardware.tool, crcl_run.crcl_group, control.session,
                control.lock, control.activate, control.deactivate, control.release,
                control.stop, control.resume, control.abort, control.reset, control.estop):
    cli.add_command(command)


def main() -> None:
    cli(prog_name="landscape")

"""`landscape crcl run FILE`: a CRCL program through the CRCL gateway."""
from __future__ import annotations

import click

from landscape.client import crcl
from landscape.client.cli.context import CliState, pass_state


@click.group("crcl")
def crcl_group() -> None:
    """NIST CRCL programs, through the CRCL gateway (TCP, default port 64444)."""


@crcl_group.command("run")
@click.argument("file", type=click.Path(exists=True, dir_okay=False))
@click.option("--gateway", default=f"127.0.0.1:{crcl.DEFAULT_PORT}", show_default=True,
              help="HOST:PORT of the CRCL gateway.")
@click.option("--command-timeout", type=float, default=60.0, show_default=True,
              help="Seconds each command may take.")
@pass_state
def crcl_run(state: CliState, file: str, gateway: str, command_timeout: float) -> None:
    """Send the CRCLProgram in FILE one command at a time, each waited for (Done or Error)."""
    host, _, port = gateway.rpartition(":")
    if not host or not port.isdigit():
        raise click.BadParameter(f"{gateway!r} is not HOST:PORT", param_hint="--gateway")
    with open(file, "rb") as source:
        text = source.read()
    done = []

    def report(command: crcl.CrclCommand, status: crcl.CrclStatus) -> None:
        done.append({"command_id": command.command_id, "type": command.type,
                     "state": status.state})
        state.out.note(f"{command.command_id} {command.type}: {status.state}")

    try:
        count = crcl.run_program(text, host.strip("[]"), int(port), command_timeout, report)
    except crcl.CrclError as error:
        raise CrclFailure(str(error)) from None
    state.out.result({"commands": done}, f"{count} commands done")


class CrclFailure(click.ClickException):
    """The program, the gateway or a command failed (exit code 1)."""
    exit_code = 1

"""`landscape crcl run FILE`: a CRCL program through the CRCL gateway (landscape.gateway.run)."""
from __future__ import annotations

from pathlib import Path

import click

from landscape.client.cli.context import CliState, pass_state


@click.group("crcl")
def crcl_group() -> None:
    """NIST CRCL programs, through the CRCL gateway (TCP, default port 64444)."""


@crcl_group.command("run")
@click.argument("file", type=click.Path(exists=True, dir_okay=False))
@click.option("--gateway", default="127.0.0.1:64444", show_default=True,
              help="HOST:PORT of the CRCL gateway.")
@click.option("--command-timeout", type=float, default=60.0, show_default=True,
              help="Seconds each command may take.")
@pass_state
def crcl_run(state: CliState, file: str, gateway: str, command_timeout: float) -> None:
    """Send the CRCLProgram in FILE one command at a time, each waited for (Done or Error)."""
    from landscape.gateway import run   # lxml: only when a program is run
    host, _, port = gateway.rpartition(":")
    if not host or not port.isdigit():
        raise click.BadParameter(f"{gateway!r} is not HOST:PORT", param_hint="--gateway")
    done = []

    def report(progress) -> None:
        done.append({"command_id": progress.command_id, "type": progress.kind,
                     "state": progress.state, "description": progress.description})
        state.out.note(str(progress))

    try:
        count = run.run(Path(file), gateway, timeout=command_timeout, report=report)
    except run.FAILURES as error:
        raise CrclFailure(str(error)) from None
    state.out.result({"commands": done}, f"{count} commands done")


class CrclFailure(click.ClickException):
    """The program, the gateway or a command failed (exit code 1)."""
    exit_code = 1

"""`landscape session` and the commands that only make sense inside it (lock, activate, ...),
plus reset and the operator panel's e-stop."""
from __future__ import annotations

import os
import queue
import shlex
import sys
import threading

import click

from landscape.client.cli.context import EXIT_OK, EXIT_SESSION_LOST, CliState, pass_state
from landscape.client.errors import SessionEnded
from landscape.client.robot import Robot
from landscape.v1 import control_pb2

PROMPT = "landscape> "


@click.command()
@click.argument("script", type=click.File("r"), default="-")
@click.option("--keep-going", is_flag=True,
              help="Run the next line after a failed one (a script stops at the first).")
@click.pass_context
def session(ctx: click.Context, script, keep_going: bool) -> None:
    """Hold one session across many commands, read from SCRIPT (or stdin), one per line.

    A lock lives only as long as its session, so scripts that lock, move and release do it
    here: each line is a landscape command without the `landscape` (`lock`, `activate`,
    `move joint 0.5 0 1.57 0 1.57 0`, `path run p --file p.csv`, `deactivate`, `release`).
    Lines starting with # are comments; `exit` ends early. When the session ends, however it
    ends, the device is stopped, deactivated and released. The exit code is the first
    failed line's (or 0). If the device ends the session (it says why), the script ends at
    once, even while waiting for a line.
    """
    state: CliState = ctx.obj
    if state.in_session:
        raise click.UsageError("already in a session")
    interactive = script is sys.stdin and sys.stdin.isatty()
    root = ctx.find_root().command
    first_failure = EXIT_OK
    with state.open_robot() as robot:
        state.robot = robot
        try:
            for line in _lines(script, interactive, robot):
                argv = shlex.split(line, comments=True)
                if not argv:
                    continue
                if argv[0] in ("exit", "quit"):
                    break
                code = _run_line(root, argv, state)
                first_failure = first_failure or code
                if code == EXIT_SESSION_LOST or code and not (interactive or keep_going):
                    break
        finally:
            state.robot = None
            robot.relinquish()
    ctx.exit(first_failure)


def _lines(script, interactive: bool, robot: Robot):
    """The script's lines; SessionEnded as soon as the device ends the session, even while a
    line is awaited (the lines are read on a thread of their own)."""
    arrivals: queue.Queue = queue.Queue()
    robot.when_lost(arrivals.put)
    threading.Thread(target=_read, args=(script, interactive, arrivals), daemon=True,
                     name="landscape-script").start()
    while isinstance(item := arrivals.get(), str):
        yield item
        if interactive:
            click.echo(PROMPT, nl=False, err=True)
    if isinstance(item, SessionEnded):
        raise item


def _read(script, interactive: bool, arrivals: queue.Queue) -> None:
    """Put each line of the script, then None. From a file descriptor with os.read: a daemon
    thread blocked in a buffered read would hold the buffer's lock at the interpreter's exit."""
    if interactive:
        click.echo(PROMPT, nl=False, err=True)
    try:
        fd = script.fileno()
    except (AttributeError, OSError):   # no descriptor (a script in memory): nothing waits
        for line in script:
            arrivals.put(line)
        arrivals.put(None)
        return
    pending = b""
    while chunk := os.read(fd, 4096):
        *lines, pending = (pending + chunk).split(b"\n")
        for line in lines:
            arrivals.put(line.decode() + "\n")
    if pending:
        arrivals.put(pending.decode())
    arrivals.put(None)


def _run_line(root: click.Group, argv: list[str], state: CliState) -> int:
    """One line as a landscape command in this session; returns its exit code."""
    try:
        with root.make_context("landscape", argv, obj=state) as line_ctx:
            root.invoke(line_ctx)
    except click.exceptions.Exit as done:
        return done.exit_code
    except click.ClickException as failure:
        failure.show()
        return failure.exit_code
    return EXIT_OK


def _in_session(state: CliState, what: str) -> Robot:
    if not state.in_session:
        raise click.UsageError(
            f"`{what}` only lasts as long as its session, which ends with this process: use it "
            f"inside `landscape session` (or use `landscape move ...`, which locks for itself)")
    return state.robot


@click.command()
@pass_state
def lock(state: CliState) -> None:
    """Take the lock for this session (session only)."""
    robot = _in_session(state, "lock")
    robot.lock()
    state.out.result({"locked": True, "session_id": robot.session.session_id},
                     f"locked by {state.client_name}")


def _lock_holder_command(name: str, method: str, doc: str):
    @click.command(name, help=doc)
    @pass_state
    def command(state: CliState) -> None:
        state.out.reply(getattr(_in_session(state, name), method)())
    return command


activate = _lock_holder_command("activate", "activate", "Drives on (session only).")
deactivate = _lock_holder_command("deactivate", "deactivate", "Drives off (session only).")
release = _lock_holder_command("release", "release", "Give the lock back (session only).")
stop = _lock_holder_command("stop", "stop_motion",
                            "Stop the motion along its path, hold it (session only).")
resume = _lock_holder_command("resume", "resume_motion", "Resume a stopped motion (session only).")
abort = _lock_holder_command("abort", "abort_motion", "Drop a stopped motion (session only).")


@click.command()
@pass_state
def reset(state: CliState) -> None:
    """Leave the error state once its cause is cleared (the e-stop released)."""
    with state.reader() as robot:
        state.out.reply(robot.reset())


@click.command()
@click.argument("action", type=click.Choice(["press", "release"]))
@pass_state
def estop(state: CliState, action: str) -> None:
    """Press or release the cell's emergency stop (the operator panel; admin only)."""
    panel = {"press": control_pb2.PANEL_ACTION_PRESS_ESTOP,
             "release": control_pb2.PANEL_ACTION_RELEASE_ESTOP}[action]
    with state.reader() as robot:
        state.out.reply(robot.operate_panel(panel))

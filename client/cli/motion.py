"""`landscape move ...` and `landscape path ...`: motions, each waited for until done."""
from __future__ import annotations

import contextlib

import click

from landscape.client.cli.context import CliState, pass_state
from landscape.client.cli.output import to_dict
from landscape.client.errors import NotFound
from landscape.client.pathfile import FRAMES, PathFileError, read_path
from landscape.client.values import Frame, Motion

# Negative numbers are values here, not options.
NUMBERS = {"ignore_unknown_options": True}
CARTESIAN_FRAMES = {"world": Frame.WORLD, "base": Frame.BASE, "tool": Frame.TOOL}


@click.group()
def move() -> None:
    """Move the arm to (or by) a point and wait until it is there.

    Values are in the device's units (see `landscape status`). Negative numbers need no
    quoting: `landscape move joint 0.5 -0.2 1.57 0 1.57 0`.
    """


def _motion_options(func):
    func = click.option("--relative", is_flag=True, help="Values are an offset (moveRelative).")(func)
    func = click.option("--speed", type=float, default=None,
                        help="Percent of maximum speed for this move (default: the set speed).")(func)
    func = click.option("--point-name", default="", help="Names the move in its events.")(func)
    return func


@move.command("joint", context_settings=NUMBERS)
@click.argument("values", nargs=-1, type=float, required=True)
@_motion_options
@pass_state
def move_joint(state: CliState, values, relative, speed, point_name) -> None:
    """Joint values J1 J2 ... (joint interpolation)."""
    _move(state, values, Frame.JOINT, relative, speed, None, point_name)


@move.command("cartesian", context_settings=NUMBERS)
@click.argument("values", nargs=6, type=float)
@click.option("--frame", type=click.Choice(list(CARTESIAN_FRAMES)), default="world",
              show_default=True, help="Frame of X Y Z ROLL PITCH YAW.")
@click.option("--straight", is_flag=True, help="The tool tip on a straight line.")
@_motion_options
@pass_state
def move_cartesian(state: CliState, values, frame, straight, relative, speed, point_name) -> None:
    """The tool tip to X Y Z ROLL PITCH YAW (fixed-axis X-Y-Z angles)."""
    _move(state, values, CARTESIAN_FRAMES[frame], relative, speed,
          Motion.STRAIGHT if straight else Motion.JOINT, point_name)


def _move(state: CliState, values, frame: Frame, relative: bool, speed, motion, point_name) -> None:
    with state.commander() as robot:
        start = robot.move_relative if relative else robot.move_absolute
        command = start(list(values), frame, point_name=point_name, speed=speed, motion=motion)
        done = command.wait(state.timeout)
        position = robot.get_robot_position()
    joints = " ".join(f"{q:.4f}" for q in position.joint_position)
    state.out.result({"command_id": command.command_id, "done": to_dict(done),
                      "position": to_dict(position)},
                     f"{command.command_id} done; joints now {joints}")


@click.group()
def path() -> None:
    """Load named paths from files, run them, clear them (seed 3.5).

    A path file is JSON or CSV (see landscape/client/pathfile.py): one point per row, with
    j1..jN or x,y,z,roll,pitch,yaw columns and optional tag_name, time_delay,
    transition_speed, speed, accel and aux_commands.
    """


def _file_options(func):
    func = click.option("--frame", type=click.Choice(list(FRAMES)), default=None,
                        help="Frame of the file's values (default: the file's, else joint; "
                             "CSV with x..yaw columns: world).")(func)
    func = click.option("--straight", is_flag=True,
                        help="Straight lines between points (default: the file's, else joint).")(func)
    return func


def _read(file: str, frame, straight: bool):
    try:
        return read_path(file, frame or None, "straight" if straight else None)
    except PathFileError as error:
        raise click.BadParameter(str(error), param_hint="FILE") from None


@path.command("load")
@click.argument("file", type=click.Path(exists=True, dir_okay=False))
@click.option("--name", default=None, help="Path name (default: the file name without suffix).")
@_file_options
@pass_state
def path_load(state: CliState, file: str, name, frame, straight) -> None:
    """Append the points of FILE to a named path (all or nothing)."""
    points = _read(file, frame, straight)
    name = name or click.format_filename(file).rsplit("/", 1)[-1].rsplit(".", 1)[0]
    with state.commander(activate=False) as robot:
        reply = robot.path_load(name, points.points, points.frame, motion=points.motion)
    state.out.result({"path_name": name, **to_dict(reply)},
                     f"path {name}: {reply.points_loaded} points loaded, {reply.path_length} in all")


@path.command("run")
@click.argument("name")
@click.option("--file", type=click.Path(exists=True, dir_okay=False), default=None,
              help="Load this file as the path first, replacing it (then the bar knows "
                   "every tag).")
@click.option("--cycles", type=int, default=1, show_default=True,
              help="Repetitions; 0 is a dry run without auxiliary commands.")
@_file_options
@pass_state
def path_run(state: CliState, name: str, file, cycles: int, frame, straight) -> None:
    """Run the named path and show its tags as they are reached."""
    points = _read(file, frame, straight) if file else None
    with state.commander() as robot:
        if points is not None:   # the file is the path: replace, not append to, the old one
            with contextlib.suppress(NotFound):
                robot.path_clear_path(name)
            robot.path_load(name, points.points, points.frame, motion=points.motion)
        command = robot.path_move(name, cycles)
        total = points.tags * max(cycles, 1) if points is not None else None
        tags = _follow(state, command, total)
    state.out.result({"command_id": command.command_id, "path_name": name, "tags_reached": tags,
                      "done": to_dict(command.events[-1])},
                     f"path {name} done ({command.command_id}, {tags} tags reached)")


def _follow(state: CliState, command, total: int | None) -> int:
    """Follow the command to its end, with a progress bar on a terminal's stderr."""
    reached = 0
    if state.as_json or total is None:
        for event in command.follow(state.timeout):
            if event.event_id == "tag_reached":
                reached += 1
                state.out.note(f"tag {event.command.tag_name} reached")
        return reached
    with click.progressbar(length=max(total, 1), label=f"{command.command_id}",
                           file=click.get_text_stream("stderr"),
                           show_pos=True) as bar:
        for event in command.follow(state.timeout):
            if event.event_id == "tag_reached":
                reached += 1
                bar.update(1)
            elif event.event_id == "command_done" and not total:
                bar.update(1)
    return reached


@path.command("clear")
@click.argument("name")
@pass_state
def path_clear(state: CliState, name: str) -> None:
    """Delete a named path (seed pathClearPath)."""
    with state.commander(activate=False) as robot:
        state.out.reply(robot.path_clear_path(name))

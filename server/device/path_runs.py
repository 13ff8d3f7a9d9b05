"""Path runs (seed 3.5): the named paths, loading them, running them, and their marks.

A path is resolved and checked against the cell when it is loaded (planning/process.py's jobs,
in a process of their own beside a cycle process) and kept in the path store; a run is planned
and started through the motions (motion_control.py). On the real-time clock a long run is
timed and checked as it plays (issue 31 item 4): it starts on its first pieces and
run_check.follow hands the cycle the rest (_hand_on). The marks the cycle reports along a run
(path points) run its aux commands and publish its tag events.
"""
from __future__ import annotations

import itertools

from landscape.robot.controller import DoutValue, Status
from landscape.server.config import PROCESS_CLOCKS
from landscape.server.cycle.run_arrays import pack_run
from landscape.server.device.motion_control import MotionControl, RunningMotion
from landscape.server.device.motion_settings import MotionSettings
from landscape.server.device.stored_settings import SettingsKeeper
from landscape.server.errors import NotFound, WrongState
from landscape.server.events import alarms
from landscape.server.events.bus import EventBus, Phase, Severity
from landscape.server.link.clock import CycleProcessError
from landscape.server.link.controller_link import ControllerLink
from landscape.server.planning import aux_commands, run_check
from landscape.server.planning.collision import CollisionScene
from landscape.server.planning.moves import Planner
from landscape.server.planning.path_planning import LONG_SECTION
from landscape.server.planning.paths import PathLibrary, PathStore
from landscape.server.planning.process import InProcessPlanning, PlanningProcess
from landscape.server.planning.targets import Frame


class PathRuns:
    def __init__(self, motions: MotionControl, link: ControllerLink, bus: EventBus,
                 planner: Planner, collisions: CollisionScene, paths: PathStore,
                 settings: SettingsKeeper, outputs: set[str]):
        self.motions, self.link, self.bus, self.settings = motions, link, bus, settings
        self.dt = planner.dt
        self.paths = PathLibrary(paths)
        self.outputs = outputs          # digital outputs aux commands may set
        self.last_tag = ("", "")        # (path name, tag name), for getTagId
        # A long path run is timed and checked against the cell as it plays (issue 31 item 4)
        # on the real-time clock only: on the lock-step and fast clocks simulated time outruns
        # work done in wall time, so the arm would slow for it (a simulation not as
        # commanded); there the whole run is timed and checked before it starts. Tests turn
        # it on there, and make each later stretch late by `check_ahead_delay` s (the arm then
        # slows along the path, run_check.py).
        self.time_ahead = link.clock_kind == "realtime"
        self.check_ahead_delay = 0.0
        # rad of joint path above which a stretch is timed in chunks as it plays (tests make
        # their paths' sections long with a lower one)
        self.long_section = LONG_SECTION
        self._runs = itertools.count(1)   # keys of runs timed as they play
        # Long paths are planned beside a cycle process in a process of their own as well.
        self.planning = (PlanningProcess(collisions, link.cycle_time, self._planning_lost)
                         if link.clock_kind in PROCESS_CLOCKS
                         else InProcessPlanning(planner, collisions))

    def _planning_lost(self, why: str) -> None:
        self.bus.alarm(Severity.ERROR, alarms.PLANNING_LOST, why)

    def close(self) -> None:
        self.planning.close()
        self.paths.close()

    def path_load(self, name: str, frame: Frame, straight: bool, relative: bool, specs,
                  total: int | None = None) -> tuple[int, int]:
        """Seed 3.5.1 pathLoad: resolve and check every point (PointSpecs, or a StreamRef to
        a PathLoad stream's), and the whole path against the cell, then append them to the
        named queue in one transaction; nothing is stored if any point fails. Returns (points
        loaded, path length)."""
        path, loaded = self.planning.run("load_path", self.paths.get(name), name, frame,
                                         straight, relative, specs, self.settings.current,
                                         self.outputs, self.motions.planning_start(), total)
        self.paths.put(path)
        return loaded, len(path.points)

    def path_clear(self, name: str) -> None:
        motion = self.motions.running
        if motion is not None and motion.point_name == name and motion.command == "PathMove":
            raise WrongState(f"path {name!r} is running; stop and abort it first")
        self.paths.delete(name)

    def path_move(self, name: str, cycles: int, settings: MotionSettings | None = None) -> str:
        """Seed 3.5.2 pathMove: `cycles` passes; 0 is a dry run without aux commands;
        `settings`: this run's (default: the device's)."""
        path = self.paths.get(name)
        if path is None:
            raise NotFound(f"no path named {name!r}")
        settings = settings or self.settings.current
        if self.time_ahead:
            return self._path_move_lazily(f"run-{next(self._runs)}", path, cycles, settings)
        trajectories = self.planning.run("plan_path_run", path, self.motions.planning_start(),
                                         settings, cycles, f"PathMove {name}")
        return self.motions.start("PathMove", name, trajectories,
                                  *self._path_marks(path, cycles), checked=True)

    def _path_move_lazily(self, key: str, path, cycles: int, settings: MotionSettings) -> str:
        """path_move on a run timed as it plays (issue 31 item 4): it starts on its first
        pieces timed and checked, and run_check.follow hands the cycle the rest."""
        pieces, continues, checked, brake, everything = self.planning.run(
            "plan_path_lazily", key, path, self.motions.planning_start(), settings, cycles,
            f"PathMove {path.name}", self.long_section)
        trajectories, _ = run_check.joined(pieces, continues)
        try:
            motion = self.motions.start_motion("PathMove", path.name, trajectories,
                                               *self._path_marks(path, cycles), checked=True,
                                               ahead=None if everything else (checked, brake))
        except BaseException:
            self.planning.run("drop_run", key)
            raise
        if not everything:
            run_check.following(self.planning, key, motion.command_id,
                                lambda *args: self._hand_on(motion, *args),
                                self.motions.send,
                                lambda: self.check_ahead_delay)
        return motion.command_id

    def _hand_on(self, motion: RunningMotion, pieces: list, continues: list, checked: int,
                 brake: int, everything: bool) -> bool:
        """Later pieces of a run timed as it plays, how far it is checked and the brake rows
        for its fastest so far, sent to the cycle; False if the motion no longer runs."""
        with self.motions.appending(motion) as running:
            if not running:
                return False
            if not pieces:
                self.motions.send({"op": "checked", "id": motion.command_id,
                                   "rows": checked, "all": everything})
                return True
            trajectories, joins = run_check.joined(pieces, continues)
            arrays = self.link.share(pack_run(trajectories, self.dt))
            motion.appended.append(arrays)
            self.motions.send({"op": "append", "id": motion.command_id, "arrays": arrays,
                               "continues": joins, "rows": checked, "brake": brake,
                               "all": everything})
        return True

    @staticmethod
    def _path_marks(path, cycles: int) -> tuple[dict, dict]:
        """A path run's (tags, aux) by mark label (point index); no aux in a dry run."""
        tags = {i: (p.tag_name, p.tag_index) for i, p in enumerate(path.points) if p.tag_name}
        aux = {} if cycles == 0 else {i: p.aux_commands for i, p in enumerate(path.points)
                                      if p.aux_commands}
        return tags, aux

    # ---- marks -------------------------------------------------------------------------------

    def mark(self, motion: RunningMotion, label: int) -> None:
        """A mark the cycle reported on a motion: its aux commands run, its tag is published."""
        for command in motion.aux.get(label, ()):
            self._run_aux(motion, command)
        if label in motion.tags:
            name, index = motion.tags[label]
            self.last_tag = (motion.point_name, name)
            self.bus.command(motion.command_id, motion.command, Phase.TAG_REACHED,
                             motion.point_name, name, index)

    def _run_aux(self, motion: RunningMotion, command: str) -> None:
        out = aux_commands.parse(command, self.outputs)
        controller = self.link.proxy
        try:
            io = controller.get_dout_id(out.name)
            ok = controller.write_dout(io, DoutValue.ONE if out.value else DoutValue.ZERO) \
                is Status.OK
        except (CycleProcessError, TimeoutError):
            ok = False
        if not ok:
            self.bus.alarm(Severity.WARNING, alarms.CONTROLLER,
                           f"aux command {command!r} failed", motion.command_id)

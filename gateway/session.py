"""One CRCL session: a TCP connection's (or a gRPC stream's) commands, in order, and its status.

- Documents are parsed safely, validated against the schemas when configured, and always by
  the typed parser; a refused document becomes a CRCL_Error status saying why, and the
  session goes on.
- GetStatus is answered at once from the live state; it never waits behind a command.
- Settings and reporting commands (handlers.IMMEDIATE: no device call) are carried out at
  once when nothing else runs, so they are Done for the very next GetStatus.
- Other commands run in the order they arrive, each the current one (CRCL_Working) while it
  runs. A new command preempts a running one that lasts (a motion, a dwell, a program: spec
  section VI): it is cancelled and the arm stops along its path before the new one starts;
  quick commands (settings) just finish first. CommandIDs are the client's.
- Before InitCanon, and after EndCanon, commands other than InitCanon are errors (EndCanon
  and StopMotion before InitCanon have nothing to do, and are done).
- InitCanon takes the device's lock for this session (one session at a time holds it), turns
  the drives on, starts the session's settings from the cell's workstation (its frame and
  units, workstation.py) and has the arm hold the cell's end effector; EndCanon stops, turns
  the drives off, puts back what the session set on the device and releases. A connection
  that ends does the same (device.py), the device's disconnect handler at the last.
- A lock lost (the device ended the session: its keep-alives stopped arriving, the server
  stopped) ends the running command, and those queued, in CRCL_Error naming the loss and the
  device's reason; every later status says so, until InitCanon takes the lock again (never
  by itself). EndCanon then has nothing to release, and is done.
"""
from __future__ import annotations

import asyncio
import collections
import itertools
import logging
from dataclasses import dataclass

from landscape.client import LandscapeError, SessionEnded
from landscape.gateway import model as m
from landscape.gateway import guards, parse, status, xmlsafe
from landscape.gateway.device import Control, CrclDevice
from landscape.gateway.errors import CrclError, describe
from landscape.gateway.live import live_state
from landscape.gateway.guards import GuardReport
from landscape.gateway.handlers import HANDLERS, immediate
from landscape.gateway.program import expand
from landscape.gateway.schemas import NEWEST, SchemaInvalid, SchemaSet
from landscape.gateway.settings import CrclSettings
from landscape.gateway.status import DONE, ERROR, WORKING, CommandRecord
from landscape.gateway.tooling import hold_end_effector
from landscape.gateway.wire import DEFAULT_MAX_DOCUMENT, DOCUMENT_IDLE
from landscape.gateway.workstation import Workstation
from landscape.v1 import types_pb2

log = logging.getLogger(__name__)
_session_numbers = itertools.count(1)
MAX_QUEUED = 10_000     # commands waiting behind the running one, per session


@dataclass(frozen=True)
class GatewayOptions:
    schemas: SchemaSet | None = None
    max_document: int = DEFAULT_MAX_DOCUMENT
    document_idle: float = DOCUMENT_IDLE    # s a started document may wait for more bytes
    gripper_stroke: float = status.DEFAULT_GRIPPER_STROKE
    workstation: Workstation = Workstation()

    @property
    def revision(self) -> int:
        """The CRCL schemas' revision statuses are written in: the configured one's, else
        the newest."""
        return self.schemas.revision if self.schemas is not None else NEWEST


class CrclSession:
    def __init__(self, device: CrclDevice, options: GatewayOptions, peer: str = ""):
        self.device = device
        self.options = options
        self.peer = peer
        self.name = f"crcl-{next(_session_numbers)}{' ' + peer if peer else ''}"
        self.settings = CrclSettings()
        self.record = CommandRecord()
        self.control: Control | None = None
        self.ended = False                  # after EndCanon, until the next InitCanon
        self.lost = ""                      # why the lock is lost, until the next InitCanon
        self._status_ids = itertools.count(1)
        self._queue: collections.deque = collections.deque()
        self._worker: asyncio.Task | None = None
        self._running: asyncio.Task | None = None
        self._running_lasts = False         # the running command is preempted by the next
        self._must_halt = False             # a preempted motion may still move the arm
        self.motion_start: asyncio.Future | None = None   # a motion call in flight
        self._dropped: asyncio.Future | None = None       # closing a lost control
        self.motion_ended = 0.0    # unix s the last device motion ended (its done event)
        self.guard_report: GuardReport | None = None   # the last guarded command's
        self.listeners: list = []           # called with no argument when the record changes

    # ---- documents -------------------------------------------------------------------------

    def read(self, data: bytes) -> m.CommandInstance | m.Program:
        """The typed document; raises CrclError saying what is wrong (line, element)."""
        try:
            tree = xmlsafe.parse(data, self.options.max_document)
            if self.options.schemas is not None:
                self.options.schemas.validate(tree)
            return parse.document(tree)
        except (xmlsafe.XmlRefused, SchemaInvalid, parse.CrclParseError) as error:
            raise CrclError(f"document refused: {error}") from None
        except Exception as error:   # a gateway bug: refuse the document, keep the connection
            log.exception("%s: reading a document", self.name)
            raise CrclError(f"document refused: gateway error {error!r}") from None

    async def receive(self, data: bytes) -> bytes | None:
        """Take one document; returns the status to send back (GetStatus only), else None."""
        try:
            document = self.read(data)
        except CrclError as error:
            await self.refuse(str(error), _command_id_of(data))
            return self.status() if b"GetStatusType" in data else None
        if isinstance(document, m.Program):
            self.submit(lambda: self._run_program(document), True, CommandRecord(
                document.commands[0].command_id, WORKING, program_index=0,
                program_length=len(document.commands)))
            return None
        command = document.command
        if isinstance(command, m.GetStatus):
            return self.status()
        if immediate(command) and self._running is None and not self._queue:
            record = CommandRecord(command.command_id, WORKING, program_file=document.program_file,
                                   program_index=document.program_index,
                                   program_length=document.program_length)
            self.record = record
            await self._outcome(record, self.execute(command))   # never waits: no device
            self.changed()
            return None
        self.submit(lambda: self.execute(command), command.MOTION or command.LASTS,
                    CommandRecord(command.command_id, WORKING, program_file=document.program_file,
                                  program_index=document.program_index,
                                  program_length=document.program_length),
                    urgent=isinstance(command, m.StopMotion) and self.control is not None)
        await asyncio.sleep(0)   # a command done at once is Done for the next GetStatus
        return None

    async def refuse(self, why: str, command_id: int | None = None) -> None:
        """A document or stream fault that is no command: logged, and reported as an error."""
        log.info("%s: %s", self.name, why)
        self.fail(why, command_id)

    def fail(self, why: str, command_id: int | None = None) -> None:
        """The status says CRCL_Error, why, for `command_id` (default: the current one)."""
        self.record = CommandRecord(self.record.command_id if command_id is None else command_id,
                                    ERROR, why)
        self.changed()

    def changed(self) -> None:
        for listener in self.listeners:
            listener()

    def status(self) -> bytes:
        feed = self.device.feed
        live = live_state(feed.latest) if feed.latest is not None else None
        return status.build(self.record, next(self._status_ids), self.settings, live,
                            feed.stale(), self.options.gripper_stroke, self.options.revision,
                            self.guard_report)

    # ---- running commands ---------------------------------------------------------------------

    def submit(self, body, lasts: bool, record: CommandRecord, urgent: bool = False) -> None:
        """Queue a command (`body()` makes its coroutine). Commands run in order; a new one
        preempts a running command that lasts (a motion, a dwell, a program). An urgent one (a
        stop) starts at once: the commands queued before it are dropped, and it waits neither
        for them nor for the preempted motion's controlled stop."""
        if len(self._queue) >= MAX_QUEUED:
            self.record = CommandRecord(record.command_id, ERROR,
                                        f"more than {MAX_QUEUED} commands queued: refused")
            return
        if urgent:
            self._queue.clear()
            started = asyncio.ensure_future(body())
            body = lambda: started            # noqa: E731 - the worker awaits it in turn
        self._queue.append((body, lasts, record, urgent))
        if urgent or (self._running is None and len(self._queue) == 1):
            self.record = record     # it runs next: status names it from now on
        if self._running is not None and self._running_lasts and not self._running.done():
            self._running.cancel()
        if self._worker is None or self._worker.done():
            self._worker = asyncio.create_task(self._work(), name=f"{self.name} commands")

    async def _work(self) -> None:
        while self._queue:
            body, lasts, record, urgent = self._queue.popleft()
            if lasts and self._queue and not urgent:
                # Preempted before it began: the next command came while it waited.
                record.state, record.description = ERROR, "preempted by the next command"
                continue
            if self._must_halt:
                self._must_halt = False
                if not urgent:                   # a stop stops the arm its own way
                    await self._halt_quietly()
            self.record = record
            self.changed()
            self._running, self._running_lasts = asyncio.ensure_future(body()), lasts
            try:
                await self._outcome(record, asyncio.shield(self._running))
            except asyncio.CancelledError:
                if not self._running.cancelled():
                    raise              # the worker itself is cancelled: the session closes
                record.state = ERROR
                record.description = self.lost or "preempted by the next command"
                self._must_halt = lasts and not self.lost
            finally:
                self._running = None
                self.changed()

    async def _outcome(self, record: CommandRecord, running) -> None:
        """Await a command (its coroutine or task) and write how it ended into its record."""
        try:
            description = await running
            if self.record is record:
                record.state, record.description = DONE, description or ""
        except SessionEnded as lost:
            self.lose(lost)
            record.state, record.description = ERROR, self.lost or str(lost)
        except (CrclError, LandscapeError) as error:
            record.state, record.description = ERROR, describe(error)
            log.info("%s: command %d: %s", self.name, record.command_id, record.description)
        except Exception as error:   # a bug must not take the connection down silently
            log.exception("%s: command %d failed", self.name, record.command_id)
            record.state, record.description = ERROR, f"gateway error: {error!r}"

    async def wait(self) -> None:
        """Until every queued command has finished (for programs and tests)."""
        while self._worker is not None and not self._worker.done():
            await asyncio.gather(self._worker, return_exceptions=True)

    async def _halt_quietly(self) -> None:
        """After a preempted motion: stop on the path. A failure here is the next command's
        to report."""
        if self.control is not None:
            try:
                await self.halt()
            except LandscapeError as error:
                log.warning("%s: stopping the preempted motion: %s", self.name, error)

    async def halt(self) -> None:
        """Stop a motion along its path and drop it (the arm rests, drives stay on); once more
        after a motion request still in flight has landed."""
        await self._halt_once()
        if self.motion_start is not None:
            await asyncio.gather(self.motion_start, return_exceptions=True)
            self.motion_start = None
            await self._halt_once()

    async def _halt_once(self) -> None:
        state = await self.control.state()
        if state == types_pb2.DEVICE_STATE_MOVING:
            await self.control.robot.stop_motion()
            state = types_pb2.DEVICE_STATE_PAUSED
        if state == types_pb2.DEVICE_STATE_PAUSED:
            await self.control.robot.abort_motion()

    async def execute(self, command: m.Command) -> str | None:
        """Carry out one command; returns a description for its Done status."""
        if command.guards:
            guards.refuse(command)       # unless the device can watch them (a MoveTo's)
        if isinstance(command, m.InitCanon):
            return await self.init_canon()
        if self.control is None and self.lost:
            return self._after_loss(command)
        if self.control is None:
            if isinstance(command, (m.EndCanon, m.StopMotion)):
                return "no CRCL session is active: nothing to do"
            when = "after EndCanon" if self.ended else "before InitCanon"
            raise CrclError(f"{command.KIND} {when}: only InitCanon is accepted")
        if isinstance(command, m.EndCanon):
            return await self.end_canon()
        return await HANDLERS[type(command)](self, command)

    async def init_canon(self) -> str:
        if self.control is None:
            taken = self.control = await self.device.take_control(self.name, self.peer)
            taken.robot.session.add_end_listener(lambda lost: self._ended(taken, lost))
        control = self.control
        workstation = self.options.workstation
        try:
            await control.prepare()
            self.settings = CrclSettings(units=workstation.units, frame=workstation.frame)
            self.guard_report = None
            await self.device.feed.watch(self, ())
            tool = await hold_end_effector(self, workstation.end_effector)
            if self.control is not control:
                raise CrclError(self.lost)
        except BaseException as error:
            # The device may end the session during any await above (a keep-alive starved on
            # a busy machine): `lose` has cleared self.control, and the loss is the reason.
            lost = self.control is not control and self.lost
            await self.drop_control()
            if lost and isinstance(error, Exception) and not isinstance(error, CrclError):
                raise CrclError(lost) from error
            raise
        self.ended, self.lost = False, ""
        units = self.settings.units
        return (f"session started: lock held, drives on, {units.length} and {units.angle}"
                f"{', ' + tool if tool else ''}")

    def _ended(self, control: Control, lost: SessionEnded | None) -> None:
        """The device session of `control` ended: lost, unless this client closed it."""
        if lost is not None and self.control is control:
            self.lose(lost)

    def lose(self, lost: SessionEnded) -> None:
        """The device ended this session's own (it stopped the arm and freed the lock): the
        running command and those queued end in CRCL_Error saying so, and so does every
        status until InitCanon. Nothing takes the lock back by itself."""
        if self.control is None:
            return
        self.lost = f"the lock is lost: {lost}; InitCanon takes it again"
        log.warning("%s: %s", self.name, self.lost)
        control, self.control = self.control, None
        self._dropped = asyncio.ensure_future(self.device.end(control))   # it has ended
        self._queue.clear()
        if self._running is not None and not self._running.done():
            self._running.cancel()
        self.record.state, self.record.description = ERROR, self.lost
        self.changed()

    def _after_loss(self, command: m.Command) -> str:
        """A command after a lost lock: EndCanon and StopMotion have nothing to do (the
        device stopped the arm and released), the others are errors saying so."""
        if isinstance(command, m.EndCanon):
            self.lost, self.ended = "", True
            return "nothing to release: the lock was lost before"
        if isinstance(command, m.StopMotion):
            return f"nothing to stop: {self.lost}"
        raise CrclError(self.lost)

    async def end_canon(self) -> str:
        control, self.control = self.control, None
        await control.release()
        self.ended = True
        return "session ended: motion stopped, drives off, lock released"

    async def drop_control(self) -> None:
        control, self.control = self.control, None
        if control is not None:
            await self.device.end(control)

    async def close(self) -> None:
        """The connection ended: its command stopped, then its session (device.ending)."""
        await self.device.ending(self._close())

    async def _close(self) -> None:
        self._queue.clear()
        for task in (self._running, self._worker):
            if task is not None:
                task.cancel()
        await asyncio.gather(*(t for t in (self._running, self._worker) if t),
                             return_exceptions=True)
        await self.drop_control()
        try:
            await self.device.feed.watch(self, ())     # its sensors, if no one else's
        except LandscapeError as error:
            log.warning("%s: %s", self.name, error)

    # ---- programs ----------------------------------------------------------------------------

    async def _run_program(self, program: m.Program) -> str:
        """A CRCLProgram sent whole: its commands in order, each to its end; the first error
        ends the program and names the command."""
        commands = expand(program)
        record = self.record
        for index, command in enumerate(commands):
            record.command_id, record.program_index = command.command_id, index
            record.program_length = len(commands)
            self.changed()
            try:
                await self.execute(command)
            except SessionEnded:
                raise                             # the loss ends the program: lose() says so
            except (CrclError, LandscapeError) as error:
                raise CrclError(f"program stopped at command {index} ({command.KIND}, CommandID "
                                f"{command.command_id}): {describe(error)}") from None
        return f"program done: {len(commands)} commands"


def _command_id_of(data: bytes) -> int | None:
    """The CommandID of a document that was refused, if it can be read at all."""
    start = data.find(b"<CommandID>")
    end = data.find(b"</CommandID>", start)
    if start < 0 or end < 0:
        return None
    try:
        return int(data[start + len(b"<CommandID>"):end].strip())
    except ValueError:
        return None

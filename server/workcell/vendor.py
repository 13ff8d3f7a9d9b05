"""sendCommand (seed 4.1): the vendor hook, a small set of text commands for this device.

One command per call, words separated by spaces; the result is text. Commands that change
something (the recorder, a tare) need the lock holder's lease while the device is locked.
Anything else is CMD_PARAM_ERR listing the commands.
"""
from __future__ import annotations

from dataclasses import dataclass
from importlib import metadata
from typing import Callable

from landscape.robot.controller import IoctrlCode, Status
from landscape.server.device.state_machine import StateMachine
from landscape.server.errors import ControllerFailure, ParamError, WrongState
from landscape.server.link.controller_link import ControllerLink
from landscape.server.workcell.sensing import Sensors



@dataclass(frozen=True)
class VendorCommand:
    words: str           # e.g. "recorder start"
    help: str
    mutating: bool       # needs the lock holder's lease while locked
    run: Callable[[list[str]], str]   # the words after the command's own -> the result


class VendorCommands:
    def __init__(self, link: ControllerLink, state: StateMachine, sensors: Sensors,
                 record_path: str):
        self.link, self.state, self.sensors, self.record_path = link, state, sensors, record_path
        self.commands = [
            VendorCommand("help", "this list", False, lambda _: self.help()),
            VendorCommand("version", "server, controller and robot versions", False,
                          lambda _: self._version()),
            VendorCommand("cycle stats", "timing of the controller's cycle", False,
                          lambda _: self._stats()),
            VendorCommand("recorder start", "record every cycle (LLI recorder, MCAP)", True,
                          lambda _: self._recorder("start")),
            VendorCommand("recorder stop", "stop recording", True,
                          lambda _: self._recorder("stop")),
            VendorCommand("recorder store", "write the recording to its MCAP file", True,
                          lambda _: self._recorder("store")),
            VendorCommand("tare <sensor>", "zero a sensor at its present reading", True,
                          self._tare),
        ]
        self._recorder_ready = False

    def find(self, text: str) -> tuple[VendorCommand, list[str]]:
        words = text.split()
        for command in self.commands:
            own = [w for w in command.words.split() if not w.startswith("<")]
            if words[:len(own)] == own and len(words) == len(command.words.split()):
                return command, words[len(own):]
        raise ParamError(f"unknown vendor command {text!r}; the commands: "
                         + "; ".join(c.words for c in self.commands))

    def run(self, text: str, lease: str | None) -> str:
        command, args = self.find(text)
        if command.mutating:
            self.state.check_holder(f"SendCommand {command.words!r}", lease)
        return command.run(args)

    def help(self) -> str:
        return "\n".join(f"{c.words}: {c.help}" + (" (lock holder)" if c.mutating else "")
                         for c in self.commands)

    def _version(self) -> str:
        controller = self.link.proxy
        return (f"landscape-grpc {metadata.version('landscape-grpc')}; controller "
                f"{controller.ioctrl(IoctrlCode.GET_SOFTWARE_VERSION)}; robot "
                f"{controller.ioctrl(IoctrlCode.GET_ROBOT_TYPE)}")

    def _stats(self) -> str:
        stats = self.link.stats()
        if stats is None:
            return (f"lock-step clock (simulated time, no wall-clock deadlines): cycle "
                    f"{self.link.cycle_time * 1000:g} ms, "
                    f"{self.link.feedback.head + 1} cycles")
        return stats.summary()

    def _recorder(self, action: str) -> str:
        controller = self.link.proxy
        if action == "start":
            self._check(controller.rec_init(), "rec_init")   # a fresh recording
            self._recorder_ready = True
        elif not self._recorder_ready:
            raise WrongState("the recorder has not been started: \"recorder start\" first")
        self._check(getattr(controller, f"rec_{action}")(), f"rec_{action}")
        return {"start": "recording", "stop": "stopped",
                "store": f"stored to {self.record_path}"}[action]

    def _tare(self, args: list[str]) -> str:
        self.sensors.tare(args[0])
        return f"{args[0]} tared"

    @staticmethod
    def _check(status: Status, call: str) -> None:
        if status is not Status.OK:
            raise ControllerFailure(f"the controller refused {call}")

"""Start every service of a cell as a child process, say where each listens, watch them, and
stop them the safe way.

Order: the device servers (each must say it listens before the next service starts), then
the CRCL gateway and the web supervisor, built with the targets the devices really have. A
child's output is shown line by line behind its name. A child that exits on its own is
reported with its exit code and, by the configuration's restart policy, either started again
(on the port it had) or the whole cell stops (exit 1).

Stopping (SIGINT, SIGTERM or SIGHUP to the launcher): the clients first (their sessions end,
so any lock they hold is released by the device's disconnect handler), then the device
servers, each by SIGTERM, which it takes as its own safe stop: motion stops along its path,
drives off, lock released, exit 0. A child still running after the stop timeout is killed,
and said so. The children run in their own process group, so a Ctrl-C in the terminal
reaches the launcher alone and the order holds.
"""
from __future__ import annotations

import collections
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import TextIO

from landscape.cell.config import CellConfig
from landscape.cell.services import (ServiceSpec, device_service, foxglove_service,
                                     gateway_service, metrics_of, opcua_service,
                                     supervisor_missing, supervisor_service)
from landscape.cell.tokens import make_tokens

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
POLL = 0.1           # s between looks at the children
TAIL = 20            # lines of a child's output kept to show when it fails


class LaunchError(RuntimeError):
    """A service did not start; the message says which and shows its last lines."""


class Child:
    """One running service: its process, the thread that shows its output, where it
    listens."""

    def __init__(self, spec: ServiceSpec, out: "Output"):
        self.spec, self.out = spec, out
        self.where: str | None = None
        self.ready = threading.Event()
        self.tail: collections.deque = collections.deque(maxlen=TAIL)
        self.restarts = 0
        self.process: subprocess.Popen | None = None

    def start(self) -> None:
        self.spec.cwd.mkdir(parents=True, exist_ok=True)
        self.ready.clear()
        self.process = subprocess.Popen(
            self.spec.argv, cwd=self.spec.cwd, stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, bufsize=1,
            process_group=0)
        threading.Thread(target=self._pump, args=(self.process,), daemon=True,
                         name=f"output-{self.spec.name}").start()

    def _pump(self, process: subprocess.Popen) -> None:
        for line in process.stdout:
            line = line.rstrip()
            if not line:
                continue     # pybullet's banners come with blank lines
            self.tail.append(line)
            self.out.line(self.spec.name, line)
            if not self.ready.is_set():
                match = self.spec.ready.search(line)
                if match:
                    self.where = match.group(1)
                    self.ready.set()
        process.stdout.close()

    def wait_ready(self, timeout: float, cancel: threading.Event) -> None:
        deadline = time.monotonic() + timeout
        while not self.ready.wait(POLL):
            if cancel.is_set():
                raise LaunchError(f"stopped while {self.spec.name} was starting")
            if self.process.poll() is not None:
                time.sleep(POLL)    # let the pump show its last lines
                raise LaunchError(f"{self.spec.name} ({self.spec.kind}) exited with code "
                                  f"{self.process.returncode} before listening:\n"
                                  + self.last_lines())
            if time.monotonic() > deadline:
                raise LaunchError(f"{self.spec.name} ({self.spec.kind}) did not listen within "
                                  f"{timeout:g} s:\n" + self.last_lines())

    def last_lines(self) -> str:
        return "\n".join(f"    {line}" for line in self.tail) or "    (it printed nothing)"

    @property
    def exit_code(self) -> int | None:
        return None if self.process is None else self.process.poll()

    def terminate(self) -> None:
        if self.process is not None and self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)

    def finish(self, timeout: float) -> int:
        """Waits for the exit after terminate(); kills it after `timeout`. The exit code."""
        try:
            return self.process.wait(timeout)
        except subprocess.TimeoutExpired:
            self.out.say(f"{self.spec.name} did not stop within {timeout:g} s: killed")
            self.process.kill()
            return self.process.wait()


class Output:
    """The launcher's own lines and its children's, one at a time."""

    def __init__(self, stream: TextIO, width: int):
        self.stream, self.width = stream, width
        self._lock = threading.Lock()

    def line(self, name: str, text: str) -> None:
        with self._lock:
            self.stream.write(f"{name:<{self.width}} | {text}\n")
            self.stream.flush()

    def say(self, text: str) -> None:
        self.line("cell", text)


class Cell:
    """A running cell: `start()`, then `watch()` until a stop signal or a death, `stop()`."""

    def __init__(self, config: CellConfig, stream: TextIO = sys.stdout):
        self.config = config
        self.out = Output(stream, width=max(10, *(len(d.name) for d in config.devices)))
        self.children: list[Child] = []
        self.stopping = threading.Event()
        self.interrupted = False            # a stop signal came
        self.failed: str | None = None      # why the cell stopped on its own

    def interrupt(self, *_) -> None:
        """What a stop signal does: the launcher stops the cell (from the main thread)."""
        self.interrupted = True
        self.stopping.set()

    # -- start
    def start(self) -> None:
        """Starts every service in order and returns once all listen; LaunchError (the
        others stopped) if one does not."""
        config, workdir = self.config, Path.cwd()
        try:
            for index, device in enumerate(config.devices):
                self._launch(device_service(device, config.security,
                                            **metrics_of(config.metrics, index)))
            targets = {child.spec.name: self._target(child) for child in self.children}
            if config.gateway.enabled:
                self._launch(gateway_service(config, targets, workdir))
            if config.supervisor.enabled:
                why_not = supervisor_missing()
                if why_not:
                    self.out.say(f"web supervisor not started: {why_not}")
                else:
                    self._sign_in_tokens(config.supervisor.sign_in_tokens)
                    self._launch(supervisor_service(config, targets, workdir))
            if config.foxglove.enabled:
                self._launch(foxglove_service(config, targets, workdir))
            if config.opcua.enabled:
                self._launch(opcua_service(config, targets, workdir))
        except BaseException:
            self.stop()
            raise
        self._summary()

    def _sign_in_tokens(self, folder: Path) -> None:
        """People sign in to the supervisor with a role token: on a first run the folder is
        made as `landscape-cell tokens` makes it."""
        if folder.exists():
            return
        make_tokens(folder)
        self.out.say(f"made role tokens for signing in to the web supervisor in {folder} "
                     f"(`landscape-cell tokens`): operator.tokens to command, viewer.tokens "
                     f"to watch, admin.tokens for the operator panel")

    def _launch(self, spec: ServiceSpec) -> Child:
        child = Child(spec, self.out)
        self.children.append(child)
        child.start()
        child.wait_ready(self.config.launcher.start_timeout, self.stopping)
        return child

    def _target(self, child: Child) -> str:
        """host:port by which the others reach a device (its configured host, its real
        port)."""
        device = self.config.device(child.spec.name)
        port = child.where.rsplit(":", 1)[1]
        host = f"[{device.host}]" if ":" in device.host else device.host
        return f"{host}:{port}"

    def _summary(self) -> None:
        lines = [f'cell "{self.config.name}" is up; Ctrl-C stops it (the arms stop, power down '
                 f'and release):']
        for child in self.children:
            lines.append(f"  {child.spec.name:<{self.out.width}}  {child.spec.kind:<15} "
                         f"{child.where:<22} {child.spec.note}  (pid {child.process.pid})")
        for line in lines:
            self.out.say(line)

    # -- watch
    def watch(self) -> None:
        """Returns when stop is asked (`stopping` set, e.g. by a signal) or when a child dies
        and the policy says not to start it again (`failed` says which)."""
        launcher = self.config.launcher
        while not self.stopping.wait(POLL):
            for child in self.children:
                code = child.exit_code
                if code is None:
                    continue
                self.out.say(f"{child.spec.name} ({child.spec.kind}) exited on its own with "
                             f"code {code}")
                if launcher.restart == "on-failure" and child.restarts < launcher.max_restarts:
                    child.restarts += 1
                    self._restart(child)
                    continue
                self.failed = f"{child.spec.name} exited with code {code}"
                return

    def _restart(self, child: Child) -> None:
        """The same service again; a device server on the port it had."""
        if child.spec.kind == "device server" and child.where:
            port = int(child.where.rsplit(":", 1)[1])
            index = [d.name for d in self.config.devices].index(child.spec.name)
            child.spec = device_service(self.config.device(child.spec.name),
                                        self.config.security, port,
                                        **metrics_of(self.config.metrics, index))
        self.out.say(f"starting {child.spec.name} again ({child.restarts} of "
                     f"{self.config.launcher.max_restarts})")
        child.start()
        try:
            child.wait_ready(self.config.launcher.start_timeout, self.stopping)
        except LaunchError as error:
            self.out.say(str(error))

    # -- stop
    def stop(self) -> bool:
        """Stops the clients, then the device servers; True if every one exited 0."""
        self.stopping.set()
        timeout = self.config.launcher.stop_timeout
        clean = True
        clients = [c for c in self.children if c.spec.kind != "device server"]
        devices = [c for c in self.children if c.spec.kind == "device server"]
        for group in (clients, devices):
            running = [c for c in group if c.exit_code is None]
            for child in running:
                child.terminate()
            for child in running:
                code = child.finish(timeout)
                self.out.say(f"{child.spec.name} stopped (exit code {code})")
                clean = clean and code == 0
        return clean


def run(config: CellConfig, stream: TextIO = sys.stdout) -> int:
    """Runs the cell until a stop signal (exit 0 if it stopped cleanly) or a service's death
    (exit 1). Must be called from the main thread (it takes the stop signals)."""
    cell = Cell(config, stream)
    previous = {sig: signal.signal(sig, cell.interrupt) for sig in STOP_SIGNALS}
    try:
        try:
            cell.start()
        except LaunchError as error:
            cell.out.say(str(error))
            return 0 if cell.interrupted else 1
        cell.watch()
        if cell.failed:
            cell.out.say(f"stopping the cell: {cell.failed}")
        else:
            cell.out.say("stopping the cell")
        clean = cell.stop()
        return 1 if cell.failed or not clean else 0
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)

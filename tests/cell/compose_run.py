"""The services of docker-compose.yml as processes on this machine, without Docker.

Each service runs its own `command` with its own `environment`, in the order `depends_on`
gives, each waited for by its own `healthcheck` command. What Docker would provide is given
the plainest way:

- the image: its console scripts are this virtualenv's, and the folders docker/Dockerfile's
  final stage COPYs from the repository are read where they are in the repository;
- volumes: a named volume is a folder of the test's own, a bind mount its host folder (the
  file's ${VAR:-default} interpolated from the environment given);
- the network: every service gets its own free loopback port for each container port it
  has, and a word naming `service:port` (or this service's own 127.0.0.1/0.0.0.0 and port)
  is rewritten to it.
"""
from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[2]
COMPOSE_FILE = ROOT / "docker-compose.yml"
DOCKERFILE = ROOT / "docker" / "Dockerfile"
_VARIABLE = re.compile(r"\$\{(\w+)(?::-([^}]*))?\}")
_HOST_PORT = re.compile(r"([A-Za-z0-9_.-]+):(\d+)\b")


def interpolate(text: str, env: dict[str, str]) -> str:
    """Compose's ${NAME} and ${NAME:-default} (the forms the file uses)."""
    return _VARIABLE.sub(lambda m: env.get(m.group(1)) or (m.group(2) or ""), text)


def image_copies(dockerfile: Path = DOCKERFILE) -> dict[str, Path]:
    """Container path -> repository path, for each COPY from the build context in the final
    stage."""
    copies: dict[str, Path] = {}
    for line in dockerfile.read_text().splitlines():
        words = line.split()
        if words[:1] == ["FROM"]:
            copies = {}
        elif words[:1] == ["COPY"] and not any(w.startswith("--from") for w in words):
            source, target = words[1], words[2]
            copies[target.rstrip("/")] = ROOT / source
    return copies


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def _container_ports(service: dict) -> list[int]:
    ports = [int(str(entry).split(":")[-1].split("/")[0]) for entry in service.get("ports", ())]
    return ports + [int(p) for p in service.get("expose", ())]


class ComposeRun:
    def __init__(self, folder: Path, env: dict[str, str], compose_file: Path = COMPOSE_FILE):
        self.folder = folder
        self.env = env
        text = interpolate(compose_file.read_text(), env)
        self.services: dict[str, dict] = yaml.safe_load(text)["services"]
        self.copies = image_copies()
        self.ports = {(name, port): _free_port() for name, service in self.services.items()
                      for port in _container_ports(service)}
        self.processes: dict[str, subprocess.Popen] = {}
        self.logs: dict[str, Path] = {}

    # -- what Docker would give
    def mounts(self, name: str) -> list[tuple[str, Path]]:
        """(container path, host path), longest container path first."""
        pairs = [(target, source) for target, source in self.copies.items()]
        for volume in self.services[name].get("volumes", ()):
            source, target = volume.split(":")[:2]
            host = (self.folder / "volumes" / source if not source.startswith((".", "/"))
                    else (COMPOSE_FILE.parent / source).resolve())
            host.mkdir(parents=True, exist_ok=True)
            pairs.append((target, host))
        return sorted(pairs, key=lambda pair: -len(pair[0]))

    def translate(self, name: str, word: str) -> str:
        for target, host in self.mounts(name):
            if word == target or word.startswith(target + "/"):
                return str(host) + word[len(target):]
        if word == "0.0.0.0":
            return "127.0.0.1"
        if word.isdigit() and (name, int(word)) in self.ports:
            return str(self.ports[name, int(word)])

        def address(match):
            host, port = match.group(1), int(match.group(2))
            if host in self.services and (host, port) in self.ports:
                return f"127.0.0.1:{self.ports[host, port]}"
            if host in ("127.0.0.1", "localhost", "0.0.0.0") and (name, port) in self.ports:
                return f"127.0.0.1:{self.ports[name, port]}"
            return match.group(0)
        return _HOST_PORT.sub(address, word)

    def _argv(self, name: str, words: list[str]) -> list[str]:
        program, *rest = [self.translate(name, str(w)) for w in words]
        program = sys.executable if program == "python" else \
            str(Path(sys.executable).parent / program)
        return [program, *rest]

    def command(self, name: str) -> list[str]:
        return self._argv(name, self.services[name]["command"])

    def healthcheck(self, name: str) -> list[str]:
        test = self.services[name]["healthcheck"]["test"]
        assert test[0] == "CMD", f"{name}: only the exec form of a health check is run here"
        return self._argv(name, test[1:])

    def target(self, name: str, port: int) -> str:
        return f"127.0.0.1:{self.ports[name, port]}"

    # -- running
    def order(self, wanted: list[str]) -> list[str]:
        """`wanted` and what they depend on, dependencies first."""
        done: list[str] = []

        def visit(name):
            for dependency in self.services[name].get("depends_on", ()):
                visit(dependency)
            if name not in done:
                done.append(name)
        for name in wanted:
            visit(name)
        return done

    def start(self, name: str) -> None:
        service = self.services[name]
        workdir = service.get("working_dir")
        cwd = Path(self.translate(name, workdir)) if workdir else self.folder / "work" / name
        cwd.mkdir(parents=True, exist_ok=True)
        env = {**os.environ, **{k: self.translate(name, str(v))
                                for k, v in (service.get("environment") or {}).items()}}
        self.logs[name] = self.folder / f"{name}.log"
        with open(self.logs[name], "w") as log:
            self.processes[name] = subprocess.Popen(self.command(name), cwd=cwd, env=env,
                                                    stdout=log, stderr=subprocess.STDOUT,
                                                    stdin=subprocess.DEVNULL)

    def healthy(self, name: str) -> bool:
        """One run of its health check; one that outlasts 30 s failed, as Docker counts a
        check past its timeout (a busy machine: the next try decides)."""
        try:
            return subprocess.run(self.healthcheck(name), capture_output=True,
                                  timeout=30).returncode == 0
        except subprocess.TimeoutExpired:
            return False

    def wait_healthy(self, name: str, timeout: float = 120.0) -> float:
        """Seconds until its health check passed; AssertionError (with its log) if it exits
        or does not pass in time."""
        began = time.monotonic()
        while not self.healthy(name):
            if self.processes[name].poll() is not None:
                raise AssertionError(f"{name} exited with {self.processes[name].returncode}:\n"
                                     f"{self.logs[name].read_text()[-3000:]}")
            if time.monotonic() - began > timeout:
                raise AssertionError(f"{name} not healthy within {timeout} s:\n"
                                     f"{self.logs[name].read_text()[-3000:]}")
            time.sleep(0.5)
        return time.monotonic() - began

    def up(self, wanted: list[str]) -> dict[str, float]:
        return {name: (self.start(name), self.wait_healthy(name))[1]
                for name in self.order(wanted)}

    def down(self, timeout: float = 30.0) -> dict[str, int]:
        """SIGTERM to each, the clients first (compose's stop_signal); their exit codes."""
        codes = {}
        for name in reversed(list(self.processes)):
            process = self.processes[name]
            if process.poll() is None:
                process.send_signal(signal.SIGTERM)
            try:
                codes[name] = process.wait(timeout)
            except subprocess.TimeoutExpired:
                process.kill()
                codes[name] = process.wait()
        return codes

"""docker-compose.yml: Debian's docker-compose validates it (nothing is built: no Docker
engine here), and its services run without Docker, from the file's own commands, health
checks and environment (compose_run.py): every health check passes, an operator moves each
arm over TLS with a token, a CRCL client drives the first arm through the gateway, and the
web supervisor serves its page, reaches both arms over TLS with its own token, and a person
signed in to it with an operator's token takes a lock."""
from __future__ import annotations

import os
import shutil
import subprocess

import pytest

from cell_support import make_keys, move_as_operator, through_the_supervisor
from compose_run import COMPOSE_FILE, DOCKERFILE, ComposeRun
from crcl_support import RawClient, command, field

ARMS = {"arm1": [0.3, -0.2, 1.8, 0.1, 1.2, -0.4], "arm2": [0.3, -0.1, 1.6, 0.0, 1.4, 0.2]}


def _docker_compose() -> str:
    """Debian's docker-compose (.ci/run installs it; a test never does); skips saying so."""
    found = shutil.which("docker-compose")
    if not found:
        pytest.skip("docker-compose is not installed here (apt-get install docker-compose)")
    return found


def test_docker_compose_config_validates_the_file(tmp_path):
    exe = _docker_compose()
    env = {**os.environ, "LANDSCAPE_CERTS": str(tmp_path / "certs"),
           "LANDSCAPE_TOKENS": str(tmp_path / "tokens")}
    check = subprocess.run([exe, "-f", str(COMPOSE_FILE), "config", "--quiet"], env=env,
                           capture_output=True, text=True, timeout=120)
    assert check.returncode == 0, check.stderr
    services = subprocess.run([exe, "-f", str(COMPOSE_FILE), "config", "--services"], env=env,
                              capture_output=True, text=True, timeout=120).stdout.split()
    assert sorted(services) == ["arm1", "arm2", "gateway", "supervisor"]
    volumes = subprocess.run([exe, "-f", str(COMPOSE_FILE), "config", "--volumes"], env=env,
                             capture_output=True, text=True, timeout=120).stdout.split()
    assert sorted(volumes) == sorted(f"{arm}-{kind}" for arm in ARMS
                                     for kind in ("store", "recordings", "audit"))


def test_the_compose_services_run_without_docker_and_each_arm_moves(tmp_path):
    keys = make_keys(tmp_path / "keys")
    run = ComposeRun(tmp_path, {"LANDSCAPE_CERTS": str(keys.certs.ca.parent),
                                "LANDSCAPE_TOKENS": str(keys.tokens)})
    wanted = ["arm1", "arm2", "gateway", "supervisor"]
    try:
        took = run.up(wanted)
        print("healthy after " + ", ".join(f"{name} {s:.1f} s" for name, s in took.items()))
        assert all(run.healthy(name) for name in wanted)
        for arm, goal in ARMS.items():
            reached = move_as_operator(run.target(arm, 50051), keys, goal)
            print(f"{arm} moved to {reached.round(4).tolist()}")
        seen = through_the_supervisor(f"http://{run.target('supervisor', 8080)}/", list(ARMS),
                                      keys.token("operator"))
        for arm in ARMS:   # its reads reached each arm over TLS with its own (viewer) token
            assert seen[arm]["GetDeviceState"]["state"].startswith("DEVICE_STATE_")
        assert [seen[arm]["GetCellDescription"]["cellName"] for arm in ARMS] == [
            "default", "press_tending"]   # each arm in its own world
        crcl = RawClient(int(run.target("gateway", 64444).rsplit(":", 1)[1]))
        try:   # the gateway locks arm1 with its own token, over TLS
            status = crcl.run("InitCanon", 1)
            assert field(status, "CommandState") == "CRCL_Done", status
            crcl.send(command("EndCanon", 2))
            assert field(crcl.wait_done(2), "CommandState") == "CRCL_Done"
        finally:
            crcl.close()
    finally:
        codes = run.down()
    assert codes == {name: 0 for name in wanted}, codes
    volumes = tmp_path / "volumes"
    for arm in ARMS:
        assert (volumes / f"{arm}-store" / "paths.sqlite3").is_file()
        audit = (volumes / f"{arm}-audit" / "audit.log").read_text()
        assert '"DeviceService/MoveAbsolute"' in audit and '"who": "operator"' in audit


def test_the_image_builds_the_supervisors_page():
    """The page is built in the image (a Node stage, as `make install` builds it) and goes in
    with the package: the supervisor raises without it."""
    text = DOCKERFILE.read_text()
    stages = [line.split()[1] for line in text.splitlines() if line.startswith("FROM ")]
    assert stages[0].startswith("node:")
    assert "RUN npm ci" in text and "RUN npm run build" in text
    assert "COPY --from=page /page/dist supervisor_gui_web/frontend/dist" in text
    ignored = (COMPOSE_FILE.parent / ".dockerignore").read_text().split()
    assert "**/node_modules" in ignored   # the host's packages stay out of the context

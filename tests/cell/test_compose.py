"""docker-compose.yml: Debian's docker-compose validates it (nothing is built: no Docker
engine here), and its services run without Docker, from the file's own commands, health
checks and environment (compose_run.py): every health check passes, an operator moves each
arm over TLS with a token, a CRCL client drives the first arm through the gateway, and the
web supervisor serves its page, reaches both arms over TLS with its own token, and a person
signed in to it with an operator's token takes a lock; with the bridges profile, every
service's /metrics answers a scrape (the devices' over HTTPS), Foxglove advertises both arms,
and an OPC UA client with the cell's client certificate browses both arms' axes."""
from __future__ import annotations

import asyncio
import os
import shutil
import ssl
import subprocess
import urllib.request

import pytest
import yaml

from cell_support import make_keys, move_as_operator, through_the_supervisor
from compose_run import COMPOSE_FILE, DOCKERFILE, ComposeRun
from crcl_support import RawClient, command, field
from foxglove_client import FoxgloveClient

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
    assert sorted(services) == ["arm1", "arm2", "foxglove", "gateway", "opcua", "supervisor"]
    plain = yaml.safe_load(subprocess.run([exe, "-f", str(COMPOSE_FILE), "config"], env=env,
                                          capture_output=True, text=True, timeout=120).stdout)
    for bridge in ("foxglove", "opcua"):   # `up` leaves them out unless --profile bridges
        assert plain["services"][bridge]["profiles"] == ["bridges"]
    volumes = subprocess.run([exe, "-f", str(COMPOSE_FILE), "config", "--volumes"], env=env,
                             capture_output=True, text=True, timeout=120).stdout.split()
    assert sorted(volumes) == sorted(f"{arm}-{kind}" for arm in ARMS
                                     for kind in ("store", "recordings", "audit"))


def test_the_compose_services_run_without_docker_and_each_arm_moves(tmp_path):
    keys = make_keys(tmp_path / "keys", opcua=True)
    run = ComposeRun(tmp_path, {"LANDSCAPE_CERTS": str(keys.certs.ca.parent),
                                "LANDSCAPE_TOKENS": str(keys.tokens)})
    wanted = ["arm1", "arm2", "gateway", "supervisor", "foxglove", "opcua"]
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
        check_metrics(run, keys)
        check_bridges(run, keys)
    finally:
        codes = run.down()
    assert codes == {name: 0 for name in wanted}, codes
    volumes = tmp_path / "volumes"
    for arm in ARMS:
        assert (volumes / f"{arm}-store" / "paths.sqlite3").is_file()
        audit = (volumes / f"{arm}-audit" / "audit.log").read_text()
        assert '"DeviceService/MoveAbsolute"' in audit and '"who": "operator"' in audit


def check_metrics(run: ComposeRun, keys) -> None:
    """Each service's /metrics, as the file publishes it: the devices' over HTTPS (their
    certificate, verified with the cell's CA), the front ends' in plain HTTP."""
    tls = ssl.create_default_context(cafile=str(keys.certs.ca))
    for name, scheme, figure in (("arm1", "https", "landscape_device_state"),
                                 ("arm2", "https", "landscape_device_state"),
                                 ("gateway", "http", "landscape_crcl_connections"),
                                 ("supervisor", "http", "process_resident_memory_bytes")):
        url = f"{scheme}://{run.target(name, 9464)}/metrics"
        text = urllib.request.urlopen(url, timeout=10,
                                      context=tls if scheme == "https" else None).read().decode()
        assert figure in text, f"{name}: {figure} not in its scrape"


def check_bridges(run: ComposeRun, keys) -> None:
    """Foxglove advertises both arms; OPC UA lets the cell's client certificate in, signed
    and encrypted, and shows both arms."""
    fox = FoxgloveClient(int(run.target("foxglove", 8765).rsplit(":", 1)[1]))
    try:
        fox.channel("/arm1/joint_states"), fox.channel("/arm2/joint_states")
    finally:
        fox.close()
    from asyncua import Client

    cert, key = keys.certs.opcua_client

    async def browse() -> list[str]:
        client = Client(f"opc.tcp://{run.target('opcua', 4840)}")
        await client.set_security_string(f"Basic256Sha256,SignAndEncrypt,{cert},{key}")
        async with client:
            children = await client.nodes.objects.get_children()
            return [(await node.read_browse_name()).Name for node in children]
    names = asyncio.run(browse())
    assert "DeviceSet" in names, names   # OPC 40010's motion devices, there to be browsed


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

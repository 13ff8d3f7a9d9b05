"""grpcurl, a client in another language, against the device server started as users start it."""
from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from support import ROOT, installed, spawned_server


@pytest.fixture(scope="module")
def grpcurl() -> Path:
    # The Makefile pins the version and builds it (with Go); `make test` does that first.
    return installed(ROOT / ".tools" / "bin" / "grpcurl", "tools", "grpcurl")


@pytest.fixture(scope="module")
def target(tmp_path_factory):
    with spawned_server("--paths", str(tmp_path_factory.mktemp("var") / "paths.sqlite3")) as t:
        yield t


def run(grpcurl, *args) -> str:
    done = subprocess.run([str(grpcurl), "-plaintext", *args], capture_output=True, text=True,
                          timeout=30)
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_list_shows_the_services_health_and_reflection(grpcurl, target):
    listed = set(run(grpcurl, target, "list").split())
    assert {"landscape.v1.DeviceService", "landscape.v1.DigitalIOService",
            "landscape.v1.EventService", "landscape.v1.SessionService",
            "grpc.health.v1.Health", "grpc.reflection.v1alpha.ServerReflection"} <= listed


def test_describe_a_method(grpcurl, target):
    out = run(grpcurl, target, "describe", "landscape.v1.DeviceService.PathLoad")
    assert "rpc PathLoad ( stream .landscape.v1.PathLoadRequest )" in out


def test_health_check(grpcurl, target):
    out = run(grpcurl, target, "grpc.health.v1.Health/Check")
    assert json.loads(out) == {"status": "SERVING"}

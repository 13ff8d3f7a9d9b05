"""Issue 9: `make run` and `make test` open with no setuptools warnings. The build backend
(setuptools, as pip runs it) builds a wheel and an editable wheel from a copy of the
repository's sources warning of nothing but the one notice every editable install of this
layout gets (the Makefile filters that one), and the wheel holds the package data."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# Not sources: environments, caches, what builds make, what other tests leave.
NOT_SOURCES = {".git", ".venv", ".tools", "node_modules", "gen", "build", "var", "__pycache__",
               ".hypothesis", ".pytest_cache", "tests", "bench"}
BUILD = """
import json, sys, warnings
from setuptools import build_meta
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    wheel = build_meta.build_wheel(sys.argv[1])
    build_meta.build_editable(sys.argv[1])
print(json.dumps({"wheel": wheel, "warnings": [
    f"{w.category.__name__}: {w.message}" for w in caught
    if not str(w.message).startswith("Editable installation")]}))
"""


def test_the_build_warns_of_nothing_and_packages_the_data(tmp_path):
    source = tmp_path / "src"
    shutil.copytree(ROOT, source, ignore=lambda _, names: [
        n for n in names if n in NOT_SOURCES or n.endswith(".egg-info")])
    out = tmp_path / "out"
    done = subprocess.run([sys.executable, "-c", BUILD, str(out)], cwd=source,
                          capture_output=True, text=True, timeout=240)
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout.strip().splitlines()[-1])
    assert result["warnings"] == [], "\n\n".join(result["warnings"])
    names = set(zipfile.ZipFile(out / result["wheel"]).namelist())
    for folder in ("sim/cells", "cell/cells"):
        for toml in (ROOT / folder).glob("*.toml"):
            assert f"landscape/{folder}/{toml.name}" in names
    if (ROOT / "supervisor_gui_web/frontend/dist/index.html").is_file():
        assert "landscape/supervisor/frontend/dist/index.html" in names

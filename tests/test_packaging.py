"""Issue 9, a newcomer's install: `make run` and `make test` open with no setuptools warnings.
The build backend (setuptools, as pip runs it) builds a wheel and an editable wheel from a copy
of the repository's sources warning of nothing but the one notice every editable install of
this layout gets (the Makefile filters that one), and the wheel holds the package data.
Without npm, the page's build is skipped with one line saying so, not an error."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

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
    for folder in ("robot/cells", "cell/cells"):
        for toml in (ROOT / folder).glob("*.toml"):
            assert f"landscape/{folder}/{toml.name}" in names
    if (ROOT / "supervisor_gui_web/frontend/dist/index.html").is_file():
        assert "landscape/supervisor/frontend/dist/index.html" in names


def test_without_npm_the_page_is_skipped_in_one_line_and_make_goes_on(tmp_path):
    make = shutil.which("make")
    if make is None:
        pytest.skip("no make on this machine")
    page = "supervisor_gui_web/frontend/dist/index.html"
    # -B: as on a fresh clone, whatever is built here; an empty PATH: no npm (nor anything).
    done = subprocess.run([make, "-s", "-B", page], cwd=ROOT, capture_output=True, text=True,
                          env={"PATH": str(tmp_path), "HOME": str(tmp_path)}, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == [
        "make: no npm on this machine, so the web supervisor's page is not built and the cell "
        "runs without it (install Node.js and npm, then make install)"], done.stdout
    assert done.stderr == ""


def test_the_cell_says_why_the_web_supervisor_does_not_start_without_its_page(tmp_path):
    from landscape.cell.services import supervisor_missing
    why = supervisor_missing(page=tmp_path / "index.html")
    assert why.startswith("its page is not built") and "npm" in why, why
    (tmp_path / "index.html").write_text("<html></html>")
    assert supervisor_missing(page=tmp_path / "index.html") is None

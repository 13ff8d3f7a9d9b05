"""The fuzz targets in the test suite: every input of their corpora (seeds, and the inputs that
once crashed them) replayed, then a few seconds of coverage-guided fuzzing each, starting from
the corpus (what they find goes to a temporary folder, not into the repository)."""
from __future__ import annotations

import importlib
import os
import subprocess
import sys
from pathlib import Path

import pytest

atheris = pytest.importorskip("atheris", reason="atheris (the fuzzer) is not installed here")

HERE = Path(__file__).resolve().parent
TARGETS = ["crcl", "pathfile"]
SECONDS = 5


def _corpus(target: str) -> list[Path]:
    return sorted((HERE / "corpus" / target).iterdir())


@pytest.mark.parametrize("target", TARGETS)
def test_every_corpus_input_runs_clean(target):
    sys.path.insert(0, str(HERE))
    try:
        fuzz = importlib.import_module(f"fuzz_{target}")
    finally:
        sys.path.remove(str(HERE))
    inputs = _corpus(target)
    assert len(inputs) >= 4
    for path in inputs:
        fuzz.test_one_input(path.read_bytes())


@pytest.mark.parametrize("target", TARGETS)
def test_a_short_fuzzing_run_finds_nothing(target, tmp_path):
    found = tmp_path / "found"
    found.mkdir()
    run = subprocess.run(
        [sys.executable, str(HERE / f"fuzz_{target}.py"), str(found), str(HERE / "corpus" / target),
         f"-max_total_time={SECONDS}", "-rss_limit_mb=2048", "-timeout=10",
         f"-artifact_prefix={tmp_path}/"],
        capture_output=True, text=True, timeout=SECONDS + 120,
        env={**os.environ, "TMPDIR": str(tmp_path)})   # libFuzzer's exit skips clean-ups
    crashes = sorted(p.name for p in tmp_path.glob("crash-*"))
    assert run.returncode == 0 and not crashes, (crashes, run.stderr[-3000:])
    assert "DONE" in run.stderr

"""A coverage-guided fuzz target (atheris, libFuzzer) for the path-file reader
(landscape.client.pathfile.read_path): whatever a .json or .csv file holds, the outcome is a
PathFile or a PathFileError naming the file, never another exception.

    python tests/fuzz/fuzz_pathfile.py NEW_INPUTS_DIR tests/fuzz/corpus/pathfile -max_total_time=60

The first byte of an input picks the suffix (even: .json, odd: .csv); the rest is the file.
"""
from __future__ import annotations

import atexit
import shutil
import sys
import tempfile
from pathlib import Path

import atheris

# Coverage of the reader and the values it makes, not of the client package's gRPC side that
# importing it brings in (instrumenting all of that took 7 of a 12 s test).
with atheris.instrument_imports(include=["landscape.client.pathfile",
                                         "landscape.client.values"]):
    from landscape.client.pathfile import PathFileError, read_path

_FOLDER = Path(tempfile.mkdtemp(prefix="fuzz-pathfile-"))
atexit.register(shutil.rmtree, _FOLDER, True)
_FILES = {0: _FOLDER / "path.json", 1: _FOLDER / "path.csv"}


def test_one_input(data: bytes) -> None:
    if not data:
        return
    path = _FILES[data[0] % 2]
    path.write_bytes(data[1:])
    try:
        read_path(path)
    except PathFileError:
        pass


if __name__ == "__main__":
    atheris.Setup(sys.argv, test_one_input)
    atheris.Fuzz()

"""Issue 26: the packages follow the process lines, and their rules hold (docs/architecture.md).

- The import rules, as import-linter contracts in pyproject.toml: the robot imports neither the
  server nor the simulator; the simulator is reached only through the backend registry; what
  runs in the cycle process imports nothing of the gRPC surface, nor grpc; nothing imports a
  servicer but the server's assembly. Indirect imports count.
- No module reads or writes another's private names (ruff's SLF001), outside the tests.
- Every package says, in its docstring, what it owns and what it may import.
"""
from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# Being reshaped on other branches of issue 26 (the client core; the supervisor's page): their
# private reach-throughs are theirs to remove; checked here once those branches are merged.
CHECKED = ("server", "robot", "sim", "cell", "gateway", "client", "supervisor_gui_web", "bench",
           "examples", "bridges", "setup.py")


def test_the_import_rules_hold():
    lint = "from importlinter.cli import lint_imports_command; lint_imports_command()"
    done = subprocess.run([sys.executable, "-c", lint, "--no-cache"], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "0 broken" in done.stdout, done.stdout


def test_no_module_touches_another_s_private_names():
    done = subprocess.run([sys.executable, "-m", "ruff", "check", "--select", "SLF001",
                           "--no-cache", "--output-format", "concise", *CHECKED], cwd=ROOT,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr


def test_every_package_says_what_it_owns_and_may_import():
    silent = []
    for top in ("server", "robot", "sim", "bridges"):
        for init in sorted((ROOT / top).rglob("__init__.py")):
            doc = ast.get_docstring(ast.parse(init.read_text())) or ""
            if "Owns" not in doc or "May import" not in doc:
                silent.append(str(init.relative_to(ROOT)))
    assert not silent, f"packages not saying what they own and may import: {silent}"

"""Role tokens for a cell (`landscape-cell tokens`): one file per role in the format the
device server reads (server/auth.py: `<token> <name>` a line), each with one fresh token.

The same file serves a client: `--token-file var/tokens/operator.tokens` presents its first
token. For a real cell give each client its own named line (`<token> crcl-gateway`), so the
audit log tells them apart.
"""
from __future__ import annotations

import os
import secrets
from pathlib import Path

ROLES = ("viewer", "operator", "admin")


def make_tokens(folder: str | Path, force: bool = False) -> dict[str, Path]:
    """Writes `<role>.tokens` (mode 0600) for each role that has none (all of them with
    `force`); returns every role's file."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    files = {}
    for role in ROLES:
        path = files[role] = folder / f"{role}.tokens"
        if path.exists() and not force:
            continue
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(fd, "w") as out:
            out.write(f"# LandScape {role} tokens: '<token> <name>' a line\n"
                      f"{secrets.token_urlsafe(32)} {role}\n")
    return files

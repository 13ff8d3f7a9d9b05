"""The cell tests' helpers are modules beside them (and the CRCL client of the gateway
tests, for a command through the gateway, and the Foxglove client of the bridge tests)."""
from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).parent
for folder in (HERE, HERE.parent / "gateway", HERE.parent / "bridges"):
    if str(folder) not in sys.path:
        sys.path.insert(0, str(folder))

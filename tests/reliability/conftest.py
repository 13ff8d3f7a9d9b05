"""The reliability suite (issue 17): stops that stop, faults survived, load carried."""
from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))

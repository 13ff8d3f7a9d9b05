"""The bridges' tests import their helpers (bridge_support.py, foxglove_client.py) from here."""
from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))

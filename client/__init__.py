"""Python client helpers for a LandScape device server."""
from landscape.client.session import Session

__all__ = ["Session"]

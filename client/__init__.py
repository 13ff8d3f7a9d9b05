"""Python client helpers for a LandScape device server."""
from landscape.client.aio_session import AsyncSession
from landscape.client.session import Session

__all__ = ["AsyncSession", "Session"]

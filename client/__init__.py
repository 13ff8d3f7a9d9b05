"""Python client helpers for a LandScape device server."""
from landscape.client.aio_session import AsyncSession
from landscape.client.credentials import ClientTLS, open_aio_channel, open_channel, read_token
from landscape.client.session import Session

__all__ = ["AsyncSession", "ClientTLS", "Session", "open_aio_channel", "open_channel",
           "read_token"]

"""The page's session with a device: landscape.client.AsyncSession, with one repair.

TEMPORARY: AsyncSession.open() reads the first message with call.read() and its reader task
then iterates the same call, which grpc.aio refuses ("The iterator and read/write APIs may not
be mixed on a single RPC", UsageError): the reader dies at once, `ended` is set while the
session lives on, and no RSVP question is ever heard. This subclass reads with read()
throughout. Remove it once client/aio_session.py does the same.
"""
from __future__ import annotations

import asyncio

import grpc

from landscape.client import AsyncSession


class PageSession(AsyncSession):
    async def _read(self) -> None:
        try:
            while (message := await self._call.read()) is not grpc.aio.EOF:
                if message.WhichOneof("message") == "rsvp_request":
                    await self._answer(message.rsvp_request)
        except grpc.aio.AioRpcError as error:
            self.end_status = error.code()
        except asyncio.CancelledError:
            pass
        finally:
            self.ended.set()

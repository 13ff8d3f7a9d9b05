"""The CRCL TCP server (asyncio): one CrclSession per connection, documents in, status out.

Each connection reads into its own DocumentSplitter; a document is handled before the next is
read, and GetStatus answers are written in order. A connection whose stream is no CRCL (bytes
outside a document: an HTTP request a browser was made to send) or cannot be resynchronised
(a DOCTYPE, a single token past the size bound) is closed, with one log line naming the peer
(a DOCTYPE is answered with a CRCL_Error status first); so is one whose document stops short
for `document_idle` seconds. Everything else a client gets wrong is a CRCL_Error status on the
connection, which stays open. One client's trouble never touches another's connection. A
gateway that stops (SIGTERM) ends every connection as if its client had left, then exits.
"""
from __future__ import annotations

import asyncio
import logging
from dataclasses import dataclass, field

from landscape.gateway.device import CrclDevice
from landscape.gateway.session import CrclSession, GatewayOptions
from landscape.gateway.wire import (DeclarationRefused, Document, DocumentSplitter,
                                    WireError)

log = logging.getLogger(__name__)

DEFAULT_PORT = 64444
READ_SIZE = 64 * 1024


@dataclass
class Gateway:
    device: CrclDevice
    options: GatewayOptions
    server: asyncio.base_events.Server | None = None
    connections: set = field(default_factory=set)    # their tasks, until they have ended
    reading: set = field(default_factory=set)        # those not ending yet

    @property
    def port(self) -> int:
        return self.server.sockets[0].getsockname()[1]

    async def serve(self, host: str = "127.0.0.1", port: int = DEFAULT_PORT) -> "Gateway":
        self.server = await asyncio.start_server(self._connection, host, port,
                                                 limit=READ_SIZE)
        log.info("CRCL gateway listening on %s:%d (device %s)", host, self.port, self.device.target)
        return self

    async def close(self) -> None:
        """No new connections; each open one ends as if its client had left (its session
        closes: the device stops the arm and frees the lock), its socket closed in order."""
        if self.server is not None:
            self.server.close()
            for task in list(self.reading):   # one ending already finishes in its own time
                task.cancel()
            await asyncio.gather(*self.connections, return_exceptions=True)
            await self.server.wait_closed()

    async def _connection(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter):
        peer = writer.get_extra_info("peername")
        session = CrclSession(self.device, self.options, f"{peer[0]}:{peer[1]}" if peer else "")
        splitter = DocumentSplitter(self.options.max_document)
        log.debug("%s connected", session.name)
        self.connections.add(asyncio.current_task())
        self.reading.add(asyncio.current_task())
        closing = ""                      # why the gateway ends the connection, if it does
        try:
            while data := await self._read(reader, splitter):
                for item in splitter.feed(data):
                    if isinstance(item, Document):
                        reply = await session.receive(item.data)
                        if reply is not None:
                            writer.write(reply)
                    else:
                        await session.refuse(f"byte {item.offset}: {item.reason}")
                await writer.drain()
        except DeclarationRefused as error:
            closing = str(error)
            session.fail(closing)
            writer.write(session.status())
        except WireError as error:
            closing = str(error)
        except TimeoutError:
            closing = (f"a document stopped short: no byte for {self.options.document_idle:g} s "
                       f"({splitter.pending} bytes held)")
        except (ConnectionError, asyncio.IncompleteReadError):
            pass
        except asyncio.CancelledError:
            pass                          # the gateway is closing (close()): end in order
        finally:
            self.reading.discard(asyncio.current_task())
            if closing:                   # the one line this connection gets
                log.warning("%s: closing: %s", session.name, closing)
            else:
                log.info("%s disconnected", session.name)
            try:
                await self._end(session, writer)
            finally:
                self.connections.discard(asyncio.current_task())

    @staticmethod
    async def _end(session: CrclSession, writer: asyncio.StreamWriter) -> None:
        """The connection's session ends (the device stops the arm and frees the lock), then
        its socket closes in order."""
        await session.close()
        writer.close()
        try:
            await writer.wait_closed()
        except ConnectionError:
            pass

    async def _read(self, reader: asyncio.StreamReader, splitter: DocumentSplitter) -> bytes:
        """The next bytes; TimeoutError if a started document gets none for document_idle s
        (between documents a client may be silent as long as it likes)."""
        if not splitter.pending:
            return await reader.read(READ_SIZE)
        async with asyncio.timeout(self.options.document_idle):
            return await reader.read(READ_SIZE)

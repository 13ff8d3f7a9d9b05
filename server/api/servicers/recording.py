"""RecordingService: the controller recorder's stored MCAP file, streamed in chunks.

The file is opened once per call, so a store that replaces it meanwhile (the recorder writes
a new file and renames it over the old) leaves this transfer whole. Reads run on the guard's
read pool a chunk at a time: the event loop never waits on the disk.
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path

from landscape.server.api import services
from landscape.server.api.guard import guarded
from landscape.server.errors import OutOfRange, WrongState
from landscape.v1 import recording_service_pb2 as pb

CHUNK = 64 * 1024
MEDIA_TYPE = "application/x-mcap"


class NoRecording(WrongState):
    reason = "NO_RECORDING"


@guarded(services.RECORDINGS)
class RecordingServicer(services.RECORDINGS.servicer_base):
    def __init__(self, device, path: str, dispatch, limits):
        """path: the recorder's file (the cell file's [recorder] path, from the server's
        working directory)."""
        self.device, self.path, self.dispatch, self.limits = device, Path(path), dispatch, limits

    async def FetchRecording(self, request, context):
        try:
            stream = self.path.open("rb")
        except FileNotFoundError:
            raise NoRecording(f"no recording is stored at {self.path.name} yet: SendCommand "
                              f"\"recorder store\" writes one") from None
        with stream:
            size = os.fstat(stream.fileno()).st_size
            if request.offset > size:
                raise OutOfRange(f"offset {request.offset} is past the end of the recording "
                                 f"({size} bytes)")
            digest = hashlib.sha256()
            position = 0
            while True:
                data = await self.dispatch.run(self.dispatch.reads, stream.read, CHUNK)
                digest.update(data)
                start, position = position, position + len(data)
                last = position >= size or not data
                if position > request.offset or last:
                    part = data[max(0, request.offset - start):]
                    yield pb.FetchRecordingResponse(
                        name=self.path.name, size=size, offset=max(start, request.offset),
                        data=part, sha256=digest.hexdigest() if last else "",
                        media_type=MEDIA_TYPE)
                if last:
                    return

"""Telemetry logs: every MAVLink frame a process sends or receives, with its wall time.

In:  raw MAVLink frames (bytes), as an endpoint sends or receives them; a path
Out: a ``.tlog`` file: per frame an 8-byte big-endian Unix time in us, then the raw frame (what
     pymavlink's ``mavlogdump.py`` reads), written in batches of ``batch_bytes``
"""

from __future__ import annotations

import os
import struct
import time
from pathlib import Path

_STAMP = struct.Struct(">Q")


class Tlog:
    """A telemetry log: records of an 8-byte big-endian timestamp (microseconds since the
    Unix epoch) followed by one raw MAVLink frame, in both directions, as pymavlink's
    ``mavlogdump.py`` reads them.

    Records are buffered and written whole, many per ``os.write``: a process killed
    with SIGKILL leaves the file readable up to its last flush. Call :meth:`flush`
    from the housekeeping of a loop (it is cheap when there is nothing to write).
    """

    def __init__(self, path: str | Path, batch_bytes: int = 1 << 16) -> None:
        self.path = Path(path)
        self._fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_APPEND, 0o644)
        self._buf: list[bytes] = []
        self._size = 0
        self._batch = batch_bytes
        self.records = 0

    def record(self, frame: bytes, stamp_us: int | None = None) -> None:
        """Log ``frame`` stamped ``stamp_us`` (us since the epoch; None: now)."""
        self._buf.append(_STAMP.pack(time.time_ns() // 1000 if stamp_us is None else stamp_us))
        self._buf.append(frame)
        self._size += 8 + len(frame)
        self.records += 1
        if self._size >= self._batch:
            self.flush()

    def flush(self) -> None:
        if self._buf and self._fd >= 0:
            os.write(self._fd, b"".join(self._buf))
            self._buf.clear()
            self._size = 0

    def close(self) -> None:
        if self._fd >= 0:
            self.flush()
            os.close(self._fd)
            self._fd = -1

"""A SITL side's half of the trace as binary records: ``vehicle.bin`` and ``controller.bin``.

In:  rows of floats (ints allowed: a step number is stored as its float) in the order of a file's columns
Out: the file: one JSON header line, ``{"format": "bsst-half", "version": 1, "columns": [...], "dtype": "<f8"}``,
     then one record per row, ``len(columns)`` little-endian float64 values each (units: those of
     :mod:`bridge.record.columns`); read back as named rows while the file grows (:class:`HalfReader`: whole
     records only, so a record being written is read next time) or as numpy arrays by column (:func:`read_half`)

Why binary: each side wrote its half as CSV text, and the session parsed it back to join ``trace.csv`` while the
flight ran; in lockstep that text (``repr`` of 45 floats a vehicle row, their parsing in the session) cost more CPU
than the step's own work and competed with the flight for the two cores (docs/figures.md). A record is packed
in one C call and read in one, and a float64 keeps every value to the bit, as ``repr`` did.
"""

from __future__ import annotations

import json
import os
import struct
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from bridge.record.columns import column_index
from bridge.record.runlog import LineWriter

FORMAT, VERSION, DTYPE = "bsst-half", 1, "<f8"
_MAX_HEADER = 1 << 16  # bytes: a header line longer than this is not ours


def header_line(columns: Sequence[str]) -> bytes:
    """The file's first line: its format, version, columns and value type, as one JSON object."""
    return (json.dumps({"format": FORMAT, "version": VERSION, "columns": list(columns), "dtype": DTYPE})
            + "\n").encode()


def parse_header(line: bytes, where: str) -> tuple[str, ...]:
    """The columns of a header line (without its newline); ValueError naming ``where`` and what is wrong."""
    try:
        head = json.loads(line)
    except ValueError:
        raise ValueError(f"{where}: its first line is not a JSON header (not a {FORMAT} file)") from None
    if not isinstance(head, dict) or head.get("format") != FORMAT:
        raise ValueError(f"{where}: its header does not say format {FORMAT!r}")
    if head.get("version") != VERSION or head.get("dtype") != DTYPE:
        raise ValueError(f"{where}: {FORMAT} version {head.get('version')!r} with dtype {head.get('dtype')!r}; "
                         f"this bsst reads version {VERSION} with dtype {DTYPE!r}")
    columns = head.get("columns")
    if not isinstance(columns, list) or not columns or not all(isinstance(c, str) for c in columns):
        raise ValueError(f"{where}: its header's columns are not a list of names")
    return tuple(columns)


class HalfWriter(LineWriter):
    """Appends records to a half, in batches of ``batch`` records, one write each (``batch=1``: each at once):
    a :class:`LineWriter` whose pending lines are packed records."""

    def __init__(self, path: str | Path, columns: Sequence[str], batch: int = 100) -> None:
        super().__init__(path, header_line(columns).decode().rstrip("\n"), batch)
        self._pack = struct.Struct(f"<{len(columns)}d").pack

    def write(self, values: Sequence[float]) -> None:  # type: ignore[override]  # a record, not a line
        """One record: exactly one value per column (``struct.error`` otherwise: a writer's bug)."""
        self._pending.append(self._pack(*values))  # type: ignore[arg-type]  # bytes here
        if len(self._pending) >= self._batch:
            self.flush()

    def flush(self) -> None:
        if self._pending and self._fd >= 0:
            os.write(self._fd, b"".join(self._pending))  # type: ignore[arg-type]
            self._pending.clear()


class HalfReader:
    """Reads the whole new records of a half as rows of ``row_type`` (a namedtuple of the columns it needs), each
    value taken from its column of the file's own header (ValueError naming the file and a missing column)."""

    def __init__(self, path: Path, row_type: Any) -> None:
        self.path = path
        self.row_type = row_type
        self.columns: tuple[str, ...] | None = None  # the file's header, once read
        self._fd = -1
        self._buf = b""
        self._unpack: Any = None
        self._size = 0  # bytes a record
        self._head = 0  # bytes of the header line
        self._read_past_head = False  # read() has passed the header (last() may have parsed it first)
        self._pick: list[int] | None = None  # the header's positions of row_type's fields (None: the same order)

    def _open(self) -> bool:
        if self._fd < 0:
            try:
                self._fd = os.open(self.path, os.O_RDONLY)
            except FileNotFoundError:
                return False
        return True

    def _header_end(self, buf: bytes) -> int:
        """Where the header line in ``buf`` (the file's first bytes) ends, -1 if not yet whole."""
        end = buf.find(b"\n")
        if end < 0 and len(buf) > _MAX_HEADER:
            raise ValueError(f"{self.path}: no header line in its first {_MAX_HEADER} bytes")
        if end >= 0 and self.columns is None:
            self._start(parse_header(buf[:end], str(self.path)))
            self._head = end + 1
        return end

    def read(self) -> list[Any]:
        if not self._open():
            return []
        chunks = [self._buf]
        while data := os.read(self._fd, 1 << 20):
            chunks.append(data)
        buf = b"".join(chunks)
        if not self._read_past_head:
            end = self._header_end(buf)
            if end < 0:
                self._buf = buf
                return []
            self._read_past_head = True
            buf = buf[end + 1:]
        whole = len(buf) - len(buf) % self._size
        self._buf = buf[whole:]
        if not whole:
            return []
        return [self._row(v) for v in self._unpack(buf[:whole])]

    def last(self) -> Any | None:
        """The newest whole record in the file now, as a row, without moving :meth:`read` on (None: no header
        yet, or no record): a look at a flight in progress, one ``pread`` (two while the header is not read)."""
        if self.columns is None and (not self._open() or self._header_end(os.pread(self._fd, _MAX_HEADER + 1, 0)) < 0):
            return None
        n = (os.fstat(self._fd).st_size - self._head) // self._size
        if n <= 0:
            return None
        return self._row(struct.unpack(f"<{len(self.columns)}d",
                                       os.pread(self._fd, self._size, self._head + (n - 1) * self._size)))

    def _row(self, values: tuple[float, ...]) -> Any:
        pick = self._pick
        return tuple.__new__(self.row_type, values if pick is None else [values[i] for i in pick])

    def _start(self, columns: tuple[str, ...]) -> None:
        self.columns = columns
        record = struct.Struct(f"<{len(columns)}d")
        self._unpack, self._size = record.iter_unpack, record.size
        fields = self.row_type._fields
        if columns != fields:
            where = column_index(columns, fields, str(self.path))
            self._pick = [where[n] for n in fields]

    def close(self) -> None:
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1


def read_half(path: str | Path) -> dict[str, Any]:
    """A whole half as numpy arrays by column name (:func:`half_arrays`)."""
    return half_arrays(Path(path).read_bytes(), str(path))


def half_arrays(data: bytes, where: str) -> dict[str, Any]:
    """A half's bytes as numpy arrays by column name (a record cut short at the end, as by a killed writer, is
    left out); ValueError naming ``where`` if they are not a half."""
    import numpy as np  # lazy: the nodes write records and never need numpy

    end = data.find(b"\n")
    if end < 0:
        raise ValueError(f"{where}: no header line (not a {FORMAT} file)")
    columns = parse_header(data[:end], where)
    body = data[end + 1:]
    n = len(body) // (8 * len(columns))
    arr = np.frombuffer(body, dtype=DTYPE, count=n * len(columns)).reshape(n, len(columns))
    return {name: arr[:, i] for i, name in enumerate(columns)}


def count_records(path: str | Path) -> int:
    """Whole records a half holds so far (0 if it does not exist yet or has no header line yet)."""
    try:
        with open(path, "rb") as f:
            head = f.readline(_MAX_HEADER)
            size = os.fstat(f.fileno()).st_size
    except FileNotFoundError:
        return 0
    if not head.endswith(b"\n"):
        return 0
    return (size - len(head)) // (8 * len(parse_header(head[:-1], str(path))))


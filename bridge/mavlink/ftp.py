"""MAVLink FTP, read-only: the FILE_TRANSFER_PROTOCOL payload's codec and a server of a fixed set of files. Pure:
payload bytes in, payload bytes out; no sockets, no file system (the files are bytes held in memory).

In:  a request's payload (251 bytes: seq u16, session, opcode, size, req_opcode, burst_complete, padding, offset u32,
     then up to 239 bytes of data), who sent it (any hashable: the node passes the sender's address), the files
     served (path -> bytes, paths without a leading ``/``)
Out: the reply payloads, in order (one ACK or NAK; a BurstReadFile's data messages and, at the file's end, its EOF
     NAK); [] for a reply (opcode >= 128) or a payload too short to hold a header

As the MAVLink FTP spec (mavlink-devguide, en/services/ftp.md) and PX4's server (PX4-Autopilot
src/modules/mavlink/mavlink_ftp.cpp) have it: a reply's seq is the request's + 1 and a burst's messages count on from
there; a request sent again (its seq + 1 is the seq of the last reply to its sender, for the same opcode and session:
MAVProxy numbers each session's requests from 0) gets that reply again, unchanged; OpenFileRO's ACK carries the file's
size (4 bytes), ReadFile up to ``size`` bytes at ``offset``, a read at or past the end NAKs EOF; BurstReadFile streams
:data:`BURST_MESSAGES` messages of its ``size`` bytes each (239 at most), the last with ``burst_complete`` 1, or the
file's rest and an EOF NAK (PX4 sends the file to its end and then that NAK, a burst of at most 35 000 bytes);
ListDirectory lists the entries from index ``offset`` (``F<name>\\t<size>`` and ``D<name>``, each NUL-ended) and NAKs
EOF past the last. Ours: a session takes the id the client gave (PX4 has one session, 0, which QGroundControl sends;
MAVProxy gives each operation its own id and routes the replies by it), per sender, at most :data:`MAX_SESSIONS` (the
least recently used is closed for a new one). Writing, removing, renaming and every other opcode NAK UnknownCommand:
nothing here can be changed.
"""

from __future__ import annotations

import struct
from collections.abc import Hashable, Mapping
from dataclasses import dataclass

HEADER = struct.Struct("<HBBBBBBI")
PAYLOAD_LEN = 251  # FILE_TRANSFER_PROTOCOL's payload
DATA_LEN = PAYLOAD_LEN - HEADER.size  # 239
MAX_SESSIONS = 8
MAX_SENDERS = 64  # senders whose last replies are kept (a request sent again); the oldest forgotten first
BURST_MESSAGES = 4  # data messages in one burst: one datagram of about 1.1 kB, under an Ethernet MTU

# opcodes (MAV_FTP_OPCODE)
NONE, TERMINATE_SESSION, RESET_SESSIONS, LIST_DIRECTORY, OPEN_FILE_RO, READ_FILE = 0, 1, 2, 3, 4, 5
BURST_READ_FILE = 15
ACK, NAK = 128, 129
# errors (MAV_FTP_ERR)
ERR_INVALID_DATA_SIZE, ERR_INVALID_SESSION, ERR_EOF, ERR_UNKNOWN_COMMAND, ERR_FILE_NOT_FOUND = 3, 4, 6, 7, 10


@dataclass(frozen=True)
class Op:
    """One FTP payload, decoded: the header's fields and its ``data`` (``size`` bytes of it)."""

    seq: int
    session: int
    opcode: int
    size: int  # the header's size: the data's length, or for a read the bytes asked for
    req_opcode: int
    burst_complete: int
    offset: int
    data: bytes

    def encode(self) -> bytes:
        """The 251-byte payload (data zero-padded)."""
        head = HEADER.pack(self.seq & 0xFFFF, self.session, self.opcode, self.size, self.req_opcode,
                           self.burst_complete, 0, self.offset)
        return (head + self.data).ljust(PAYLOAD_LEN, b"\x00")

    @property
    def text(self) -> str:
        """The data as a path: up to its first NUL, ASCII (a byte beyond it replaced: no such file)."""
        return self.data.split(b"\x00", 1)[0].decode("ascii", errors="replace")


def decode(payload: bytes) -> Op | None:
    """An FTP payload's :class:`Op`; None when too short for a header. Its data is at most ``size`` bytes (fewer
    when the payload ends first; :meth:`FtpServer.handle` NAKs a ``size`` over :data:`DATA_LEN`)."""
    if len(payload) < HEADER.size:
        return None
    seq, session, opcode, size, req_opcode, burst, _, offset = HEADER.unpack_from(payload)
    return Op(seq, session, opcode, size, req_opcode, burst, offset, bytes(payload[HEADER.size:HEADER.size + size]))


def is_request(payload: bytes) -> bool:
    """Whether an FTP payload is a request the server answers (a header, an opcode below 128: not a reply)."""
    op = decode(payload)
    return op is not None and op.opcode < ACK


def reply(request: Op, opcode: int, data: bytes, seq: int, offset: int = 0, burst_complete: int = 0) -> Op:
    """A reply (ACK or NAK) to ``request`` carrying ``data``."""
    return Op(seq, request.session, opcode, len(data), request.opcode, burst_complete, offset, data)


def nak(request: Op, error: int, seq: int | None = None, offset: int = 0) -> Op:
    """A NAK of ``request`` with ``error`` (one byte of data; seq the request's + 1 unless given)."""
    return reply(request, NAK, bytes((error,)), request.seq + 1 if seq is None else seq, offset)


def ack(request: Op, data: bytes = b"", offset: int = 0) -> Op:
    """An ACK of ``request`` carrying ``data`` (seq the request's + 1)."""
    return reply(request, ACK, data, request.seq + 1, offset)


def _path(text: str) -> str:
    """A requested path as the files are keyed: no leading or trailing ``/`` (QGroundControl sends ``/etc/...``,
    the spec's examples ``etc/...``)."""
    return text.strip("/")


class FtpServer:
    """Serves ``files`` (path -> bytes) read-only to any number of senders."""

    def __init__(self, files: Mapping[str, bytes]) -> None:
        self.files = {_path(p): bytes(b) for p, b in files.items()}
        self.sessions: dict[tuple[Hashable, int], str] = {}  # (sender, session id) -> path; oldest use first
        self.last: dict[Hashable, list[Op]] = {}  # each sender's last replies (a request sent again: the same)

    def handle(self, payload: bytes, sender: Hashable) -> list[bytes]:
        """The reply payloads to one request ``payload`` from ``sender`` (the module docstring)."""
        op = decode(payload)
        if op is None or op.opcode >= ACK:
            return []
        last = self.last.get(sender)
        again = (op.opcode, op.session, (op.seq + 1) & 0xFFFF)
        if last and (last[0].req_opcode, last[0].session, last[0].seq) == again:
            return [r.encode() for r in last]  # its reply was lost: the same again (PX4's _last_reply)
        replies = self._answer(op, sender)
        self.last.pop(sender, None)
        if len(self.last) >= MAX_SENDERS:
            del self.last[next(iter(self.last))]
        self.last[sender] = replies
        return [r.encode() for r in replies]

    def _answer(self, op: Op, sender: Hashable) -> list[Op]:
        if op.size > DATA_LEN:
            return [nak(op, ERR_INVALID_DATA_SIZE)]
        if op.opcode == NONE:
            return [ack(op)]
        if op.opcode == OPEN_FILE_RO:
            return [self._open(op, sender)]
        if op.opcode in (READ_FILE, BURST_READ_FILE):
            key = (sender, op.session)
            path = self.sessions.get(key)
            if path is None:
                return [nak(op, ERR_INVALID_SESSION)]
            self.sessions[key] = self.sessions.pop(key)  # the most recently used now
            data = self.files[path]
            return [self._read(op, data)] if op.opcode == READ_FILE else self._burst(op, data)
        if op.opcode == TERMINATE_SESSION:
            return [ack(op) if self.sessions.pop((sender, op.session), None) is not None
                    else nak(op, ERR_INVALID_SESSION)]
        if op.opcode == RESET_SESSIONS:  # this sender's sessions: another ground station's go on
            for key in [k for k in self.sessions if k[0] == sender]:
                del self.sessions[key]
            return [ack(op)]
        if op.opcode == LIST_DIRECTORY:
            return [self._list(op)]
        return [nak(op, ERR_UNKNOWN_COMMAND)]

    def _open(self, op: Op, sender: Hashable) -> Op:
        path = _path(op.text)
        if path not in self.files:
            return nak(op, ERR_FILE_NOT_FOUND)
        key = (sender, op.session)
        self.sessions.pop(key, None)
        if len(self.sessions) >= MAX_SESSIONS:
            del self.sessions[next(iter(self.sessions))]
        self.sessions[key] = path
        return ack(op, struct.pack("<I", len(self.files[path])))

    def _read(self, op: Op, data: bytes) -> Op:
        if op.offset >= len(data):
            return nak(op, ERR_EOF)
        return ack(op, data[op.offset:op.offset + (op.size or DATA_LEN)], op.offset)

    def _burst(self, op: Op, data: bytes) -> list[Op]:
        size = op.size or DATA_LEN  # each message's bytes: the request's size (239 when 0)
        out: list[Op] = []
        offset, seq = op.offset, op.seq + 1
        while offset < len(data) and len(out) < BURST_MESSAGES:
            out.append(reply(op, ACK, data[offset:offset + size], seq, offset))
            offset += size
            seq += 1
        if offset >= len(data):  # the file's end: an EOF NAK after its last data (PX4's stream)
            out.append(nak(op, ERR_EOF, seq, len(data)))
        else:
            last = out[-1]
            out[-1] = reply(op, ACK, last.data, last.seq, last.offset, burst_complete=1)
        return out

    def _list(self, op: Op) -> Op:
        directory = _path(op.text)
        prefix = f"{directory}/" if directory else ""
        entries: dict[str, bytes] = {}
        for path, data in self.files.items():
            if not path.startswith(prefix):
                continue
            name, sep, _ = path[len(prefix):].partition("/")
            entries.setdefault(name, b"D" + name.encode() if sep else f"F{name}\t{len(data)}".encode())
        if not entries:
            return nak(op, ERR_FILE_NOT_FOUND)
        listed = list(entries.values())[op.offset:]
        if not listed:
            return nak(op, ERR_EOF)
        out = b""
        for entry in listed:
            if len(out) + len(entry) + 1 > DATA_LEN:
                break
            out += entry + b"\x00"
        return ack(op, out, op.offset)

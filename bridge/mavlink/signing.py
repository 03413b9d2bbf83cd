"""MAVLink 2 message signing (docs/design.md, "The MAVLink contract"): the key file, signing and verifying.

In:  a key file (exactly 32 bytes: the key; anything else: a passphrase, hashed with SHA-256), and
     MAVLink 2 frames to sign or to check with their sender's sysid and compid
Out: signed frames (a 13-byte block appended: link id, timestamp in 10 us units since 2015-01-01,
     48-bit signature); for a received frame None, or the reason it is refused (``unsigned``,
     ``bad_signature``, ``replayed``)

The MAVLink 2 signing scheme: a signed frame sets bit 0 of its incompatibility flags and
ends with a 13-byte block ``link_id (1) + timestamp (6, little-endian, units of 10 us since
2015-01-01 00:00 UTC) + signature (6)``, where the signature is the first 48 bits of
``sha256(secret_key + header + payload + CRC + link_id + timestamp)`` (the header with the
signed flag set, so the CRC covers it). A receiver keeps, per stream (sender sysid,
compid and link id), the newest timestamp it accepted and refuses anything not newer. The
specification keeps one such table per receiving system, whatever link a frame came in on:
the :class:`Signing` objects of one system's links share theirs (``streams``), so a frame
replayed from one link onto another is refused.

One implementation serves every frame of this project, hot path or not: :meth:`Signing.sign`
completes a frame whose header already has the flag (the hot codec builds it so),
:meth:`Signing.resign` signs a frame pymavlink packed unsigned, :meth:`Signing.verify`
checks one; tests/test_signing.py compares them byte for byte with pymavlink's own
``setup_signing``.

The key is read from a file only (:func:`key_from_file`), never from a command-line value,
and is never printed: :class:`Signing` does not show it in its ``repr``, and errors name the
file, not its content.
"""

from __future__ import annotations

import hashlib
import os
import stat
import struct
import time
from pathlib import Path

from pymavlink.dialects.v20 import common as mavlink

from params import ConfigError, note_input

try:  # pymavlink uses fastcrc when it is installed; so do the hot codec and the signer
    from fastcrc.crc16 import mcrf4xx as crc16
except ImportError:  # pragma: no cover - pure Python fallback
    from pymavlink.generator.mavcrc import x25crc

    def crc16(data: bytes, initial: int = 0xFFFF) -> int:
        """MAVLink's CRC-16/MCRF4XX (X.25) of ``data``."""
        return x25crc(data).crc

KEY_BYTES = 32
IFLAG_SIGNED = 0x01
SIGNATURE_BYTES = 13  # link id, 6-byte timestamp, 6-byte signature
EPOCH_2015 = 1420070400  # s: the signing clock counts from 2015-01-01 00:00 UTC
NEW_STREAM_SLACK = 6_000_000  # 10 us units (60 s): how far behind our clock a new stream may start
_LINK_TS = struct.Struct("<BQ")
_sha256 = hashlib.sha256


def key_from_file(path: str | os.PathLike[str], flag: str = "--key") -> bytes:
    """The 32-byte secret key in ``path``: the file's bytes if it holds exactly 32, else a
    passphrase (UTF-8 text, trailing newline dropped) hashed with SHA-256, as MAVProxy's
    ``signing setup PASSPHRASE`` does.

    Raises :class:`ConfigError` (exit 2 material, naming ``flag`` and the file, never its
    content) when the file is missing, not a regular file, readable or writable by others,
    unreadable or empty; a ``path`` that is no path (a Python caller's ``key=5``) is a TypeError naming ``key``.
    """
    if not isinstance(path, str | os.PathLike):
        raise TypeError(f"key: expected a signing key file's path, got {type(path).__name__}")  # (never the value:
        # bytes here may be the secret itself)
    p = Path(path)
    try:
        st = p.stat()
    except FileNotFoundError:
        raise ConfigError.at(f"{flag} {p}", None, "no such file") from None
    except OSError as exc:
        raise ConfigError.at(f"{flag} {p}", None, f"cannot read ({exc.strerror})") from None
    if not stat.S_ISREG(st.st_mode):
        raise ConfigError.at(f"{flag} {p}", None, "not a regular file")
    if st.st_mode & (stat.S_IROTH | stat.S_IWOTH):
        raise ConfigError.at(f"{flag} {p}", None, f"readable or writable by others "
                             f"(mode {stat.S_IMODE(st.st_mode):04o}); chmod 600 it")
    note_input(p)  # a user's file this process reads (an --overwrite never replaces it)
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise ConfigError.at(f"{flag} {p}", None, f"cannot read ({exc.strerror})") from None
    if len(data) == KEY_BYTES:
        return data
    try:
        text = data.decode("utf-8").rstrip("\r\n")
    except UnicodeDecodeError:
        raise ConfigError.at(f"{flag} {p}", None, f"neither a {KEY_BYTES}-byte key nor a UTF-8 passphrase") from None
    if not text.strip():
        raise ConfigError.at(f"{flag} {p}", None, f"empty (a {KEY_BYTES}-byte key or a passphrase expected)")
    return _sha256(text.encode("utf-8")).digest()


def clock_timestamp() -> int:
    """Now on the signing clock: 10 us units since 2015-01-01 00:00 UTC."""
    return int((time.time() - EPOCH_2015) * 100_000)


class Signing:
    """Signs outgoing and verifies incoming MAVLink 2 frames with one secret key.

    ``link_id`` tells this sender's links apart (the vehicle signs its controller link and
    its GCS link with different ids). Outgoing timestamps follow the clock and grow by at
    least 1 per frame, so they stay unique and monotonic at any send rate. ``streams`` is the
    replay table, (sysid, compid, link id) -> newest timestamp accepted: pass one dict to the
    Signing of every link of a system (one table per system, as the specification says).
    """

    __slots__ = ("_key", "link_id", "timestamp", "streams")

    def __init__(self, key: bytes, link_id: int = 0, streams: dict[tuple[int, int, int], int] | None = None) -> None:
        if len(key) != KEY_BYTES:
            raise ValueError(f"a signing key has {KEY_BYTES} bytes")
        if not 0 <= link_id <= 255:
            raise ValueError("link_id must be in [0, 255]")
        self._key = bytes(key)
        self.link_id = link_id
        self.timestamp = 0  # the last one sent (10 us units)
        # (sysid, compid, link id) -> newest accepted; shared by the links of one system
        self.streams: dict[tuple[int, int, int], int] = streams if streams is not None else {}

    def __repr__(self) -> str:  # never the key
        return f"Signing(link_id={self.link_id})"

    def next_timestamp(self) -> int:
        now = clock_timestamp()
        ts = now if now > self.timestamp else self.timestamp + 1
        self.timestamp = ts
        return ts

    def sign(self, body: bytes) -> bytes:
        """``body`` (header with the signed flag, payload, CRC) + its signature block."""
        tail = _LINK_TS.pack(self.link_id, self.next_timestamp())[:7]
        return body + tail + _sha256(self._key + body + tail).digest()[:6]

    def resign(self, frame: bytes) -> bytes:
        """A frame pymavlink packed unsigned, signed: the flag set, the CRC (which covers the
        flag) recomputed, the signature appended. MAVLink 1 frames cannot be signed: as is."""
        if frame[0] != mavlink.PROTOCOL_MARKER_V2 or frame[2] & IFLAG_SIGNED:
            return frame
        n = frame[1]
        cls = mavlink.mavlink_map[frame[7] | frame[8] << 8 | frame[9] << 16]
        head = frame[:2] + bytes((frame[2] | IFLAG_SIGNED,)) + frame[3:10 + n]
        crc = crc16(head[1:] + bytes((cls.crc_extra,)), 0xFFFF)
        return self.sign(head + struct.pack("<H", crc))

    def verify(self, frame: bytes, sysid: int, compid: int) -> str | None:
        """None for a correctly signed frame newer than the last of its stream (then
        remembered); else the reason: ``unsigned``, ``bad_signature`` (not made with our
        key: forged or corrupted) or ``replayed`` (timestamp not newer than the last seen on
        that stream, or a new stream starting more than a minute behind our clock).

        The signature is checked before the timestamp is remembered, so a forged frame
        cannot move a stream's timestamp forward and lock its owner out."""
        if not frame[2] & IFLAG_SIGNED or len(frame) < 12 + SIGNATURE_BYTES:
            return "unsigned"
        if _sha256(self._key + frame[:-6]).digest()[:6] != frame[-6:]:
            return "bad_signature"
        ts = int.from_bytes(frame[-12:-6], "little")
        stream = (sysid, compid, frame[-13])
        last = self.streams.get(stream)
        if last is None:
            if ts + NEW_STREAM_SLACK < clock_timestamp():
                return "replayed"
        elif ts <= last:
            return "replayed"
        self.streams[stream] = ts
        return None

"""MAVLink 2 frames: the frame stage of the receive path, and the hot-path codec.

In:  one UDP datagram's bytes (whole MAVLink 2 frames: 10-byte header, payload, CRC-16/MCRF4XX,
     and when signed a 13-byte signature), a pymavlink ``MAVLink`` decoder, an optional
     :class:`~bridge.mavlink.signing.Signing`, the frame budget of the sender
Out: the frames' messages (pymavlink messages, or a :class:`HotMessage` for ODOMETRY and the
     two actuator targets); each refusal counted by its reason in a
     :class:`~bridge.mavlink.receive.Rejections`; for a hot message, its payload from the flat
     field values (:class:`HotLayout`)

:func:`parse_datagram` is the frame stage of :mod:`bridge.mavlink.receive`: every frame is
checked (magic, length, flags, known id, CRC, size, signature) before anything is decoded.
:func:`hot_frame` takes a datagram that is exactly one hot-path frame without building a
pymavlink message. :class:`bridge.mavlink.endpoint.Endpoint` owns the sockets around them.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from bridge.mavlink.receive import MAX_DATAGRAM, Rejections
from bridge.mavlink.signing import IFLAG_SIGNED, SIGNATURE_BYTES, Signing
from bridge.mavlink.signing import crc16 as _crc16

MAGIC2 = 0xFD
HEADER2 = struct.Struct("<BBBBBBBHB")  # magic len incompat compat seq sysid compid msgid(24 bit)


class HotLayout:
    """Wire layout of one message type, from pymavlink's metadata: encode a flat tuple of
    field values (pymavlink's ``ordered_fieldnames`` order, arrays flattened) into a
    MAVLink 2 payload, and decode a payload into a :class:`HotMessage`."""

    def __init__(self, cls: Any) -> None:
        self.id = cls.id
        self.name = cls.msgname
        self.crc_extra = bytes([cls.crc_extra])
        self.struct = cls.unpacker
        self.size = cls.unpacker.size
        self.spans: list[tuple[str, int, int]] = []
        i = 0
        for name, n in zip(cls.ordered_fieldnames, cls.array_lengths, strict=True):
            self.spans.append((name, i, n))
            i += max(n, 1)
        self._fields = _fields_function(self.spans)

    def decode(self, payload: bytes) -> dict[str, Any]:
        """Field values by name (arrays as tuples); a truncated MAVLink 2 payload is zero-padded."""
        if len(payload) < self.size:
            payload = payload + bytes(self.size - len(payload))
        return self._fields(self.struct.unpack(payload))


def _fields_function(spans: list[tuple[str, int, int]]) -> Callable[[tuple[Any, ...]], dict[str, Any]]:
    """``values -> {name: value}`` for a layout's ``spans`` (an array's values as a tuple), as one dict display:
    a step's message is decoded in about half the time of a comprehension over the spans (the same dict)."""
    items = ", ".join(f"{name!r}: v[{i}]" if n == 0 else f"{name!r}: v[{i}:{i + n}]" for name, i, n in spans)
    scope: dict[str, Any] = {}
    exec(f"def fields(v):\n    return {{{items}}}\n", scope)  # the names are string literals (repr)
    return scope["fields"]


class HotMessage:
    """A message decoded on the hot path: its fields as attributes, and the few methods of
    a pymavlink message the handlers use."""

    def __init__(self, layout: HotLayout, fields: dict[str, Any], src: int, comp: int, buf: bytes) -> None:
        self.__dict__ = fields  # (a new dict each message: HotLayout.decode's) taken, not copied
        self._type = layout.name
        self._src = src
        self._comp = comp
        self._buf = buf

    def get_type(self) -> str:
        return self._type

    def get_srcSystem(self) -> int:  # noqa: N802 - pymavlink's name
        return self._src

    def get_srcComponent(self) -> int:  # noqa: N802
        return self._comp

    def get_msgbuf(self) -> bytes:
        return self._buf


ODOMETRY = HotLayout(mavlink.MAVLink_odometry_message)
HIL_ACTUATOR_CONTROLS = HotLayout(mavlink.MAVLink_hil_actuator_controls_message)
SET_ACTUATOR_CONTROL_TARGET = HotLayout(mavlink.MAVLink_set_actuator_control_target_message)
HOT = {lay.id: lay for lay in (ODOMETRY, HIL_ACTUATOR_CONTROLS, SET_ACTUATOR_CONTROL_TARGET)}


def hot_frame(data: bytes) -> HotMessage | None:
    """A datagram that is exactly one hot-path frame, unsigned or signed (the signature is
    the caller's to verify), with a good CRC and a payload no longer than its message,
    decoded; None for anything else (it then takes :func:`parse_datagram`)."""
    if len(data) < 12 or data[0] != MAGIC2:
        return None
    n = data[1]
    flags = data[2]
    if flags == 0:
        size = 12 + n
    elif flags == IFLAG_SIGNED:
        size = 12 + n + SIGNATURE_BYTES
    else:
        return None
    if len(data) != size:
        return None
    layout = HOT.get(data[7] | data[8] << 8 | data[9] << 16)
    if layout is None or n > layout.size:
        return None
    if _crc16(data[1:10 + n] + layout.crc_extra, 0xFFFF) != data[10 + n] | data[11 + n] << 8:
        return None
    return HotMessage(layout, layout.decode(data[10:10 + n]), data[5], data[6], data)


def parse_datagram(data: bytes, dec: Any, signing: Signing | None, rejected: Rejections,
                   from_peer: bool = False, frame_budget: Callable[[], bool] | None = None) -> list[Any]:
    """The frame stage of the receive path (:mod:`bridge.mavlink.receive`): the messages of one
    datagram, each a whole MAVLink 2 frame with a known id, a good CRC, a payload no longer
    than its message and, with ``signing``, a good signature newer than its stream's last.
    With ``frame_budget`` (:meth:`RateLimiter.frame`), each frame is charged before it is
    checked: once it says no, the rest is ``rate_limited``. The first bad frame ends the
    datagram and is counted once in ``rejected`` by its reason; frames before it are kept.
    Never raises. ``dec`` is a pymavlink ``MAVLink`` without a key (it decodes what passed;
    the hot messages are decoded by the hot codec)."""
    n = len(data)
    why = "truncated" if n == 0 else "oversized" if n > MAX_DATAGRAM else None
    out: list[Any] = []
    pos = 0
    while why is None and pos < n:
        magic = data[pos]
        if magic != MAGIC2:
            why = "mavlink1" if magic == mavlink.PROTOCOL_MARKER_V1 else "no_frame"
            break
        if n - pos < 12:
            why = "truncated"
            break
        if frame_budget is not None and not frame_budget():
            why = "rate_limited"
            break
        plen, flags = data[pos + 1], data[pos + 2]
        if flags & ~IFLAG_SIGNED:
            why = "bad_flags"
            break
        end = pos + 12 + plen + (SIGNATURE_BYTES if flags else 0)
        if end > n:
            why = "truncated"
            break
        mid = data[pos + 7] | data[pos + 8] << 8 | data[pos + 9] << 16
        cls = mavlink.mavlink_map.get(mid)
        if cls is None:
            why = "unknown_id"
            break
        crc_at = pos + 10 + plen
        if _crc16(data[pos + 1:crc_at] + bytes((cls.crc_extra,)), 0xFFFF) != data[crc_at] | data[crc_at + 1] << 8:
            why = "bad_crc"
            break
        if plen > cls.unpacker.size:
            why = "oversized"
            break
        frame = data[pos:end]
        if signing is not None:
            why = signing.verify(frame, frame[5], frame[6])
            if why:
                break
        layout = HOT.get(mid)
        if layout is not None:
            out.append(HotMessage(layout, layout.decode(frame[10:10 + plen]), frame[5], frame[6], frame))
        else:
            try:
                out.append(dec.decode(bytearray(frame)))
            except Exception:  # whatever pymavlink raises on a frame it cannot decode, it is refused
                why = "malformed"
                break
        pos = end
    if why is not None:
        rejected.add(why, from_peer)
    return out

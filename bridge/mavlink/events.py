"""The vehicle's events as MAVLink's typed EVENT messages (MAVLink's events interface),
sent as PX4 sends its own (src/modules/mavlink/mavlink_events.cpp, ``SendProtocol``): one stable id per event kind,
a log level, a sequence number per event, CURRENT_EVENT_SEQUENCE, and re-sends on REQUEST_EVENT from a short ring.

In:  an event's kind (the vehicle's event kinds, bridge.autopilot.vehicleevents.Event.kind), its simulation time (s),
     its MAV_SEVERITY (0 emergency .. 7 debug: the events interface's log levels are the same numbers); a received
     EVENT, REQUEST_EVENT (its sequence range, uint16, wrapping)
Out: EVENT (id 410), CURRENT_EVENT_SEQUENCE (411), RESPONSE_EVENT_ERROR (413) as pymavlink messages; a received
     EVENT's :class:`EventId` (None: not one of ours)

pymavlink's bundled common dialect (2.4.50) lacks the events messages (ids 410-413) although MAVLink's common.xml
has them: :func:`register` adds them to it (their fields, wire order and CRC extras as in common.xml; tests check
the CRC extras against pymavlink's own generator), so every endpoint of ours decodes them. A ground station built on
the full common set (MAVSDK, QGroundControl) decodes them itself; one without them (MAVProxy) skips them as unknown.
"""

from __future__ import annotations

import struct
from collections import deque
from enum import IntEnum
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

EVENT, CURRENT_EVENT_SEQUENCE, REQUEST_EVENT, RESPONSE_EVENT_ERROR = 410, 411, 412, 413
ARGUMENTS = 40  # bytes of an EVENT's arguments (ours carry none: zeros)
SEQUENCE_RESET = 1  # MAV_EVENT_CURRENT_SEQUENCE_FLAGS_RESET: nothing sent yet (PX4: its buffer is empty)
ERROR_UNAVAILABLE = 0  # MAV_EVENT_ERROR_REASON_UNAVAILABLE: the event asked for is no longer (or never was) kept
RING = 20  # events kept for REQUEST_EVENT: PX4's EventBuffer default capacity (mavlink_events.h)
NAMESPACE = 0xB5 << 24  # an id's upper 8 bits: whose event (libevents: 0 MAVLink's common events, 1 PX4's); ours


class EventId(IntEnum):
    """One stable EVENT id per kind of the vehicle's events: NAMESPACE | its number, and the short message a ground
    station shows for it (the libevents metadata the vehicle publishes, :mod:`bridge.mavlink.compmeta`; the details
    are in the STATUSTEXT sent with it). Never renumbered: a new kind takes a new number, and OTHER stands for a kind
    not in the table yet (its STATUSTEXT still says it). The one table of kinds: every list of them is made from it."""

    message: str

    def __new__(cls, number: int, message: str) -> EventId:
        member = int.__new__(cls, NAMESPACE | number)
        member._value_ = NAMESPACE | number
        member.message = message
        return member

    ARMED = 1, "Armed"
    DISARMED = 2, "Disarmed"
    MODE = 3, "Flight mode changed"
    FAILSAFE = 4, "Failsafe: the vehicle took over"
    LOCKSTEP = 5, "Left lockstep"  # its controller silent, or a ground station took it
    DIVERGED = 6, "The flight diverged"
    CRASHED = 7, "Crashed"
    IMPACT = 8, "Hard touchdown"
    TERMINATED = 9, "Flight termination: motors off"
    PREFLIGHT = 10, "Arming refused by a preflight check"
    BATTERY = 11, "Battery warning"
    GEOFENCE = 12, "Geofence breached"
    POSITION = 13, "Position estimate changed"
    LANDING = 14, "Landing"
    LANDED = 15, "Landed"
    TOUCHDOWN = 16, "Touchdown"
    COLLISION = 17, "Collision"
    END = 18, "Mission over"
    PARAM = 19, "Parameter changed"
    MISSION = 20, "Mission changed"
    SPEED = 21, "Speed changed"
    INTERVAL = 22, "Message interval changed"
    FAULT = 23, "Fault injected"
    WIND = 24, "Wind changed"
    LINK = 25, "Link changed"
    OTHER = 0xFFFFFF, "Vehicle event"


# the one table: event kind -> id (each kind's id is its name's member)
KIND_IDS: dict[str, EventId] = {e.name.lower(): e for e in EventId if e is not EventId.OTHER}


def event_id(kind: str) -> EventId:
    """The EVENT id of an event ``kind`` (:data:`KIND_IDS`; OTHER for a kind not in it)."""
    return KIND_IDS.get(kind, EventId.OTHER)


def log_levels(severity: int) -> int:
    """EVENT's ``log_levels`` for a MAV_SEVERITY: the external level (low 4 bits) and the internal one (for logs,
    high 4 bits) both that severity, whose numbers are the events interface's levels (2 critical, 6 info)."""
    return (severity << 4) | severity


def received_id(m: Any) -> EventId | None:
    """The :class:`EventId` of a received EVENT (None: an id not ours)."""
    try:
        return EventId(m.id)
    except ValueError:
        return None


class EventRing:
    """The events sent, numbered: a uint16 sequence from 0 (wrapping) and the last :data:`RING` kept for re-sends."""

    def __init__(self) -> None:
        self.next = 0  # the sequence of the next event
        self.kept: deque[Any] = deque(maxlen=RING)

    def add(self, kind: str, t: float, severity: int) -> Any:
        """The EVENT of an event of ``kind`` at simulation time ``t`` (s) of MAV_SEVERITY ``severity``, numbered
        and kept; broadcast (destination 0, 0), as PX4 sends every event."""
        m = MAVLink_event_message(0, 0, int(event_id(kind)), max(0, int(round(t * 1000.0))) & 0xFFFFFFFF, self.next,
                                  log_levels(severity), [0] * ARGUMENTS)
        self.next = (self.next + 1) & 0xFFFF
        self.kept.append(m)
        return m

    def current(self) -> Any:
        """CURRENT_EVENT_SEQUENCE: the newest event's sequence (65535 before any, then RESET is flagged)."""
        return MAVLink_current_event_sequence_message((self.next - 1) & 0xFFFF, 0 if self.kept else SEQUENCE_RESET)

    def resend(self, first: int, last: int, sysid: int, compid: int) -> list[Any]:
        """The answer to REQUEST_EVENT ``first``..``last`` (inclusive, wrapping) from ``sysid``/``compid``, as PX4's
        ``handle_request_event``: each kept EVENT again, else a RESPONSE_EVENT_ERROR naming the oldest kept after
        it; a range longer than the ring gets one error for its start, then its newest :data:`RING` sequences."""
        by_seq = {m.sequence: m for m in self.kept}
        end = (last + 1) & 0xFFFF
        seq = first & 0xFFFF
        out: list[Any] = []
        if (end - seq) & 0xFFFF > RING:
            out.append(self._unavailable(seq, sysid, compid))
            seq = (end - RING) & 0xFFFF
        while seq != end:
            m = by_seq.get(seq)
            out.append(m if m is not None else self._unavailable(seq, sysid, compid))
            seq = (seq + 1) & 0xFFFF
        return out

    def _unavailable(self, seq: int, sysid: int, compid: int) -> Any:
        after = [m.sequence for m in self.kept if m.sequence != seq]
        oldest = min(after, key=lambda s: (s - seq) & 0xFFFF) if after else (self.next - 1) & 0xFFFF
        return MAVLink_response_event_error_message(sysid, compid, seq, oldest, ERROR_UNAVAILABLE)


# -- the messages, as mavgen would generate them from common.xml ---------------------------------------------------
_FORMATS = {"uint8_t": "B", "uint16_t": "H", "uint32_t": "I", "char": "s"}
_SIZES = {"uint8_t": 1, "uint16_t": 2, "uint32_t": 4, "char": 1}


def message_class(name: str, msgid: int, crc_extra: int, fields: tuple[tuple[str, str, int], ...]) -> type:
    """A pymavlink message class of ``fields`` (name, type, array length; 0: a scalar) in common.xml's order; on
    the wire sorted by type size, largest first (MAVLink 2's rule, stable). A ``char`` array is a string: given as
    bytes or str, read back as str up to its first NUL (as pymavlink's own classes)."""
    wire = sorted(range(len(fields)), key=lambda i: -_SIZES[fields[i][1]])
    names = [f[0] for f in fields]
    chars = {f[0] for f in fields if f[1] == "char"}
    fmt = "<" + "".join(f"{fields[i][2]}{_FORMATS[fields[i][1]]}" if fields[i][2] else _FORMATS[fields[i][1]]
                        for i in wire)

    def __init__(self: Any, *values: Any) -> None:
        mavlink.MAVLink_message.__init__(self, msgid, name)
        self._fieldnames = names
        self._instance_field = None
        self._instance_offset = -1
        for n, v in zip(names, values, strict=True):
            if n in chars:
                raw = v.encode() if isinstance(v, str) else bytes(v)
                setattr(self, f"_{n}_raw", raw)
                v = raw.split(b"\x00", 1)[0].decode("ascii", errors="replace")
            setattr(self, n, v)

    def pack(self: Any, mav: Any, force_mavlink1: bool = False) -> bytes:
        flat: list[Any] = []
        for i in wire:
            n = names[i]
            if n in chars:
                flat.append(getattr(self, f"_{n}_raw"))
                continue
            v = getattr(self, n)
            flat.extend(v) if fields[i][2] else flat.append(v)
        return self._pack(mav, crc_extra, struct.pack(fmt, *flat), force_mavlink1=force_mavlink1)

    attrs = {"id": msgid, "msgname": name, "fieldnames": names, "ordered_fieldnames": [names[i] for i in wire],
             "fieldtypes": [f[1] for f in fields], "fielddisplays_by_name": {}, "fieldenums_by_name": {},
             "fieldunits_by_name": {}, "native_format": bytearray(fmt.encode()),
             "orders": [wire.index(i) for i in range(len(fields))],
             "lengths": [1 if fields[i][1] == "char" else fields[i][2] or 1 for i in wire],
             "array_lengths": [fields[i][2] for i in wire],
             "crc_extra": crc_extra, "unpacker": struct.Struct(fmt), "instance_field": None, "instance_offset": -1,
             "__init__": __init__, "pack": pack}
    return type(f"MAVLink_{name.lower()}_message", (mavlink.MAVLink_message,), attrs)


MAVLink_event_message = message_class("EVENT", EVENT, 160, (
    ("destination_component", "uint8_t", 0), ("destination_system", "uint8_t", 0), ("id", "uint32_t", 0),
    ("event_time_boot_ms", "uint32_t", 0), ("sequence", "uint16_t", 0), ("log_levels", "uint8_t", 0),
    ("arguments", "uint8_t", ARGUMENTS)))
MAVLink_current_event_sequence_message = message_class("CURRENT_EVENT_SEQUENCE", CURRENT_EVENT_SEQUENCE, 106, (
    ("sequence", "uint16_t", 0), ("flags", "uint8_t", 0)))
MAVLink_request_event_message = message_class("REQUEST_EVENT", REQUEST_EVENT, 33, (
    ("target_system", "uint8_t", 0), ("target_component", "uint8_t", 0), ("first_sequence", "uint16_t", 0),
    ("last_sequence", "uint16_t", 0)))
MAVLink_response_event_error_message = message_class("RESPONSE_EVENT_ERROR", RESPONSE_EVENT_ERROR, 77, (
    ("target_system", "uint8_t", 0), ("target_component", "uint8_t", 0), ("sequence", "uint16_t", 0),
    ("sequence_oldest_available", "uint16_t", 0), ("reason", "uint8_t", 0)))
MESSAGES = (MAVLink_event_message, MAVLink_current_event_sequence_message, MAVLink_request_event_message,
            MAVLink_response_event_error_message)


def register() -> None:
    """Add the events messages to pymavlink's common dialect (idempotent): every MAVLink parser of it decodes them."""
    for cls in MESSAGES:
        mavlink.mavlink_map.setdefault(cls.id, cls)

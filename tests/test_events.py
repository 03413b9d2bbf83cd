"""Covers bridge.mavlink.events: the vehicle's events as MAVLink's typed EVENT messages, offline.

The messages' wire form against pymavlink's own generator (their CRC extras from common.xml's fields), the stable id
table, the log levels, and the ring that numbers the EVENTs and answers REQUEST_EVENT as PX4's ``handle_request_event``
(src/modules/mavlink/mavlink_events.cpp). A real vehicle and controller: tests/test_events_sitl.py.
"""

from __future__ import annotations

from pathlib import Path

from pymavlink.dialects.v20 import common as mavlink
from pymavlink.generator import mavparse

from bridge.mavlink import events as ev
from bridge.nodes.vehicle.announcer import CRITICAL_KINDS

# the four messages as MAVLink's common.xml defines them (fields in its order; descriptions left out)
COMMON_XML = """<?xml version="1.0"?><mavlink><version>3</version><messages>
<message id="410" name="EVENT"><description>-</description><field type="uint8_t" name="destination_component">-</field>
<field type="uint8_t" name="destination_system">-</field><field type="uint32_t" name="id">-</field>
<field type="uint32_t" name="event_time_boot_ms">-</field><field type="uint16_t" name="sequence">-</field>
<field type="uint8_t" name="log_levels">-</field><field type="uint8_t[40]" name="arguments">-</field></message>
<message id="411" name="CURRENT_EVENT_SEQUENCE"><description>-</description>
<field type="uint16_t" name="sequence">-</field><field type="uint8_t" name="flags">-</field></message>
<message id="412" name="REQUEST_EVENT"><description>-</description><field type="uint8_t" name="target_system">-</field>
<field type="uint8_t" name="target_component">-</field><field type="uint16_t" name="first_sequence">-</field>
<field type="uint16_t" name="last_sequence">-</field></message>
<message id="413" name="RESPONSE_EVENT_ERROR"><description>-</description>
<field type="uint8_t" name="target_system">-</field><field type="uint8_t" name="target_component">-</field>
<field type="uint16_t" name="sequence">-</field><field type="uint16_t" name="sequence_oldest_available">-</field>
<field type="uint8_t" name="reason">-</field></message></messages></mavlink>"""


def _wire(m):
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    return mav.decode(bytearray(m.pack(mav)))


def test_the_messages_match_common_xml_by_pymavlinks_generator(tmp_path: Path) -> None:
    (tmp_path / "events.xml").write_text(COMMON_XML)
    spec = {m.id: m for m in mavparse.MAVXML(str(tmp_path / "events.xml"), "2.0").message}
    for cls in ev.MESSAGES:
        s = spec[cls.id]
        assert (cls.msgname, cls.crc_extra, cls.fieldnames, cls.ordered_fieldnames) == (
            s.name, s.crc_extra, s.fieldnames, s.ordered_fieldnames), cls.msgname
        assert mavlink.mavlink_map[cls.id] is cls  # registered: every parser of the common dialect decodes them


def test_an_event_goes_over_the_wire_whole() -> None:
    ring = ev.EventRing()
    sent = ring.add("failsafe", 15.5004, mavlink.MAV_SEVERITY_CRITICAL)
    got = _wire(sent)
    assert got.get_type() == "EVENT" and ev.received_id(got) is ev.EventId.FAILSAFE
    assert (got.id, got.event_time_boot_ms, got.sequence, got.log_levels, got.destination_system,
            got.destination_component, got.arguments) == (0xB5000004, 15500, 0, 0x22, 0, 0, [0] * 40)
    assert ev.received_id(ev.MAVLink_event_message(0, 0, 0x01000001, 0, 0, 0, [0] * 40)) is None  # PX4's, not ours


def test_one_stable_id_per_kind() -> None:
    """Pinned: a kind's id never changes (a receiver decides by it). Every CRITICAL kind has its own."""
    assert {k: int(i) & 0xFFFFFF for k, i in ev.KIND_IDS.items()} == {
        "armed": 1, "disarmed": 2, "mode": 3, "failsafe": 4, "lockstep": 5, "diverged": 6, "crashed": 7,
        "impact": 8, "terminated": 9, "preflight": 10, "battery": 11, "geofence": 12, "position": 13,
        "landing": 14, "landed": 15, "touchdown": 16, "collision": 17, "end": 18, "param": 19, "mission": 20,
        "speed": 21, "interval": 22, "fault": 23, "wind": 24, "link": 25}
    assert all(int(i) >> 24 == 0xB5 for i in ev.EventId)
    assert all(k in ev.KIND_IDS for k in CRITICAL_KINDS)
    assert ev.event_id("something new") is ev.EventId.OTHER
    assert ev.log_levels(mavlink.MAV_SEVERITY_INFO) == 0x66


def test_the_sequence_counts_events_and_wraps() -> None:
    ring = ev.EventRing()
    first = _wire(ring.current())
    assert (first.sequence, first.flags) == (0xFFFF, ev.SEQUENCE_RESET)  # nothing sent yet
    ring.next = 0xFFFE
    seqs = [ring.add("param", 1.0, mavlink.MAV_SEVERITY_INFO).sequence for _ in range(3)]
    assert seqs == [0xFFFE, 0xFFFF, 0]
    assert (ring.current().sequence, ring.current().flags) == (0, 0)


def test_request_event_resends_the_kept_and_says_what_is_gone() -> None:
    ring = ev.EventRing()
    sent = [ring.add("mode", i * 0.1, mavlink.MAV_SEVERITY_INFO) for i in range(ev.RING + 5)]  # 0..24, 5..24 kept
    again = [_wire(m) for m in ring.resend(6, 7, 255, 190)]
    assert [(m.get_type(), m.sequence) for m in again] == [("EVENT", 6), ("EVENT", 7)]
    assert again[0].get_msgbuf()[10:] == _wire(sent[6]).get_msgbuf()[10:]  # the same payload (and CRC)
    gone = [_wire(m) for m in ring.resend(3, 5, 255, 190)]
    assert [(m.get_type(), m.sequence, m.sequence_oldest_available, m.target_system, m.target_component, m.reason)
            for m in gone[:2]] == [("RESPONSE_EVENT_ERROR", 3, 5, 255, 190, 0), ("RESPONSE_EVENT_ERROR", 4, 5, 255,
                                                                                    190, 0)]
    assert (gone[2].get_type(), gone[2].sequence) == ("EVENT", 5)
    every = ring.resend(2, 0, 1, 1)  # 65535 wrapping: one error for the start, then the newest RING sequences
    assert len(every) == 1 + ev.RING and every[0].get_type() == "RESPONSE_EVENT_ERROR"

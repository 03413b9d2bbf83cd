"""Covers bridge.mavlink.ftp and bridge.mavlink.compmeta: the read-only MAVLink FTP server and the files it serves.

The payload's bytes as the MAVLink FTP spec lays them out; each request's reply as PX4's server gives it (seq + 1, the
request's opcode, OpenFileRO's size, EOF past the end, a burst's numbered messages and its EOF NAK, a request sent again
answered again); every opcode that would change a file NAKed UnknownCommand. The metadata: MAVLink's CRC32 as PX4's
generator computes it, the general file naming the events file by URI and CRC, and the events file naming every kind
of the one table with its id, in libevents' layout.
"""

from __future__ import annotations

import json
import struct

import pytest
from pymavlink.dialects.v20 import common as M
from pymavlink.generator import mavparse

from bridge.mavlink import compmeta, ftp
from bridge.mavlink.events import KIND_IDS, NAMESPACE, EventId

FILES = {"etc/extras/a.json": bytes(range(256)) * 3, "etc/extras/b.json": b"{}", "top.txt": b"x"}
ME = ("127.0.0.1", 14550)


def _req(seq: int, opcode: int, session: int = 0, offset: int = 0, data: bytes = b"", size: int | None = None) -> bytes:
    head = ftp.HEADER.pack(seq, session, opcode, len(data) if size is None else size, 0, 0, 0, offset)
    return (head + data).ljust(ftp.PAYLOAD_LEN, b"\x00")


def _ops(replies: list[bytes]) -> list[ftp.Op]:
    out = [ftp.decode(r) for r in replies]
    assert all(len(r) == ftp.PAYLOAD_LEN for r in replies) and None not in out
    return out  # type: ignore[return-value]


def test_the_payload_layout_is_the_specs() -> None:
    op = ftp.Op(0x1234, 5, ftp.ACK, 3, ftp.OPEN_FILE_RO, 1, 0xA0B0C0D0, b"abc")
    raw = op.encode()
    assert raw[:12] == bytes([0x34, 0x12, 5, ftp.ACK, 3, ftp.OPEN_FILE_RO, 1, 0, 0xD0, 0xC0, 0xB0, 0xA0])
    assert raw[12:15] == b"abc" and not any(raw[15:]) and ftp.decode(raw) == op
    assert ftp.decode(b"\x00" * 11) is None and ftp.DATA_LEN == 239


def test_open_read_and_terminate_a_file() -> None:
    s = ftp.FtpServer(FILES)
    (opened,) = _ops(s.handle(_req(10, ftp.OPEN_FILE_RO, 7, data=b"/etc/extras/a.json"), ME))
    assert (opened.seq, opened.session, opened.opcode, opened.req_opcode) == (11, 7, ftp.ACK, ftp.OPEN_FILE_RO)
    assert struct.unpack("<I", opened.data) == (768,)
    (read,) = _ops(s.handle(_req(12, ftp.READ_FILE, 7, offset=700, size=100), ME))
    assert (read.seq, read.opcode, read.offset, read.data) == (13, ftp.ACK, 700, FILES["etc/extras/a.json"][700:])
    (eof,) = _ops(s.handle(_req(14, ftp.READ_FILE, 7, offset=768, size=239), ME))
    assert (eof.opcode, eof.data) == (ftp.NAK, bytes([ftp.ERR_EOF]))
    (other,) = _ops(s.handle(_req(20, ftp.READ_FILE, 7, size=10), ("127.0.0.1", 1)))  # not its session
    assert other.data == bytes([ftp.ERR_INVALID_SESSION])
    (done,) = _ops(s.handle(_req(16, ftp.TERMINATE_SESSION, 7), ME))
    assert done.opcode == ftp.ACK and not s.sessions
    (gone,) = _ops(s.handle(_req(18, ftp.READ_FILE, 7, size=10), ME))
    assert gone.data == bytes([ftp.ERR_INVALID_SESSION])


def test_a_burst_streams_numbered_chunks_then_eof() -> None:
    s = ftp.FtpServer(FILES)
    s.handle(_req(0, ftp.OPEN_FILE_RO, data=b"etc/extras/a.json"), ME)
    first = _ops(s.handle(_req(2, ftp.BURST_READ_FILE, size=100), ME))
    assert [(o.seq, o.offset, len(o.data), o.burst_complete) for o in first] == [
        (3, 0, 100, 0), (4, 100, 100, 0), (5, 200, 100, 0), (6, 300, 100, 1)]
    rest = _ops(s.handle(_req(7, ftp.BURST_READ_FILE, offset=400, size=239), ME))
    assert [(o.opcode, o.seq, o.offset, len(o.data)) for o in rest] == [
        (ftp.ACK, 8, 400, 239), (ftp.ACK, 9, 639, 129), (ftp.NAK, 10, 768, 1)]
    assert rest[-1].data == bytes([ftp.ERR_EOF]) and rest[-1].req_opcode == ftp.BURST_READ_FILE
    got = b"".join(o.data for o in first + rest[:-1])
    assert got == FILES["etc/extras/a.json"]


def test_a_request_sent_again_gets_the_same_reply() -> None:
    s = ftp.FtpServer(FILES)
    once = s.handle(_req(4, ftp.OPEN_FILE_RO, 2, data=b"top.txt"), ME)
    assert s.handle(_req(4, ftp.OPEN_FILE_RO, 2, data=b"top.txt"), ME) == once
    burst = s.handle(_req(6, ftp.BURST_READ_FILE, 2), ME)
    assert s.handle(_req(6, ftp.BURST_READ_FILE, 2), ME) == burst


def test_another_sessions_request_with_the_same_seq_is_its_own() -> None:
    """MAVProxy numbers each operation's requests from 0 in its own session: its parameter module's OpenFileRO of
    ``@PARAM/param.pck`` (NAKed) and then a typed ``ftp get``'s are both seq 0. Until 2026-12-07 the second got the
    first's NAK again (a request sent again, by seq and opcode alone), and so did each of its retries."""
    s = ftp.FtpServer(FILES)
    (nak,) = _ops(s.handle(_req(0, ftp.OPEN_FILE_RO, 7, data=b"@PARAM/param.pck"), ME))
    assert (nak.opcode, nak.session) == (ftp.NAK, 7)
    for _ in range(2):  # and its retry, the same request sent again
        (ack,) = _ops(s.handle(_req(0, ftp.OPEN_FILE_RO, 8, data=b"top.txt"), ME))
        assert (ack.opcode, ack.session, ack.seq, ack.data) == (ftp.ACK, 8, 1, struct.pack("<I", 1))
    assert {r.session for r in _ops(s.handle(_req(1, ftp.BURST_READ_FILE, 8), ME))} == {8}
    (other,) = _ops(s.handle(_req(1, ftp.BURST_READ_FILE, 9), ME))  # no session 9: not session 8's burst again
    assert (other.opcode, other.session, other.data) == (ftp.NAK, 9, bytes((ftp.ERR_INVALID_SESSION,)))


def test_list_a_directory_from_an_index() -> None:
    s = ftp.FtpServer(FILES)
    (root,) = _ops(s.handle(_req(0, ftp.LIST_DIRECTORY, data=b"/"), ME))
    assert root.data == b"Detc\x00Ftop.txt\t1\x00"
    (extras,) = _ops(s.handle(_req(2, ftp.LIST_DIRECTORY, offset=1, data=b"etc/extras"), ME))
    assert extras.data == b"Fb.json\t2\x00"
    (eof,) = _ops(s.handle(_req(4, ftp.LIST_DIRECTORY, offset=2, data=b"etc/extras"), ME))
    assert eof.data == bytes([ftp.ERR_EOF])
    (none,) = _ops(s.handle(_req(6, ftp.LIST_DIRECTORY, data=b"nowhere"), ME))
    assert none.data == bytes([ftp.ERR_FILE_NOT_FOUND])


@pytest.mark.parametrize("opcode", [6, 7, 8, 9, 10, 11, 12, 13, 14, 16, 42])
def test_everything_else_is_naked_unknown_command(opcode: int) -> None:
    """Create, write, remove, mkdir, rmdir, open for writing, truncate, rename, CRC32, list with times, unknown."""
    s = ftp.FtpServer(FILES)
    (nak,) = _ops(s.handle(_req(0xFFFF, opcode, 3, data=b"top.txt"), ME))
    assert (nak.seq, nak.session, nak.opcode, nak.size, nak.req_opcode) == (0, 3, ftp.NAK, 1, opcode)
    assert nak.data == bytes([ftp.ERR_UNKNOWN_COMMAND]) and FILES["top.txt"] == b"x"


def test_missing_files_oversized_requests_and_replies() -> None:
    s = ftp.FtpServer(FILES)
    (missing,) = _ops(s.handle(_req(0, ftp.OPEN_FILE_RO, data=b"@PARAM/param.pck?withdefaults=1"), ME))
    assert missing.data == bytes([ftp.ERR_FILE_NOT_FOUND])
    (big,) = _ops(s.handle(_req(2, ftp.READ_FILE, size=240), ME))
    assert big.data == bytes([ftp.ERR_INVALID_DATA_SIZE])
    assert s.handle(_req(4, ftp.ACK), ME) == [] and s.handle(_req(4, ftp.NAK), ME) == [] and s.handle(b"\x01", ME) == []
    assert ftp.is_request(_req(4, 42)) and not ftp.is_request(_req(4, ftp.ACK)) and not ftp.is_request(b"\x01")


def test_sessions_are_bounded_the_oldest_closed_first() -> None:
    s = ftp.FtpServer(FILES)
    for i in range(ftp.MAX_SESSIONS + 1):
        s.handle(_req(2 * i, ftp.OPEN_FILE_RO, i, data=b"top.txt"), ME)
    assert len(s.sessions) == ftp.MAX_SESSIONS and (ME, 0) not in s.sessions
    (reset,) = _ops(s.handle(_req(100, ftp.RESET_SESSIONS), ME))
    assert reset.opcode == ftp.ACK and not s.sessions


def _mavlink_crc32(data: bytes) -> int:
    """MAVLink's CRC32 as PX4's generate_crc.py computes it: table of 0x1db710640, from 0, no final XOR."""
    table = []
    for i in range(256):
        k = i
        for _ in range(8):
            k = (k ^ 0x1DB710640) >> 1 if k & 1 else k >> 1
        table.append(k)
    crc = 0
    for b in data:
        crc = (crc >> 8) ^ table[(crc & 0xFF) ^ b]
    return crc


def test_the_crc_is_mavlinks() -> None:
    for data in (b"", b"123456789", compmeta.FILES[compmeta.EVENTS_PATH]):
        assert compmeta.crc32(data) == _mavlink_crc32(data)


def test_the_general_file_names_the_events_file_by_uri_and_crc() -> None:
    general = json.loads(compmeta.FILES[compmeta.GENERAL_PATH])
    assert general["version"] == 1
    (events,) = general["metadataTypes"]
    assert events == {"type": 4, "uri": "mftp://etc/extras/all_events.json",
                      "fileCrc": compmeta.crc32(compmeta.FILES[compmeta.EVENTS_PATH])}
    assert compmeta.GENERAL_CRC == compmeta.crc32(compmeta.FILES[compmeta.GENERAL_PATH])


def test_the_events_file_names_every_kind_with_its_id() -> None:
    doc = json.loads(compmeta.FILES[compmeta.EVENTS_PATH])
    assert doc["version"] == 2 and list(doc["components"]) == [str(NAMESPACE >> 24)] == ["181"]
    comp = doc["components"]["181"]
    assert comp["namespace"] == "bsst" and list(comp["event_groups"]) == ["default"]
    events = comp["event_groups"]["default"]["events"]
    named = {e["name"]: (NAMESPACE >> 24) << 24 | int(sub) for sub, e in events.items()}
    assert {k: named[k] for k in KIND_IDS} == {k: int(i) for k, i in KIND_IDS.items()}
    assert named["other"] == EventId.OTHER and len(events) == len(EventId)
    assert all(0 < len(e["message"]) <= 120 and "\n" not in e["message"] for e in events.values())


def test_component_metadata_messages_round_trip() -> None:
    mav = M.MAVLink(None, srcSystem=1, srcComponent=1)
    for m in (compmeta.component_metadata(1234), compmeta.component_information(1234)):
        back = mav.decode(bytearray(m.pack(mav)))
        assert back.get_type() == m.msgname and back.time_boot_ms == 1234
    meta = mav.decode(bytearray(compmeta.component_metadata(5).pack(mav)))
    assert (meta.uri, meta.file_crc) == ("mftp://etc/extras/component_general.json", compmeta.GENERAL_CRC)
    info = mav.decode(bytearray(compmeta.component_information(5).pack(mav)))
    assert (info.general_metadata_uri, info.general_metadata_file_crc, info.peripherals_metadata_uri) == (
        meta.uri, compmeta.GENERAL_CRC, "")


COMMON_XML = """<?xml version="1.0"?><mavlink><version>3</version><messages>
<message id="395" name="COMPONENT_INFORMATION"><description>-</description>
<field type="uint32_t" name="time_boot_ms">-</field><field type="uint32_t" name="general_metadata_file_crc">-</field>
<field type="char[100]" name="general_metadata_uri">-</field>
<field type="uint32_t" name="peripherals_metadata_file_crc">-</field>
<field type="char[100]" name="peripherals_metadata_uri">-</field></message>
<message id="397" name="COMPONENT_METADATA"><description>-</description>
<field type="uint32_t" name="time_boot_ms">-</field><field type="uint32_t" name="file_crc">-</field>
<field type="char[100]" name="uri">-</field></message>
</messages></mavlink>"""


def test_the_messages_match_common_xml_by_pymavlinks_generator(tmp_path) -> None:
    """Both messages as MAVLink's common.xml defines them (fields in its order), through pymavlink's generator."""
    (tmp_path / "m.xml").write_text(COMMON_XML)
    spec = {m.id: m for m in mavparse.MAVXML(str(tmp_path / "m.xml"), "2.0").message}
    for cls in compmeta.MESSAGES:
        s = spec[cls.id]
        assert (cls.msgname, cls.crc_extra, cls.fieldnames, cls.ordered_fieldnames) == (
            s.name, s.crc_extra, s.fieldnames, s.ordered_fieldnames), cls.msgname

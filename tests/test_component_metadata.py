"""Covers bridge.nodes.vehicle.receiver, bridge.nodes.vehicle.streams and bridge.mavlink.ftp: component metadata.

A real ``bsst sitl --await-mission`` session's vehicle answers REQUEST_MESSAGE COMPONENT_METADATA (and the older
COMPONENT_INFORMATION) with the general metadata file's ``mftp://`` URI and MAVLink CRC32; a pymavlink ground station
downloads it and the events file it names over MAVLink FTP as QGroundControl's FTPManager does (OpenFileRO,
BurstReadFile to the EOF NAK, ResetSessions; a ReadFile of a part), each file's CRC the one it was announced with, and
the events file names every kind of the vehicle's table with its id. MAVProxy's own ``ftp`` module lists the
directory and gets the file. The client's FTP payloads are laid out here from the spec, not with the vehicle's codec.
"""

from __future__ import annotations

import json
import os
import struct
import time
from pathlib import Path
from typing import Any

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as M

from bridge.mavlink import compmeta
from bridge.mavlink.endpoint import GCS_PORT
from bridge.mavlink.events import KIND_IDS
from bridge.session import instance_slot
from tests.sitlkit import MavProxy, Proc
from tests.test_ftp import _mavlink_crc32

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast

HEADER = struct.Struct("<HBBBBBBI")  # seq, session, opcode, size, req_opcode, burst_complete, padding, offset
OPEN_RO, READ, RESET, BURST, ACK, NAK, EOF = 4, 5, 2, 15, 128, 129, 6


class FtpClient:
    """A MAVLink FTP client on a pymavlink connection, as QGroundControl's FTPManager runs one: session 0, each
    request's seq one past the last reply's, replies matched by seq and opcode (every wait with a deadline)."""

    def __init__(self, conn: Any, target: int) -> None:
        self.conn, self.target, self.seq = conn, target, 0

    def send(self, opcode: int, offset: int = 0, data: bytes = b"", size: int | None = None) -> int:
        self.seq = (self.seq + 1) & 0xFFFF
        head = HEADER.pack(self.seq, 0, opcode, len(data) if size is None else size, 0, 0, 0, offset)
        self.conn.mav.file_transfer_protocol_send(0, self.target, 1, list((head + data).ljust(251, b"\x00")))
        return self.seq

    def reply(self, timeout: float = 10.0) -> tuple[tuple[int, ...], bytes]:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            m = self.conn.recv_match(type="FILE_TRANSFER_PROTOCOL", blocking=True, timeout=0.5)
            if m is not None and m.get_srcSystem() == self.target and m.target_system == 255:
                raw = bytes(m.payload)
                head = HEADER.unpack_from(raw)
                self.seq = head[0]
                return head, raw[12:12 + head[3]]
        raise AssertionError("no FTP reply within the deadline")

    def download(self, path: str) -> tuple[bytes, int]:
        """The file at ``path`` (OpenFileRO, BurstReadFile until the EOF NAK, ResetSessions) and the bursts asked."""
        self.send(OPEN_RO, data=path.encode())
        head, data = self.reply()
        assert (head[2], head[4], head[3]) == (ACK, OPEN_RO, 4), (head, data)
        (size,) = struct.unpack("<I", data)
        got, bursts = bytearray(), 0
        while True:
            asked = self.send(BURST, offset=len(got), size=239)
            bursts += 1
            expect = asked + 1
            while True:
                head, data = self.reply()
                assert head[0] == expect and head[4] == BURST, (head, expect)  # numbered on from the request
                expect += 1
                if head[2] == NAK:
                    assert data == bytes([EOF]) and len(got) == size
                    self.send(RESET)
                    assert self.reply()[0][2] == ACK
                    return bytes(got), bursts
                assert head[7] == len(got)
                got += data
                if head[5]:  # burst complete: ask for the next
                    break


def _request(gcs: Any, target: int, mid: int) -> Any:
    """REQUEST_MESSAGE ``mid``: ACCEPTED, and the message."""
    gcs.mav.command_long_send(target, 1, M.MAV_CMD_REQUEST_MESSAGE, 0, mid, 0, 0, 0, 0, 0, 0)
    ack = gcs.recv_match(type="COMMAND_ACK", blocking=True, timeout=10,
                         condition=f"COMMAND_ACK.command=={M.MAV_CMD_REQUEST_MESSAGE}")
    assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
    m = gcs.recv_match(type=mavutil.mavlink.mavlink_map[mid].msgname, blocking=True, timeout=10)
    assert m is not None
    return m


def test_a_ground_station_reads_the_metadata_over_ftp_and_finds_every_event(tmp_path: Path) -> None:
    os.environ["MAVLINK20"] = "1"
    with instance_slot() as n:
        gcs = mavutil.mavlink_connection(f"udpin:127.0.0.1:{GCS_PORT + n}", source_system=255, source_component=190,
                                         dialect="common")
        sitl = Proc.bsst("sitl", "--await-mission", "--instance", str(n), "--out", str(tmp_path / "run"),
                         "--no-plots")
        try:
            assert gcs.wait_heartbeat(timeout=30) is not None
            meta = _request(gcs, n + 1, compmeta.COMPONENT_METADATA)
            assert meta.uri == "mftp://etc/extras/component_general.json"
            info = _request(gcs, n + 1, compmeta.COMPONENT_INFORMATION)
            assert (info.general_metadata_uri, info.general_metadata_file_crc) == (meta.uri, meta.file_crc)
            client = FtpClient(gcs, n + 1)
            general, _ = client.download("/" + meta.uri.removeprefix("mftp://"))  # as QGroundControl asks
            assert _mavlink_crc32(general) == meta.file_crc
            (kind,) = json.loads(general)["metadataTypes"]
            assert kind["type"] == 4 and kind["uri"].startswith("mftp://")
            events, bursts = client.download(kind["uri"].removeprefix("mftp://"))  # as the spec's examples
            assert _mavlink_crc32(events) == kind["fileCrc"] and bursts > 1
            client.send(OPEN_RO, data=b"etc/extras/all_events.json")
            client.reply()
            client.send(READ, offset=100, size=50)  # a part, as QGroundControl fills a hole
            head, part = client.reply()
            assert (head[2], head[7], part) == (ACK, 100, events[100:150])
            client.send(OPEN_RO, data=b"@PARAM/param.pck")  # no parameter file: NAKed at once
            head, err = client.reply()
            assert (head[2], err) == (NAK, bytes([10]))  # FileNotFound
        finally:
            gcs.close()
            sitl.stop()
    doc = json.loads(events)
    (comp_id, comp), = doc["components"].items()
    listed = {e["name"]: int(comp_id) << 24 | int(sub) for sub, e in comp["event_groups"]["default"]["events"].items()}
    assert {k: listed.get(k) for k in KIND_IDS} == {k: int(i) for k, i in KIND_IDS.items()}


def test_mavproxys_ftp_module_lists_and_gets_the_events_file(tmp_path: Path) -> None:
    with instance_slot() as n:
        sitl = Proc.bsst("sitl", "--await-mission", "--instance", str(n), "--out", str(tmp_path / "run"),
                         "--no-plots")
        mp = MavProxy(f"udpin:127.0.0.1:{GCS_PORT + n}", tmp_path)
        try:
            mp.wait_online()
            mark = mp.say("ftp list /etc/extras")
            mp.wait_line(lambda s: "all_events.json" in s, start=mark)
            mark = mp.say("ftp get /etc/extras/all_events.json events.json")
            mp.wait_line(lambda s: "Wrote" in s and "events.json" in s, start=mark, timeout=30)
            # MAVProxy prints 'Wrote' before it closes the file (its last chunk still in the file object's
            # buffer): stopped then, it could end first. One thread reads the link and runs typed commands, a
            # command only once the packet in hand is handled, the close included: an answer to one typed now
            # is the file complete ('No transfer in progress', or the sessions its parameter module's FTP holds)
            mark = mp.say("ftp status")
            mp.wait_line(lambda s: "No transfer in progress" in s or "FTP session" in s, start=mark)
            got = (tmp_path / "events.json").read_bytes()
        finally:
            mp.stop()
            sitl.stop()
    assert got == compmeta.FILES[compmeta.EVENTS_PATH]

"""Covers bridge.mavlink.signing: key files, and MAVLink 2 signatures byte for byte against pymavlink."""

from __future__ import annotations

import hashlib
import math
import os
import time
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from bridge.loop import simulate
from bridge.mavlink.endpoint import (
    GCS_PORT,
    HIL_ACTUATOR_CONTROLS,
    LINK_PORT,
    ODOMETRY,
    SET_ACTUATOR_CONTROL_TARGET,
    Endpoint,
    hot_frame,
    parse_address,
    parse_datagram,
)
from bridge.mavlink.receive import Rejections
from bridge.mavlink.signing import SIGNATURE_BYTES, Signing, clock_timestamp, key_from_file
from bridge.nodes.report import Ready, Stats
from bridge.session import instance_slot, sitl
from missions import Mission, Sine
from params import ConfigError
from tests.hostile import Station
from tests.sitlkit import Proc

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast

KEY = hashlib.sha256(b"bsst test key").digest()
OTHER = hashlib.sha256(b"not our key").digest()
f32 = st.floats(width=32, allow_nan=False, allow_infinity=False)


def _key_file(tmp_path, data: bytes, mode: int = 0o600):
    p = tmp_path / "key"
    p.write_bytes(data)
    p.chmod(mode)
    return p


def test_key_file_raw_and_passphrase(tmp_path):
    assert key_from_file(_key_file(tmp_path, KEY)) == KEY
    # a passphrase is hashed with SHA-256, as MAVProxy's "signing setup PASSPHRASE" does
    assert key_from_file(_key_file(tmp_path, b"correct horse battery staple\n")) == hashlib.sha256(
        b"correct horse battery staple").digest()


@pytest.mark.parametrize("data, mode, words", [
    (None, 0o600, "no such file"),
    (b"", 0o600, "empty"),
    (b"\n", 0o600, "empty"),
    (KEY, 0o644, "readable or writable by others"),
    (KEY, 0o602, "readable or writable by others"),
    (b"\xff\xfe" * 20, 0o600, "neither"),
])
def test_bad_key_files_name_the_flag_never_the_content(tmp_path, data, mode, words):
    p = tmp_path / "key" if data is None else _key_file(tmp_path, data, mode)
    with pytest.raises(ConfigError) as err:
        key_from_file(p)
    text = str(err.value)
    assert text.startswith(f"--key {p}") and words in text
    if data:
        assert data.hex() not in text and repr(data) not in text


def test_a_directory_is_not_a_key(tmp_path):
    with pytest.raises(ConfigError, match="not a regular file"):
        key_from_file(tmp_path)


@pytest.mark.parametrize("given", [5, KEY, None])
def test_a_key_that_is_no_path_is_named_never_shown(given):
    """``sitl(m, key=KEY)`` (the secret itself, not its file) or ``key=5`` raised os.fspath's bare TypeError until the
    third wave's forty-third session: it names ``key`` and the type now, never the value."""
    with pytest.raises(TypeError, match=rf"^key: expected a signing key file's path, got {type(given).__name__}$"):
        key_from_file(given)


def test_signing_never_shows_its_key():
    s = Signing(KEY, 7)
    assert KEY.hex() not in repr(s) and str(KEY) not in repr(s)


def _pymavlink(key: bytes, link_id: int, timestamp: int, sysid: int, compid: int, seq: int) -> mavlink.MAVLink:
    """pymavlink set up as mavutil's ``setup_signing`` does, at a chosen timestamp."""
    mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    mav.signing.secret_key = key
    mav.signing.sign_outgoing = True
    mav.signing.link_id = link_id
    mav.signing.timestamp = timestamp
    mav.seq = seq
    return mav


def _signed_endpoint(link_id: int, sysid: int = 200, compid: int = 191) -> Endpoint:
    return Endpoint(parse_address("udpin:127.0.0.1:0"), sysid=sysid, compid=compid, signing=Signing(KEY, link_id))


def _stamp(frame: bytes) -> int:
    return int.from_bytes(frame[-12:-6], "little")


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**63), st.lists(f32, min_size=16, max_size=16), st.integers(0, 255), st.integers(0, 255))
def test_hot_codec_signs_as_pymavlink(t, controls, link_id, seq):
    """Signed hot frames are pymavlink's bytes (setup_signing, same timestamp), and pymavlink
    with the key accepts them; with another key it refuses them."""
    ep = _signed_endpoint(link_id)
    try:
        ep.mav.seq = seq
        ours = ep.encode_hot(HIL_ACTUATOR_CONTROLS, (t, 1, *controls, 128))
        assert ours[2] == 1 and len(ours) == 12 + ours[1] + SIGNATURE_BYTES
        ref = mavlink.MAVLink_hil_actuator_controls_message(t, controls, 128, 1).pack(
            _pymavlink(KEY, link_id, _stamp(ours), 200, 191, seq))
        assert ours == ref
        ours = ep.encode_hot(SET_ACTUATOR_CONTROL_TARGET, (t, *controls[:8], 0, 7, 1))
        ref = mavlink.MAVLink_set_actuator_control_target_message(t, 0, 7, 1, controls[:8]).pack(
            _pymavlink(KEY, link_id, _stamp(ours), 200, 191, (seq + 1) & 0xFF))
        assert ours == ref
        cov = [math.nan] + [0.0] * 20
        ours = ep.encode_hot(ODOMETRY, (t, *controls[:13], *cov, *cov, 1, 12, 0, 1, 100))
        c = controls
        ref = mavlink.MAVLink_odometry_message(t, 1, 12, c[0], c[1], c[2], c[3:7], c[7], c[8], c[9], c[10], c[11],
                                               c[12], cov, cov, 0, 1, 100).pack(
            _pymavlink(KEY, link_id, _stamp(ours), 200, 191, (seq + 2) & 0xFF))
        assert ours == ref
        checker = mavlink.MAVLink(None)
        checker.signing.secret_key = KEY
        assert checker.decode(bytearray(ours)).get_type() == "ODOMETRY"
        checker.signing.secret_key = OTHER
        checker.signing.stream_timestamps.clear()
        with pytest.raises(mavlink.MAVError, match="signature"):
            checker.decode(bytearray(ours))
    finally:
        ep.close()


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 255), st.integers(0, 255), st.floats(allow_nan=False, allow_infinity=False, width=32))
def test_other_messages_are_signed_as_pymavlink(link_id, seq, p1):
    """A message pymavlink packs unsigned, signed by :meth:`Signing.resign`: pymavlink's bytes."""
    s = Signing(KEY, link_id)
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    mav.seq = seq
    for msg in (mavlink.MAVLink_heartbeat_message(2, 8, 128, 0, 4, 3),
                mavlink.MAVLink_command_long_message(1, 1, 400, 0, p1, 0, 0, 0, 0, 0, 0),
                mavlink.MAVLink_statustext_message(4, b"rejected 3: bad_crc 3")):
        mav.seq = seq
        ours = s.resign(msg.pack(mav))
        mav.seq = seq
        assert ours == msg.pack(_pymavlink(KEY, link_id, _stamp(ours), 1, 1, seq))


def test_verify_accepts_pymavlink_signed_and_refuses_unsigned_forged_replayed():
    gcs = _pymavlink(KEY, 2, clock_timestamp(), 255, 190, 0)
    forger = _pymavlink(OTHER, 2, clock_timestamp() + 1000, 255, 190, 0)
    plain = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    arm = mavlink.MAVLink_command_long_message(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
    v = Signing(KEY, 0)
    good = arm.pack(gcs)
    assert v.verify(good, 255, 190) is None
    assert v.verify(good, 255, 190) == "replayed"  # the same frame again
    assert v.verify(arm.pack(plain), 255, 190) == "unsigned"
    assert v.verify(arm.pack(forger), 255, 190) == "bad_signature"
    # a forged frame with a later timestamp did not move the stream on: the owner still gets in
    assert v.verify(arm.pack(gcs), 255, 190) is None
    # an old recording of a stream never seen is refused (more than a minute behind our clock)
    old = _pymavlink(KEY, 9, clock_timestamp() - 7_000_000, 255, 190, 0)
    assert v.verify(arm.pack(old), 255, 190) == "replayed"


def test_links_sharing_a_replay_table_refuse_a_frame_replayed_across_them():
    """One table per system (sysid, compid, link id -> newest timestamp), as the MAVLink 2
    signing specification keeps it: a frame accepted on one link is a replay on the other.
    Two tables (one per link) would take it twice."""
    arm = mavlink.MAVLink_command_long_message(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0).pack(
        _pymavlink(KEY, 4, clock_timestamp(), 200, 191, 0))
    table: dict = {}
    link, gcs = Signing(KEY, 0, table), Signing(KEY, 1, table)
    assert link.verify(arm, 200, 191) is None and gcs.verify(arm, 200, 191) == "replayed"
    apart = Signing(KEY, 0), Signing(KEY, 1)
    assert [s.verify(arm, 200, 191) for s in apart] == [None, None]  # what one table per link let through


def test_the_receive_path_counts_each_kind_and_decodes_the_rest():
    gcs = _pymavlink(KEY, 1, clock_timestamp(), 255, 190, 0)
    hb = mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3)
    rej = Rejections()
    v = Signing(KEY, 0)
    dec = mavlink.MAVLink(None)
    good = hb.pack(gcs)
    assert [m.get_type() for m in parse_datagram(good, dec, v, rej)] == ["HEARTBEAT"]
    assert parse_datagram(good, dec, v, rej) == []
    assert parse_datagram(hb.pack(mavlink.MAVLink(None, 255, 190)), dec, v, rej) == []
    assert parse_datagram(hb.pack(_pymavlink(OTHER, 1, clock_timestamp(), 255, 190, 0)), dec, v, rej) == []
    assert rej == {"replayed": 1, "unsigned": 1, "bad_signature": 1}
    # the hot path only frames a signed hot message; its signature is the caller's to check
    ep = _signed_endpoint(0)
    frame = ep.encode_hot(HIL_ACTUATOR_CONTROLS, (5, 1, *([0.5] * 16), 128))
    ep.close()
    assert hot_frame(frame) is not None and v.verify(frame, 200, 191) is None
    assert hot_frame(frame[:-1]) is None


def test_key_file_mode_is_checked_before_reading(tmp_path):
    p = _key_file(tmp_path, KEY, 0o604)
    with pytest.raises(ConfigError):
        key_from_file(p)
    os.chmod(p, 0o600)
    assert key_from_file(p) == KEY


# -- with real processes: a signed vehicle, a signed ground station, a signed session ------------
HOLD = 'name = "hold"\nduration_s = 600.0\n[trajectory]\nkind = "sine"\n[failsafe]\ntimeout_s = 30.0\n'


def _heartbeat_now(gcs) -> Any:
    """Ask the vehicle for a HEARTBEAT now (signed REQUEST_MESSAGE) and return it: the vehicle
    handles its messages in order, so this shows the state after everything sent before."""
    gcs.mav.command_long_send(gcs.target_system, 1, mavlink.MAV_CMD_REQUEST_MESSAGE, 0,
                              mavlink.MAVLINK_MSG_ID_HEARTBEAT, 0, 0, 0, 0, 0, 0)
    hb = gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=10, condition="HEARTBEAT.get_srcSystem() != 255")
    assert hb is not None
    return hb


def _armed(hb) -> bool:
    return bool(hb.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)


def _ack(conn, command: int) -> Any:
    m = conn.recv_match(type="COMMAND_ACK", blocking=True, timeout=10, condition=f"COMMAND_ACK.command=={command}")
    assert m is not None, f"no COMMAND_ACK for {command}"
    return m


def test_signed_vehicle_refuses_unsigned_forged_and_replayed_commands_and_targets(tmp_path):
    """With --key: every unsigned, forged (other key) and replayed ARM, DISARM and actuator
    target is refused and counted by kind; a pymavlink ground station with setup_signing arms
    and disarms; nothing of the key is in the files or in the vehicle's command line."""
    key = _key_file(tmp_path, KEY)
    mission = tmp_path / "hold.toml"
    mission.write_text(HOLD)
    os.environ["MAVLINK20"] = "1"
    sent = {"unsigned": 0, "bad_signature": 0, "replayed": 0}
    with instance_slot() as n:
        gcs = mavutil.mavlink_connection(f"udpin:127.0.0.1:{GCS_PORT + n}", source_system=255,
                                         source_component=190, dialect="common")
        gcs.setup_signing(KEY, sign_outgoing=True)
        v = Proc.bsst("vehicle", str(mission), "--instance", str(n), "--out", str(tmp_path / "v"), "--key", str(key))
        ctl = None
        try:
            v.wait_report(Ready)
            with open(f"/proc/{v.p.pid}/cmdline", "rb") as f:
                cmdline = f.read()
            assert KEY not in cmdline and KEY.hex().encode() not in cmdline and str(key).encode() in cmdline
            assert gcs.wait_heartbeat(timeout=20) is not None  # signed, and pymavlink checked it with the key
            sysid = gcs.target_system
            plain = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
            forger = _pymavlink(OTHER, 0, clock_timestamp(), 255, 190, 0)

            def arm(p1: float, p2: float = 0.0) -> Any:
                return mavlink.MAVLink_command_long_message(sysid, 1, 400, 0, p1, p2, 0, 0, 0, 0, 0)

            def bad(conn, msg) -> None:
                for packer, kind in ((plain, "unsigned"), (forger, "bad_signature")):
                    for _ in range(3):
                        conn.write(msg.pack(packer))
                        sent[kind] += 1

            def replay(conn, frame: bytes) -> None:
                for _ in range(3):
                    conn.write(frame)
                    sent["replayed"] += 1

            bad(gcs, arm(1))
            assert not _armed(_heartbeat_now(gcs))  # none of them armed it
            # the signed controller speaks on its link (the vehicle answers with its heartbeat), and OFFBOARD is
            # selected for the arm (signed): the vehicle boots in HOLD, as PX4's, where its targets would not be taken
            ctl = mavutil.mavlink_connection(f"udpout:127.0.0.1:{LINK_PORT + n}", source_system=200,
                                             source_component=191, dialect="common")
            ctl.setup_signing(KEY, sign_outgoing=True)
            deadline = time.monotonic() + 10.0  # heartbeats until the vehicle's answers (a stranger is on trial:
            while True:  # its first small message earns too little to be answered, as bsst controller meets it)
                ctl.mav.heartbeat_send(mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 4)
                if ctl.recv_match(type="HEARTBEAT", blocking=True, timeout=0.2) is not None:
                    break
                assert time.monotonic() < deadline, "the vehicle never answered the controller's heartbeats"
            gcs.mav.command_long_send(sysid, 1, mavlink.MAV_CMD_DO_SET_MODE, 0, 29, 6, 0, 0, 0, 0, 0)
            assert _ack(gcs, mavlink.MAV_CMD_DO_SET_MODE).result == mavlink.MAV_RESULT_ACCEPTED
            good_arm = arm(1).pack(gcs.mav)
            gcs.write(good_arm)
            assert _ack(gcs, 400).result == mavlink.MAV_RESULT_ACCEPTED
            assert _armed(_heartbeat_now(gcs))

            # actuator targets on the controller link: the signed controller steps the vehicle (a flight armed from
            # a ground station learns its controller afresh: it speaks again)
            ctl.mav.heartbeat_send(mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 4)
            odo = ctl.recv_match(type="ODOMETRY", blocking=True, timeout=10)
            assert odo is not None
            k_usec = odo.time_usec
            target = mavlink.MAVLink_set_actuator_control_target_message(k_usec, 0, sysid, 1,
                                                                         [0.0, 0.0, 0.0, 0.245, 0, 0, 0, 0])
            bad(ctl, target)
            good_target = target.pack(ctl.mav)
            ctl.write(good_target)
            assert ctl.recv_match(type="ODOMETRY", blocking=True, timeout=10,
                                  condition=f"ODOMETRY.time_usec > {k_usec}") is not None  # it stepped
            replay(ctl, good_target)

            bad(gcs, arm(0, 21196))
            assert _armed(_heartbeat_now(gcs))  # none of them disarmed it
            good_disarm = arm(0, 21196).pack(gcs.mav)
            gcs.write(good_disarm)
            assert _ack(gcs, 400).result == mavlink.MAV_RESULT_ACCEPTED
            assert not _armed(_heartbeat_now(gcs))
            replay(gcs, good_arm)
            replay(gcs, good_disarm)
            assert not _armed(_heartbeat_now(gcs))  # a replayed ARM did not arm it again
        finally:
            assert v.stop() == 0
            gcs.close()
            if ctl is not None:
                ctl.close()
    stats = v.wait_report(Stats).values
    assert stats["rejected"] == sent and all(n == 9 for n in sent.values()), (stats["rejected"], sent)
    _assert_key_nowhere(tmp_path / "v")


def _assert_key_nowhere(run: Path) -> None:
    files = [f for f in run.rglob("*") if f.is_file()]
    assert files
    for f in files:
        data = f.read_bytes()
        for needle in (KEY, KEY.hex().encode(), KEY.hex().upper().encode()):
            assert needle not in data, f"{f} holds the key"


def test_signed_session_flies_and_never_writes_the_key(tmp_path):
    """bsst sitl --key: both sides sign, the flight is the unsigned one (its offline twin's trace.csv, which an
    unsigned lockstep session's is to the byte: tests/test_sitl.py), and the key is in no file."""
    key = _key_file(tmp_path, KEY)
    mission = Mission(Sine(), duration_s=2.0, name="signed")
    simulate(mission, out=tmp_path / "plain", plots=False)
    run = sitl(mission, out=tmp_path / "signed", plots=True, instance=None, key=key)
    assert run.outcome == "completed" and run.summary["sitl"]["signed"] is True
    assert run.summary["link"]["rejected"] == {}
    assert (tmp_path / "signed" / "trace.csv").read_bytes() == (tmp_path / "plain" / "trace.csv").read_bytes()
    frames = (tmp_path / "signed" / "vehicle.tlog").read_bytes()
    assert frames[8] == 0xFD and frames[8 + 2] & 1  # the first record (8-byte stamp, frame) is signed
    _assert_key_nowhere(tmp_path / "signed")


def test_a_signed_frame_replayed_from_one_link_onto_the_other_is_refused(tmp_path):
    """Issue 11, finding 4, against a real ``bsst vehicle --key``: the controller's signed ARM,
    replayed onto the GCS link (which obeys any ground station) once a ground station has
    disarmed the vehicle, does not arm it again; a ground station's signed request replayed
    onto the controller link is refused too. Both count as ``replayed``: the vehicle keeps
    one replay table for its two links."""
    key = _key_file(tmp_path, KEY)
    with instance_slot() as n:
        v = Proc.bsst("vehicle", "--instance", str(n), "--out", str(tmp_path / "v"), "--key", str(key))
        gcs = ctl = None
        try:
            v.wait_report(Ready)
            gcs = Station((255, 190), port=GCS_PORT + n, key=KEY, link_id=3)
            gcs.wait(lambda m: m.get_type() == "HEARTBEAT", 20, "the vehicle's heartbeat")
            ctl = Station((200, 191), ("127.0.0.1", LINK_PORT + n), key=KEY, link_id=4)
            arm = ctl.command(400, 1.0, target=(n + 1, 1))
            assert ctl.ack(400) == mavlink.MAV_RESULT_ACCEPTED
            gcs.command(400, 0.0, 21196.0, target=(n + 1, 1))
            assert gcs.ack(400) == mavlink.MAV_RESULT_ACCEPTED
            gcs.send_raw(arm)  # the controller's ARM, from the ground station's address
            asked = gcs.command(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_HEARTBEAT, target=(n + 1, 1))
            assert gcs.ack(mavlink.MAV_CMD_REQUEST_MESSAGE) == mavlink.MAV_RESULT_ACCEPTED  # after the replay
            hb = [m for m in gcs.seen if m.get_type() == "HEARTBEAT"][-1]  # the one asked for (it came with the ACK)
            assert not _armed(hb)
            ctl.send_raw(asked)  # the ground station's request, from the controller's address
            ctl.command(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_HEARTBEAT, target=(n + 1, 1))
            assert ctl.ack(mavlink.MAV_CMD_REQUEST_MESSAGE) == mavlink.MAV_RESULT_ACCEPTED
        finally:
            rc = v.stop()
            for st_ in (gcs, ctl):
                if st_ is not None:
                    st_.close()
    assert rc == 0
    stats = v.wait_report(Stats).values
    assert stats["rejected"] == {"replayed": 2}, stats["rejected"]

"""Covers bridge.nodes.vehicle and bridge.mavlink.receive.

Who may command the vehicle, with what numbers, at what cost (issue 11; docs/design.md,
"Authority"): real ``bsst vehicle`` and ``bsst sitl`` processes over real UDP on 127.0.0.1,
real pymavlink frames; and a hypothesis property over every message the vehicle handles,
into a real vehicle object on real loopback sockets.

- bad numbers (NaN, +-inf, fractions, out of range) in every command parameter the vehicle
  uses, on both links, signed or not: DENIED and counted, never a traceback;
- the controller link obeys only the flight's controller (its ids, from the address its
  flight is on); interval requests there change only what the controller link gets; every
  arm, disarm and interval change is an event naming its sender;
- a packed flood (40 frames a datagram) neither slows a lockstep flight nor is amplified.
"""

from __future__ import annotations

import contextlib
import functools
import json
import math
import re
import socket
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, example, given, note, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import common as mavlink

from bridge.autopilot.simvehicle import OFFBOARD
from bridge.core.flight import prepare
from bridge.loop import simulate
from bridge.mavlink.endpoint import CONTROLLER_COMPID, CONTROLLER_SYSID, GCS_PORT, LINK_PORT, Endpoint, parse_address
from bridge.mavlink.receive import REPLY_RATE_HZ, RateLimiter, ReplyBudget
from bridge.nodes.report import Ready, Stats
from bridge.nodes.vehicle import Vehicle, VehicleConfig
from bridge.record.halves import count_records
from bridge.session import instance_slot
from missions import Mission, Sine
from tests.hostile import Flood, Station, drop_held_answer, packed_requests, vehicle_state
from tests.sitlkit import Proc
from tests.waiting import wait_for

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast

M = mavlink
KEY = bytes(range(100, 132))
ARM = M.MAV_CMD_COMPONENT_ARM_DISARM
SET_IV = M.MAV_CMD_SET_MESSAGE_INTERVAL
GET_IV = M.MAV_CMD_GET_MESSAGE_INTERVAL
REQ = M.MAV_CMD_REQUEST_MESSAGE
ATT = M.MAVLINK_MSG_ID_ATTITUDE
NAN, INF = math.nan, math.inf
# (command, param1, param2): every one has a number the vehicle must refuse (bad_number, DENIED)
BAD = [(SET_IV, NAN, 1e4), (SET_IV, INF, 1e4), (SET_IV, -INF, 1e4), (SET_IV, 33.5, 1e4), (SET_IV, -1.0, 1e4),
       (SET_IV, 2.0**24, 1e4), (SET_IV, ATT, NAN), (SET_IV, ATT, INF), (SET_IV, ATT, -5.0), (SET_IV, ATT, 1e12),
       (GET_IV, NAN, 0.0), (GET_IV, INF, 0.0), (GET_IV, -INF, 0.0), (REQ, NAN, 0.0), (REQ, -INF, 0.0),
       (REQ, 1e30, 0.0), (ARM, NAN, 0.0), (ARM, 0.5, 0.0), (ARM, INF, 0.0), (ARM, -1.0, 0.0), (ARM, 2.0, 0.0)]
TAG = re.compile(r" \[by (\d+):(\d+) ([\d.]+):(\d+) (controller|gcs)\]$")


@contextlib.contextmanager
def _vehicle(n: int, out: Path, *extra: str) -> Iterator[Proc]:
    """``bsst vehicle`` on instance ``n``, ready; stopped (SIGTERM) whatever happens."""
    v = Proc.bsst("vehicle", "--instance", str(n), "--out", str(out), *extra)
    try:
        v.wait_report(Ready)
        yield v
    finally:
        v.stop()


def _stats(v: Proc) -> dict[str, Any]:
    return v.wait_report(Stats).values


def _events(v: Proc) -> list[str]:
    """The vehicle's events as a person reads them (``kind: text [by ...]``), in order."""
    return v.events()


def _stations(n: int, key: bytes | None = None) -> tuple[Station, Station]:
    """A ground station on the instance's GCS port (it has heard the vehicle) and the
    configured controller (200:191) on the controller link (the vehicle has learned it)."""
    gcs = Station((255, 190), port=GCS_PORT + n, key=key, link_id=3)
    ctl = Station((200, 191), ("127.0.0.1", LINK_PORT + n), key=key, link_id=4)
    try:
        gcs.wait(lambda m: m.get_type() == "HEARTBEAT", 20, "the vehicle's heartbeat")
        ctl.send(M.MAVLink_heartbeat_message(M.MAV_TYPE_ONBOARD_CONTROLLER, M.MAV_AUTOPILOT_INVALID, 0, 0, 4, 3))
        ctl.wait(lambda m: m.get_type() == "ODOMETRY", 10, "ODOMETRY at the controller")
    except BaseException:
        gcs.close()  # the GCS port is the next test's
        ctl.close()
        raise
    return gcs, ctl


def _armed(gcs: Station) -> bool:
    """The vehicle's state after everything sent before (it handles its messages in order):
    the HEARTBEAT asked for, which comes with the request's COMMAND_ACK (or a newer one)."""
    gcs.command(REQ, M.MAVLINK_MSG_ID_HEARTBEAT)
    assert gcs.ack(REQ) == M.MAV_RESULT_ACCEPTED
    hb = [m for m in gcs.seen if m.get_type() == "HEARTBEAT"][-1]
    return bool(hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)


def _step(ctl: Station, thrust: float, sysid: int, usec: int) -> int:
    """Answer the state stamped ``usec`` with a wrench target (paper profile) and wait for the
    next one (the step is flown): its stamp."""
    ctl.send(M.MAVLink_set_actuator_control_target_message(usec, 0, sysid, 1, [0.0, 0.0, 0.0, thrust, 0, 0, 0, 0]))
    odo = ctl.wait(lambda m: m.get_type() == "ODOMETRY" and m.time_usec > usec, 10, f"the state after {usec} us")
    return odo.time_usec


@pytest.mark.parametrize("signed", [False, True], ids=["unsigned", "signed"])
def test_bad_numbers_are_denied_on_both_links_never_a_traceback(tmp_path, signed):
    """Finding 1: NaN, +-inf, fractions and out-of-range values in SET/GET_MESSAGE_INTERVAL,
    REQUEST_MESSAGE and ARM_DISARM, as COMMAND_LONG and COMMAND_INT, from the controller and
    from a ground station, on the ground and in the air (with --key: correctly signed): each
    is DENIED and counted ``bad_number``, nothing changes (not armed by them, the GCS streams
    flow on), and the vehicle lives on to exit 0."""
    key = tmp_path / "key"
    key.write_bytes(KEY)
    key.chmod(0o600)
    with instance_slot() as n, _vehicle(n, tmp_path / "v", *(["--key", str(key)] if signed else [])) as v:
        gcs, ctl = _stations(n, KEY if signed else None)
        sent = 0
        try:
            for st_ in (gcs, ctl):
                for as_int in (False, True):
                    for cmd, p1, p2 in BAD:
                        st_.command(cmd, p1, p2, as_int=as_int)
                        assert st_.ack(cmd) == M.MAV_RESULT_DENIED, (cmd, p1, p2, as_int)
                        sent += 1
            assert not _armed(gcs)
            att = gcs.got["ATTITUDE"]
            gcs.wait(lambda m: m.get_type() == "ATTITUDE", 5, "ATTITUDE after the bad intervals")
            assert gcs.got["ATTITUDE"] > att
            # in the air: armed by the controller, one step of climbing thrust
            ctl.command(ARM, 1.0)
            assert ctl.ack(ARM) == M.MAV_RESULT_ACCEPTED
            usec = _step(ctl, 0.5, n + 1, 0)
            for st_ in (gcs, ctl):
                for as_int in (False, True):
                    st_.command(ARM, 0.0, NAN, as_int=as_int)  # not forced: in the air, refused as PX4 refuses it
                    assert st_.ack(ARM) == M.MAV_RESULT_TEMPORARILY_REJECTED
                    for cmd, p1, p2 in ((ARM, NAN, 21196.0), (SET_IV, NAN, 1e4), (REQ, INF, 0.0)):
                        st_.command(cmd, p1, p2, as_int=as_int)
                        assert st_.ack(cmd) == M.MAV_RESULT_DENIED
                        sent += 1
                    usec = _step(ctl, 0.3, n + 1, usec)  # the lockstep flight goes on between commands
            assert _armed(gcs)
        finally:
            gcs.close()
            ctl.close()
    assert v.p.returncode == 0
    assert not any("Traceback" in ln for ln in v.lines), "\n".join(v.lines[-20:])
    assert _stats(v)["rejected"] == {"bad_number": sent}


def test_the_controller_link_obeys_only_the_flights_controller(tmp_path):
    """Finding 2, against a real vehicle: on the controller link, another system's ARM,
    forced DISARM and SET_MESSAGE_INTERVAL -1 are DENIED (``not_authorised``); once a flight
    is on, the controller's own ids from another address are a ``stranger``'s (a spoofed
    HEARTBEAT does not take the states away); the controller's interval requests change only
    its own link's streams; each arm, disarm and interval change is an event naming its
    sender, a ground station's too."""
    with instance_slot() as n, _vehicle(n, tmp_path / "v") as v:
        sysid = n + 1
        gcs, ctl = _stations(n)
        other = Station((201, 191), ("127.0.0.1", LINK_PORT + n))
        spoof = Station((200, 191), ("127.0.0.1", LINK_PORT + n))
        try:
            other.command(ARM, 1.0)
            assert other.ack(ARM) == M.MAV_RESULT_DENIED
            other.command(SET_IV, ATT, -1.0)
            assert other.ack(SET_IV) == M.MAV_RESULT_DENIED
            assert not _armed(gcs)
            ctl.command(ARM, 1.0)
            assert ctl.ack(ARM) == M.MAV_RESULT_ACCEPTED
            for _ in range(20):
                spoof.send(M.MAVLink_heartbeat_message(M.MAV_TYPE_ONBOARD_CONTROLLER, M.MAV_AUTOPILOT_INVALID,
                                                       0, 0, 4, 3))
            spoof.command(ARM, 0.0, 21196.0)
            assert spoof.ack(ARM) == M.MAV_RESULT_DENIED
            other.command(ARM, 0.0, 21196.0)
            assert other.ack(ARM) == M.MAV_RESULT_DENIED
            usec = 0
            for _ in range(5):
                usec = _step(ctl, 0.2, sysid, usec)  # under the hover thrust: it stays on the ground
            assert usec == 5 * 4000 and _armed(gcs)  # stepped on, still armed
            # intervals asked on the controller link: its own streams only
            ctl.command(SET_IV, ATT, 1e5)
            assert ctl.ack(SET_IV) == M.MAV_RESULT_ACCEPTED
            ctl.wait(lambda m: m.get_type() == "ATTITUDE", 5, "ATTITUDE on the controller link")
            ctl.command(SET_IV, M.MAVLINK_MSG_ID_LOCAL_POSITION_NED, -1.0)
            assert ctl.ack(SET_IV) == M.MAV_RESULT_ACCEPTED
            gcs.command(GET_IV, M.MAVLINK_MSG_ID_LOCAL_POSITION_NED)
            iv = gcs.wait(lambda m: m.get_type() == "MESSAGE_INTERVAL", 5, "MESSAGE_INTERVAL")
            assert iv.interval_us == 40000  # the GCS link's stream is untouched
            seen = gcs.got["LOCAL_POSITION_NED"]
            gcs.wait(lambda m: m.get_type() == "LOCAL_POSITION_NED", 5, "LOCAL_POSITION_NED at the GCS")
            assert gcs.got["LOCAL_POSITION_NED"] > seen
            ctl.command(ARM, 0.0, 21196.0)
            assert ctl.ack(ARM) == M.MAV_RESULT_ACCEPTED
            # a ground station has authority: it arms and disarms (on the ground: not forced)
            gcs.command(ARM, 1.0)
            assert gcs.ack(ARM) == M.MAV_RESULT_ACCEPTED
            gcs.command(ARM, 0.0)
            assert gcs.ack(ARM) == M.MAV_RESULT_ACCEPTED
            spoof.poll()
            other.poll()
        finally:
            for s in (gcs, ctl, other, spoof):
                s.close()
    assert v.p.returncode == 0
    assert spoof.got["ODOMETRY"] == 0 and other.got["ODOMETRY"] == 0  # the states went to the controller only
    stats = _stats(v)
    assert stats["rejected"] == {"not_authorised": 3, "stranger": 21}, stats["rejected"]
    c = f"[by 200:191 127.0.0.1:{ctl.addr[1]} controller]"
    g = f"[by 255:190 127.0.0.1:{GCS_PORT + n} gcs]"
    assert _events(v) == [
        f"armed: armed, offboard control {c}",
        f"interval: ATTITUDE every 0.1 s on the controller link {c}",
        f"disarmed: disarmed by command (forced) {c}",
        f"armed: armed, offboard control {g}",
        f"disarmed: disarmed by command {g}",
    ]


def test_a_pinned_controller_address_leaves_a_stranger_nothing_even_before_the_flight(tmp_path):
    """The gap an address learned from the first message leaves (docs/design.md, "Not enforced"),
    closed by ``--controller-from`` (what ``bsst sitl`` passes): before any flight, a process
    claiming 200:191 from another address is a ``stranger`` (its ARM DENIED, no state sent to
    it); the controller from the pinned address arms and flies, and is named in the events."""
    ctl = Station((200, 191))  # bound first: its port is the one the vehicle is told
    with instance_slot() as n, _vehicle(n, tmp_path / "v", "--controller-from", f"127.0.0.1:{ctl.addr[1]}") as v:
        ctl.dest = ("127.0.0.1", LINK_PORT + n)
        gcs = Station((255, 190), port=GCS_PORT + n, link_id=3)
        thief = Station((200, 191), ("127.0.0.1", LINK_PORT + n))
        try:
            gcs.wait(lambda m: m.get_type() == "HEARTBEAT", 20, "the vehicle's heartbeat")
            thief.send(M.MAVLink_heartbeat_message(M.MAV_TYPE_ONBOARD_CONTROLLER, M.MAV_AUTOPILOT_INVALID, 0, 0, 4, 3))
            thief.command(ARM, 1.0)
            assert thief.ack(ARM) == M.MAV_RESULT_DENIED  # no flight on, the ids right: refused all the same
            assert not _armed(gcs)
            ctl.command(ARM, 1.0)
            assert ctl.ack(ARM) == M.MAV_RESULT_ACCEPTED
            usec = ctl.wait(lambda m: m.get_type() == "ODOMETRY", 10, "ODOMETRY at the controller").time_usec
            for _ in range(3):
                usec = _step(ctl, 0.2, n + 1, usec)
            assert _armed(gcs)
            thief.command(ARM, 0.0, 21196.0)
            assert thief.ack(ARM) == M.MAV_RESULT_DENIED
            assert _armed(gcs)
            thief.poll()
        finally:
            for st_ in (gcs, ctl, thief):
                st_.close()
    assert v.p.returncode == 0
    assert thief.got["ODOMETRY"] == 0
    assert _stats(v)["rejected"] == {"stranger": 3}
    assert _events(v)[0] == f"armed: armed, offboard control [by 200:191 127.0.0.1:{ctl.addr[1]} controller]"


def test_a_ping_is_answered_to_its_sender_and_an_answer_is_not(tmp_path):
    """PING with no target (MAVSDK sends one at connect to measure the link) is answered with
    the same sequence and time, addressed to the sender, on either link; a PING addressed to
    someone (an answer) gets nothing back."""
    with instance_slot() as n, _vehicle(n, tmp_path / "v") as v:
        gcs, ctl = _stations(n)
        try:
            for st_, ids in ((gcs, (255, 190)), (ctl, (200, 191))):
                st_.send(M.MAVLink_ping_message(123456789, 42, 0, 0))
                pong = st_.wait(lambda m: m.get_type() == "PING", 5, "the PING answer")
                assert (pong.time_usec, pong.seq, pong.target_system, pong.target_component) == (123456789, 42, *ids)
                assert pong.get_srcSystem() == n + 1
                st_.send(M.MAVLink_ping_message(5, 6, 7, 8))  # an answer to someone: no reply
                st_.command(REQ, M.MAVLINK_MSG_ID_HEARTBEAT)  # handled in order: its ACK comes after any reply
                assert st_.ack(REQ) == M.MAV_RESULT_ACCEPTED
                assert [m.seq for m in st_.seen if m.get_type() == "PING"] == [42]
        finally:
            gcs.close()
            ctl.close()
    assert v.p.returncode == 0


STRANGE_MISSION = 'name = "strangers"\nduration_s = 10.0\n[trajectory]\nkind = "sine"\n'
DEFAULT_STREAM_IDS = (M.MAVLINK_MSG_ID_ATTITUDE, M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION,
                      M.MAVLINK_MSG_ID_LOCAL_POSITION_NED, M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT,
                      M.MAVLINK_MSG_ID_SYS_STATUS, M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE,
                      M.MAVLINK_MSG_ID_ACTUATOR_OUTPUT_STATUS, M.MAVLINK_MSG_ID_VFR_HUD)
GCS_BAD = ((SET_IV, NAN, 1e4), (SET_IV, ATT, INF), (ARM, NAN, 0.0), (REQ, -INF, 0.0))


def test_strangers_and_bad_numbers_during_a_lockstep_session_change_nothing(tmp_path):
    """Findings 1 and 2 end to end: during a lockstep ``bsst sitl`` flight, another system
    arms, force-disarms and switches every GCS stream off on the controller link, a stranger
    with the controller's ids spoofs its HEARTBEAT at 200 Hz for a second and sends a forced
    DISARM, and the ground station sends commands with NaN and infinite numbers: the trace is
    the undisturbed flight's byte for byte (flown offline: a lockstep session's trace.csv is its offline twin's to
    the byte, tests/test_sitl.py), the mission completes, every refusal is counted,
    the GCS streams flow on, the states go to the controller only, and events.log names the
    controller as the only one who armed the vehicle (it disarms itself, landed after the mission)."""
    mission = tmp_path / "m.toml"
    mission.write_text(STRANGE_MISSION)
    ref = simulate(mission, out=tmp_path / "ref", plots=False).summary
    seen: dict[str, Any] = {}
    run = _fly(mission, tmp_path / "run", seen)
    assert ref["outcome"] == run["outcome"] == "completed"
    assert seen["flown"] < 2500, "the mission ended before the attack did: fly longer"
    assert (tmp_path / "run" / "trace.csv").read_bytes() == (tmp_path / "ref" / "trace.csv").read_bytes()
    assert run["link"]["rejected_by"]["vehicle"] == {
        "not_authorised": 2 + len(DEFAULT_STREAM_IDS), "stranger": seen["spoofed"] + 1, "bad_number": len(GCS_BAD)}
    assert run["link"]["rejected_by"]["controller"] == {}
    assert seen["spoof_replies"] == 0 and seen["other_odometry"] == 0  # no state went to a stranger
    assert seen["attitude_after"] > seen["attitude_before"]  # the GCS streams flowed on
    log = (tmp_path / "run" / "events.log").read_text().splitlines()
    who = [TAG.search(ln.removesuffix(" [vehicle]")) for ln in log
           if ln.endswith(" [vehicle]") and re.match(r"t=\S+ (armed|disarmed): ", ln)]
    assert len(who) == 2 and who[0] and who[0].group(1, 2, 5) == ("200", "191", "controller"), log
    # the disarm is the vehicle's own, on the ground after the mission's landing ([end] action): nobody else's
    assert [ln for ln in log if re.match(r"t=\S+ disarmed: ", ln)] == [
        ln for ln in log if ln.endswith("disarmed: landed: disarmed [by vehicle] [vehicle]")], log


def _fly(mission: Path, out: Path, seen: dict[str, Any]) -> dict[str, Any]:
    """``bsst sitl`` lockstep at 3x real time, attacked (:func:`_attack`) once the vehicle is past step 10,
    what the attackers saw put into ``seen``. The summary."""
    with instance_slot() as n:
        gcs = Station((255, 190), port=GCS_PORT + n)
        p = Proc.bsst("sitl", str(mission), "--out", str(out), "--instance", str(n), "--speed", "3", "--no-plots")
        try:
            _attack(n, out, gcs, p, seen)
            p.p.wait(timeout=120)
        finally:
            p.stop()
            gcs.close()
    return json.loads((out / "summary.json").read_text())


def _attack(n: int, out: Path, gcs: Station, p: Proc, seen: dict[str, Any]) -> None:
    """Once instance ``n``'s flight is past step 10: another system's ARM, forced DISARM and
    streams off; a second of spoofed controller heartbeats and a spoofed forced DISARM; the
    ground station's bad numbers (each DENIED). What the attackers saw goes into ``seen``."""
    wait_for(lambda: count_records(out / "vehicle.bin") > 10 or p.p.poll() is not None, 60, "the flight starting")
    assert p.p.poll() is None, "the session ended before the attack"
    to = (n + 1, 1)
    other = Station((201, 191), ("127.0.0.1", LINK_PORT + n))
    spoof = Station((200, 191), ("127.0.0.1", LINK_PORT + n))
    hb = spoof.frame(M.MAVLink_heartbeat_message(M.MAV_TYPE_ONBOARD_CONTROLLER, M.MAV_AUTOPILOT_INVALID, 0, 0, 4, 3))
    flood = Flood(LINK_PORT + n, 200.0, n + 1, datagrams=[hb])  # the spoofed heartbeat, 200 Hz from one address
    try:
        gcs.poll()
        seen["attitude_before"] = gcs.got["ATTITUDE"]
        flood.start()
        other.command(ARM, 1.0, target=to)
        other.command(ARM, 0.0, 21196.0, target=to)
        for mid in DEFAULT_STREAM_IDS:
            other.command(SET_IV, mid, -1.0, target=to)
        spoof.command(ARM, 0.0, 21196.0, target=to)
        for cmd, p1, p2 in GCS_BAD:
            gcs.command(cmd, p1, p2, target=to)
            assert gcs.ack(cmd) == M.MAV_RESULT_DENIED
        wait_for(lambda: flood.sent >= 200, 10, "a second of spoofed heartbeats")
    finally:
        flood.stop()
    seen["spoofed"] = flood.sent
    seen["spoof_replies"] = flood.replies
    gcs.wait(lambda m: m.get_type() == "ATTITUDE", 5, "ATTITUDE after the attack")
    seen["attitude_after"] = gcs.got["ATTITUDE"]
    seen["flown"] = count_records(out / "vehicle.bin")
    for s in (other, spoof):
        s.poll()
    seen["other_odometry"] = other.got["ODOMETRY"] + spoof.got["ODOMETRY"]
    other.close()
    spoof.close()


# 3 s (1.5 s of wall each at 2x), ending in hold: a land and COM_DISARM_LAND would fly ~3.5 s more, flooded, that
# nothing here reads (it was a 6 s sine that landed: the rates and counts are per second of the flight)
FLOOD_MISSION = 'name = "packed"\nduration_s = 3.0\n[trajectory]\nkind = "sine"\n[end]\naction = "hold"\n'


def test_a_packed_flood_neither_slows_lockstep_nor_is_amplified(tmp_path):
    """Finding 3: one source sends 900 datagrams/s (under its 1000/s) of 40 REQUEST_MESSAGE
    frames each (36 000 requests/s, each asking for the vehicle's longest answer) to the
    controller link of a lockstep ``bsst sitl`` at 2x real time: the flight keeps its step
    rate (at least half the slower of two clean runs flown before and after it, on the same
    machine at the same time; unbounded it fell to a few per cent), the flooder gets back
    fewer datagrams and bytes than it sent and at most the reply budget, and the excess is
    refused and counted (``rate_limited``)."""
    mission = tmp_path / "m.toml"
    mission.write_text(FLOOD_MISSION)
    before, _ = _fly_packed(mission, tmp_path / "clean1", flood=False)
    flooded, flood = _fly_packed(mission, tmp_path / "flood", flood=True)
    after, _ = _fly_packed(mission, tmp_path / "clean2", flood=False)
    assert before["outcome"] == flooded["outcome"] == after["outcome"] == "completed"
    rate = flooded["timing"]["step_rate_hz"]
    ref = min(before["timing"]["step_rate_hz"], after["timing"]["step_rate_hz"])
    assert flood is not None
    print(f"packed flood: {rate:.0f} steps/s flooded, clean {before['timing']['step_rate_hz']:.0f} and "
          f"{after['timing']['step_rate_hz']:.0f}; sent {flood.sent} datagrams ({flood.bytes_sent} B) in "
          f"{flood.elapsed_s:.1f} s, got back {flood.replies} ({flood.reply_bytes} B); refused "
          f"{flooded['link']['rejected_by']['vehicle']}")
    assert rate >= 0.5 * ref, (rate, ref)
    assert flood.sent >= 0.9 * 900 * flood.elapsed_s
    assert flood.replies <= flood.sent and flood.reply_bytes <= flood.bytes_sent, vars(flood)
    assert flood.replies <= REPLY_RATE_HZ * (flood.elapsed_s + 1.0), (flood.replies, flood.elapsed_s)
    by = flooded["link"]["rejected_by"]["vehicle"]
    assert by.get("rate_limited", 0) > 0 and by.get("not_authorised", 0) > 0, by
    assert flooded["link"]["rejected_by"]["controller"] == {}


def _fly_packed(mission: Path, out: Path, flood: bool) -> tuple[dict[str, Any], Flood | None]:
    """Lockstep ``bsst sitl`` at 2x real time into ``out``; with ``flood``, a packed flood on its
    controller link from before the session starts to its end. The summary and the flood."""
    with instance_slot() as n:
        f = Flood(LINK_PORT + n, 900.0, n + 1, datagrams=[packed_requests(n + 1)]).start() if flood else None
        p = Proc.bsst("sitl", str(mission), "--out", str(out), "--instance", str(n), "--speed", "2", "--no-plots")
        try:
            p.p.wait(timeout=120)  # unbounded, the flooded flight took 160 s here
        finally:
            p.stop()
            if f is not None:
                f.stop()
    return json.loads((out / "summary.json").read_text()), f


# -- the property: any message, any values, from anyone -----------------------------------------
SYSID = 1
HOME_ALT_M = 488.0  # the vehicle's default home (m AMSL): NAV_TAKEOFF's param7 is AMSL
CTL_IDS = (CONTROLLER_SYSID, CONTROLLER_COMPID)
HANDLED = [M.MAVLink_heartbeat_message, M.MAVLink_command_long_message, M.MAVLink_command_int_message,
           M.MAVLink_timesync_message, M.MAVLink_ping_message, M.MAVLink_mission_request_list_message,
           M.MAVLink_hil_actuator_controls_message, M.MAVLink_set_actuator_control_target_message]
COMMANDS = [ARM, SET_IV, GET_IV, REQ, M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, M.MAV_CMD_GET_HOME_POSITION,
            M.MAV_CMD_DO_SET_MODE, M.MAV_CMD_NAV_TAKEOFF, M.MAV_CMD_NAV_LAND, M.MAV_CMD_NAV_RETURN_TO_LAUNCH,
            M.MAV_CMD_DO_REPOSITION]
EXTREME_FLOATS = [NAN, INF, -INF, 0.0, -0.0, 1.0, -1.0, 0.5, 21196.0, 3.4e38, -3.4e38, 1e-45, 2.0**24, 33.0]
INT_RANGES = {"int8_t": (-2**7, 2**7 - 1), "uint8_t": (0, 2**8 - 1), "int16_t": (-2**15, 2**15 - 1),
              "uint16_t": (0, 2**16 - 1), "int32_t": (-2**31, 2**31 - 1), "uint32_t": (0, 2**32 - 1),
              "int64_t": (-2**63, 2**63 - 1), "uint64_t": (0, 2**64 - 1)}


@functools.cache
def _value(ftype: str) -> st.SearchStrategy[Any]:
    """Random and extreme values of one MAVLink field type (one strategy per type: hypothesis checks each strategy
    object it is given anew, which cost the property a sixth to a third of its CPU when made for every field drawn)."""
    if ftype == "float":
        return st.one_of(st.floats(width=32), st.sampled_from(EXTREME_FLOATS))
    if ftype == "double":
        return st.one_of(st.floats(), st.sampled_from(EXTREME_FLOATS))
    lo, hi = INT_RANGES[ftype]
    return st.one_of(st.integers(lo, hi), st.sampled_from([lo, hi, 0, 1, SYSID]))


# fields the vehicle looks at get their interesting values more often than chance gives them
FOCUS: dict[str, st.SearchStrategy[Any]] = {
    "target_system": st.sampled_from([0, SYSID, SYSID, SYSID, 2, 255]),
    "target_component": st.sampled_from([0, 1, 1, 1, 2, 190]),
    "command": st.one_of(st.sampled_from(COMMANDS), st.sampled_from(COMMANDS[:4]), st.integers(0, 2**16 - 1)),
    "param1": st.one_of(st.sampled_from([0.0, 1.0, float(ATT), float(M.MAVLINK_MSG_ID_HEARTBEAT),
                                         float(M.MAVLINK_MSG_ID_AUTOPILOT_VERSION)]), _value("float")),
    "param2": st.one_of(st.sampled_from([-1.0, 0.0, 1e4, 1e6, 21196.0]), _value("float")),
    "tc1": st.one_of(st.just(0), _value("int64_t")),
    "mode": st.sampled_from([0, M.MAV_MODE_FLAG_SAFETY_ARMED, 255]), "group_mlx": st.sampled_from([0, 1, 255]),
}


# a command the vehicle acts on, to it, with its two parameters valid or not
AIMED: dict[str, st.SearchStrategy[Any]] = {
    "target_system": st.sampled_from([0, SYSID]), "target_component": st.sampled_from([0, 1]),
    "command": st.sampled_from([ARM, SET_IV, GET_IV, REQ]),
    "param1": st.one_of(st.sampled_from([0.0, 1.0]), st.sampled_from([float(ATT), 32.0, 245.0]),
                        st.sampled_from([NAN, INF, -INF, 0.5, 2.0**24, -1.0, 30.5])),
    "param2": st.one_of(st.sampled_from([-1.0, 0.0, 1e4, 1e6, 21196.0]), st.sampled_from([NAN, INF, -5.0, 1e12])),
}


AIMED_KINDS = st.sampled_from(HANDLED[1:3])
ANY_KINDS = st.one_of(st.sampled_from(HANDLED), st.sampled_from(HANDLED), st.sampled_from(HANDLED[5:]),
                      st.sampled_from(sorted(M.mavlink_map.values(), key=lambda c: c.id)))


@functools.cache
def _field(name: str, ftype: str, n: int, aimed: bool) -> st.SearchStrategy[Any]:
    """The values of one field of a message (:func:`messages`): made once for each field (:func:`_value` says why)."""
    if ftype == "char":
        return st.binary(max_size=max(n, 1))
    if n:
        each = st.one_of(st.sampled_from([0.0, 0.3, 1.0, -1.0]), _value(ftype)) if name == "controls" \
            else _value(ftype)
        return st.lists(each, min_size=n, max_size=n)
    if name == "time_usec":  # uint64_t in most messages, uint32_t in some (SERVO_OUTPUT_RAW): its own range
        return st.one_of(st.sampled_from([0, 4000]), _value(ftype))
    focus = AIMED if aimed else FOCUS
    return focus[name] if name in focus else FOCUS.get(name, _value(ftype))


@st.composite
def messages(draw: Any) -> Any:
    """Half the time an aimed command (:data:`AIMED`), else a message of a kind the vehicle
    handles (one in four of any kind of the dialect), every field random or extreme."""
    aimed = draw(st.booleans())
    cls = draw(AIMED_KINDS if aimed else ANY_KINDS)
    return cls(*(draw(_field(name, ftype, cls.array_lengths[cls.orders[i]], aimed))
                 for i, (name, ftype) in enumerate(zip(cls.fieldnames, cls.fieldtypes, strict=True))))


def _whole(v: float, hi: int) -> bool:
    return math.isfinite(v) and v == int(v) and 0 <= v <= hi


def _bad_numbers(m: Any) -> bool:
    """Whether a command the vehicle acts on has a number it must refuse (DENIED): ARM_DISARM's
    param1 not exactly 0 or 1; a message id not a whole number in [0, 2^24 - 1]; an interval
    not -1, 0 or in (0, 3.6e9] us."""
    if m.command == ARM:
        return m.param1 not in (0.0, 1.0)
    if m.command in (SET_IV, GET_IV, REQ):
        bad_id = not _whole(m.param1, 2**24 - 1)
        p2 = m.param2
        return bad_id or (m.command == SET_IV and not (p2 in (-1.0, 0.0) or 0.0 < p2 <= 3.6e9))
    return False


def _acks(datagrams: list[bytes]) -> list[int]:
    return [a.result for d in datagrams for a in M.MAVLink(None).parse_buffer(d) or [] if a.get_type() == "COMMAND_ACK"]


def _may_change(link: str, source: str, ids: tuple[int, int], m: Any) -> bool:
    """The spec (docs/design.md, "Authority"), written apart from the vehicle's code: whether
    ``m`` is valid and its sender has the authority to change anything. The controller link
    obeys the flight's controller only (its ids, from its address); the GCS link any ground
    station (its one address), never with actuator targets."""
    kind = m.get_type()
    if source == "intruder" or (link == "controller" and (source != "peer" or ids != CTL_IDS)):
        return False
    if kind in ("COMMAND_LONG", "COMMAND_INT"):
        if m.target_system not in (0, SYSID) or m.target_component not in (0, 1):
            return False
        if m.command == ARM:
            return m.param1 in (0.0, 1.0)
        if m.command == SET_IV:
            p2 = m.param2
            return _whole(m.param1, 2**24 - 1) and (p2 in (-1.0, 0.0) or 0.0 < p2 <= 3.6e9)
        if m.command == M.MAV_CMD_NAV_TAKEOFF:  # as PX4: NaN, or at most 50 m above home (lower: raised)
            alt = m.param7 if kind == "COMMAND_LONG" else m.z  # m AMSL
            return math.isnan(alt) or (math.isfinite(alt) and alt - HOME_ALT_M <= 50.0)
        if m.command == M.MAV_CMD_DO_SET_MODE:  # PX4's custom modes: AUTO (4, a sub mode) or OFFBOARD (6)
            return math.isfinite(m.param1) and int(m.param1) & 1 == 1 and m.param2 in (4.0, 6.0)
        if m.command in (M.MAV_CMD_NAV_LAND, M.MAV_CMD_NAV_RETURN_TO_LAUNCH):  # LAND, RTL: no number is read
            return True  # (a CI run drew RTL, command 20, among the random ones: this spec had missed it)
        return False  # requests answer, they change nothing; DO_REPOSITION is DENIED on the ground
    if kind == "SET_ACTUATOR_CONTROL_TARGET" and link == "controller":
        c = m.controls
        return (m.group_mlx == 0 and m.target_system in (0, SYSID) and m.target_component in (0, 1)
                and all(-1.0 <= v <= 1.0 for v in c[:3]) and 0.0 <= c[3] <= 1.0)
    if kind == "HIL_ACTUATOR_CONTROLS" and link == "controller":
        return not m.mode & M.MAV_MODE_FLAG_SAFETY_ARMED  # the no-target acknowledgement (paper: wrench)
    return False




class _Bench:
    """A real vehicle object (lockstep, paper profile) on real loopback sockets, and who talks
    to it: its controller (``peer``), a ``stranger`` on the controller link, the ground
    station (``gcs``, on the GCS port the vehicle sends to) and an ``intruder`` on the GCS
    link. The reply and read budgets are opened wide: every message reaches the message
    stage (the budgets are the flood test's)."""

    def __init__(self) -> None:
        socks = {}
        for name in ("peer", "stranger", "gcs", "intruder"):
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            s.bind(("127.0.0.1", 0))
            s.setblocking(False)
            socks[name] = s
        self.socks = socks
        self._build()

    def _build(self) -> None:
        """A new vehicle, armed by its controller: at the start, and after a message changed its mode
        (an accepted NAV_TAKEOFF or DO_SET_MODE), so that every example meets an armed lockstep OFFBOARD flight."""
        socks = self.socks
        flight = prepare(Mission(Sine(), duration_s=5.0, name="authority"))
        gcs = parse_address(f"udpout:127.0.0.1:{socks['gcs'].getsockname()[1]}")
        self.v = v = Vehicle(flight, VehicleConfig(parse_address("udpin:127.0.0.1:0"), gcs, sysid=SYSID))
        for ep in v.endpoints:
            ep.replies = ReplyBudget(1e9, 1e12)
            ep.limiter = RateLimiter(1e9, 1e9, source_bytes_s=1e12, others_bytes_s=1e12)
        self.dest = {"peer": v.link.local, "stranger": v.link.local, "gcs": v.gcs.local, "intruder": v.gcs.local}
        ctl = M.MAVLink(None, srcSystem=CTL_IDS[0], srcComponent=CTL_IDS[1])
        self.deliver("peer", M.MAVLink_command_long_message(SYSID, 1, ARM, 0, 1, 0, 0, 0, 0, 0, 0).pack(ctl))
        assert v.sim.armed and v.clock.engaged and v.link.peer == socks["peer"].getsockname()

    def endpoint(self, source: str) -> Endpoint:
        return self.v.link if source in ("peer", "stranger") else self.v.gcs

    def deliver(self, source: str, data: bytes) -> tuple[int, int]:
        """Send ``data`` from ``source`` and have the vehicle take it in; (messages decoded,
        refusals counted)."""
        v, ep = self.v, self.endpoint(source)
        r0 = v.rejected.total
        self.socks[source].sendto(data, self.dest[source])
        got: list[Any] = []

        def consumed() -> bool:
            msgs = ep.poll()
            for m, addr in msgs:
                v._handle(ep, m, addr)
            got.extend(msgs)
            return bool(got) or v.rejected.total > r0

        wait_for(consumed, 5.0, "the vehicle receiving the datagram", poll_s=0.001)
        return len(got), v.rejected.total - r0

    def replies(self, source: str) -> list[bytes]:
        out = []
        while True:
            try:
                out.append(self.socks[source].recv(65535))
            except BlockingIOError:
                return out

    def reset(self) -> None:
        """Armed at step 0 of its flight, that step not answered, the controller its peer."""
        v = self.v
        if v.sim.mode != OFFBOARD or v.clock.on_wall_clock or v.clock.halted:
            v.close()
            self._build()
            for s in self.socks:
                self.replies(s)
            v = self.v
        drop_held_answer(v)
        v.link.peer = self.socks["peer"].getsockname()
        if not v.sim.armed:
            v.commander.arm_disarm(1.0, 0.0)
            v.announcer.drain()  # its event goes out now, not with the next example's answer
        for s in self.socks:
            self.replies(s)

    def close(self) -> None:
        self.v.close()
        for s in self.socks.values():
            s.close()


@pytest.fixture(scope="module")
def bench():
    b = _Bench()
    yield b
    b.close()


@settings(max_examples=600, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(messages(), st.one_of(
    st.sampled_from([("peer", CTL_IDS), ("gcs", (255, 190)), ("gcs", CTL_IDS), ("stranger", CTL_IDS),
                     ("stranger", (255, 190)), ("peer", (201, 191)), ("intruder", (255, 190))]),
    st.sampled_from([("peer", CTL_IDS), ("gcs", (245, 190))]),
    st.tuples(st.sampled_from(["peer", "stranger", "gcs", "intruder"]),
              st.tuples(st.integers(1, 255), st.integers(0, 255)))))
# an upload of 0 items, and a clear, of a fence the vehicle does not hold: answered once, nothing said (a CI run
# once drew the first, when a clear of nothing was still announced with a HEARTBEAT)
@example(M.MAVLink_mission_count_message(SYSID, 1, 0, M.MAV_MISSION_TYPE_FENCE), ("gcs", (255, 190)))
@example(M.MAVLink_mission_clear_all_message(SYSID, 1, M.MAV_MISSION_TYPE_ALL), ("gcs", (255, 190)))
def test_any_message_from_anyone_changes_nothing_unless_valid_and_authorised(bench, m, who):
    """Finding 5: every message id the vehicle handles (and any other of the dialect), random
    and extreme values in every field, from its controller, a stranger on the controller
    link, its ground station and an intruder on the GCS link, over real UDP into a real armed
    lockstep vehicle: nothing raises; nothing changes unless the message is valid and its
    sender has authority there; every message from a sender without authority is counted
    once; a command with a bad number from one with authority is DENIED; and nobody gets
    more than one datagram back for it."""
    source, ids = who
    bench.reset()
    v = bench.v
    link = "controller" if source in ("peer", "stranger") else "gcs"
    data = bytes(m.pack(M.MAVLink(None, srcSystem=ids[0], srcComponent=ids[1])))
    before = vehicle_state(v)
    decoded, refused = bench.deliver(source, data)
    may = _may_change(link, source, ids, m)
    after = vehicle_state(v)
    if not may:
        assert after == before, (m, source, ids)
    authorised = source == "gcs" or (source == "peer" and ids == CTL_IDS)
    if not authorised:
        assert refused == 1, (m, source, ids, dict(v.rejected))
    back = bench.replies(source)
    if not may:  # (an accepted mode change also sends its event and a heartbeat: a second datagram)
        assert len(back) <= 1, (m, source, back)
    if authorised and decoded and m.get_type() in ("COMMAND_LONG", "COMMAND_INT") and _bad_numbers(m) \
            and m.target_system in (0, SYSID) and m.target_component in (0, 1):
        if not back:  # the answer may still be on its way on loopback: wait for it
            wait_for(lambda: bool(back.extend(bench.replies(source)) or back), 5.0, "the COMMAND_ACK", poll_s=0.001)
        assert _acks(back) == [M.MAV_RESULT_DENIED], (m, source, ids)
        assert after == before
    assert decoded <= 1



# -- issue 22 defect 2: a mode request that changes nothing is no takeover ----------------------------------
# 3 s (it was 4 s: each request goes at the vehicle's first heartbeat or once it is past step 10, and its answer is
# awaited), ending in hold: the end landing and COM_DISARM_LAND after it (~4 s more of each flight, the vehicle's own
# modes, which the test leaves out) were read by nobody until the fortieth session; trace.csv, the mission's steps,
# is the same byte for byte either way
NOOP_MISSION = 'name = "noop-modes"\nduration_s = 3.0\n[trajectory]\nkind = "sine"\n[end]\naction = "hold"\n'
SET_MODE = M.MAV_CMD_DO_SET_MODE
OFFBOARD_MODE = (29.0, 6.0, 0.0)  # DO_SET_MODE param1..3: custom mode enabled, PX4 main mode OFFBOARD
TAKEOFF_MODE = (29.0, 4.0, 2.0)  # AUTO.TAKEOFF (LAND and RTL: not selected disarmed)


def _set_mode(gcs: Station, to: tuple[int, int], mode: tuple[float, float, float]) -> int:
    gcs.send(M.MAVLink_command_long_message(*to, SET_MODE, 0, *mode, 0, 0, 0, 0))
    return gcs.ack(SET_MODE)


def _fly_noop(mission: Path, out: Path, when: str, mode: tuple[float, float, float]) -> tuple[int, dict[str, Any]]:
    """Lockstep ``bsst sitl`` at 3x real time; a ground station on the GCS port selects ``mode`` (accepted)
    ``when`` ``"disarmed"`` (at the vehicle's first heartbeat, before its controller can arm it) or
    ``"armed"`` (past step 10 of the flight). The exit status and the summary."""
    with instance_slot() as n:
        gcs = Station((255, 190), port=GCS_PORT + n)
        p = Proc.bsst("sitl", str(mission), "--out", str(out), "--instance", str(n), "--speed", "3", "--no-plots",
                      "--overwrite")
        try:
            to = (n + 1, 1)
            if when == "disarmed":
                hb = gcs.wait(lambda m: m.get_type() == "HEARTBEAT", 30, "the vehicle's first heartbeat")
                assert not hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED
            else:
                wait_for(lambda: count_records(out / "vehicle.bin") > 10 or p.p.poll() is not None, 60, "the flight")
                assert p.p.poll() is None, "the session ended before the mode request"
                gcs.wait(lambda m: True, 10, "the vehicle's telemetry")  # where the vehicle's GCS link is
            assert _set_mode(gcs, to, mode) == M.MAV_RESULT_ACCEPTED
            rc = p.p.wait(timeout=120)
        finally:
            p.stop()
            gcs.close()
    return rc, json.loads((out / "summary.json").read_text())


@pytest.fixture
def noop_ref(tmp_path) -> tuple[Path, dict[str, Any], bytes]:
    """NOOP_MISSION's file, and the summary and trace.csv of its flight with no ground station speaking, flown
    offline (a lockstep session's trace.csv is its offline twin's to the byte, tests/test_sitl.py; a session of
    its own once, shared by the three cases below, which it then kept on one worker)."""
    mission = tmp_path / "m.toml"
    mission.write_text(NOOP_MISSION)
    ref = simulate(mission, out=tmp_path / "ref", plots=False)
    return mission, ref.summary, (tmp_path / "ref" / "trace.csv").read_bytes()


@pytest.mark.parametrize(("when", "mode"), [("armed", OFFBOARD_MODE), ("disarmed", TAKEOFF_MODE),
                                            ("disarmed", OFFBOARD_MODE)], ids=["offboard-in-offboard",
                                                                               "takeoff-before-arming",
                                                                               "offboard-before-arming"])
def test_a_mode_request_that_changes_nothing_is_no_takeover(noop_ref, tmp_path, when, mode):
    """Issue 22, defect 2, with real processes: a ground station's DO_SET_MODE OFFBOARD while the vehicle
    flies in OFFBOARD, or a mode selected while it is disarmed (TAKEOFF; OFFBOARD, the vehicle booting in HOLD),
    before its controller arms it (which arms it in OFFBOARD), changes nothing: the trace is byte for byte the
    undisturbed run's, and the run says so (completed, ended by the mission, exit 0). Only an armed exit from
    OFFBOARD ends a flight."""
    mission, ref, ref_trace = noop_ref
    for attempt in range(3):  # disarmed: the selection races the controller's arm (both follow the first heartbeat)
        rc, run = _fly_noop(mission, tmp_path / "run", when, mode)
        # (not the vehicle's own, such as an end landing's: this mission ends in hold, test_strangers' lands)
        modes = [e for e in run["events"] if e["kind"] == "mode" and not e["text"].endswith("[by vehicle]")]
        if not (when == "disarmed" and modes and modes[0].get("armed")):
            break
        print(f"attempt {attempt}: the controller armed before the selection (a real takeover): again")
    else:  # a loaded machine: the controller won the race each time, and the selection came in flight
        if mode == TAKEOFF_MODE:  # then TAKEOFF took the vehicle from its controller: a takeover, named, exit 1
            [change] = [c for c in run["interventions"] if c["kind"] == "mode"]
            assert change["by"].startswith("255:190 127.0.0.1:") and change["by"].endswith(" gcs"), change
            assert rc == 1 and run["ended_by"]["who"].startswith("255:190"), (rc, run["ended_by"])
            return
    assert ref["outcome"] == "completed"
    if when == "armed" or (mode == OFFBOARD_MODE and not modes):
        # OFFBOARD in OFFBOARD changes nothing (disarmed too, when the controller's arm came first)
        assert modes == [], modes
    else:  # recorded as a selection for the next arm, made before the controller armed it
        armed = next(e for e in run["events"] if e["kind"] == "armed")
        assert len(modes) == 1 and modes[0]["armed"] is False and modes[0]["t"] <= armed["t"], run["events"]
        assert "[by 255:190" in modes[0]["text"]
    assert (run["outcome"], run["ended_by"], rc) == ("completed", {"who": "mission", "how": "completed"}, 0), \
        (run["ended_by"], run["events"])
    assert (tmp_path / "run" / "trace.csv").read_bytes() == ref_trace


# -- issue 22: the ground station's authority, as a property over whole lockstep flights --------------------
# (ends in hold: every frame is sent by t = 2.5 s, and the ~3.5 s of a land and COM_DISARM_LAND after the mission are
# read by nobody; trace.csv, the mission's steps, is the same byte for byte either way)
GCS_MISSION = 'name = "gcs"\nduration_s = 3.0\n[trajectory]\nkind = "sine"\n[end]\naction = "hold"\n'
_PX4 = {"OFFBOARD": (6, 0), "HOLD": (4, 3), "TAKEOFF": (4, 2), "LAND": (4, 6)}  # PX4 main, sub mode
_CUSTOM = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED


def _param_value(spec: Any) -> st.SearchStrategy[tuple[str, float, int]]:
    """A PARAM_SET's (name, wire value, type) of ``spec`` inside its range (an INT32 one of its choices)."""
    from bridge.mavlink.modes import PARAM_TYPES, param_to_wire  # local: only this strategy needs them

    kind = PARAM_TYPES[spec.kind]
    values = (st.sampled_from(sorted(spec.choices)) if spec.choices
              else st.floats(spec.lo, spec.hi, allow_nan=False))
    return values.map(lambda v: (spec.name, param_to_wire(v, kind), kind))


def _gcs_frames() -> st.SearchStrategy[Any]:
    """One valid frame a ground station may send: PARAM_SET, DO_SET_MODE, SET_MODE, NAV_TAKEOFF, NAV_LAND, ARM or
    DISARM (forced or not); addressed to the vehicle (``target`` filled in when sent)."""
    from bridge.autopilot.params import PARAMS  # local: only this strategy needs it

    settable = [p for p in PARAMS if not p.at_start_only]
    mode = st.sampled_from(sorted(_PX4))
    return st.one_of(
        st.sampled_from(settable).flatmap(_param_value).map(lambda p: ("PARAM_SET", *p)),
        mode.map(lambda m: ("DO_SET_MODE", m)),
        mode.map(lambda m: ("SET_MODE", m)),
        st.floats(1.0, 5.0).map(lambda alt: ("NAV_TAKEOFF", alt)),
        st.just(("NAV_LAND",)),
        st.sampled_from([(1.0, 0.0), (0.0, 0.0), (0.0, 21196.0)]).map(lambda p: ("ARM", *p)),
    )


def _gcs_message(frame: tuple, to: tuple[int, int]) -> Any:
    kind = frame[0]
    if kind == "PARAM_SET":
        return M.MAVLink_param_set_message(*to, frame[1].encode(), frame[2], frame[3])
    if kind in ("DO_SET_MODE", "SET_MODE"):
        main, sub = _PX4[frame[1]]
        if kind == "SET_MODE":
            return M.MAVLink_set_mode_message(to[0], _CUSTOM, (main << 16) | (sub << 24))
        return M.MAVLink_command_long_message(*to, M.MAV_CMD_DO_SET_MODE, 0, _CUSTOM, main, sub, 0, 0, 0, 0)
    if kind == "NAV_TAKEOFF":  # param7: m AMSL (home at 0 m AMSL in SITL's default home: above home)
        return M.MAVLink_command_long_message(*to, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, math.nan, math.nan, math.nan,
                                              frame[1])
    if kind == "NAV_LAND":
        return M.MAVLink_command_long_message(*to, M.MAV_CMD_NAV_LAND, 0, 0, 0, 0, math.nan, math.nan, math.nan, 0)
    return M.MAVLink_command_long_message(*to, ARM, 0, frame[1], frame[2], 0, 0, 0, 0, 0)


def _fly_gcs(mission: Path, out: Path, frames: list[tuple[float, tuple]]) -> tuple[int, dict[str, Any]]:
    """``bsst sitl`` lockstep at 2x real time; each frame of ``frames`` (at the vehicle's time s, in order) sent
    by a ground station on the GCS link once the vehicle has flown that far. The exit status and summary."""
    with instance_slot() as n:
        gcs = Station((255, 190), port=GCS_PORT + n)
        p = Proc.bsst("sitl", str(mission), "--out", str(out), "--instance", str(n), "--speed", "2", "--no-plots")
        try:
            to = (n + 1, 1)
            for t, frame in frames:
                wait_for(lambda t=t: count_records(out / "vehicle.bin") >= 250 * t or p.p.poll() is not None, 60,
                         f"the flight at t={t:g} s")
                if p.p.poll() is not None:
                    break
                wait_for(lambda: bool(gcs.poll()) or gcs.dest is not None, 20, "the vehicle's telemetry")
                gcs.send(_gcs_message(frame, to))
            p.p.wait(timeout=120)
        finally:
            p.stop()
            gcs.close()
    return p.p.returncode, json.loads((out / "summary.json").read_text())


@pytest.fixture(scope="module")
def undisturbed(tmp_path_factory) -> tuple[Path, bytes]:
    """The mission and the trace.csv of its flight with no ground station speaking, flown offline: a lockstep
    session's trace.csv is its offline twin's to the byte (tests/test_sitl.py, which also checks a clean session's
    held lockstep and exit 0; here each example that changed nothing asserts them of its own flight)."""
    d = tmp_path_factory.mktemp("gcs-ref")
    mission = d / "m.toml"
    mission.write_text(GCS_MISSION)
    ref = simulate(mission, out=d / "ref", plots=False)
    assert ref.outcome == "completed", ref.summary["ended_by"]
    return mission, (d / "ref" / "trace.csv").read_bytes()


@settings(max_examples=6, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(st.lists(st.tuples(st.floats(0.3, 2.5), _gcs_frames()), min_size=1, max_size=3))
def test_a_ground_stations_frames_leave_the_flight_reproducible_or_are_named_with_their_step(
        undisturbed, tmp_path_factory, frames):
    """Issue 22: random valid frames of a ground station during a lockstep flight. Either nothing changed:
    the trace is the undisturbed run's byte for byte, the summary says completed and held, exit 0; or the
    summary names each change (its sender, the ground station; what; t and step), the lockstep record says
    from which step the run is no longer reproducible (or that it left lockstep), and the exit status is 1."""
    mission, ref = undisturbed
    out = tmp_path_factory.mktemp("gcs") / "run"
    rc, s = _fly_gcs(mission, out, sorted(frames, key=lambda f: f[0]))
    changes = s["interventions"]
    note(f"{frames}: exit {rc}, {s['outcome']}, changes {[c['what'] for c in changes]}")
    if not changes:
        assert (out / "trace.csv").read_bytes() == ref, (frames, s["ended_by"], s["events"])
        assert s["outcome"] == "completed" and s["lockstep"] == {"held": True} and rc == 0, (frames, s)
        return
    assert rc == 1, (frames, s)
    for c in changes:
        assert c["by"].startswith("255:190 127.0.0.1:") and c["by"].endswith(" gcs"), c
        assert c["step"] == round(c["t"] * 250) and c["kind"] in ("param", "mode", "armed", "disarmed"), c
        assert c["kind"] != "param" or {"name", "old", "new"} <= set(c), c
    lock = s["lockstep"]
    assert lock["held"] is False or lock["reproducible_until_step"] == changes[0]["step"], lock

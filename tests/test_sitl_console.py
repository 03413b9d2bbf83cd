"""Covers bridge.session.announce, bridge.session and bridge.cli.flying: what ``bsst sitl`` tells a person.

Found by a new user's audit: ``bsst sitl --await-mission`` said nothing while it waited for a ground station's
mission, even on a terminal (where to connect QGroundControl, MAVSDK or MAVProxy was nowhere but the docs), and
the printed summary listed the session's closing notes (``ended``, ``stall``, ``policy``) after the vehicle's end
landing, out of time order. Now every ``bsst sitl`` says on stderr, as soon as its vehicle is up, where a ground
station connects (``--await-mission``: that it waits, with no time limit), and lists its events in time order
(stdout keeps its contract: the summary, nothing else). Real ``bsst sitl`` processes on 127.0.0.1.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import signal
import socket
from pathlib import Path
from typing import Any

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from bridge.core.clock import lockstep_pace
from bridge.mavlink.endpoint import GCS_PORT
from bridge.nodes.report import Ready
from bridge.session import instance_slot
from bridge.session.announce import pace_words, vehicle_up_line
from bridge.session.children import free_udp_port
from tests.sitlkit import ROOT, Proc, run_bsst
from tests.waiting import wait_for

pytestmark = pytest.mark.process  # starts processes and opens sockets

UP = "bsst sitl: vehicle up, sysid "
SINE_2S = 'name = "sine2"\nduration_s = 2.0\n[trajectory]\nkind = "sine"\n'


def said_up(n: int, sysid: int) -> str:
    """The line of a vehicle of system ``sysid`` whose ground-station link sends to 127.0.0.1:14550 + ``n``."""
    port = GCS_PORT + n
    return (f"{UP}{sysid}: a ground station connects by listening on UDP 127.0.0.1:{port}, where the vehicle sends "
            f"its telemetry ({'QGroundControl listens there by default; ' if port == GCS_PORT else ''}"
            f"mavproxy.py --master=udpin:127.0.0.1:{port}; MAVSDK udpin://0.0.0.0:{port})")


def test_await_mission_says_at_once_where_a_ground_station_connects_and_that_it_waits(tmp_path: Path) -> None:
    """``bsst sitl --await-mission`` says, while it waits and before any ground station is there, the port a ground
    station listens on and the vehicle's system id, and that it waits with no time limit for an upload and a start;
    a ground station that listens there hears that vehicle's heartbeats. Ctrl-C ends the wait (exit 1, aborted)."""
    out = tmp_path / "run"
    with instance_slot() as n:
        sitl = Proc.bsst("sitl", "--await-mission", "--instance", str(n), "--out", str(out), "--no-plots", cwd=ROOT)
        gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            line = sitl.wait_line(lambda s: s.startswith(UP), timeout=60)
            assert line == said_up(n, n + 1) + ("; waiting, with no time limit (Ctrl-C stops), for a ground station to "
                                                "upload a mission and start it: MISSION_START, or AUTO.MISSION and "
                                                "arm; it flies in lockstep at 1x real time (--speed X: X times; 0: as "
                                                "fast as it goes)"), line
            gcs.bind(("127.0.0.1", GCS_PORT + n))  # what the line says to do
            gcs.settimeout(0.5)
            mav, beats = mavlink.MAVLink(None), []

            def heartbeat() -> bool:
                with contextlib.suppress(TimeoutError):
                    beats.extend(m for m in mav.parse_buffer(gcs.recv(65535)) or []
                                 if m.get_type() == "HEARTBEAT" and m.get_srcSystem() == n + 1)
                return bool(beats)

            wait_for(heartbeat, 30.0, f"a HEARTBEAT of system {n + 1} on 127.0.0.1:{GCS_PORT + n}")
            sitl.p.send_signal(signal.SIGINT)
            assert sitl.p.wait(timeout=60) == 1
        finally:
            sitl.stop()
            gcs.close()
    summary = json.loads((out / "summary.json").read_text())
    assert summary["outcome"] == "aborted" and summary["sitl"]["speed"] == 1.0, summary["sitl"]  # as said
    assert sum(ln.startswith(UP) for ln in sitl.lines) == 1, sitl.lines


@pytest.mark.parametrize("form", ["udpin:", "udp:"])
def test_a_bound_ground_station_link_says_to_send_to_it_and_a_ground_station_doing_so_hears_the_vehicle(
        tmp_path: Path, form: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """``--gcs udpin:HOST:PORT`` (``udp:`` the same) binds the vehicle's GCS link there: the line says a ground
    station sends there (udpout), not that it listens there (the port is the vehicle's: a ground station binding
    it met "Address already in use"); pymavlink doing what the line says hears that vehicle's heartbeats."""
    port = free_udp_port()
    out = tmp_path / "run"
    with instance_slot() as n:
        sitl = Proc.bsst("sitl", "--await-mission", "--instance", str(n), "--gcs", f"{form}127.0.0.1:{port}",
                         "--out", str(out), "--no-plots", cwd=ROOT)
        gcs = None
        try:
            line = sitl.wait_line(lambda s: s.startswith(UP), timeout=60)
            said = f"mavproxy.py --master=udpout:127.0.0.1:{port}; MAVSDK udpout://127.0.0.1:{port})"
            assert line.startswith(f"{UP}{n + 1}: a ground station connects by sending to UDP 127.0.0.1:{port}, "
                                   "where the vehicle listens and answers with its telemetry (") and said in line, line
            monkeypatch.setenv("MAVLINK20", "1")  # the vehicle takes MAVLink 2 only
            gcs = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=255, source_component=190,
                                             dialect="common")  # what the line says
            beats: list[Any] = []

            def heartbeat() -> bool:
                gcs.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
                m = gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=0.5)
                if m is not None and m.get_srcSystem() == n + 1:
                    beats.append(m)
                return bool(beats)

            wait_for(heartbeat, 30.0, f"a HEARTBEAT of system {n + 1} answering udpout:127.0.0.1:{port}")
            sitl.p.send_signal(signal.SIGINT)
            assert sitl.p.wait(timeout=60) == 1
        finally:
            sitl.stop()
            if gcs is not None:
                gcs.close()
    summary = json.loads((out / "summary.json").read_text())
    assert summary["outcome"] == "aborted" and summary["sitl"]["gcs"] == f"{form}127.0.0.1:{port}", summary["sitl"]


def _event_times(stdout: str) -> list[float]:
    return [float(ln.split()[1].removeprefix("t=")) for ln in stdout.splitlines() if ln.startswith("event t=")]


def test_a_mission_says_where_a_ground_station_connects_on_stderr_and_lists_its_events_in_time_order(
        tmp_path: Path) -> None:
    """``bsst sitl MISSION``: stderr is the one line (no wait: the controller flies the file), stdout the summary as
    before; its events, and summary.json's, in time order: the session's ``ended`` (stamped at the trace's last row,
    1.996 s) before the end landing's ``end``, ``landed`` and ``disarmed`` (it was printed last, after 4.566 s)."""
    (tmp_path / "m.toml").write_text(SINE_2S)
    with instance_slot() as n:
        r = run_bsst("sitl", str(tmp_path / "m.toml"), "--instance", str(n), "--out", str(tmp_path / "run"),
                     "--no-plots", timeout=120)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    assert r.stderr.splitlines() == [said_up(n, n + 1)], r.stderr
    assert r.stdout.startswith("mission sine2  controller bsst") and UP not in r.stdout, r.stdout
    times = _event_times(r.stdout)
    assert times == sorted(times) and len(times) >= 8, r.stdout
    kinds = [ln.split()[2].rstrip(":") for ln in r.stdout.splitlines() if ln.startswith("event t=")]
    assert kinds.index("ended") < kinds.index("end") < kinds.index("landed") < kinds.index("disarmed"), kinds
    events: list[dict[str, Any]] = json.loads((tmp_path / "run" / "summary.json").read_text())["events"]
    assert [round(e["t"], 3) for e in events] == times and len(events) <= 16  # the same list, printed whole


def test_a_fleet_says_it_for_each_vehicle(tmp_path: Path) -> None:
    """``bsst sitl --vehicles``: each vehicle's line, its own system id, the fleet's one ground-station port; with
    no ground-station link the line says so."""
    (tmp_path / "m.toml").write_text(SINE_2S.replace("2.0", "0.5"))
    with instance_slot() as n:
        r = run_bsst("sitl", str(tmp_path / "m.toml"), "--vehicles", "1", "--instance", str(n), "--out",
                     str(tmp_path / "run"), "--no-plots", timeout=120)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    assert r.stderr.splitlines() == [said_up(n, n + 1)], r.stderr
    assert vehicle_up_line(Ready("vehicle", sysid=3), await_mission=True) == f"{UP}3: no ground-station link"


def test_the_pace_a_started_mission_flies_at_is_said_and_chosen_once() -> None:
    """``lockstep_pace``: 0 is as fast as it goes (None), a ground station's mission with no ``--speed`` flies at 1x
    real time (as PX4's and ArduPilot's SITL), a mission file as fast as it goes, a given pace as given, real time
    as given; ``pace_words`` says each with the flag that changes it."""
    assert [lockstep_pace(s, realtime=False, await_mission=a) for s, a in
            [(None, True), (None, False), (0.0, True), (0.0, False), (4.0, True), (0.5, False)]] == \
        [1.0, None, None, None, 4.0, 0.5]
    assert [lockstep_pace(s, realtime=True, await_mission=True) for s in (None, 1.0, 0.0)] == [None, 1.0, None]
    assert pace_words(False, 1.0) == "in lockstep at 1x real time (--speed X: X times; 0: as fast as it goes)"
    assert pace_words(False, 2.5).startswith("in lockstep at 2.5x real time")
    assert pace_words(False, None) == "as fast as it goes (--speed 0; --speed X: at most X times real time)"
    assert pace_words(True, None) == pace_words(True, 1.0) == "on the wall clock (--realtime)"
    line = vehicle_up_line(Ready("vehicle", sysid=2, gcs="127.0.0.1:14551"), True, False, None)
    assert line.endswith("AUTO.MISSION and arm; it flies as fast as it goes (--speed 0; --speed X: at most X times "
                         "real time)"), line


def test_a_signed_session_says_a_ground_station_must_sign_and_one_signing_as_sitl_md_says_flies_its_mission(
        tmp_path: Path) -> None:
    """``bsst sitl --await-mission --key K``: the line says every frame is signed and a ground station must sign
    (it said only where to listen: a ground station that does not sign sees the telemetry and has every message
    refused, its upload never answered); a pymavlink ground station set up as docs/sitl.md says (the vehicle's
    HEARTBEAT heard, then ``setup_signing``) uploads a takeoff and a landing, starts them, and the session completes.
    (With ``setup_signing`` before it had heard a frame, pymavlink's switch to MAVLink 2 at the first one rebuilt its
    codec without the signing: every frame it sent was unsigned, the vehicle's ``rejected 1: unsigned 1``, a tour's
    upload never answered.)"""
    passphrase = b"correct horse battery staple"
    key = tmp_path / "bsst.key"
    key.write_bytes(passphrase + b"\n")
    key.chmod(0o600)
    items = [(mavlink.MAV_CMD_NAV_TAKEOFF, 473977420, 85455940, 2.0), (mavlink.MAV_CMD_NAV_LAND, 0, 0, 0.0)]
    with instance_slot() as n:
        sitl = Proc.bsst("sitl", "--await-mission", "--key", str(key), "--speed", "0", "--instance", str(n),
                         "--out", str(tmp_path / "run"), "--no-plots", cwd=ROOT)
        gcs = mavutil.mavlink_connection(f"udpin:127.0.0.1:{GCS_PORT + n}", source_system=255, source_component=190)
        try:
            line = sitl.wait_line(lambda s: s.startswith(UP), timeout=60)
            assert line.startswith(said_up(n, n + 1) + "; every frame signed (--key): a ground station signs with "
                                   "the same key, or the vehicle refuses what it sends (docs/sitl.md, Signing); "
                                   "waiting"), line
            assert gcs.wait_heartbeat(timeout=30) is not None  # (pymavlink now speaks the MAVLink 2 it heard)
            gcs.setup_signing(hashlib.sha256(passphrase).digest(), sign_outgoing=True)
            gcs.mav.mission_count_send(n + 1, 1, len(items), 0)

            def uploaded() -> bool:  # answer the vehicle's requests until its ACK
                m = gcs.recv_match(type=["MISSION_REQUEST_INT", "MISSION_ACK"], blocking=True, timeout=0.5)
                if m is not None and m.get_type() == "MISSION_REQUEST_INT":
                    cmd, lat, lon, alt = items[m.seq]
                    gcs.mav.mission_item_int_send(n + 1, 1, m.seq, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, cmd, 0,
                                                  1, 0, 0, 0, float("nan"), lat, lon, alt, 0)
                return m is not None and m.get_type() == "MISSION_ACK" and m.type == mavlink.MAV_MISSION_ACCEPTED

            wait_for(uploaded, 30.0, "the signed upload's MISSION_ACK ACCEPTED")
            gcs.mav.command_long_send(n + 1, 1, mavlink.MAV_CMD_MISSION_START, 0, 0, 0, 0, 0, 0, 0, 0)
            assert sitl.p.wait(timeout=120) == 0
        finally:
            gcs.close()
            sitl.stop()
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["outcome"] == "completed" and summary["sitl"]["signed"], summary["ended_by"]

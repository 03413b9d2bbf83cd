"""Covers bridge.nodes.vehicle.actions: MAV_CMD_DO_CHANGE_SPEED, MAV_CMD_DO_FLIGHTTERMINATION and
MAV_CMD_REQUEST_PROTOCOL_VERSION as PX4 takes them (docs/ground-station.md), with a pymavlink ground station against
a vehicle built in this process, and end to end with MAVSDK's Action plugin (``set_current_speed``, ``terminate``)
against ``bsst vehicle`` and a ``bsst sitl`` session: its outcome ``terminated``, exit 1, who ended it.
"""

from __future__ import annotations

import json
import math
import struct
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import common as M
from pymavlink.mavutil import x25crc

from bridge.core.flight import prepare
from bridge.mavlink.endpoint import parse_address
from bridge.nodes.vehicle import Vehicle, VehicleConfig
from bridge.session import instance_slot
from missions import MISSION_DIR, Mission, Sine
from tests.gcskit import command_ack, gcs_link
from tests.sitlkit import GcsSocket, Proc
from tests.test_ground_stations import FAST, _mavsdk
from tests.test_vehicle import _vehicle
from tests.waiting import wait_for

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast


def _in_process() -> tuple[Vehicle, GcsSocket]:
    """A lockstep vehicle built here, disarmed on the ground in HOLD (its boot mode), its controller pinned, and a
    ground station's socket on its GCS link."""
    gcs = GcsSocket()
    flight = prepare(Mission(Sine(), duration_s=5.0, name="actions"))
    v = Vehicle(flight, VehicleConfig(parse_address("udpin:127.0.0.1:0"), parse_address(gcs.url), clock="lockstep",
                                      controller_from=("127.0.0.1", 9)))
    return v, gcs


def _command(v: Vehicle, gcs: GcsSocket, cmd: int, *p: float) -> int:
    got = gcs.exchange(v, M.MAVLink_command_long_message(1, 1, cmd, 0, *p, *([0.0] * (7 - len(p)))), "COMMAND_ACK")
    assert got.command == cmd
    return got.result


def test_flight_termination_stops_the_motors_latches_termination_and_refuses_arming_and_modes() -> None:
    """DO_FLIGHTTERMINATION as PX4 main's commander takes it: param1 0 DENIED (it cancels nothing), NaN DENIED (a bad
    number), 1 or 2 DENIED while disarmed (1 was ACCEPTED, and latched the vehicle unarmable; 2 UNSUPPORTED, as PX4's
    old lockdown test); armed, 1 ACCEPTED: a ``terminated`` event naming the
    ground station, the vehicle disarmed (motors off), its HEARTBEAT as PX4's in termination (base mode
    CUSTOM_MODE_ENABLED only, main mode MANUAL, MAV_STATE_FLIGHT_TERMINATION), its lockstep clock left for the wall
    clock (it falls on its own, said); from then on an arm, a mode and a cancel are DENIED, each saying why."""
    v, gcs = _in_process()
    try:
        assert _command(v, gcs, M.MAV_CMD_DO_FLIGHTTERMINATION, 0.0) == M.MAV_RESULT_DENIED
        assert _command(v, gcs, M.MAV_CMD_DO_FLIGHTTERMINATION, math.nan) == M.MAV_RESULT_DENIED
        assert _command(v, gcs, M.MAV_CMD_DO_FLIGHTTERMINATION, 2.0) == M.MAV_RESULT_DENIED  # not armed, as 1
        assert not any(e.kind == "terminated" for e in v.sim.events) and v.rejected["bad_number"] == 1
        said = gcs.exchange(v, M.MAVLink_command_long_message(1, 1, M.MAV_CMD_DO_FLIGHTTERMINATION, 0, 1, 0, 0, 0, 0,
                                                              0, 0), "STATUSTEXT")
        assert said.text.startswith("DO_FLIGHTTERMINATION: not armed (PX4 terminates"), said.text  # (50 a chunk)
        assert not any(e.kind == "terminated" for e in v.sim.events) and v.sim.mode == "hold"
        v.commander.arm_disarm(1.0, 0.0)  # the controller's arm: OFFBOARD, in lockstep
        assert v.sim.armed and not v.clock.free_running
        assert _command(v, gcs, M.MAV_CMD_DO_FLIGHTTERMINATION, 1.0) == M.MAV_RESULT_ACCEPTED
        (t,) = [e for e in v.sim.events if e.kind == "terminated"]
        assert t.text.startswith("flight termination: motors off at x=0.000 y=0.000 z=0.000 m") and t.by is not None
        assert (t.by.sysid, t.by.compid, t.by.link) == (255, 190, "gcs") and not v.sim.armed
        assert any(e.kind == "lockstep" and "the vehicle falls on the wall clock" in e.text for e in v.sim.events)
        assert v.clock.free_running
        hb = v.streaming.heartbeat()
        assert (hb.base_mode, hb.custom_mode, hb.system_status) == (M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 1 << 16,
                                                                     M.MAV_STATE_FLIGHT_TERMINATION)
        assert _command(v, gcs, M.MAV_CMD_DO_FLIGHTTERMINATION, 1.0) == M.MAV_RESULT_ACCEPTED  # again: nothing more
        assert sum(e.kind == "terminated" for e in v.sim.events) == 1
        for cmd, p in ((M.MAV_CMD_COMPONENT_ARM_DISARM, (1.0,)), (M.MAV_CMD_DO_SET_MODE, (29.0, 4.0, 3.0)),
                       (M.MAV_CMD_DO_FLIGHTTERMINATION, (0.0,))):
            assert _command(v, gcs, cmd, *p) == M.MAV_RESULT_DENIED, cmd
        said = gcs.exchange(v, M.MAVLink_command_long_message(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0,
                                                              0, 0), "STATUSTEXT")
        assert said.text.startswith("arming denied: the flight was terminated")
        assert v.sim.mode == "termination" and not v.sim.armed
    finally:
        v.close()
        gcs.close()


def test_flight_termination_over_1_5_terminates_as_px4_mains(tmp_path: Path) -> None:
    """PX4 main's commander terminates on any param1 over 0.5 (Commander.cpp, handle_command,
    VEHICLE_CMD_DO_FLIGHTTERMINATION: no lockdown test over 1.5 any more; its ``commander lockdown on`` sends 2):
    ``bsst vehicle`` armed by a pymavlink ground station, param1 2 is ACCEPTED, the vehicle is disarmed and shows
    PX4's termination (MANUAL, MAV_STATE_FLIGHT_TERMINATION), a ``terminated`` event naming the ground station. Until
    the third wave's thirty-eighth session it was UNSUPPORTED and nothing happened."""
    with instance_slot() as n:
        gcs = gcs_link(n)
        v = _vehicle(n, tmp_path)
        try:
            gcs.wait_heartbeat(timeout=20)
            tgt = (gcs.target_system, gcs.target_component)
            gcs.mav.command_long_send(*tgt, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
            assert command_ack(gcs, M.MAV_CMD_COMPONENT_ARM_DISARM).result == M.MAV_RESULT_ACCEPTED  # armed in HOLD
            gcs.mav.command_long_send(*tgt, M.MAV_CMD_DO_FLIGHTTERMINATION, 0, 2, 0, 0, 0, 0, 0, 0)
            assert command_ack(gcs, M.MAV_CMD_DO_FLIGHTTERMINATION).result == M.MAV_RESULT_ACCEPTED
            hb = gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=10,
                                condition=f"HEARTBEAT.system_status=={M.MAV_STATE_FLIGHT_TERMINATION}")
            assert hb is not None and (hb.base_mode, hb.custom_mode) == (M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 1 << 16)
            v.wait_event(lambda s: s.startswith("terminated: flight termination: motors off") and "[by 255:190 " in s)
        finally:
            v.stop()
            gcs.close()


@pytest.mark.parametrize("cmd, p1", [(M.MAV_CMD_REQUEST_PROTOCOL_VERSION, 1), (M.MAV_CMD_REQUEST_MESSAGE, 300)])
def test_protocol_version_is_answered_as_px4_does(cmd: int, p1: float) -> None:
    """REQUEST_PROTOCOL_VERSION, or REQUEST_MESSAGE of message 300 (it was UNSUPPORTED): ACCEPTED and PROTOCOL_VERSION
    (version 200, min 100, max 200, as PX4's receiver sends it), a MAVLink 2 frame whose checksum holds with the
    message's CRC extra (217)."""
    v, gcs = _in_process()
    try:
        req = M.MAVLink_command_long_message(1, 1, cmd, 0, p1, 0, 0, 0, 0, 0, 0)
        gcs.sock.sendto(req.pack(gcs.mav), v.gcs.local)
        frames: list[bytes] = []

        def answered() -> bool:
            for m, addr in v.gcs.poll():
                v._handle(v.gcs, m, addr)
            try:
                data = gcs.sock.recv(65535)
            except BlockingIOError:
                return False
            while len(data) >= 12 and data[0] == 0xFD:  # the datagram's MAVLink 2 frames, one after another
                n = 12 + data[1] + (13 if data[2] & 1 else 0)
                frames.append(data[:n])
                data = data[n:]
            return any(int.from_bytes(f[7:10], "little") == 300 for f in frames)

        wait_for(answered, 5.0, "PROTOCOL_VERSION", poll_s=0.001)
        f = next(f for f in frames if int.from_bytes(f[7:10], "little") == 300)
        payload = f[10:10 + f[1]] + bytes(22 - f[1])  # MAVLink 2 trims trailing zeros
        crc = x25crc(f[1:10 + f[1]])
        crc.accumulate(bytes([217]))
        assert struct.unpack("<H", f[10 + f[1]:12 + f[1]])[0] == crc.crc
        assert struct.unpack("<HHH8s8s", payload)[:3] == (200, 100, 200)
        acks = [m for m in M.MAVLink(None).parse_buffer(b"".join(frames)) or [] if m.get_type() == "COMMAND_ACK"]
        assert [(a.command, a.result) for a in acks] == [(cmd, M.MAV_RESULT_ACCEPTED)]
    finally:
        v.close()
        gcs.close()


def test_change_speed_on_the_ground_changes_nothing_and_an_infinite_speed_is_refused() -> None:
    """Disarmed (nothing flown by the vehicle's own controller), DO_CHANGE_SPEED is ACCEPTED as PX4's navigator
    answers it, and its ``speed`` event says it changed nothing; +inf is DENIED (a bad number), saying why."""
    v, gcs = _in_process()
    try:
        assert _command(v, gcs, M.MAV_CMD_DO_CHANGE_SPEED, 1.0, 0.5, -1.0) == M.MAV_RESULT_ACCEPTED
        (e,) = [e for e in v.sim.events if e.kind == "speed"]
        assert e.text.startswith("0.5 m/s: nothing flown by the vehicle's own controller now (HOLD, disarmed)")
        assert v.sim.onboard.g.v_xy_max == 2.0
        assert _command(v, gcs, M.MAV_CMD_DO_CHANGE_SPEED, 1.0, math.inf, -1.0) == M.MAV_RESULT_DENIED
    finally:
        v.close()
        gcs.close()


# what both MAVSDK scripts share: the system, the Action and Telemetry plugins, armed and the flight mode seen, and
# ``until`` (a wait on one condition, its result in ``out``)
MAVSDK_HEAD = r"""
import json, math, sys, threading
from mavsdk import Mavsdk, Configuration, ComponentType
from mavsdk.plugins.action import Action
from mavsdk.plugins.telemetry import Telemetry

sdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
sdk.add_any_connection(sys.argv[1])
system = sdk.first_autopilot(30.0)
out = {"found": system is not None}
tel, act = Telemetry(system), Action(system)
cond = threading.Condition()
seen = {"armed": None, "modes": []}
def on_mode(m, ud=None):
    with cond:
        if not seen["modes"] or seen["modes"][-1] != m.name:
            seen["modes"].append(m.name)
        cond.notify_all()
def on_armed(a, ud=None):
    with cond:
        seen["armed"] = a
        cond.notify_all()
tel.subscribe_flight_mode(on_mode)
tel.subscribe_armed(on_armed)
def until(what, pred, timeout):
    with cond:
        out[what] = cond.wait_for(pred, timeout)
"""

MAVSDK_SPEED = MAVSDK_HEAD + r"""
seen.update(ned=None, geo=None, speeds=[])
def on_geo(p, ud=None):
    with cond:
        seen["geo"] = (p.latitude_deg, p.longitude_deg, p.absolute_altitude_m, p.relative_altitude_m)
        cond.notify_all()
def on_ned(pv, ud=None):
    with cond:
        seen["ned"] = (pv.position.north_m, pv.position.east_m, -pv.position.down_m)
        seen["speeds"].append((seen["modes"][-1] if seen["modes"] else "", math.hypot(pv.velocity.north_m_s,
                                                                                     pv.velocity.east_m_s)))
        cond.notify_all()
tel.subscribe_position(on_geo)
tel.subscribe_position_velocity_ned(on_ned)
out["rtl_alt"] = act.get_return_to_launch_altitude()  # RTL_RETURN_ALT: PX4's multicopter default
out["hold"] = act.hold().name
out["arm"] = act.arm().name
out["set_takeoff_altitude"] = act.set_takeoff_altitude(3.0).name
out["takeoff"] = act.takeoff().name
until("at_height", lambda: seen["modes"][-2:] == ["TAKEOFF", "HOLD"] and seen["geo"][3] > 2.9, 15)
lat0, lon0, amsl, rel = seen["geo"]
start = seen["ned"]
R = 6371000.0
lat = lat0 + (8.0 - start[0]) / R * 180.0 / math.pi
out["goto"] = act.goto_location(lat, lon0, amsl - rel + 3.0, 0.0).name
until("there", lambda: math.dist(seen["ned"], (8.0, start[1], 3.0)) < 0.1, 30)
n_goto = len(seen["speeds"])
out["rtl"] = act.return_to_launch().name
until("rtl_seen", lambda: seen["modes"][-1] == "RETURN_TO_LAUNCH", 10)
out["speed"] = act.set_current_speed(0.5).name
n_slow = len(seen["speeds"])
until("disarmed", lambda: seen["armed"] is False, 60)
until("hold_after", lambda: seen["modes"][-1] == "HOLD", 10)
with cond:
    out["goto_top"] = max(s for _, s in seen["speeds"][:n_goto])
    out["return_top"] = max(s for m, s in seen["speeds"][n_slow:] if m == "RETURN_TO_LAUNCH")
    out["landed_at"] = seen["ned"]
    out["modes"] = seen["modes"]
print("RESULT " + json.dumps(out), flush=True)
sdk.destroy()
"""


def test_mavsdk_set_current_speed_slows_a_return_home_to_it(tmp_path: Path) -> None:
    """MAVSDK's ``Action.set_current_speed(0.5)`` (DO_CHANGE_SPEED: speed type 1, 0.5 m/s) as Return begins, 8 m
    north of home at 3 m, after a ``goto_location`` flown at the on-board controller's 2 m/s: the way home is flown at
    0.5 m/s, it lands at home, disarms and is in HOLD again (PX4's mode after a disarm). Ground speeds as MAVSDK saw
    them: the on-board velocity loop overshoots its limit by ~15 % either way (2.31 m/s on the goto, 0.59 m/s home,
    measured). ``get_return_to_launch_altitude`` reads RTL_RETURN_ALT: 30 m, PX4's multicopter default."""
    with instance_slot() as n:
        v = _vehicle(n, tmp_path, *FAST)
        try:
            out = _mavsdk(n, "speed", MAVSDK_SPEED)
        finally:
            assert v.stop() == 0
    keys = ("hold", "arm", "set_takeoff_altitude", "takeoff", "goto", "rtl", "speed")
    assert out["found"] and [out[k] for k in keys] == ["SUCCESS"] * len(keys), out
    assert all(out[k] for k in ("at_height", "there", "rtl_seen", "disarmed", "hold_after")), out
    assert out["rtl_alt"] == 30.0
    assert out["goto_top"] > 1.8 and 0.4 < out["return_top"] < 0.7, out  # 2 m/s, then the 0.5 asked for
    north, east, up = out["landed_at"]
    assert math.hypot(north, east) < 0.3 and abs(up) < 0.05, out
    assert out["modes"][-2:] == ["RETURN_TO_LAUNCH", "HOLD"], out["modes"]
    v.wait_event(lambda s: s.startswith("speed: RTL flies at most 0.5 m/s across [by 245:190"))


MAVSDK_TERMINATE = MAVSDK_HEAD + r"""
seen.update(rel=0.0, texts=[])
def on_position(p, ud=None):
    with cond:
        seen["rel"] = p.relative_altitude_m
        cond.notify_all()
def on_text(s, ud=None):
    with cond:
        seen["texts"].append([s.type.name, s.text])
        cond.notify_all()
tel.subscribe_position(on_position)
tel.subscribe_status_text(on_text)
until("flying", lambda: seen["armed"] is True and seen["rel"] > 0.8, 60)  # the step mission's first set-point
out["terminate"] = act.terminate().name
until("disarmed", lambda: seen["armed"] is False, 10)
until("said", lambda: any(t.startswith("terminated: flight termination") for _, t in seen["texts"]), 10)
until("manual", lambda: seen["modes"][-1] == "MANUAL", 10)
with cond:
    out["texts"] = [t for t in seen["texts"] if t[1].startswith("terminated")]
    out["arm"] = None
try:
    act.arm()
except Exception as e:  # ActionError: denied
    out["arm"] = type(e).__name__ + ": " + str(e)
print("RESULT " + json.dumps(out), flush=True)
sdk.destroy()
"""


def test_mavsdk_terminate_ends_a_sessions_flight_terminated_exit_1(tmp_path: Path) -> None:
    """MAVSDK's ``Action.terminate`` (DO_FLIGHTTERMINATION, param1 1) while ``bsst sitl`` flies the step mission 1 m
    up: ACCEPTED; the motors stop, the vehicle falls (disarmed, as a ground station sees it) and shows PX4's
    termination (MANUAL, a CRITICAL "terminated" STATUSTEXT); an arm after it is refused. The session ends honestly:
    exit 1, outcome ``terminated``, ended by MAVSDK's system (its ids, the GCS link), "flight terminated at t=..."."""
    out_dir = tmp_path / "run"
    with instance_slot() as n:
        p = Proc.bsst("sitl", str(MISSION_DIR / "step.toml"), "--out", str(out_dir), "--instance", str(n),
                      "--speed", "1", "--no-plots")
        try:
            got = _mavsdk(n, "terminate", MAVSDK_TERMINATE)
            code = p.p.wait(timeout=120)
        finally:
            p.stop()
    assert got["found"] and got["flying"] and got["terminate"] == "SUCCESS", got
    assert got["disarmed"] and got["said"] and got["manual"], got
    assert got["texts"][0][0] == "CRITICAL" and got["arm"] and "DENIED" in got["arm"].upper(), got
    summary = json.loads((out_dir / "summary.json").read_text())
    assert code == 1 and summary["outcome"] == "terminated", (code, summary["outcome"], summary["ended_by"])
    who, how = summary["ended_by"]["who"], summary["ended_by"]["how"]
    assert who.startswith("245:190 ") and who.endswith(" gcs"), who
    assert how.startswith("flight terminated at t=") and "motors off at x=" in how, how
    kinds = [e["kind"] for e in summary["events"]]
    assert [e["source"] for e in summary["events"] if e["kind"] == "terminated"] == ["vehicle", "controller"]
    assert "disarmed" in kinds
    said = next(e["text"] for e in summary["events"] if e["kind"] == "terminated" and e["source"] == "controller")
    assert said == "the vehicle's flight ended: a flight termination (its EVENT)", said

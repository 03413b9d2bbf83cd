"""Covers bridge.nodes.vehicle, bridge.mavlink.modes and bridge.autopilot.params.

The ground-station surface of ``bsst vehicle`` with the real tools (issue 14): MAVSDK 4's native
binding (parameters; HOLD, arm, TAKEOFF, HOLD, LAND, disarmed; its flight mode) and MAVProxy typed
into through stdin (``param show`` / ``param set``, a refused set, HOLD and LAND, its prompt naming
the mode), against real vehicle processes over UDP on 127.0.0.1.

Each test holds an instance slot (bridge.session.instance_slot). The vehicle flies its own modes
on the wall clock: 4x real time (``--speed 4``) for MAVSDK, so that a takeoff and a landing take about
a second; real time for MAVProxy, whose prompt is asked for while TAKEOFF lasts. Every wait is on an
event (a line, a callback) with a deadline.
"""

from __future__ import annotations

import math
import re
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as M

from bridge.autopilot.params import PARAMS, VehicleParams, read_param
from bridge.core.flight import prepare
from bridge.mavlink.endpoint import GCS_PORT, parse_address
from bridge.nodes.report import Refused
from bridge.nodes.vehicle import Vehicle, VehicleConfig
from bridge.nodes.vehicle.reposition import UNSET_INT
from bridge.session import instance_slot
from missions import MISSION_DIR, Mission, Sine
from missions.geodetic import Home
from tests.gcskit import command_ack, gcs_link
from tests.sitlkit import ENV, GcsSocket, MavProxy, Proc, run_script, script_result, shown
from tests.test_vehicle import _vehicle
from tests.waiting import wait_for

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast

# a takeoff to 3 m and its landing in ~1 s of wall time; 1.5 m/s: the on-board LAND touches down about 1.2 times
# faster than it sinks, and over 2 m/s the vehicle ends crashed (plant.quadrotor.CRASH_SPEED_MPS, issue 27)
FAST = ("--speed", "4", "--param", "MPC_LAND_SPEED=1.5")


def _answers(tlog: Path, sysid: int) -> tuple[set[int], int, int]:
    """From a vehicle's tlog: the commands others sent that got no COMMAND_ACK, and the FTP requests
    others sent and the FTP replies the vehicle sent."""
    log = mavutil.mavlink_connection(str(tlog), dialect="common")
    asked, acked, ftp = set(), set(), Counter()
    kinds = ["COMMAND_LONG", "COMMAND_INT", "COMMAND_ACK", "FILE_TRANSFER_PROTOCOL"]
    while (m := log.recv_match(type=kinds)) is not None:
        mine = m.get_srcSystem() == sysid
        if m.get_type() == "FILE_TRANSFER_PROTOCOL":
            ftp["replies" if mine else "requests"] += 1
        elif mine and m.get_type() == "COMMAND_ACK":
            acked.add(m.command)
        elif not mine and m.get_type() != "COMMAND_ACK":
            asked.add(m.command)
    return asked - acked, ftp["requests"], ftp["replies"]


# -- MAVSDK ---------------------------------------------------------------------------------------

MAVSDK_SCRIPT = r"""
import json, sys, threading, time
from mavsdk import Mavsdk, Configuration, ComponentType
from mavsdk.plugins.action import Action
from mavsdk.plugins.param import Param, ParamError
from mavsdk.plugins.telemetry import Telemetry

sdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
sdk.add_any_connection(sys.argv[1])
system = sdk.first_autopilot(30.0)
out = {"found": system is not None}

def refused(call, *args):
    try:
        return "SUCCESS: " + str(call(*args))
    except ParamError as e:
        return e.result.name

if sys.argv[2] == "params":
    par = Param(system)
    every = par.get_all_params()
    out["ints"] = {p.name: p.value for p in every.int_params}
    out["floats"] = {p.name: p.value for p in every.float_params}
    out["get"] = par.get_param_float("COM_OF_LOSS_T")
    out["set"] = par.set_param_float("COM_OF_LOSS_T", 1.5).name
    out["get_after_set"] = par.get_param_float("COM_OF_LOSS_T")
    out["set_out_of_range"] = refused(par.set_param_float, "COM_OF_LOSS_T", 100.0)
    out["get_after_refusal"] = par.get_param_float("COM_OF_LOSS_T")
    out["set_unknown"] = refused(par.set_param_float, "NO_SUCH_PARAM", 1.0)
    out["get_unknown"] = refused(par.get_param_float, "NO_SUCH_PARAM")
    out["obl_act"] = par.get_param_int("COM_OBL_ACT")
    out["set_obl_act"] = par.set_param_int("COM_OBL_ACT", 1).name
    out["obl_rc_act"] = par.get_param_int("COM_OBL_RC_ACT")  # the same setting under PX4 1.14's name
    # 42: never an instance's own id (instances 0-9 are systems 1-10), whose echo MAVSDK would take as made
    out["set_sys_id"] = refused(par.set_param_int, "MAV_SYS_ID", 42)
else:  # the flight parts: what MAVSDK's telemetry shows, each callback under one condition
    tel, act = Telemetry(system), Action(system)
    cond = threading.Condition()
    modes, seen = [], {"armed": None, "rel": None, "top": -1.0, "ned": None, "rtl_top": -1.0, "hud": None,
                       "climb_top": 0.0, "altitude": None}
    def on_mode(m, ud=None):
        with cond:
            if not modes or modes[-1] != m.name:
                modes.append(m.name)
            cond.notify_all()
    def on_armed(a, ud=None):
        with cond:
            seen["armed"] = a
            cond.notify_all()
    def on_position(p, ud=None):
        with cond:
            seen["rel"] = p.relative_altitude_m
            seen["top"] = max(seen["top"], p.relative_altitude_m)
            seen["geo"] = (p.latitude_deg, p.longitude_deg, p.absolute_altitude_m, p.relative_altitude_m)
            cond.notify_all()
    def on_heading(h, ud=None):
        with cond:
            seen["heading"] = h.heading_deg
            cond.notify_all()
    neds = []  # every position, in order
    def on_ned(pv, ud=None):
        with cond:
            seen["ned"] = (pv.position.north_m, pv.position.east_m, -pv.position.down_m)
            neds.append(seen["ned"])
            if modes and modes[-1] == "RETURN_TO_LAUNCH":
                seen["rtl_top"] = max(seen["rtl_top"], -pv.position.down_m)
            cond.notify_all()
    def on_hud(f, ud=None):  # VFR_HUD
        with cond:
            seen["hud"] = (f.throttle_percentage, f.climb_rate_m_s, f.groundspeed_m_s, f.absolute_altitude_m,
                           f.heading_deg, f.airspeed_m_s)
            seen["climb_top"] = max(seen["climb_top"], f.climb_rate_m_s)
            cond.notify_all()
    def on_altitude(a, ud=None):  # ALTITUDE
        with cond:
            seen["altitude"] = (a.altitude_amsl_m, a.altitude_local_m, a.altitude_relative_m, a.altitude_terrain_m)
            cond.notify_all()
    landed = []
    def on_landed(s, ud=None):  # EXTENDED_SYS_STATE
        with cond:
            if not landed or landed[-1] != s.name:
                landed.append(s.name)
            cond.notify_all()
    tel.subscribe_flight_mode(on_mode)
    tel.subscribe_landed_state(on_landed)
    tel.subscribe_fixedwing_metrics(on_hud)
    tel.subscribe_altitude(on_altitude)
    tel.subscribe_armed(on_armed)
    tel.subscribe_position(on_position)
    tel.subscribe_position_velocity_ned(on_ned)
    tel.subscribe_heading(on_heading)
    def until(what, pred, timeout):
        with cond:
            out[what] = cond.wait_for(pred, timeout)
if sys.argv[2] == "rtl":  # the controller flies the step mission; at its second set-point, Return
    away = lambda: seen["ned"] is not None and (seen["ned"][0] ** 2 + seen["ned"][1] ** 2) ** 0.5 > 2.0 \
        and seen["ned"][2] > 1.8
    until("away", away, 60)
    out["from"] = seen["ned"]
    out["rtl"] = act.return_to_launch().name
    until("rtl_seen", lambda: modes and modes[-1] == "RETURN_TO_LAUNCH", 10)
    until("disarmed_seen", lambda: seen["armed"] is False, 60)
    until("on_ground", lambda: abs(seen["ned"][2]) < 0.02, 5)  # positions come at 25 Hz: the next ones
    with cond:
        out.update(modes=modes, landed_at=seen["ned"], top=seen["rtl_top"])
elif sys.argv[2] == "goto":  # take off to 3 m, then goto_location 4 m north, 3 m east, 5 m up, facing east
    out["hold"] = act.hold().name
    out["arm"] = act.arm().name
    until("armed_seen", lambda: seen["armed"] is True, 10)
    out["set_takeoff_altitude"] = act.set_takeoff_altitude(3.0).name
    out["takeoff"] = act.takeoff().name
    until("at_height", lambda: modes[-2:] == ["TAKEOFF", "HOLD"] and seen["rel"] > 2.9, 15)
    with cond:
        lat0, lon0, amsl, rel = seen["geo"]
        start = seen["ned"]
    R = 6371000.0  # the vehicle's projection's sphere (PX4's): the target within a centimetre of 4 m, 3 m here
    lat = lat0 + (4.0 - start[0]) / R * 180.0 / 3.141592653589793
    lon = lon0 + (3.0 - start[1]) / (R * __import__("math").cos(lat0 * 3.141592653589793 / 180.0)) * 180.0 \
        / 3.141592653589793
    # 5 m above home: the home's altitude from one message (GLOBAL_POSITION_INT's alt and relative_alt, in mm),
    # not from two taken at different moments (a CI run once got 3.5 cm of the climb between them)
    out["goto"] = act.goto_location(lat, lon, amsl - rel + 5.0, 90.0).name
    there = lambda: sum((a - b) ** 2 for a, b in zip(seen["ned"], (4.0, 3.0, 5.0))) ** 0.5 < 0.1 \
        and abs(seen["heading"] - 90.0) < 3.0
    until("there", there, 30)
    with cond:
        out.update(modes=list(modes), at=seen["ned"], heading=seen["heading"])
    out["land"] = act.land().name
    until("disarmed_seen", lambda: seen["armed"] is False, 30)
elif sys.argv[2] == "goto_fence":  # a fence 10 m about home; goto 4 m north (inside), then 30 m north (outside)
    from math import cos, dist, pi
    from mavsdk.plugins.geofence import FenceType, Geofence, GeofenceData, Point, Polygon
    texts = []
    tel.subscribe_status_text(lambda s, ud=None: texts.append([s.type.name, s.text]))
    until("geo_seen", lambda: "geo" in seen, 10)
    lat0, lon0, amsl0, _ = seen["geo"]  # on the ground at home
    R = 6371000.0  # the vehicle's projection's sphere (PX4's)
    at = lambda n, e: Point(lat0 + n / R * 180.0 / pi, lon0 + e / (R * cos(lat0 * pi / 180.0)) * 180.0 / pi)
    square = [at(-10.0, -10.0), at(-10.0, 10.0), at(10.0, 10.0), at(10.0, -10.0)]
    out["fence"] = Geofence(system).upload_geofence(GeofenceData([Polygon(square, FenceType.INCLUSION)], [])).name
    out["hold"] = act.hold().name
    out["arm"] = act.arm().name
    out["set_takeoff_altitude"] = act.set_takeoff_altitude(3.0).name
    out["takeoff"] = act.takeoff().name
    until("at_height", lambda: modes[-2:] == ["TAKEOFF", "HOLD"] and seen["rel"] > 2.9, 15)
    p = at(4.0, 0.0)
    out["goto_inside"] = act.goto_location(p.latitude_deg, p.longitude_deg, amsl0 + 3.0, 0.0).name
    until("there", lambda: dist(seen["ned"], (4.0, 0.0, 3.0)) < 0.1, 30)
    q = at(30.0, 0.0)
    out["goto_outside"] = act.goto_location(q.latitude_deg, q.longitude_deg, amsl0 + 3.0, 0.0).name
    until("said", lambda: any(t.startswith("Reposition is outside geofence") for _, t in texts), 10)
    n0 = len(neds)
    until("watched", lambda: len(neds) >= n0 + 25, 10)  # 1 s of wall time at 25 Hz: 4 s of the vehicle's
    with cond:
        out["farthest"] = max(dist(p, (4.0, 0.0, 3.0)) for p in neds[n0:])
        out["modes"], out["texts"] = list(modes), list(texts)
    out["land"] = act.land().name
    until("disarmed_seen", lambda: seen["armed"] is False, 30)
elif sys.argv[2] == "hard_land":  # take off to 8 m, then LAND (at the vehicle's MPC_LAND_SPEED)
    out["hold"] = act.hold().name
    out["arm"] = act.arm().name
    out["set_takeoff_altitude"] = act.set_takeoff_altitude(8.0).name
    out["takeoff"] = act.takeoff().name
    until("at_height", lambda: modes[-2:] == ["TAKEOFF", "HOLD"] and seen["rel"] > 7.9, 20)
    out["land"] = act.land().name
    until("disarmed_seen", lambda: seen["armed"] is False, 20)
elif sys.argv[2] == "flight":  # MAVSDK's own takeoff_and_land example: arm, wait, take off, land
    tel.set_rate_landed_state(10.0)  # MAVSDK asks for 1 Hz of EXTENDED_SYS_STATE: a takeoff at --speed 4 is shorter
    until("hold_seen", lambda: modes and modes[-1] == "HOLD", 10)  # the boot mode, as PX4's
    out["arm"] = act.arm().name
    until("armed_seen", lambda: seen["armed"] is True, 10)
    time.sleep(0.5)  # 2 s of the vehicle's at --speed 4: four offboard timeouts, were it in OFFBOARD
    with cond:
        out["after_arm"] = (seen["armed"], modes[-1])
    out["set_takeoff_altitude"] = act.set_takeoff_altitude(3.0).name
    out["takeoff_altitude"] = act.get_takeoff_altitude()
    out["takeoff"] = act.takeoff().name
    until("at_height", lambda: modes[-2:] == ["TAKEOFF", "HOLD"] and seen["rel"] > 2.9, 15)
    out["rel_at_height"] = seen["rel"]
    # holding still at 3 m: the HUD's altitude is the position's (4 Hz and 10 Hz: wait for them to agree)
    until("hud_at_height", lambda: seen["hud"] and abs(seen["hud"][3] - seen["geo"][2]) < 0.05
          and abs(seen["hud"][1]) < 0.05, 5)
    until("altitude_at_height", lambda: seen["altitude"] and abs(seen["altitude"][2] - seen["rel"]) < 0.05, 5)  # 1 Hz
    out["hud_at_height"], out["climb_top"], out["altitude"] = seen["hud"], seen["climb_top"], seen["altitude"]
    out["land"] = act.land().name
    until("disarmed_seen", lambda: seen["armed"] is False, 15)
    until("on_ground", lambda: abs(seen["rel"]) < 0.02, 5)  # positions come at 10 Hz: the next ones
    until("hud_landed", lambda: seen["hud"][0] == 0.0, 5)  # disarmed: no thrust
    until("landed_on_ground", lambda: landed[-1] == "ON_GROUND", 5)
    until("hold_after", lambda: modes[-1] == "HOLD", 5)  # disarmed, back in the last mode it arms in (PX4's)
    with cond:
        out.update(modes=modes, rel_landed=seen["rel"], top=seen["top"], hud_landed=seen["hud"], landed=landed)
print("RESULT " + json.dumps(out), flush=True)
sdk.destroy()
"""


def _mavsdk(n: int, part: str, script: str = MAVSDK_SCRIPT) -> dict:
    """Run the MAVSDK ``script``'s ``part`` (in its own process: the native library keeps threads of its
    own) against the vehicle of instance ``n``; its RESULT."""
    r = run_script("-c", script, f"udpin://127.0.0.1:{GCS_PORT + n}", part, timeout=120, env=ENV)
    return script_result(r)


def _mavsdk_on_a_vehicle(tmp_path: Path, part: str) -> tuple[dict, Proc, int]:
    """The MAVSDK script's ``part`` against a ``bsst vehicle`` at 4x (:data:`FAST`) on an instance of its own,
    stopped after: (its RESULT, having found the vehicle; the vehicle's process; the instance)."""
    with instance_slot() as n:
        v = _vehicle(n, tmp_path, *FAST)
        try:
            out = _mavsdk(n, part)
        finally:
            assert v.stop() == 0
    assert out["found"]
    return out, v, n


def test_mavsdk_parameters(tmp_path):
    """``Param``: every parameter listed with its value (``--param`` included), read, set and read
    back, an out-of-range set refused at once with MAVSDK's VALUE_OUT_OF_RANGE and the value unchanged, an
    unknown name's set and read DOES_NOT_EXIST, an INT32 set under PX4's old name read under its new one, and the
    start-only MAV_SYS_ID refused READ_ONLY."""
    with instance_slot() as n:
        v = _vehicle(n, tmp_path, "--param", "COM_FAIL_ACT_T=7")
        try:
            out = _mavsdk(n, "params")
        finally:
            assert v.stop() == 0
    assert out["found"]
    defaults = VehicleParams()
    want = {p.name: read_param(defaults, p.name) for p in PARAMS} | {"COM_FAIL_ACT_T": 7.0, "MAV_SYS_ID": n + 1}
    got = out["ints"] | out["floats"]
    assert set(got) == set(want) and len(got) == len(PARAMS)
    assert set(out["ints"]) == {p.name for p in PARAMS if p.kind == "INT32"}  # bytewise INT32s decoded as ints
    for name, value in want.items():
        assert math.isclose(got[name], value, rel_tol=1e-6), (name, got[name], value)
    assert out["get"] == 0.5 and out["set"] == "SUCCESS" and out["get_after_set"] == 1.5
    # a refusal's PARAM_ERROR ends MAVSDK's set with its reason (on the unchanged value alone it resent the set five
    # times and said TIMEOUT; an unknown name, answered by a STATUSTEXT only, took 3 s to say TIMEOUT)
    assert out["set_out_of_range"] == "VALUE_OUT_OF_RANGE" and out["get_after_refusal"] == 1.5
    assert out["set_unknown"] == out["get_unknown"] == "DOES_NOT_EXIST"
    assert out["obl_act"] == -1 and out["set_obl_act"] == "SUCCESS" and out["obl_rc_act"] == 5  # hold
    assert out["set_sys_id"] == "READ_ONLY"
    v.wait_event(lambda s: "param: COM_OF_LOSS_T = 1.5 (was 0.5) [by " in s and " gcs]" in s)
    v.wait_report(Refused, lambda r: r.text.startswith("COM_OF_LOSS_T: must be in [0.01, 60] s, got 100"))
    v.wait_report(Refused, lambda r: r.text.startswith("MAV_SYS_ID: takes effect at start only"))
    assert not any("COM_OF_LOSS_T = 100" in s for s in v.events())
    # each refused set was sent once: MAVSDK did not resend it (one refusal each in the vehicle's records)
    assert sorted(r.text.split(":")[0] for r in v.reports() if isinstance(r, Refused)) == ["COM_OF_LOSS_T",
                                                                                          "MAV_SYS_ID"]


def test_mavsdk_arm_takeoff_land(tmp_path):
    """MAVSDK's own example's flow against a fresh vehicle: it boots in HOLD (PX4's), so ``Action.arm`` arms it
    in HOLD on the ground, where it waits (no controller needed); ``set_takeoff_altitude`` / ``takeoff``
    (TAKEOFF, then HOLD at the height), ``land`` (LAND, then disarmed on the ground and back in HOLD), with
    ``Telemetry.flight_mode`` naming each mode, ``fixedwing_metrics`` (VFR_HUD) the climb, throttle and altitude
    and ``altitude`` (ALTITUDE) the heights; every command MAVSDK sent was answered."""
    out, v, n = _mavsdk_on_a_vehicle(tmp_path, "flight")
    assert [out[k] for k in ("arm", "set_takeoff_altitude", "takeoff", "land")] == ["SUCCESS"] * 4
    assert all(out[k] for k in ("hold_seen", "armed_seen", "at_height", "disarmed_seen", "on_ground")), out
    assert out["after_arm"] == [True, "HOLD"], out  # armed and waiting on the ground, no failsafe
    assert out["takeoff_altitude"] == 3.0  # MIS_TAKEOFF_ALT, set and read back through the parameters
    assert out["modes"] == ["HOLD", "TAKEOFF", "HOLD", "LAND", "HOLD"], out["modes"]  # HOLD again once disarmed
    # MAVSDK's landed_state (EXTENDED_SYS_STATE at 10 Hz) as PX4 tells it: taking off, in the air, landing, on the
    # ground (the climb lasts ~0.5 s of wall time: a stalled machine may show none of it; tests/test_gcs_instruments.py
    # pins the states themselves)
    full = ["ON_GROUND", "TAKING_OFF", "IN_AIR", "LANDING", "ON_GROUND"]
    assert out["landed"] in (full, full[:1] + full[2:]), out["landed"]
    assert abs(out["rel_at_height"] - 3.0) < 0.1 and out["top"] < 3.1
    assert abs(out["rel_landed"]) < 0.02
    # VFR_HUD (MAVSDK's fixed-wing metrics): climbing in TAKEOFF, a hover's throttle at 3 m facing north, no
    # throttle once disarmed; airspeed 0, as PX4 sends it for a multicopter without an airspeed sensor. MAVSDK
    # gives the throttle as a fraction (VFR_HUD's percent / 100)
    throttle, climb, ground, amsl, heading, airspeed = out["hud_at_height"]
    assert out["climb_top"] > 0.5 and 0.2 < throttle < 0.9 and ground < 0.05 and airspeed == 0.0, out
    assert heading in (0.0, 359.0) and abs(amsl - 491.0) < 0.1  # home 488 m AMSL + 3 m
    assert out["hud_landed"][0] == 0.0 and abs(out["hud_landed"][3] - 488.0) < 0.05
    amsl, local, relative, terrain = out["altitude"]  # ALTITUDE (MAVSDK's altitude): the home is the local origin
    assert abs(amsl - 491.0) < 0.1 and local == relative and abs(relative - 3.0) < 0.1 and math.isnan(terrain)
    v.wait_event(lambda s: "mode: TAKEOFF to 3 m" in s)
    v.wait_event(lambda s: "mode: HOLD: takeoff done" in s)
    v.wait_event(lambda s: "mode: LAND at" in s and "1.5 m/s" in s)
    v.wait_event(lambda s: "disarmed: landed" in s)
    unanswered, _, _ = _answers(tmp_path / "vehicle.tlog", n + 1)
    assert not unanswered, f"commands MAVSDK sent that got no COMMAND_ACK: {unanswered}"


def test_a_ground_stations_land_that_touches_down_hard_is_a_crash(tmp_path):
    """MAVSDK's ``Action.land`` from 8 m with MPC_LAND_SPEED = 4 m/s: the on-board landing touches down at ~4.4 m/s,
    over CRASH_SPEED_MPS (2 m/s), armed, so the vehicle ends it ``crashed`` (its plant's verdict: the clock halted),
    though its landing may have disarmed it on the ground first (then the ``disarmed`` event comes before the
    ``crashed`` one: where the touchdown falls in its control period);
    it was once logged as a disarmed vehicle's ``impact``, and the flight went on."""
    with instance_slot() as n:
        v = _vehicle(n, tmp_path, "--speed", "4", "--param", "MPC_LAND_SPEED=4")
        try:
            out = _mavsdk(n, "hard_land")
            crash = v.wait_event(lambda s: s.startswith("crashed: hit the ground at "))
        finally:
            status = v.stop()
    assert out["found"] and [out[k] for k in ("hold", "arm", "set_takeoff_altitude", "takeoff", "land")] == \
        ["SUCCESS"] * 5, out
    # stopped, the vehicle says its flight crashed and exits 1 (until the third wave's forty-first session: 0, silent)
    assert status == 1 and any(ln.startswith("bsst vehicle: crashed at t=") for ln in v.lines), v.lines[-5:]
    assert out["at_height"] and out["disarmed_seen"], out
    speed = float(crash.text.split(" at ")[1].split(" m/s")[0])
    assert 4.0 < speed < 5.0, crash.text
    said = v.events()
    # a touchdown on a control period's last physics step is judged before the landing disarms it: no disarm then
    landed = [i for i, s in enumerate(said) if s == "disarmed: landed: disarmed [by vehicle]"]
    assert all(i < said.index(shown(crash)) for i in landed) and not any(s.startswith("impact:") for s in said), said


def test_a_sessions_vehicle_armed_by_a_ground_station_before_its_controller_holds_and_says_it_left_lockstep():
    """The vehicle boots in HOLD, as PX4's: in a lockstep session (its controller's address pinned) a ground
    station's arm that comes before the controller's arms it in HOLD on the ground, off the step clock, which it
    says (a ``lockstep`` event: the session's record then agrees, and names the ground station); the controller's
    arm after it changes nothing (the vehicle is the ground station's until it selects OFFBOARD again)."""
    gcs = GcsSocket()
    flight = prepare(Mission(Sine(), duration_s=5.0, name="boot"))
    v = Vehicle(flight, VehicleConfig(parse_address("udpin:127.0.0.1:0"), parse_address(gcs.url), clock="lockstep",
                                      controller_from=("127.0.0.1", 9)))
    try:
        assert v.streaming.heartbeat().custom_mode == (4 << 16) | (3 << 24)  # HOLD (AUTO.LOITER)
        arm = M.MAVLink_command_long_message(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
        assert gcs.exchange(v, arm, "COMMAND_ACK").result == M.MAV_RESULT_ACCEPTED
        assert v.sim.armed and v.sim.mode == "hold" and v.clock.free_running
        assert [e.kind for e in v.sim.events] == ["armed", "mode", "lockstep"], v.sim.events
        assert v.commander.arm_disarm(1.0, 0.0) == M.MAV_RESULT_ACCEPTED and v.sim.mode == "hold"
    finally:
        v.close()
        gcs.close()


def test_offboard_selected_disarmed_needs_a_controller_to_fly_it():
    """PX4 switches to OFFBOARD only while a controller streams setpoints. Disarmed, the selection is for the next
    arm, so it is refused (with a STATUSTEXT) while no controller has spoken on the controller link and none is
    pinned: armed in OFFBOARD with nobody to fly it, the failsafe would disarm it at once. A session's vehicle (its
    controller pinned) takes it."""
    select = M.MAVLink_command_long_message(1, 1, M.MAV_CMD_DO_SET_MODE, 0, 29, 6, 0, 0, 0, 0, 0)
    flight = prepare(Mission(Sine(), duration_s=5.0, name="offboard"))
    for pinned, want in ((None, M.MAV_RESULT_TEMPORARILY_REJECTED), (("127.0.0.1", 9), M.MAV_RESULT_ACCEPTED)):
        gcs = GcsSocket()
        v = Vehicle(flight, VehicleConfig(parse_address("udpin:127.0.0.1:0"), parse_address(gcs.url),
                                          controller_from=pinned))
        try:
            assert gcs.exchange(v, select, "COMMAND_ACK").result == want, pinned
            assert v.sim.mode == ("hold" if pinned is None else "offboard")
        finally:
            v.close()
            gcs.close()
    text = "OFFBOARD: no controller has spoken on the controller link"
    gcs = GcsSocket()
    v = Vehicle(flight, VehicleConfig(parse_address("udpin:127.0.0.1:0"), parse_address(gcs.url)))
    try:
        assert gcs.exchange(v, select, "STATUSTEXT").text == text[:50]
    finally:
        v.close()
        gcs.close()


def test_mavsdk_return_to_launch(tmp_path):
    """``Action.return_to_launch`` (MAV_CMD_NAV_RETURN_TO_LAUNCH: PX4's Return mode) while ``bsst controller`` flies
    the step mission, at its second set-point (2.2 m from home, 2 m up): MAVSDK shows RETURN_TO_LAUNCH; the
    vehicle (no cone: RTL_CONE_ANG 0) climbs to RTL_RETURN_ALT (3 m), flies home, comes down to RTL_DESCEND_ALT and
    lands at home, disarmed, back in OFFBOARD (the last mode it arms in: PX4's); the controller, its vehicle taken,
    ends aborted (exit 1); the vehicle's events name MAVSDK."""
    mission = tmp_path / "step.toml"
    mission.write_text((MISSION_DIR / "step.toml").read_text().replace("duration_s = 30.0", "duration_s = 20.0"))
    with instance_slot() as n:
        v = _vehicle(n, tmp_path / "v", str(mission), "--speed", "4", "--param", "MPC_LAND_SPEED=1.5",
                     "--param", "RTL_RETURN_ALT=3", "--param", "RTL_DESCEND_ALT=2.5", "--param", "RTL_CONE_ANG=0")
        ctl = Proc.bsst("controller", str(mission), "--instance", str(n), "--out", str(tmp_path / "c"))
        try:
            out = _mavsdk(n, "rtl")
            assert ctl.p.wait(timeout=60) == 1, ctl.lines[-10:]
        finally:
            ctl.stop()
            assert v.stop() == 0
    assert out["found"] and out["away"] and out["rtl"] == "SUCCESS", out
    assert out["rtl_seen"] and out["disarmed_seen"] and out["on_ground"], out
    # disarmed, it is back in OFFBOARD, the last mode it arms in (PX4's): MAVSDK may have seen that before it stopped
    rtl = out["modes"].index("RETURN_TO_LAUNCH")
    assert out["modes"][rtl:] in (["RETURN_TO_LAUNCH"], ["RETURN_TO_LAUNCH", "OFFBOARD"]), out
    assert 2.9 < out["top"] < 3.1, out  # climbed to RTL_RETURN_ALT, no higher
    north, east, up = out["landed_at"]
    assert (north ** 2 + east ** 2) ** 0.5 < 0.2 and abs(up) < 0.05, out  # at home, on the ground
    v.wait_event(lambda s: "mode: RTL from" in s and "[by 245:190" in s)
    v.wait_event(lambda s: "disarmed: landed" in s)
    v.wait_event(lambda s: s.startswith("mode: OFFBOARD (disarmed after RTL: "))


def test_mavsdk_goto_location_flies_hold_to_the_point_and_faces_its_heading(tmp_path):
    """``Action.goto_location`` (MAV_CMD_DO_REPOSITION, COMMAND_INT in GLOBAL_INT: the point AMSL, the heading in
    radians) after a takeoff to 3 m: ACCEPTED, the vehicle stays in HOLD (AUTO.LOITER), flies to 4 m north,
    3 m east and 5 m up and faces east (90 deg), all as MAVSDK's telemetry shows; its event names the point in
    the paper frame (y west: x=4.00 y=-3.00) and MAVSDK as the sender; then it lands."""
    out, v, n = _mavsdk_on_a_vehicle(tmp_path, "goto")
    assert [out[k] for k in ("hold", "arm", "set_takeoff_altitude", "takeoff", "goto", "land")] == ["SUCCESS"] * 6
    assert all(out[k] for k in ("armed_seen", "at_height", "there", "disarmed_seen")), out
    assert out["modes"][-3:] == ["HOLD", "TAKEOFF", "HOLD"], out["modes"]  # goto: HOLD stays HOLD
    north, east, up = out["at"]  # (the script's point, from float32 telemetry: within a few millimetres of it)
    assert abs(north - 4.0) < 0.1 and abs(east - 3.0) < 0.1 and abs(up - 5.0) < 0.1 and abs(out["heading"] - 90) < 3
    v.wait_event(lambda s: "mode: HOLD, repositioned: from x=" in s and " z=5.000 m, heading -1.571 rad [by 245:190"
                 in s)
    v.wait_event(lambda s: "disarmed: landed" in s)
    unanswered, _, _ = _answers(tmp_path / "vehicle.tlog", n + 1)
    assert not unanswered, f"commands MAVSDK sent that got no COMMAND_ACK: {unanswered}"


def test_mavsdk_goto_location_outside_an_uploaded_fence_is_not_flown_the_vehicle_holds(tmp_path):
    """PX4's navigator does not fly a reposition outside its geofence (``Navigator::geofence_allows_position``, with
    GF_ACTION 2-5): MAVSDK's Geofence plugin uploads an inclusion square 10 m about home; after a takeoff to 3 m,
    ``goto_location`` 4 m north (inside) is flown; 30 m north (outside) is ACCEPTED, as PX4's commander answers it
    (it takes AUTO.LOITER; the navigator judges the point after), a CRITICAL STATUSTEXT "Reposition is outside
    geofence" says why, and the vehicle holds where it was (it once flew on, out of the fence, into its failsafe)."""
    out, v, n = _mavsdk_on_a_vehicle(tmp_path, "goto_fence")
    keys = ("fence", "hold", "arm", "set_takeoff_altitude", "takeoff", "goto_inside", "goto_outside", "land")
    assert [out[k] for k in keys] == ["SUCCESS"] * len(keys), out
    assert all(out[k] for k in ("at_height", "there", "said", "watched", "disarmed_seen")), out
    # 4 s of the vehicle's after it: still about the inside point (still settling there, within centimetres), where
    # flown toward 30 m north at 2 m/s it would have gone ~6 m (8 s watched until the forty-fifth session: 16 m)
    assert out["farthest"] < 0.3 and out["modes"][-1] == "HOLD", out
    said = [t for t in out["texts"] if t[1].startswith("Reposition is outside geofence")]
    assert said and said[0][0] == "CRITICAL" and "to x=30.000 y=-0.000 z=3.000 m: outside its fence" in said[0][1]
    v.wait_report(Refused, lambda r: r.text.startswith("Reposition is outside geofence: to x=30.000") and
                  r.text.endswith("outside every inclusion zone of the geofence: not flown, holding"))
    v.wait_event(lambda s: s == "disarmed: landed: disarmed [by vehicle]")
    events = v.events()
    assert sum("repositioned" in s for s in events) == 1, events  # the inside point only
    assert not any(s.startswith(("geofence:", "failsafe:")) for s in events), events


def test_a_reposition_in_a_failsafe_takes_over_as_px4s_mode_change_and_outside_the_geofence_holds(tmp_path):
    """PX4's commander takes DO_REPOSITION as a mode change (AUTO.LOITER), and a mode change during a Hold, Return,
    Land or Descend failsafe is the user's takeover (FailsafeBase::getSelectedAction); its navigator then flies the
    point only inside the geofence. GF_MAX_VER_DIST 2 m and GF_ACTION 5 (land): a takeoff to 3 m passes the limit,
    the vehicle lands. A reposition to 5 m above home then is ACCEPTED, says "Reposition is outside geofence"
    (CRITICAL), and HOLD takes over where it is: the vehicle neither climbs back nor lands (it once climbed to 5 m).
    With the limit lowered to 1.9 m it lands again; a reposition 1 m north at 1.5 m, inside, is taken over and
    flown."""
    with instance_slot() as n:
        gcs = gcs_link(n)
        v = _vehicle(n, tmp_path, "--speed", "4", "--param", "MPC_LAND_SPEED=0.3", "--param", "GF_ACTION=5",
                     "--param", "GF_MAX_VER_DIST=2", "--param", "MIS_TAKEOFF_ALT=3")
        try:
            assert gcs.wait_heartbeat(timeout=20) is not None
            nan = math.nan

            def command(cmd: int, *p: float) -> int:
                gcs.mav.command_long_send(n + 1, 1, cmd, 0, *p)
                return command_ack(gcs, cmd).result

            def reposition(north: float, up: float) -> int:
                lat, lon, _ = Home().global_of(north, 0.0, 0.0)
                gcs.mav.command_int_send(n + 1, 1, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, M.MAV_CMD_DO_REPOSITION, 0,
                                         0, -1.0, 1.0, 0.0, nan, round(lat * 1e7), round(lon * 1e7), up)
                return command_ack(gcs, M.MAV_CMD_DO_REPOSITION).result

            def heights(count: int) -> list[float]:  # the next ``count`` LOCAL_POSITION_NED heights (m up)
                got = [gcs.recv_match(type="LOCAL_POSITION_NED", blocking=True, timeout=5) for _ in range(count)]
                assert all(got)
                return [-m.z for m in got]

            assert command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1, 0, 0, 0, 0, 0, 0) == M.MAV_RESULT_ACCEPTED
            assert command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, nan, nan, nan, nan) == M.MAV_RESULT_ACCEPTED
            v.wait_event(lambda s: s.startswith("failsafe: geofence: 2.0") and s.endswith(": land here"))
            assert reposition(0.0, 5.0) == M.MAV_RESULT_ACCEPTED
            said = gcs.recv_match(type="STATUSTEXT", blocking=True, timeout=10,
                                  condition="'Reposition is outside geofence' in STATUSTEXT.text")
            assert said is not None and said.severity == M.MAV_SEVERITY_CRITICAL
            v.wait_event(lambda s: s.startswith("mode: HOLD at ") and "[by 255:190" in s)
            # ~2.4 s of wall time at 25 Hz, ~10 s of the vehicle's: (its takeoff's climb carried it to ~2.4 m) it
            # holds there, where the landing would have come down 3 m and a climb to 5 m gone up 15 m
            held = heights(60)
            assert 1.6 < min(held) and max(held) < 2.6 and max(held[-10:]) - min(held[-10:]) < 0.05, held
            gcs.mav.param_set_send(n + 1, 1, b"GF_MAX_VER_DIST", 1.9, M.MAV_PARAM_TYPE_REAL32)
            v.wait_event(lambda s: s.startswith("failsafe: geofence: ") and "GF_MAX_VER_DIST = 1.9 m" in s)
            assert reposition(1.0, 1.5) == M.MAV_RESULT_ACCEPTED
            v.wait_event(lambda s: s.startswith("mode: HOLD, repositioned: from ") and " to x=1.00" in s
                         and "z=1.500 m" in s)
            wait_for(lambda: abs(heights(1)[0] - 1.5) < 0.05, 30, "the vehicle at 1.5 m")
            assert command(M.MAV_CMD_NAV_LAND, 0, 0, 0, nan, nan, nan, 0) == M.MAV_RESULT_ACCEPTED
            v.wait_event(lambda s: s == "disarmed: landed: disarmed [by vehicle]", timeout=30)
        finally:
            gcs.close()
            assert v.stop() == 0
    events = v.events()
    assert sum(s.startswith("failsafe: ") for s in events) == 2 and sum("repositioned" in s for s in events) == 1
    v.wait_report(Refused, lambda r: r.text.startswith("Reposition is outside geofence: to x=") and
                  r.text.endswith("z=5.000 m: 5.00 m above home, beyond GF_MAX_VER_DIST = 2 m: not flown, holding"))


def test_do_reposition_disarmed_takes_hold_on_the_ground_is_denied_and_other_flags_are_unsupported(tmp_path):
    """DO_REPOSITION as PX4 answers it where it flies nowhere: flags other than CHANGE_MODE are UNSUPPORTED; disarmed,
    ACCEPTED as the mode alone (HOLD, armed in it next: PX4's navigator keeps no point for a vehicle not armed), its
    point unchecked;
    armed on the ground, DENIED ("take off first"); each refusal with its STATUSTEXT and the vehicle's report."""
    with instance_slot() as n:
        gcs = gcs_link(n)
        v = _vehicle(n, tmp_path)
        try:
            assert gcs.wait_heartbeat(timeout=20) is not None

            def reposition(flags: float) -> int:
                gcs.mav.command_int_send(n + 1, 1, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, M.MAV_CMD_DO_REPOSITION, 0, 0,
                                         -1.0, flags, 0.0, math.nan, UNSET_INT, UNSET_INT, 5.0)
                return command_ack(gcs, M.MAV_CMD_DO_REPOSITION).result

            def said(words: str) -> None:
                m = gcs.recv_match(type="STATUSTEXT", blocking=True, timeout=10,
                                   condition=f"'{words}' in STATUSTEXT.text")
                assert m is not None, f"no STATUSTEXT saying {words!r}"

            assert reposition(0.0) == M.MAV_RESULT_UNSUPPORTED
            said("param2 (flags) must be 1")
            # TAKEOFF selected first (the vehicle boots in HOLD, as PX4): the reposition selects HOLD again
            gcs.mav.command_long_send(n + 1, 1, M.MAV_CMD_DO_SET_MODE, 0, 29, 4, 2, 0, 0, 0, 0)
            assert command_ack(gcs, M.MAV_CMD_DO_SET_MODE).result == M.MAV_RESULT_ACCEPTED
            assert reposition(1.0) == M.MAV_RESULT_ACCEPTED
            v.wait_event(lambda s: "mode: HOLD (disarmed: armed in it next) [by 255:190" in s)
            # disarmed, no point is kept, so none is checked: every field NaN (the height now: 0 m) and one 200 m
            # away are ACCEPTED too (both were DENIED, "0.00 m above home", "200.x m from home")
            for lat in (math.nan, 47.3977420 + 0.0018):
                gcs.mav.command_long_send(n + 1, 1, M.MAV_CMD_DO_REPOSITION, 0, -1.0, 1.0, 0.0, math.nan, lat,
                                          math.nan if math.isnan(lat) else 8.5455940, math.nan)
                assert command_ack(gcs, M.MAV_CMD_DO_REPOSITION).result == M.MAV_RESULT_ACCEPTED, lat
            gcs.mav.command_long_send(n + 1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
            assert command_ack(gcs, M.MAV_CMD_COMPONENT_ARM_DISARM).result == M.MAV_RESULT_ACCEPTED
            v.wait_event(lambda s: "armed, HOLD" in s)
            assert reposition(1.0) == M.MAV_RESULT_DENIED
            said("take off first")
            v.wait_report(Refused, lambda r: r.text == "DO_REPOSITION: on the ground: take off first (NAV_TAKEOFF)")
        finally:
            gcs.close()
            assert v.stop() == 0
    assert not any("repositioned" in s for s in v.events())


def test_land_and_rtl_are_not_armed_in_selected_disarmed_and_after_their_landing_it_is_back_in_hold(tmp_path):
    """PX4 does not arm in AUTO.LAND or AUTO.RTL (mode_requirements.cpp: prevent arming). Disarmed, LAND (DO_SET_MODE,
    NAV_LAND) and RTL are DENIED with a STATUSTEXT saying so, and the next arm is HOLD's, the mode it boots in. Once a
    LAND has landed, it stays armed COM_DISARM_LAND (here 1 s) on the ground, then disarms and, as PX4's
    UserModeIntention::onDisarm, is back in the last mode it can arm in (HOLD, the takeoff's end): the heartbeat says
    LOITER, and a plain arm is ACCEPTED there (it was once DENIED: the vehicle stayed in LAND). A Return's landing
    likewise."""
    with instance_slot() as n:
        gcs = gcs_link(n)
        v = _vehicle(n, tmp_path, *FAST, "--param", "COM_DISARM_LAND=1")
        try:
            assert gcs.wait_heartbeat(timeout=20) is not None

            def command(cmd: int, *p: float) -> int:
                gcs.mav.command_long_send(n + 1, 1, cmd, 0, *p)
                return command_ack(gcs, cmd).result

            def said(words: str) -> None:
                m = gcs.recv_match(type="STATUSTEXT", blocking=True, timeout=10,
                                   condition=f"{words!r} in STATUSTEXT.text")
                assert m is not None, f"no STATUSTEXT saying {words!r}"

            def disarmed_in_hold() -> bool:  # (those queued before say armed, or LAND in the period it disarmed)
                hold = (4 << 16) | (3 << 24)
                hb = gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=5, condition=(
                    f"not HEARTBEAT.base_mode & {M.MAV_MODE_FLAG_SAFETY_ARMED} and HEARTBEAT.custom_mode == {hold}"))
                return hb is not None and mavutil.mode_string_v10(hb) == "LOITER"

            nan, arm = math.nan, M.MAV_CMD_COMPONENT_ARM_DISARM
            rejected = M.MAV_RESULT_TEMPORARILY_REJECTED  # PX4's answer to a mode that cannot run now
            assert command(M.MAV_CMD_DO_SET_MODE, 29, 4, 6, 0, 0, 0, 0) == rejected
            said("mode LAND: only armed (PX4 does not arm in Land")
            assert command(M.MAV_CMD_NAV_LAND, 0, 0, 0, nan, nan, nan, 0) == rejected
            said("mode LAND: only armed")
            assert command(M.MAV_CMD_DO_SET_MODE, 29, 4, 5, 0, 0, 0, 0) == rejected
            said("mode RTL: only armed (PX4 does not arm in Return")
            for land in (M.MAV_CMD_NAV_LAND, M.MAV_CMD_NAV_RETURN_TO_LAUNCH):
                mark = len(v.events())
                assert command(arm, 1, 0, 0, 0, 0, 0, 0) == M.MAV_RESULT_ACCEPTED
                v.wait_event(_from(mark, lambda s: s.startswith("armed: armed, HOLD [by 255:190")))
                assert command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, nan, nan, nan, nan) == M.MAV_RESULT_ACCEPTED
                v.wait_event(_from(mark, lambda s: s.startswith("mode: HOLD: takeoff done")))
                assert command(land, 0, 0, 0, nan, nan, nan, 0) == M.MAV_RESULT_ACCEPTED
                landed = v.wait_event(_from(mark, lambda s: s.startswith("landed: landing detected at ")))
                assert landed.text.endswith("disarms in COM_DISARM_LAND = 1 s"), landed.text
                off = v.wait_event(_from(mark, lambda s: s == "disarmed: landed: disarmed [by vehicle]"))
                assert off.t == pytest.approx(landed.t + 1.0, abs=1e-6)  # COM_DISARM_LAND after the touchdown
                back = v.wait_event(_from(mark, lambda s: s.startswith("mode: HOLD (disarmed after ")))
                assert ("LAND" if land == M.MAV_CMD_NAV_LAND else "RTL") in back.text, back.text
                assert disarmed_in_hold()
        finally:
            gcs.close()
            assert v.stop() == 0
    armed = [s for s in v.events() if s.startswith("armed: ")]
    assert [s.split(" [by")[0] for s in armed] == ["armed: armed, HOLD"] * 2, armed  # never armed in LAND or RTL
    assert sum(s.startswith("disarmed: ") for s in v.events()) == 2


# -- MAVProxy --------------------------------------------------------------------------------------

def _from(mark: int, pred: Callable[[str], bool]) -> Callable[[str], bool]:
    """``pred`` for the lines from the ``mark`` th on (a Proc.wait_line predicate sees each line once, in order)."""
    index = -1

    def at_or_after(line: str) -> bool:
        nonlocal index
        index += 1
        return index >= mark and pred(line)
    return at_or_after


def test_mavproxy_params_and_modes(tmp_path):
    """MAVProxy, unmodified, through stdin: the parameters load at once (the vehicle NAKs MAVProxy's
    FTP try, ``@PARAM/param.pck``: without that, MAVProxy waits ~11 s for its FTP retries), ``param
    show``, ``param set`` and ``param show`` again; an out-of-range set refused (the vehicle's
    STATUSTEXT shown, the value unchanged); HOLD (MAVProxy's LOITER), arm, TAKEOFF, LAND, with
    MAVProxy naming each mode in its prompt. (The flight goes on while MAVProxy retries the refused
    set: its failure and the unchanged value are read after the landing, not 3 s of waiting before.)"""
    with instance_slot() as n:
        # real time: TAKEOFF lasts ~2 s; landed, disarmed 0.5 s later (PX4's 2 s: each second is the test's CPU)
        v = _vehicle(n, tmp_path / "v", "--param", "MPC_LAND_SPEED=1.5", "--param", "COM_DISARM_LAND=0.5")
        mp = MavProxy(f"udpin:127.0.0.1:{GCS_PORT + n}", tmp_path)
        say = mp.say

        def prompt_names(name: str) -> None:
            """Wait until MAVProxy's prompt names mode ``name`` (its "Mode X" line comes at most every
            2 s; the prompt follows each heartbeat): it prefixes the next line printed, so ask for one
            until it does."""
            deadline = time.monotonic() + 10
            while True:
                try:
                    mp.wait_line(_from(say("param show MAV_SYS_ID"),
                                       lambda s: s.startswith(f"{name}> ") and "MAV_SYS_ID" in s), timeout=0.25)
                    return
                except AssertionError:
                    assert time.monotonic() < deadline, f"MAVProxy's prompt never named {name}"

        def set_mode(name: str) -> None:
            """``mode NAME``, then its prompt. MAVProxy 1.8.75's ``mode`` fails for every PX4 autopilot
            (it hands pymavlink's PX4 (base, main, sub) tuple to set_mode as one number: "required
            argument is not a float"); then what a user types instead, DO_SET_MODE with those numbers."""
            mark = say(f"mode {name}")
            failed = f"ERROR in command ['{name}']"
            done = mp.wait_line(_from(mark, lambda s: "DO_SET_MODE: ACCEPTED" in s or failed in s))
            if "ERROR" in done:
                base, main, sub = mavutil.px4_map[name]
                mp.wait_line(_from(say(f"long DO_SET_MODE {base} {main} {sub}"),
                                   lambda s: "DO_SET_MODE: ACCEPTED" in s), timeout=10)
            prompt_names(name)

        try:
            mp.wait_line(lambda s: "online system" in s, timeout=30)
            online = len(mp.lines)
            # FTP NAKed, MAVProxy fetches the list at its next 1 s check: well inside 8 s (without: >= 11 s)
            mp.wait_line(_from(online, lambda s: f"Received {len(PARAMS)} parameters" in s and "ftp" not in s),
                         timeout=8)
            # (MAVProxy's prompt may follow the value on its line: "COM_OF_LOSS_T    1.5LOITER>", seen under load)
            show = re.compile(r"COM_OF_LOSS_T\s+([0-9.]+)(?:[A-Z_]+>)?\s*$")
            line = mp.wait_line(_from(say("param show COM_OF_LOSS_T"), show.search), timeout=10)
            assert show.search(line).group(1) == "0.5"  # type: ignore[union-attr]
            # the vehicle's STATUSTEXT saying so follows its PARAM_VALUE answer: MAVProxy has the value then
            mp.wait_line(_from(say("param set COM_OF_LOSS_T 1.5"),
                               lambda s: "AP: param: COM_OF_LOSS_T = 1.5 (was 0.5)" in s), timeout=10)
            line = mp.wait_line(_from(say("param show COM_OF_LOSS_T"), show.search), timeout=10)
            assert show.search(line).group(1) == "1.5"  # type: ignore[union-attr]

            bad = say("param set COM_OF_LOSS_T 100")
            mp.wait_line(_from(bad, lambda s: "COM_OF_LOSS_T: must be in [0.01, 60] s" in s), timeout=10)
            # MAVProxy sends the refused set twice more, a second apart, before it says it failed (~3 s): the flight
            # below goes on meanwhile, as a user's would, and its failure and the unchanged value are read after it

            set_mode("LOITER")
            mp.wait_line(_from(say("arm throttle"), lambda s: "COMPONENT_ARM_DISARM: ACCEPTED" in s), timeout=10)
            # MAVProxy's own takeoff: 3 m AMSL, below home, raised to MIS_TAKEOFF_ALT (2.5 m above) as PX4 does
            mark = say("takeoff 3")
            mp.wait_line(_from(mark, lambda s: "NAV_TAKEOFF: ACCEPTED" in s), timeout=10)
            mp.wait_line(_from(mark, lambda s: "Using minimum takeoff altitude: 490.50 m" in s), timeout=10)
            prompt_names("TAKEOFF")  # ~2 s of climb in real time
            v.wait_event(lambda s: "mode: HOLD: takeoff done at z=2.500 m" in s, timeout=15)
            prompt_names("LOITER")  # at the height: HOLD
            mark = len(mp.lines)
            set_mode("LAND")
            v.wait_event(lambda s: "disarmed: landed" in s, timeout=15)
            mp.wait_line(_from(mark, lambda s: s.strip().endswith("DISARMED")), timeout=10)
            mp.wait_line(_from(bad, lambda s: "Failed to set COM_OF_LOSS_T to 100" in s), timeout=15)
            fetched = mp.wait_line(_from(say("param fetch COM_OF_LOSS_T"), lambda s: "COM_OF_LOSS_T = " in s),
                                   timeout=10)  # read from the vehicle afresh
            assert fetched.split("COM_OF_LOSS_T = ")[1].strip() == "1.5000000"
            line = mp.wait_line(_from(say("param show COM_OF_LOSS_T"), show.search), timeout=10)
            assert show.search(line).group(1) == "1.5"  # type: ignore[union-attr]
        finally:
            mp.stop()
            assert v.stop() == 0
    assert any(isinstance(r, Refused) and r.text.startswith("COM_OF_LOSS_T: must be in") for r in v.reports())
    assert not any("COM_OF_LOSS_T = 100" in s for s in v.events())
    unanswered, ftp_requests, ftp_replies = _answers(tmp_path / "v" / "vehicle.tlog", n + 1)
    assert not unanswered, f"commands MAVProxy sent that got no COMMAND_ACK: {unanswered}"
    assert ftp_requests >= 1 and ftp_replies == ftp_requests  # every FTP request answered (its parameter file: a NAK)


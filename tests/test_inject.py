"""Covers bridge.nodes.vehicle.injection and bridge.nodes.vehicle.commander: failure injection.

A ground station injects failures as PX4's do (MAVSDK's Failure plugin, pymavlink's COMMAND_LONG), against
real ``bsst vehicle`` and ``bsst sitl`` processes over UDP on 127.0.0.1: refused (DENIED) while
SYS_FAILURE_EN = 0, acted on with 1 through the timeline's path (SimVehicle.inject), each event naming its
sender; each unit and type answered as PX4's handlers answer it (docs/weather.md, "Injection").
"""

from __future__ import annotations

import contextlib
import json
import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from bridge.mavlink.endpoint import CONTROLLER_SYSID
from bridge.nodes.report import Event, Refused, parse_line
from bridge.nodes.vehicle.injection import injection
from bridge.session import instance_slot
from tests.gcskit import command_ack, gcs_link
from tests.sitlkit import ENV, ROOT, Proc, run_bsst
from tests.test_ground_stations import _mavsdk
from tests.test_vehicle import _vehicle

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast

M = mavlink
MOTOR, GPS, MAG, BARO, GYRO = (M.FAILURE_UNIT_SYSTEM_MOTOR, M.FAILURE_UNIT_SENSOR_GPS, M.FAILURE_UNIT_SENSOR_MAG,
                               M.FAILURE_UNIT_SENSOR_BARO, M.FAILURE_UNIT_SENSOR_GYRO)
OK, OFF, STUCK = M.FAILURE_TYPE_OK, M.FAILURE_TYPE_OFF, M.FAILURE_TYPE_STUCK
BATTERY = M.FAILURE_UNIT_SYSTEM_BATTERY


def _events(v: Proc) -> list[Event]:
    """The vehicle's event reports so far (its status lines, read as the session reads them)."""
    return [r for r in map(parse_line, v.lines) if isinstance(r, Event)]


def _inject(gcs, unit: int, ftype: int, instance: float = 0, command_int: bool = False) -> int:
    tgt = (gcs.target_system, gcs.target_component)
    if command_int:
        gcs.mav.command_int_send(*tgt, 0, M.MAV_CMD_INJECT_FAILURE, 0, 0, unit, ftype, instance, 0, 0, 0, 0)
    else:
        gcs.mav.command_long_send(*tgt, M.MAV_CMD_INJECT_FAILURE, 0, unit, ftype, instance, 0, 0, 0, 0)
    return command_ack(gcs, M.MAV_CMD_INJECT_FAILURE).result


def test_mapping_pure():
    """The units and types that map, and the answers for those that do not (no processes)."""
    can = lambda kind: None  # noqa: E731 - a vehicle every event can act on
    got = injection(MOTOR, OFF, 2, 1.5, can)
    assert got.result == M.MAV_RESULT_ACCEPTED and [e.text() for e in got.events] == ["motor 2: off"]
    assert [e.text() for e in injection(MOTOR, OK, 0, 0.0, can).events] == [f"motor {n}: 1 of its thrust"
                                                                             for n in range(1, 5)]
    assert [e.text() for e in injection(GPS, OFF, 0, 0.0, can).events] == ["gps off"]
    assert [e.text() for e in injection(MAG, OK, 1, 0.0, can).events] == ["mag on"]
    # the battery's, as PX4's BatterySimulator: OFF reads the pack empty, OK as it is; instance 0 only
    assert [e.text() for e in injection(BATTERY, OFF, 0, 0.0, can).events] == ["battery empty"]
    assert [e.text() for e in injection(BATTERY, OK, 0, 0.0, can).events] == ["battery ok"]
    for args, result in (((MOTOR, STUCK, 1), M.MAV_RESULT_UNSUPPORTED), ((MOTOR, OFF, 5), M.MAV_RESULT_DENIED),
                         ((GPS, OFF, 2), M.MAV_RESULT_DENIED), ((BARO, OFF, 0), M.MAV_RESULT_UNSUPPORTED),
                         ((GYRO, OFF, 0), M.MAV_RESULT_UNSUPPORTED), ((BATTERY, OFF, 1), M.MAV_RESULT_UNSUPPORTED),
                         ((BATTERY, STUCK, 0), M.MAV_RESULT_UNSUPPORTED),
                         ((MOTOR, OFF, 1.5), M.MAV_RESULT_DENIED), ((math.nan, OFF, 0), M.MAV_RESULT_DENIED)):
        got = injection(*args, 0.0, can)
        assert got.result == result and not got.events and got.why, (args, got)
    # the barometer's: where its fault can be given (it named --at, a flag bsst vehicle does not have)
    assert injection(BARO, OFF, 0, 0.0, can).why == (
        "INJECT_FAILURE FAILURE_UNIT_SENSOR_BARO FAILURE_TYPE_OFF: its fault here has a size this command has no "
        "field for: give it in the mission's [[events]] (bsst sim/sitl: --at T:baro:drift=M_PER_S)")
    no_rotors = injection(MOTOR, OFF, 1, 0.0, lambda kind: "no rotors to fail")
    assert no_rotors.result == M.MAV_RESULT_UNSUPPORTED and "no rotors to fail" in no_rotors.why


def test_pymavlink_acks_per_unit(tmp_path):
    """SYS_FAILURE_EN = 0: every injection DENIED, nothing done. = 1 (a PARAM_SET): the x500 with a GNSS set
    and the EKF acts on motor, GPS and compass OFF/OK (ACCEPTED; COMMAND_INT too), and answers every other
    type and unit as PX4 does: UNSUPPORTED (a STATUSTEXT saying why), DENIED for a motor it does not have.
    Each accepted one is a ``fault`` event naming the ground station, acted on when the vehicle next steps; an OK
    of a unit that works is ACCEPTED and no event, as a PARAM_SET to the value in force (it was a ``fault``
    event, so a flight whose ground station sent one said "not flown as asked", exit 1, its trace unchanged)."""
    with instance_slot() as n:
        gcs = gcs_link(n)
        v = _vehicle(n, tmp_path, "--profile", "x500", "--sensors", "gnss", "--estimator", "ekf", "--realtime")
        try:
            assert gcs.wait_heartbeat(timeout=20) is not None
            assert _inject(gcs, MOTOR, OFF, 1) == M.MAV_RESULT_DENIED
            text = gcs.recv_match(type="STATUSTEXT", blocking=True, timeout=5)
            assert text is not None and "SYS_FAILURE_EN is 0" in text.text
            gcs.mav.param_set_send(gcs.target_system, gcs.target_component, b"SYS_FAILURE_EN", 1,
                                   M.MAV_PARAM_TYPE_INT32)
            v.wait_line(lambda s: "SYS_FAILURE_EN = 1 (was 0)" in s)
            assert _inject(gcs, GPS, OK, 0) == M.MAV_RESULT_ACCEPTED  # a working GPS: no change, so no event
            answers = {(MOTOR, OFF, 1): M.MAV_RESULT_ACCEPTED, (MOTOR, OK, 1): M.MAV_RESULT_ACCEPTED,
                       (GPS, OFF, 0): M.MAV_RESULT_ACCEPTED, (GPS, OK, 0): M.MAV_RESULT_ACCEPTED,
                       (MAG, OFF, 0): M.MAV_RESULT_ACCEPTED, (MAG, OK, 0): M.MAV_RESULT_ACCEPTED,
                       (MOTOR, STUCK, 1): M.MAV_RESULT_UNSUPPORTED, (MOTOR, OFF, 5): M.MAV_RESULT_DENIED,
                       (GPS, M.FAILURE_TYPE_GARBAGE, 0): M.MAV_RESULT_UNSUPPORTED,
                       (BARO, OFF, 0): M.MAV_RESULT_UNSUPPORTED, (GYRO, OFF, 0): M.MAV_RESULT_UNSUPPORTED,
                       (M.FAILURE_UNIT_SENSOR_ACCEL, OFF, 0): M.MAV_RESULT_UNSUPPORTED,
                       (M.FAILURE_UNIT_SYSTEM_BATTERY, OFF, 0): M.MAV_RESULT_UNSUPPORTED}
            got = {args: _inject(gcs, *args) for args in answers}
            assert got == answers
            assert _inject(gcs, MOTOR, OFF, 3, command_int=True) == M.MAV_RESULT_ACCEPTED
            # acted on at the vehicle's next control period (realtime: the clock runs), each naming the sender
            v.wait_line(lambda s: '"kind":"fault"' in s and "motor 3: off" in s)
        finally:
            gcs.close()  # (left open it held the instance's GCS port past its slot)
            assert v.stop() == 0
    faults = [e for e in _events(v) if e.kind == "fault"]
    assert [e.text for e in faults] == ["motor 1: off", "motor 1: 1 of its thrust", "gps off", "gps on", "mag off",
                                        "mag on", "motor 3: off"]
    assert all(e.by is not None and e.by.link == "gcs" and (e.by.sysid, e.by.compid) == (255, 190) for e in faults)


def test_an_injection_after_the_plant_ended_the_flight_is_denied(tmp_path):
    """Once the plant has ended the flight (every rotor off in the air: ``crashed``, the clock halted for good), an
    INJECT_FAILURE is DENIED saying why: the plant is stepped no more, so an accepted fault would never act nor be
    logged (it was ACCEPTED, and MAVSDK's Failure plugin said SUCCESS, for a fault that never happened)."""
    with instance_slot() as n:
        gcs = gcs_link(n)
        v = _vehicle(n, tmp_path, "--profile", "x500", "--param", "SYS_FAILURE_EN=1", "--speed", "4")
        try:
            assert gcs.wait_heartbeat(timeout=20) is not None
            tgt = (gcs.target_system, gcs.target_component)
            gcs.mav.command_long_send(*tgt, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
            assert command_ack(gcs, M.MAV_CMD_COMPONENT_ARM_DISARM).result == M.MAV_RESULT_ACCEPTED
            nan = math.nan
            gcs.mav.command_long_send(*tgt, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, nan, nan, nan, nan)
            assert command_ack(gcs, M.MAV_CMD_NAV_TAKEOFF).result == M.MAV_RESULT_ACCEPTED
            v.wait_line(lambda s: "takeoff done" in s, timeout=60)
            assert _inject(gcs, MOTOR, OFF, 0) == M.MAV_RESULT_ACCEPTED
            v.wait_line(lambda s: '"kind":"crashed"' in s, timeout=60)
            assert _inject(gcs, MOTOR, OK, 0) == M.MAV_RESULT_DENIED
            text = gcs.recv_match(type="STATUSTEXT", blocking=True, timeout=5,
                                  condition="'INJECT_FAILURE' in STATUSTEXT.text")
            assert text is not None and text.text == "INJECT_FAILURE: the plant ended the flight"
            assert _inject(gcs, GPS, OFF, 0) == M.MAV_RESULT_DENIED  # (whatever the unit)
            # a mode change is refused so too, in words true of a crash (it said "the plant diverged")
            gcs.mav.command_long_send(*tgt, M.MAV_CMD_DO_SET_MODE, 0, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4, 3,
                                      0, 0, 0, 0)
            assert command_ack(gcs, M.MAV_CMD_DO_SET_MODE).result == M.MAV_RESULT_DENIED
            text = gcs.recv_match(type="STATUSTEXT", blocking=True, timeout=5,
                                  condition="STATUSTEXT.text.startswith('mode ')")
            assert text is not None and text.text.endswith(": the plant ended the flight"), text
        finally:
            gcs.close()  # (left open it held the instance's GCS port past its slot)
            status = v.stop()
    faults = [e.text for e in _events(v) if e.kind == "fault"]
    assert faults == [f"motor {i}: off" for i in (1, 2, 3, 4)], faults
    # stopped, it says its flight crashed and exits 1 (until the third wave's forty-first session: 0, silent)
    assert status == 1 and any(ln.startswith("bsst vehicle: crashed at t=") for ln in v.lines), v.lines[-5:]


def test_paper_profile_has_no_rotors(tmp_path):
    """The paper profile (ideal wrench) has no rotor to fail, and the truth estimator no sensor: UNSUPPORTED."""
    with instance_slot() as n:
        gcs = gcs_link(n)
        v = _vehicle(n, tmp_path, "--param", "SYS_FAILURE_EN=1")
        try:
            assert gcs.wait_heartbeat(timeout=20) is not None
            assert _inject(gcs, MOTOR, OFF, 1) == M.MAV_RESULT_UNSUPPORTED
            v.wait_line(lambda s: isinstance(r := parse_line(s), Refused) and "no rotors to fail" in r.text)
            assert _inject(gcs, GPS, OFF, 0) == M.MAV_RESULT_UNSUPPORTED
            v.wait_line(lambda s: isinstance(r := parse_line(s), Refused) and "no sensor to fail" in r.text)
        finally:
            gcs.close()  # (left open it held the instance's GCS port past its slot)
            assert v.stop() == 0


MAVSDK_FAILURE = r"""
import json, sys, threading
from mavsdk import Mavsdk, Configuration, ComponentType
from mavsdk.plugins.failure import Failure, FailureError, FailureType, FailureUnit
from mavsdk.plugins.param import Param
from mavsdk.plugins.telemetry import Telemetry

sdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
sdk.add_any_connection(sys.argv[1])
system = sdk.first_autopilot(30.0)
out = {"found": system is not None}
def inject():
    try:
        Failure(system).inject(FailureUnit.SYSTEM_MOTOR, FailureType.OFF, 1)
        return "SUCCESS"
    except FailureError as e:
        return e.result.name

if sys.argv[2] == "flight":  # once the flight's controller has armed it: refused, enabled, acted on
    armed, tel = threading.Event(), Telemetry(system)  # (the plugin held: its subscriptions live while it does)
    tel.subscribe_armed(lambda a, ud=None: a and armed.set())
    out["armed"] = armed.wait(60)
    out["disabled"] = inject()
    out["set"] = Param(system).set_param_int("SYS_FAILURE_EN", 1).name
    out["enabled"] = inject()
print("RESULT " + json.dumps(out), flush=True)
sdk.destroy()
"""


def test_mavsdk_failure_plugin_motor_off(tmp_path):
    """MAVSDK's Failure plugin against a lockstep ``bsst sitl --profile x500`` flight: motor 1 OFF is DENIED
    while SYS_FAILURE_EN = 0, then (the parameter set to 1 through MAVSDK's Param) acted on: the quadrotor
    cannot fly on three rotors, and the flight ends honestly, not completed, exit 1, the fault in its events
    naming the ground station that injected it."""
    out = tmp_path / "run"
    with instance_slot() as n:
        p = Proc.bsst("sitl", "missions/sine.toml", "--profile", "x500", "--out", str(out), "--instance", str(n),
                      "--speed", "1", "--no-plots")
        try:
            got = _mavsdk(n, "flight", MAVSDK_FAILURE)
            code = p.p.wait(timeout=120)
        finally:
            p.stop()
    # refused either way: DENIED is the vehicle's answer; DISABLED is MAVSDK's own when it has already read
    # SYS_FAILURE_EN = 0 and so sends nothing (which comes first depends on timing)
    assert got["disabled"] in ("DENIED", "DISABLED"), got
    assert {k: v for k, v in got.items() if k != "disabled"} == {"found": True, "armed": True, "set": "SUCCESS",
                                                                  "enabled": "SUCCESS"}, got
    summary = json.loads((out / "summary.json").read_text())
    assert code == 1 and summary["outcome"] != "completed", summary["outcome"]
    faults = [e for e in summary["events"] if e["kind"] == "fault"]
    # summary.json's events carry their sender in the text (RunEvent.shown): MAVSDK's ids, on the GCS link
    assert len(faults) == 1 and faults[0]["text"].startswith("motor 1: off [by 245:190 "), faults
    assert faults[0]["text"].endswith(" gcs]")
    # a ground station's change: the run is reproducible only up to the step it acted at (it depends on arrival)
    (change,) = [i for i in summary["interventions"] if i["kind"] == "fault"]
    assert change["what"] == "motor 1: off" and change["by"].endswith(" gcs")
    assert change["step"] == round(faults[0]["t"] * 250)
    first = summary["interventions"][0]  # MAVSDK's SYS_FAILURE_EN = 1, before the injection (or at its step)
    assert first["kind"] == "param" and first["name"] == "SYS_FAILURE_EN" and first["step"] <= change["step"]
    assert summary["lockstep"]["reproducible"] is False
    assert summary["lockstep"]["reproducible_until_step"] == first["step"]
    assert summary["ended_by"]["after_faults"] == [f"t={faults[0]['t']:.3f} s: {faults[0]['text']}"]


WINDY_X500 = """
name = "windy-x500"
duration_s = 14.0
profile = "x500"
controller = "bsst"
rate_hz = 250
seed = 0

[trajectory]
kind = "sine"
amplitude = 1.0
omega = 0.5
climb = 0.1
psi = 0.0

[effects]
battery = true

[wind]
speed_mps = 5.0
from_deg = 270.0
turbulence = "moderate"
gusts = [[11.0, 2.0, 3.0, 90.0]]
"""
ALL_OFF = tuple(a for i in (1, 2, 3, 4) for a in ("--at", f"5:motor:{i}=0"))  # it falls from 0.5 m: crashed
HOLD_AT_END = '\n[end]\naction = "hold"\n'


def _trace(path) -> list[list[str]]:
    """trace.csv's state, reference and law's input columns (t through u4), as text: equal means equal to the
    bit (the wire's copies, c1..c4 and u*_act, are float32 under sitl)."""
    rows = path.read_text().splitlines()
    keep = rows[0].split(",").index("u4") + 1
    return [r.split(",")[:keep] for r in rows]


def _heartbeats_and_last(tlog: Path) -> tuple[list[tuple[float, int]], float]:
    """From a controller's tlog: each vehicle HEARTBEAT's (wall time s, system_status), and the wall time of its
    last record."""
    log = mavutil.mavlink_connection(str(tlog), dialect="common")
    beats, last = [], math.nan
    while (m := log.recv_match()) is not None:
        last = m._timestamp
        if m.get_type() == "HEARTBEAT" and m.get_srcSystem() != CONTROLLER_SYSID:
            beats.append((m._timestamp, m.system_status))
    return beats, last


@pytest.mark.parametrize("case", ["wind-battery", "crash", "flags", "handover", "battery-empty"])
def test_sitl_plant_blocks_equal_offline(tmp_path, case):
    """``bsst sitl`` (lockstep) reports the plant's blocks as ``bsst sim`` does, to the bit: ``wind`` and
    ``battery`` (a windy x500 with its battery), and a hard touchdown's ``crashed`` outcome (every rotor off:
    it falls from 0.5 m), its ``impact``, ``rotor_effectiveness`` and ``ended_by`` (with ``after_faults``),
    exit 1. ``flags``: the issue's ``--wind 5:270 --turbulence moderate`` (and a gust event) as flags on the
    sine: the same trace.csv state and inputs too. ``handover``: ``--at 3:link:lte``, a handover from the perfect
    link to the LTE profile's at 3 s: the same trace, the model's link statistics and the ``link`` event.
    ``battery-empty``: the windy x500's pack reads empty at 2 s (``--at 2:battery:empty``, what a ground station's
    INJECT_FAILURE of the battery acts as) with COM_LOW_BAT_ACT = 2: the battery failsafe lands it, at the same
    step, the same trace. Each mission is 6 s, ending in hold: its gust (3 to 5 s), handover (3 s), crash (5 s) and
    failsafe landing (from 2 s) are in it, and a land and COM_DISARM_LAND after it (the windy x500's 14 s took 18.2 s
    with them) are read by no case."""
    mission = tmp_path / "windy.toml"
    mission.write_text(WINDY_X500.replace("duration_s = 14.0", "duration_s = 6.0").replace(
        "gusts = [[11.0,", "gusts = [[3.0,") + HOLD_AT_END)
    sine = tmp_path / "sine6.toml"  # the paper's sine cut to 6 s
    sine.write_text((ROOT / "missions" / "sine.toml").read_text().replace("duration_s = 30.0", "duration_s = 6.0")
                    + HOLD_AT_END)
    args = {"wind-battery": (str(mission),), "crash": (str(sine), "--profile", "x500", *ALL_OFF),
            "flags": (str(sine), "--wind", "5:270", "--turbulence", "moderate", "--at", "3:gust:2,3,90"),
            "handover": (str(sine), "--at", "3:link:lte"),
            "battery-empty": (str(mission), "--at", "2:battery:empty", "--param", "COM_LOW_BAT_ACT=2")}[case]
    codes, summaries = [], []
    for command in ("sim", "sitl"):
        out = tmp_path / command
        with instance_slot() as n:
            extra = ("--instance", str(n)) if command == "sitl" else ()
            r = run_bsst(command, *args, "--out", str(out), "--no-plots", *extra, env=ENV, timeout=300)
        codes.append(r.returncode)
        assert (out / "summary.json").exists(), f"bsst {command}: exit {r.returncode}: {r.stderr[-2000:]}"
        summaries.append(json.loads((out / "summary.json").read_text()))
    offline, sitl = summaries
    keys = ("outcome", "ended_by", "wind", "battery", "impact", "rotor_effectiveness", "rms_3d")
    assert {k: sitl.get(k) for k in keys} == {k: offline.get(k) for k in keys}
    if case == "crash":
        assert codes == [1, 1] and sitl["outcome"] == "crashed" and sitl["impact"]["speed_mps"] > 2.0
        assert sitl["ended_by"]["after_faults"] == [f"t=5.000 s: motor {i}: off" for i in (1, 2, 3, 4)]
        # the crashed vehicle's HEARTBEAT says EMERGENCY, and its controller ends on hearing it: its tlog (wall
        # stamps) ends within a second of it, where it waited out its 2 s state timeout before (a bug)
        frames = _heartbeats_and_last(tmp_path / "sitl" / "controller.tlog")
        emergency = [t for t, status in frames[0] if status == mavlink.MAV_STATE_EMERGENCY]
        assert emergency and frames[1] - emergency[0] < 1.0, (emergency[:1], frames[1])
        # and its word about the crash is in the records after the crash, never stamped before it
        said = [(e["t"], e["source"], e["kind"]) for e in sitl["events"] if e["source"] in ("vehicle", "controller")]
        crash = next(i for i, e in enumerate(said) if e[2] == "crashed")
        answer = next(i for i, e in enumerate(said) if e[1] == "controller" and e[0] >= 5.0)
        assert answer > crash and said[answer][0] >= said[crash][0], said
    elif case == "battery-empty":
        assert codes == [1, 1] and sitl["outcome"] == "failsafe", (codes, sitl["outcome"])
        assert "battery critical: 0.0 % left" in sitl["ended_by"]["how"], sitl["ended_by"]
        assert sitl["ended_by"]["after_faults"] == ["t=2.000 s: battery empty"]
        assert _trace(tmp_path / "sitl" / "trace.csv") == _trace(tmp_path / "sim" / "trace.csv")
    elif case in ("flags", "handover"):
        assert codes == [0, 0] and _trace(tmp_path / "sitl" / "trace.csv") == _trace(tmp_path / "sim" / "trace.csv")
        if case == "flags":
            assert sitl["wind"]["sampling"]["duration_s"] > 0.0
        else:
            link = [(e["t"], e["text"]) for e in sitl["events"] if e["kind"] == "link"]
            assert link == [(e["t"], e["text"]) for e in offline["events"] if e["kind"] == "link"] == [
                (3.0, "link handover to lte")]
            assert "link handover to lte" in (tmp_path / "sitl" / "events.log").read_text()
            for d in ("up", "down"):
                assert sitl["link"][d]["delay_ms"] == offline["link"][d]["delay_ms"]
    else:
        assert codes == [0, 0] and sitl["wind"]["samples"] > 0 and sitl["battery"]["used_mah"] > 0.0


def test_a_pack_below_its_critical_level_shows_critical_and_is_not_armed(tmp_path):
    """PX4's battery levels and pre-arm battery check on the ground-station link: the x500's pack at 6 %, below
    PX4's BAT_CRIT_THR of 7 %: BATTERY_STATUS shows charge state CRITICAL at rest, and a ground station's arm is
    TEMPORARILY_REJECTED with a CRITICAL STATUSTEXT saying why; BAT_CRIT_THR set to 5 %, LOW, and the same arm is
    ACCEPTED (docs/weather.md, "Battery")."""
    with _x500_on_battery(tmp_path, "battery_start_pct = 6.0\n") as gcs:
        rest = gcs.recv_match(type="BATTERY_STATUS", blocking=True, timeout=10)
        assert rest is not None and (rest.battery_remaining, rest.charge_state) == (
            6, M.MAV_BATTERY_CHARGE_STATE_CRITICAL)
        tgt = (gcs.target_system, gcs.target_component)
        gcs.mav.command_long_send(*tgt, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
        assert command_ack(gcs, M.MAV_CMD_COMPONENT_ARM_DISARM).result == M.MAV_RESULT_TEMPORARILY_REJECTED
        why = gcs.recv_match(type="STATUSTEXT", blocking=True, timeout=5,
                             condition="STATUSTEXT.severity == 2")  # MAV_SEVERITY_CRITICAL
        assert why is not None and why.text.startswith("preflight: arming denied: battery critical: 6.0 %")
        gcs.mav.param_set_send(*tgt, b"BAT_CRIT_THR", 0.05, M.MAV_PARAM_TYPE_REAL32)
        assert gcs.recv_match(type="PARAM_VALUE", blocking=True, timeout=5) is not None
        low = gcs.recv_match(type="BATTERY_STATUS", blocking=True, timeout=10)
        assert low is not None and low.charge_state == M.MAV_BATTERY_CHARGE_STATE_LOW  # 6 %: below the 15 % low
        gcs.mav.command_long_send(*tgt, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
        assert command_ack(gcs, M.MAV_CMD_COMPONENT_ARM_DISARM).result == M.MAV_RESULT_ACCEPTED


@contextlib.contextmanager
def _x500_on_battery(tmp_path: Path, effects: str, *args: str) -> Iterator[Any]:
    """``bsst vehicle`` (``args``) of an x500 flying its battery (``effects``: more ``[effects]`` keys), and a
    ground station that has heard it; the vehicle stopped after (exit 0)."""
    mission = tmp_path / "battery.toml"
    mission.write_text(WINDY_X500.replace("[wind]", "[unused]").split("[unused]")[0] + effects)
    with instance_slot() as n:
        gcs = gcs_link(n)
        v = _vehicle(n, tmp_path, str(mission), *args)
        try:
            assert gcs.wait_heartbeat(timeout=20) is not None
            yield gcs
        finally:
            gcs.close()  # (left open it held the instance's GCS port past its slot)
            assert v.stop() == 0


def test_a_ground_stations_battery_failure_reads_the_pack_empty_as_px4s(tmp_path):
    """MAV_CMD_INJECT_FAILURE of the battery, as PX4's BatterySimulator takes it (it was UNSUPPORTED): instance 1
    UNSUPPORTED; OFF ACCEPTED, and the x500's pack reads empty, its measured voltage the pack's empty one and 0 %
    left (BATTERY_STATUS EMERGENCY, SYS_STATUS), so an arm is refused as PX4's pre-arm check refuses it; OK, and
    it reads full again and arms. (The rotors still draw the pack's real power, as PX4's simulated battery is no
    part of its physics; offline and lockstep fly it alike: test_sitl_plant_blocks_equal_offline.)"""
    with _x500_on_battery(tmp_path, "", "--realtime", "--param", "SYS_FAILURE_EN=1") as gcs:
        tgt = (gcs.target_system, gcs.target_component)
        assert _inject(gcs, BATTERY, OFF, 1) == M.MAV_RESULT_UNSUPPORTED
        assert _inject(gcs, BATTERY, OFF, 0) == M.MAV_RESULT_ACCEPTED
        empty = gcs.recv_match(type="BATTERY_STATUS", blocking=True, timeout=10,
                               condition="BATTERY_STATUS.battery_remaining == 0")
        assert empty is not None and empty.charge_state == M.MAV_BATTERY_CHARGE_STATE_EMERGENCY
        assert empty.voltages[0] == 4 * 3300  # the pack's empty voltage: the x500's 4 cells at cell_empty_v 3.3 V
        status = gcs.recv_match(type="SYS_STATUS", blocking=True, timeout=5,
                                condition="SYS_STATUS.battery_remaining == 0")
        assert status is not None and status.voltage_battery == empty.voltages[0]
        gcs.mav.command_long_send(*tgt, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
        assert command_ack(gcs, M.MAV_CMD_COMPONENT_ARM_DISARM).result == M.MAV_RESULT_TEMPORARILY_REJECTED
        assert _inject(gcs, BATTERY, OK, 0) == M.MAV_RESULT_ACCEPTED
        full = gcs.recv_match(type="BATTERY_STATUS", blocking=True, timeout=10,
                              condition="BATTERY_STATUS.battery_remaining == 100")
        assert full is not None and full.voltages[0] == 16800
        gcs.mav.command_long_send(*tgt, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
        assert command_ack(gcs, M.MAV_CMD_COMPONENT_ARM_DISARM).result == M.MAV_RESULT_ACCEPTED


def test_battery_on_the_ground_station_link(tmp_path):
    """An x500 flying its battery ([effects] battery): SYS_STATUS carries its voltage, current and remaining
    charge, BATTERY_STATUS streams at PX4's 0.5 Hz; at rest the pack is full and idle, in a takeoff (the
    ground station's NAV_TAKEOFF and arm) it draws current and its voltage sags. Without a battery, no
    BATTERY_STATUS stream (SET_MESSAGE_INTERVAL of it FAILED, as PX4 answers a stream it cannot make)."""
    with _x500_on_battery(tmp_path, "", "--speed", "2") as gcs:
        rest = gcs.recv_match(type="BATTERY_STATUS", blocking=True, timeout=10)
        after = gcs.recv_match(type="BATTERY_STATUS", blocking=True, timeout=10)
        assert rest is not None and after is not None
        assert 1.5 < (after._timestamp - rest._timestamp) < 2.5  # 0.5 Hz (wall clock)
        assert (rest.voltages[0], rest.current_battery, rest.current_consumed, rest.battery_remaining) == (
            16800, 0, 0, 100)
        status = gcs.recv_match(type="SYS_STATUS", blocking=True, timeout=5)
        assert (status.voltage_battery, status.current_battery, status.battery_remaining) == (16800, 0, 100)
        tgt = (gcs.target_system, gcs.target_component)
        gcs.mav.command_long_send(*tgt, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 0, math.nan)
        assert command_ack(gcs, M.MAV_CMD_NAV_TAKEOFF).result == M.MAV_RESULT_ACCEPTED
        gcs.mav.command_long_send(*tgt, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
        assert command_ack(gcs, M.MAV_CMD_COMPONENT_ARM_DISARM).result == M.MAV_RESULT_ACCEPTED
        loaded = gcs.recv_match(type="SYS_STATUS", blocking=True, timeout=10,
                                condition="SYS_STATUS.current_battery > 500")  # over 5 A: the rotors spin
        assert loaded is not None and 14000 < loaded.voltage_battery < 16800
        flying = gcs.recv_match(type="BATTERY_STATUS", blocking=True, timeout=10,
                                condition="BATTERY_STATUS.current_battery > 500")
        assert flying is not None and flying.voltages[0] < 16800 and flying.voltages[1] == 65535
    with instance_slot() as n:
        gcs = gcs_link(n)
        v = _vehicle(n, tmp_path / "no-battery", "--profile", "x500")
        try:
            assert gcs.wait_heartbeat(timeout=20) is not None
            gcs.mav.command_long_send(gcs.target_system, gcs.target_component, M.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                      M.MAVLINK_MSG_ID_BATTERY_STATUS, 1e6, 0, 0, 0, 0, 0)
            assert command_ack(gcs, M.MAV_CMD_SET_MESSAGE_INTERVAL).result == M.MAV_RESULT_FAILED  # no such stream
            assert gcs.recv_match(type="BATTERY_STATUS", blocking=True, timeout=3) is None
        finally:
            gcs.close()  # (left open it held the instance's GCS port past its slot)
            assert v.stop() == 0

"""Covers bridge.autopilot.positionloss, bridge.nodes.vehicle and bridge.session: a GPS lost, end to end.

A real ``bsst vehicle`` (x500, gnss, EKF, lockstep at 4x) flown by MAVSDK over UDP on 127.0.0.1: taken off and
holding, MAVSDK's Failure plugin turns the GPS off; MAVSDK's Telemetry sees the position health go false, then, at
EKF2_NOAID_TOUT, PX4's Descend (flight mode LAND), the landing and the disarm; GLOBAL_POSITION_INT stops (its
``position`` no longer updates) until the GPS is back and fused; ESTIMATOR_STATUS's flags say it. Then the
product's own fault event (``--at T:gps:off``) in a lockstep ``bsst sitl`` session: the same failsafe at the same
step as ``bsst sim`` offline, outcome ``failsafe``, exit 1, the summary naming it. The timing rules themselves:
tests/test_positionloss.py.
"""

from __future__ import annotations

import json

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as M

from bridge.nodes.report import Event
from bridge.session import instance_slot
from tests.sitlkit import ENV, ROOT, run_bsst
from tests.test_gps_telemetry import INJECT_GPS
from tests.test_ground_stations import FAST, _mavsdk
from tests.test_vehicle import _vehicle

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast

MAVSDK_GPS_FAILSAFE = r"""
import json, sys, threading
from mavsdk import Mavsdk, Configuration, ComponentType
from mavsdk.plugins.action import Action, ActionError
from mavsdk.plugins.failure import Failure, FailureError, FailureType, FailureUnit
from mavsdk.plugins.mavlink_direct import MavlinkDirect, MavlinkMessage
from mavsdk.plugins.telemetry import Telemetry

sdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
sdk.add_any_connection(sys.argv[1])
system = sdk.first_autopilot(30.0)
out = {"found": system is not None, "modes": [], "status": []}
tel, act, failure, direct = Telemetry(system), Action(system), Failure(system), MavlinkDirect(system)
cond = threading.Condition()
seen = {"health": None, "rel": None, "armed": None, "mode": None, "positions": 0}
def put(key, value):
    with cond:
        if key == "mode" and value != seen["mode"]:
            out["modes"].append(value)
        seen[key] = value
        seen["positions"] += key == "rel"
        cond.notify_all()
tel.subscribe_health(lambda h, ud=None: put("health", [h.is_global_position_ok, h.is_local_position_ok]))
tel.subscribe_position(lambda p, ud=None: put("rel", p.relative_altitude_m))
tel.subscribe_armed(lambda a, ud=None: put("armed", a))
tel.subscribe_flight_mode(lambda m, ud=None: put("mode", m.name))
def status(m, ud=None):
    f = json.loads(m.fields_json)
    with cond:
        out["status"].append([f["time_usec"], f["flags"], f["pos_horiz_accuracy"]])
direct.subscribe_message("ESTIMATOR_STATUS", status)
# ESTIMATOR_STATUS every 0.1 s (PX4's 0.5 Hz is a few messages in this flight): SET_MESSAGE_INTERVAL, as QGC asks
interval = {"target_system": int(sys.argv[2]), "target_component": 1, "command": 511, "confirmation": 0,
            "param1": 230.0, "param2": 100000.0, "param3": 0.0, "param4": 0.0, "param5": 0.0, "param6": 0.0,
            "param7": 0.0}
direct.send_message(MavlinkMessage("COMMAND_LONG", 0, 0, int(sys.argv[2]), 1, json.dumps(interval)))
def until(what, pred, timeout):
    with cond:
        out[what] = cond.wait_for(pred, timeout)
""" + INJECT_GPS + r"""until("ready", lambda: seen["health"] == [True, True], 20)
out["arm"] = act.arm().name
out["set_takeoff_altitude"] = act.set_takeoff_altitude(5.0).name
out["takeoff"] = act.takeoff().name
until("at_height", lambda: seen["mode"] == "HOLD" and seen["rel"] is not None and seen["rel"] > 4.9, 30)
out["off"] = inject(FailureType.OFF)
until("unhealthy", lambda: seen["health"] == [False, False], 20)
until("descending", lambda: seen["mode"] == "LAND" and seen["armed"], 30)
try:  # armed, no position: PX4 refuses a mode that needs one
    out["hold"] = act.hold().name
except ActionError as e:
    out["hold"] = e.result.name
try:  # but always takes LAND (PX4 pull request 23580): Descend flies on
    out["land"] = act.land().name
except ActionError as e:
    out["land"] = e.result.name
until("disarmed", lambda: seen["armed"] is False, 30)
with cond:
    positions = seen["positions"]
out["on"] = inject(FailureType.OK)
until("healthy", lambda: seen["health"] == [True, True], 20)
until("positions_again", lambda: seen["positions"] > positions, 20)
print("RESULT " + json.dumps(out), flush=True)
sdk.destroy()
"""


def _positions(tlog, kind: str) -> list[float]:
    """The times (s) of the position messages of ``kind`` (GLOBAL_POSITION_INT, LOCAL_POSITION_NED) the vehicle sent,
    from its tlog."""
    log = mavutil.mavlink_connection(str(tlog), dialect="common")
    out = []
    while (m := log.recv_match(type=kind)) is not None:
        out.append(m.time_boot_ms * 1e-3)
    return out


def test_mavsdk_sees_the_gps_lost_the_descent_and_the_position_back(tmp_path):
    """x500 taken off to 5 m by MAVSDK, GPS OFF through its Failure plugin: the position health false, then PX4's
    Descend at EKF2_NOAID_TOUT after the last fix fused (4.92-5.13 s after the fault: the 5 Hz fixes' phase and
    their 120 ms latency): MAVSDK's flight mode LAND, armed, until it lands and disarms, then HOLD again (the disarm
    clears PX4's failsafe: the mode before it). GPS OK: healthy again, and
    GLOBAL_POSITION_INT (MAVSDK's position) flows again, which it had not since the position was lost (the tlog).
    MAVSDK's hold during the descent is refused (armed, PX4 takes no mode that cannot run), its land taken (PX4
    always takes LAND) and the descent flies on.
    ESTIMATOR_STATUS with the horizontal position flags until the loss, without them after (its accuracy growing past
    a metre), with them again once a fix is fused, as MAVSDK reads them (MavlinkDirect, the stream asked for at
    10 Hz); the vehicle's events say each step."""
    with instance_slot() as n:
        v = _vehicle(n, tmp_path, "missions/sine.toml", "--profile", "x500", "--sensors", "gnss", "--estimator",
                     "ekf", "--param", "SYS_FAILURE_EN=1", *FAST)
        try:
            got = _mavsdk(n, str(n + 1), MAVSDK_GPS_FAILSAFE)  # (the vehicle's sysid)
            if got.get("positions_again"):  # the commander's view follows EKF2's after its 1 s probation (sim time)
                t_on = max(e.t for e in v.reports() if isinstance(e, Event) and e.kind == "fault")
                v.wait_report(Event, lambda e: e.kind == "position" and e.t > t_on)
        finally:
            assert v.stop() == 0
    steps = ("found", "ready", "at_height", "unhealthy", "descending", "disarmed", "healthy", "positions_again")
    # a failure shows what MAVSDK was told and what the vehicle did, not a dict pytest cuts short
    shown = ({k: got.get(k) for k in (*steps, "arm", "takeoff", "off", "on", "modes")},
             [(e.t, e.kind, e.text) for e in v.reports() if isinstance(e, Event)])
    assert {k: got[k] for k in steps} == dict.fromkeys(steps, True), shown
    assert (got["arm"], got["takeoff"], got["off"], got["on"]) == ("SUCCESS",) * 4, shown
    assert got["hold"] == "COMMAND_DENIED", got  # TEMPORARILY_REJECTED, as PX4's; the descent went on
    assert got["land"] == "SUCCESS", got  # taken: the descent went on in LAND, to the disarm
    # which clears the failsafe (PX4's framework.cpp): HOLD again, the mode before it (docs/ground-station.md)
    assert got["modes"][-3:] == ["HOLD", "LAND", "HOLD"], got["modes"]
    ev = [(e.t, e.kind, e.text) for e in v.reports() if isinstance(e, Event)]
    kinds = [k for _, k, _ in ev if k in ("fault", "position", "failsafe", "disarmed")]
    assert kinds == ["fault", "position", "failsafe", "disarmed", "fault", "position"], ev
    t_off, t_lost, t_fs, t_down, t_on, t_back = (t for t, k, _ in ev if k in ("fault", "position", "failsafe",
                                                                               "disarmed"))
    assert 4.9 < t_lost - t_off < 5.2 and t_fs == t_lost and t_on < t_back, ev
    said = {k: x for _, k, x in ev if k in ("failsafe", "disarmed")}
    assert said == {"failsafe": "position lost: level and descend", "disarmed": "landed: disarmed"}
    assert any(t >= t_down and k == "mode" and x.startswith("HOLD (disarmed after its failsafe") for t, k, x in ev), ev
    (land,) = [(t, x) for t, k, x in ev if k == "mode" and t_fs <= t < t_down]
    assert land[1].startswith("LAND without a valid horizontal position estimate"), ev
    # ESTIMATOR_STATUS as MAVSDK received it (its MavlinkDirect): (s, flags, horizontal accuracy m)
    status = [(us * 1e-6, f, acc) for us, f, acc in got["status"]]
    pos = M.ESTIMATOR_POS_HORIZ_REL | M.ESTIMATOR_POS_HORIZ_ABS | M.ESTIMATOR_VELOCITY_HORIZ
    during = [s for s in status if t_lost + 0.01 < s[0] < t_on]
    after = [s for s in status if s[0] > t_on]
    assert any(t < t_off for t, _, _ in status) and during and after, status
    assert all(f & pos == pos for t, f, _ in status if t < t_lost - 0.01) and after[-1][1] & pos == pos
    # its 1-sigma grows, past a metre; the first status after the loss may still be under one (0.995 in the
    # thirty-eighth session's suite: the loss is EKF2_NOAID_TOUT after the last fix fused, not an accuracy)
    assert all(f & pos == 0 for _, f, _ in during) and during[-1][2] > during[0][2] and during[-1][2] > 1.0
    # neither position goes out while it is invalid (PX4's streams: LOCAL_POSITION_NED only with xy_valid; a local
    # one sent then made MAVSDK's local position health true at a loaded machine's heartbeats), and both come back
    for kind in ("GLOBAL_POSITION_INT", "LOCAL_POSITION_NED"):
        pos = _positions(tmp_path / "vehicle.tlog", kind)
        assert not [t for t in pos if t_lost + 0.01 < t < t_on] and any(t > t_on for t in pos), kind
    # the answers the vehicle sent during the descent: PX4's TEMPORARILY_REJECTED for HOLD, LAND ACCEPTED
    log = mavutil.mavlink_connection(str(tmp_path / "vehicle.tlog"), dialect="common")
    acks = []
    while (m := log.recv_match(type="COMMAND_ACK")) is not None:
        if m.command in (M.MAV_CMD_DO_SET_MODE, M.MAV_CMD_NAV_LAND):
            acks.append((m.command, m.result))
    assert acks[-2:] == [(M.MAV_CMD_DO_SET_MODE, M.MAV_RESULT_TEMPORARILY_REJECTED),
                         (M.MAV_CMD_NAV_LAND, M.MAV_RESULT_ACCEPTED)], acks


def test_the_product_fault_event_fails_safe_in_lockstep_as_offline(tmp_path):
    """``--sensors gnss --estimator ekf --at 2:gps:off`` on the sine cut to 11 s: ``bsst sim`` and a lockstep ``bsst
    sitl`` both end ``failsafe``, exit 1, the position lost and PX4's Descend at 7.124 s (EKF2_NOAID_TOUT after the
    fault) and the disarm on the ground at 10.656 s (2 s after the touchdown, COM_DISARM_LAND) in both; the summary's
    ``ended_by`` names the position loss and the fault; the trace the same. (The docs' ``--at 10:gps:off`` on the
    sine cut to 20 s flew the same, 8 s later: 20 s in each twin; this one 11 s.)"""
    sine = tmp_path / "sine11.toml"
    sine.write_text((ROOT / "missions" / "sine.toml").read_text().replace("duration_s = 30.0", "duration_s = 11.0"))
    summaries = []
    for command in ("sim", "sitl"):
        out = tmp_path / command
        with instance_slot() as n:
            extra = ("--instance", str(n)) if command == "sitl" else ()
            r = run_bsst(command, sine, "--sensors", "gnss", "--estimator", "ekf", "--at", "2:gps:off", "--out",
                         str(out), "--no-plots", *extra, env=ENV, timeout=300)
        assert r.returncode == 1 and (out / "summary.json").exists(), f"bsst {command}: {r.stderr[-2000:]}"
        summaries.append(json.loads((out / "summary.json").read_text()))
    offline, sitl = summaries
    mine = ("fault", "position", "failsafe", "disarmed")
    events = [[(e["t"], e["kind"], e["text"].split(" [by ")[0]) for e in s["events"] if e["kind"] in mine
               and e.get("source", "vehicle") == "vehicle"] for s in summaries]
    assert events[0] == events[1] and [(t, k) for t, k, _ in events[0]] == [
        (2.0, "fault"), (7.124, "position"), (7.124, "failsafe"), (10.656, "disarmed")], events
    assert sitl["outcome"] == offline["outcome"] == "failsafe"
    assert sitl["ended_by"] == offline["ended_by"] == {
        "who": "vehicle", "how": "failsafe at t=7.124 s: position lost: level and descend",
        "after_faults": ["t=2.000 s: gps off"]}
    rows = [(tmp_path / c / "trace.csv").read_text().splitlines() for c in ("sim", "sitl")]
    keep = rows[0][0].split(",").index("z") + 1  # t and the true state's columns up to z
    assert [r.split(",")[:keep] for r in rows[0]] == [r.split(",")[:keep] for r in rows[1]]


def _vehicle_events(summary: dict, kinds: tuple[str, ...]) -> list[tuple[float, str, str]]:
    return [(e["t"], e["kind"], e["text"].split(" [by ")[0]) for e in summary["events"] if e["kind"] in kinds
            and e.get("source", "vehicle") == "vehicle"]


def test_a_gps_lost_in_the_end_landing_lands_in_descend_in_lockstep_as_offline(tmp_path):
    """``--at 10:gps:off`` on the sine cut to 14 s: the position is lost at 15.124 s, in the mission's end landing.
    Offline flies PX4's Descend on to the ground (it used to stop there, armed in the air, and call it completed), and
    a lockstep session flies the same steps on the step clock (it used to leave lockstep at the disarm, and its
    policies read the failsafe as a late one and the descent as a jump of the mission's time): touchdown 16.203 s,
    disarm 2 s later, the same ``end`` block, every policy held, outcome completed (the mission was), exit 0, in both.
    (The whole sine with ``--at 26:gps:off`` flew the same, 16 s later: 36.5 s in each twin; this one 18.2 s.)"""
    sine = tmp_path / "sine14.toml"
    sine.write_text((ROOT / "missions" / "sine.toml").read_text().replace("duration_s = 30.0", "duration_s = 14.0"))
    summaries = []
    for command in ("sim", "sitl"):
        out = tmp_path / command
        with instance_slot() as n:
            extra = ("--instance", str(n)) if command == "sitl" else ()
            r = run_bsst(command, sine, "--sensors", "gnss", "--estimator", "ekf", "--at",
                         "10:gps:off", "--out", str(out), "--no-plots", *extra, env=ENV, timeout=300)
        assert r.returncode == 0 and (out / "summary.json").exists(), f"bsst {command}: {r.stderr[-2000:]}"
        summaries.append(json.loads((out / "summary.json").read_text()))
    offline, sitl = summaries
    kinds = ("position", "failsafe", "landed", "disarmed")
    assert _vehicle_events(offline, kinds) == _vehicle_events(sitl, kinds)
    assert [(t, k) for t, k, _ in _vehicle_events(offline, kinds)] == [
        (15.124, "position"), (15.124, "failsafe"), (16.203, "landed"), (18.203, "disarmed")]
    assert offline["outcome"] == sitl["outcome"] == "completed"
    assert offline["end"] == sitl["end"] and offline["end"]["disarmed"] and offline["end"]["landing_s"] == 4.203
    assert offline["end"]["failsafe"] == "position lost: level and descend"  # who finished the landing
    assert all(v["ok"] for v in sitl["policies"]) and all(v["ok"] for v in offline["policies"]), sitl["policies"]
    assert not [e for e in sitl["events"] if e["kind"] == "lockstep"], "the session left lockstep"


def test_a_gps_lost_after_the_touchdown_keeps_the_auto_disarm_wait(tmp_path):
    """``--at 29.99999:gps:off``: the end landing touches down at 34.371 s and the position is lost at 35.124 s, on
    the ground. PX4's failsafe switches to Descend, but its auto-disarm counts from the land detector: the disarm
    comes at 36.371 s, COM_DISARM_LAND after the touchdown (it used to come at once, with the failsafe)."""
    out = tmp_path / "sim"
    r = run_bsst("sim", ROOT / "missions" / "sine.toml", "--sensors", "gnss", "--estimator", "ekf", "--at",
                 "29.99999:gps:off", "--out", str(out), "--no-plots", env=ENV, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    summary = json.loads((out / "summary.json").read_text())
    assert [(t, k) for t, k, _ in _vehicle_events(summary, ("landed", "failsafe", "disarmed"))] == [
        (34.371, "landed"), (35.124, "failsafe"), (36.371, "disarmed")]
    assert summary["outcome"] == "completed" and summary["end"]["landing_s"] == 6.371
    assert summary["end"]["failsafe"] == "position lost: level and descend"

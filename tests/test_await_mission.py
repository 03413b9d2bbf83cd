"""Covers bridge.nodes.offboard.mission, bridge.nodes.vehicle.missionwatch and bridge.session: --await-mission.

Also the start of a ground station's mission in bridge.nodes.vehicle.mission and .commander,
missions.planfiles.plan_text and summary.json's ``mission_transfer`` (bridge.record.summary). With real parts:
MAVSDK (MissionRaw: import_qgroundcontrol_mission of examples/box.plan, upload, progress; Action.arm, then
MissionRaw.start_mission, its own order) against ``bsst sitl --await-mission`` in lockstep, whose flight must be
the file's (``bsst sitl examples/box.plan`` is offline's to the bit: tests/test_plan.py; here against offline,
≤ 1e-4 m); a pymavlink
ground station that uploads a small plan and sends MAV_CMD_MISSION_START to a ``--realtime`` one and to a lossy
lockstep one; a vehicle in this process answering MISSION_START and AUTO.MISSION. Every wait has a deadline.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import signal
import socket
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from bridge import simulate
from bridge.autopilot.params import parse_change
from bridge.autopilot.vehicleevents import Sender, typed_fields
from bridge.cli import main
from bridge.core.flight import Flight, at_rest, prepare
from bridge.mavlink.endpoint import GCS_PORT, parse_address
from bridge.mavlink.missionitems import MissionItem
from bridge.nodes.report import Ready, parse_line
from bridge.nodes.uploaded import uploaded_flight
from bridge.nodes.vehicle import Vehicle, VehicleConfig
from bridge.nodes.vehicle.clock import ClockState
from bridge.nodes.vehicle.mission import START_ARM, START_ARMED, START_COMMAND
from bridge.nodes.vehicle.missionwatch import ItemWatch, goals_of
from bridge.record.endedby import ended_by_command
from bridge.record.events import RunEvent
from bridge.record.interventions import interventions
from bridge.record.joiner import read_half
from bridge.record.runlog import RunRecord, trace_cap
from bridge.record.summary import mission_transfer
from bridge.session import instance_slot
from missions import Mission, Sine
from missions.geodetic import Home
from missions.geofence import Geofence, Zone
from missions.planfiles import plan_text, read_plan_text
from params import ConfigError
from tests.gcskit import upload, vehicle_of
from tests.plans import l_plan
from tests.sitlkit import (
    ENV,
    MAVSDK_GROUND_STATION,
    ROOT,
    GcsSocket,
    MavProxy,
    Proc,
    clean_exit,
    run_bsst,
    run_script,
    script_result,
    tlog_messages,
)
from tests.waiting import wait_for

pytestmark = pytest.mark.process  # starts processes and opens sockets

M = mavlink
BOX_PLAN = ROOT / "examples" / "box.plan"

MAVSDK_SCRIPT = r"""
import json, sys, time
from mavsdk import Mavsdk, Configuration, ComponentType
from mavsdk.plugins.mission_raw import MissionRaw
from mavsdk.plugins.action import Action
from mavsdk.plugins.telemetry import Telemetry

sdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
sdk.add_any_connection(sys.argv[1])
system = sdk.first_autopilot(30.0)
out = {"found": system is not None}
mr = MissionRaw(system)
items = mr.import_qgroundcontrol_mission(sys.argv[2]).mission_items
out["items"] = len(items)
out["upload"] = mr.upload_mission(items).name
if len(sys.argv) > 4 and sys.argv[4] == "zones":  # the plan's fence and rally points too, then read back
    data = mr.import_qgroundcontrol_mission(sys.argv[2])
    def fields(its):
        return [[i.seq, i.frame, i.command, i.param1, i.x, i.y, i.mission_type] for i in its]
    out["fence_upload"] = mr.upload_geofence(data.geofence_items).name
    out["rally_upload"] = mr.upload_rally_points(data.rally_items).name
    out["fence_sent"], out["rally_sent"] = fields(data.geofence_items), fields(data.rally_items)
    out["fence_got"], out["rally_got"] = fields(mr.download_geofence()), fields(mr.download_rallypoints())
progress = []
mr.subscribe_mission_progress(lambda p, _ud: progress.append([p.current, p.total]))
telemetry = Telemetry(system)
armed = []  # the vehicle's armed state as MAVSDK's telemetry reports it: a flight its failsafe ended disarms early
zones = len(sys.argv) > 4 and sys.argv[4] == "zones"  # (its flight leaves the fence: it may end before the mission)
def landed_early():
    if not zones:
        return False
    a = telemetry.armed()
    if not armed or armed[-1] != a:
        armed.append(a)
    return True in armed and not a and not mr.is_mission_finished()
def last_reached():  # progress's current past the last item; its total is MAVSDK's count of the last transfer (the
    return any(p[0] == len(items) for p in progress)  # rally points' with zones: [5, 1], never [5, 5])
# MAVSDK's own order, as its mission examples fly a PX4: arm (in HOLD, on the ground), then start the mission
# (AUTO.MISSION)
out["arm"] = Action(system).arm().name
out["start"] = mr.start_mission().name
deadline = time.monotonic() + float(sys.argv[3])
while (time.monotonic() < deadline and not mr.is_mission_finished() and not last_reached()
       and not landed_early()):
    time.sleep(0.1)
done_by = time.monotonic() + 10.0  # the last MISSION_CURRENT (sent as its item is reached) says it complete;
# the progress callback runs on MAVSDK's own thread, so [n, n] may land after is_mission_finished() turns true
# (with zones it waited all 10 s for a [5, 5] that never came, its session gone meanwhile)
while (time.monotonic() < done_by and not (mr.is_mission_finished() and last_reached()) and not landed_early()):
    time.sleep(0.05)
out["finished"] = mr.is_mission_finished()
out["landed_early"] = landed_early()
out["progress"] = progress
print("RESULT " + json.dumps(out), flush=True)
sdk.destroy()
"""


def _trace(path: Path) -> list[tuple[float, float, float, float]]:
    rows = path.read_text().splitlines()
    head = rows[0].split(",")
    ix = [head.index(c) for c in ("t", "x", "y", "z")]
    return [tuple(float(r.split(",")[i]) for i in ix) for r in rows[1:]]  # type: ignore[misc]


def _mavsdk_flies(n: int, plan: Path, out: Path, status: int, *extra: str, sitl_args: tuple[str, ...] = ()
                  ) -> dict[str, Any]:
    """``bsst sitl --await-mission`` (instance ``n``, into ``out``, with ``sitl_args``) and the MAVSDK script flying
    ``plan`` through it (``extra``: the script's further arguments); the session's exit status asserted; what MAVSDK
    reported."""
    sitl = Proc.bsst("sitl", "--await-mission", "--speed", "0", "--instance", str(n), "--out", str(out), "--no-plots",
                     *sitl_args)
    try:
        r = run_script("-c", MAVSDK_SCRIPT, f"udpin://127.0.0.1:{GCS_PORT + n}", str(plan), "240", *extra, timeout=300,
                       env=ENV)
        said = script_result(r)
        assert sitl.p.wait(timeout=120) == status, "\n".join(sitl.lines[-30:])
        return said
    finally:
        sitl.stop()


def test_mavsdk_flies_a_plan_file_through_await_mission_as_the_file_flies(tmp_path):
    """MAVSDK imports a QGroundControl plan (examples/box.plan cut to an L: takeoff, speed change, waypoint,
    pass-through corner, land; tests/plans.py), uploads it, arms (HOLD) and starts it (AUTO.MISSION), MAVSDK's
    own order: the controller
    downloads the 5 items over its link and flies them; the flight is the file's (offline, to ≤ 1e-4 m, as many
    rows), landed and disarmed; MISSION_ITEM_REACHED says every item in order on the GCS link, MISSION_CURRENT
    follows to the last, the vehicle shows AUTO.MISSION while it flies; the run keeps mission.plan (the same
    items) and the resolved mission.toml; summary.json's mission_transfer says the download. (The whole box,
    90 s, is flown offline to its figures by tests/test_plan.py; 100 items go through MAVSDK in
    benchmarks/missions_mavsdk.py.)"""
    plan = l_plan(tmp_path)
    out = tmp_path / "run"
    with instance_slot() as n:
        gs = _mavsdk_flies(n, plan, out, 0)
    assert gs["upload"] == gs["start"] == gs["arm"] == "SUCCESS" and gs["items"] == 5, gs
    assert gs["finished"] and gs["progress"][-1] == [5, 5], gs  # MAVSDK: every item reached, mission complete
    summary = json.loads((out / "summary.json").read_text())
    assert summary["outcome"] == "completed" and summary["end"]["disarmed"], summary["ended_by"]
    t = summary["mission_transfer"]
    assert (t["items"], t["result"]) == (5, "accepted") and t["attempts"] == 6 + t["re_requests"], t
    assert t["started_by"]["command"] == START_ARMED and t["started_by"]["by"].endswith(" gcs"), t  # MAVSDK's ids
    assert summary["interventions"] == [] and summary["lockstep"]["held"], summary["lockstep"]  # the arm: the start's
    assert summary["sitl"]["speed"] is None, summary["sitl"]  # --speed 0: as fast as it goes
    offline = simulate(plan, plots=False)
    flown = _trace(out / "trace.csv")
    assert len(flown) == len(offline.trace["t"])
    worst = max(math.dist(row[1:], (offline.trace["x"][i], offline.trace["y"][i], offline.trace["z"][i]))
                for i, row in enumerate(flown))
    assert worst <= 1e-4, worst
    kept = read_plan_text((out / "mission.plan").read_text(), "kept")
    want = read_plan_text(plan.read_text(), "l")
    assert [(i.command, i.frame) for i in kept.items] == [(i.command, i.frame) for i in want.items]
    assert all(abs(a.lat - b.lat) < 1e-9 and abs(a.lon - b.lon) < 1e-9 and a.alt == b.alt
               for a, b in zip(kept.items, want.items, strict=True))
    assert 'kind = "smooth"' in (out / "mission.toml").read_text()
    sysid = n + 1
    reached = [m.seq for m in tlog_messages(out / "vehicle.tlog", sysid, ["MISSION_ITEM_REACHED"])]
    assert list(dict.fromkeys(reached)) == list(range(5)), reached  # each in order (then PX4's repeats)
    currents = tlog_messages(out / "vehicle.tlog", sysid, ["MISSION_CURRENT"])
    current = [m.seq for m in currents]
    assert current[-1] == 4 and current == sorted(current), current
    # the mission flown in AUTO.MISSION: PX4's mission_mode "in mission" whenever it was ACTIVE; COMPLETE at the end
    assert {m.mission_mode for m in currents if m.mission_state == mavlink.MISSION_STATE_ACTIVE} == {1}, currents
    assert currents[-1].mission_state == mavlink.MISSION_STATE_COMPLETE
    beats = tlog_messages(out / "vehicle.tlog", sysid, ["HEARTBEAT"])
    modes = {(m.custom_mode, bool(m.base_mode & 128)) for m in beats}
    assert ((4 << 16) | (4 << 24), True) in modes  # AUTO.MISSION, armed
    # its end landing disarmed, it shows AUTO.MISSION again, as PX4 stays in Mission (docs/ground-station.md): the
    # event's typed mode says so too (it said "offboard", the vehicle's mode under the controller)
    back = [(e["text"], e["mode"]) for e in summary["events"] if e["kind"] == "mode" and "disarmed after" in e["text"]]
    assert back == [("MISSION (disarmed after LAND: PX4 takes the last mode it arms in; armed in it next) [by vehicle]",
                     "mission")]
    # the session's note of the download at the controller's word, before the flight's time 0; until the third wave's
    # fortieth session at the newest row joined when the session read it (the smooth path prepared, the flight had
    # flown on at --speed 0: t=0.468 and 0.860 for examples/box.plan)
    note = next(e for e in summary["events"] if e["source"] == "session" and e["kind"] == "mission")
    said = next(e for e in summary["events"] if e["source"] == "controller" and e["text"].startswith("downloaded 5"))
    assert note["t"] == said["t"] <= 0.0, summary["events"]


@pytest.mark.parametrize("action", [5, 0], ids=["gf-action-5-land", "gf-action-0-not-watched"])
def test_mavsdk_uploads_a_plans_fence_and_rally_points_and_the_flight_leaving_the_fence_fails(tmp_path, action,
                                                                                               capsys):
    """MAVSDK MissionRaw uploads the L plan's mission, and its geoFence (an inclusion rectangle about the north
    leg only) and rallyPoints as the fence's and rally points' mission types, reads both back item for item, and
    flies the mission: the east leg leaves the fence, so the geofence policy fails at the first row outside and
    ``bsst sitl`` exits 1. With ``--param GF_ACTION=5`` the vehicle says so (its ``geofence`` event, once) and
    lands there (2, PX4's default, would hold until the session gives up: its failsafe, outcome ``failsafe``);
    with 0 it does not watch and flies on to the mission's end, and the run still says where it left the fence
    (it said nothing until the third wave's thirty-sixth session: the run's record left the uploaded fence out).
    Each upload a ``mission`` event naming MAVSDK. The controller downloads the fence and rally points with the
    mission, so the run's mission.plan and mission.toml hold them as flown, and ``bsst sim`` of that mission.toml
    flies the session's flight to its outcome and the same breach; summary.json's ``mission_transfer`` has the three
    downloads."""
    def fenced(data: dict) -> None:
        data["geoFence"]["polygons"] = [{"inclusion": True, "version": 1, "polygon": [
            [47.39770, 8.54555], [47.39770, 8.54564], [47.39790, 8.54564], [47.39790, 8.54555]]}]
        data["rallyPoints"]["points"] = [[47.39779, 8.54562, 10.0]]
    plan = l_plan(tmp_path)
    data = json.loads(plan.read_text())
    fenced(data)
    plan.write_text(json.dumps(data))
    out = tmp_path / "run"
    with instance_slot() as n:
        gs = _mavsdk_flies(n, plan, out, 1, "zones", sitl_args=("--param", f"GF_ACTION={action}"))
    assert gs["fence_upload"] == gs["rally_upload"] == gs["upload"] == "SUCCESS", gs
    assert gs["landed_early"] != gs["finished"] == (action == 0), gs  # MAVSDK saw it land early, or finish
    assert len(gs["fence_sent"]) == 4 and gs["fence_got"] == gs["fence_sent"], gs
    assert len(gs["rally_sent"]) == 1 and gs["rally_got"] == gs["rally_sent"], gs
    summary = json.loads((out / "summary.json").read_text())
    assert summary["outcome"] == ("completed" if action == 0 else "failsafe"), summary["ended_by"]
    fence = next(p for p in summary["policies"] if p["name"] == "geofence")
    assert not fence["ok"] and "outside every inclusion zone of the geofence" in fence["why"], fence
    events = (out / "events.log").read_text()
    kinds = [ln.split(" ", 2)[1] for ln in events.splitlines() if ln.startswith("t=")]
    assert kinds.count("geofence:") == (action != 0) and "fence: uploaded 4 items" in events, events
    if action:
        assert "geofence: outside its fence" in events and ": land here [vehicle]" in events, events
        assert "GF_ACTION = 5: land" in events and "disarmed: landed: disarmed" in events, events
    assert "rally: uploaded 1 items" in events and "a fence of 4 items and 1 rally points" in events, events
    got = summary["mission_transfer"]  # each download's figures (the mission's alone until the thirty-seventh session)
    assert (got["items"], got["fence"]["items"], got["rally"]["items"]) == (5, 4, 1), got
    assert got["fence"]["result"] == got["rally"]["result"] == "accepted" and got["fence"]["attempts"] >= 5, got
    edge = Home().paper(47.39780, 8.54564, 488.0)[1]  # the fence's east side (y west, m)
    east = next(t for t, x, y, z in _trace(out / "trace.csv") if y < edge)
    assert abs(fence["t"] - east) <= 0.005, (fence["t"], east)  # (the event: after the step, at its end)
    kept = json.loads((out / "mission.plan").read_text())  # the fence and rally points as uploaded
    assert [(z["inclusion"], z["polygon"]) for z in kept["geoFence"]["polygons"]] == [
        (True, data["geoFence"]["polygons"][0]["polygon"])] and kept["geoFence"]["circles"] == []
    assert kept["rallyPoints"]["points"] == data["rallyPoints"]["points"], kept["rallyPoints"]
    flown = prepare(out / "mission.toml").mission
    want = prepare(plan).mission
    assert flown.geofence is not None and len(flown.geofence.zones) == 1 and len(flown.rally) == 1
    assert np.allclose(flown.geofence.zones[0].points, want.geofence.zones[0].points, atol=1e-6)
    assert np.allclose(flown.rally, want.rally, atol=1e-6)
    # (bsst sim in this process: its flight is what is read, not the command's start)
    assert main(["sim", str(out / "mission.toml"), "--out", str(tmp_path / "again"), "--no-plots"]) == 1, \
        capsys.readouterr().err
    offline = json.loads((tmp_path / "again" / "summary.json").read_text())
    assert offline["outcome"] == summary["outcome"], offline["ended_by"]
    assert next(p for p in offline["policies"] if p["name"] == "geofence")["t"] == fence["t"], offline["policies"]


MAVSDK_GEOFENCE_SCRIPT = r"""
import json, sys
from mavsdk import Mavsdk, Configuration, ComponentType
from mavsdk.plugins.geofence import Circle, FenceType, Geofence, GeofenceData, Point, Polygon

sdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
sdk.add_any_connection(sys.argv[1])
system = sdk.first_autopilot(30.0)
fence = Geofence(system)
def read(data):
    return {"polygons": [[p.fence_type.name, [[q.latitude_deg, q.longitude_deg] for q in p.points]]
                         for p in data.polygons],
            "circles": [[c.fence_type.name, c.point.latitude_deg, c.point.longitude_deg, c.radius]
                        for c in data.circles]}
square = [Point(47.39770, 8.54555), Point(47.39770, 8.54564), Point(47.39790, 8.54564), Point(47.39790, 8.54555)]
hole = Circle(Point(47.39780, 8.54560), 3.0, FenceType.EXCLUSION)
sent = GeofenceData([Polygon(square, FenceType.INCLUSION)], [hole])
out = {"sent": read(sent), "upload": fence.upload_geofence(sent).name, "got": read(fence.download_geofence())}
out["clear"] = fence.clear_geofence().name
out["after_clear"] = read(fence.download_geofence())
print("RESULT " + json.dumps(out), flush=True)
sdk.destroy()
"""


def _mavsdk_against_await_mission(script: str, out: Path) -> dict[str, Any]:
    """``bsst sitl --await-mission`` (into ``out``) and a MAVSDK ``script`` against its ground-station port, stopped
    once the script is done: the script's RESULT."""
    with instance_slot() as n:
        sitl = Proc.bsst("sitl", "--await-mission", "--instance", str(n), "--out", str(out), "--no-plots")
        try:
            r = run_script("-c", script, f"udpin://127.0.0.1:{GCS_PORT + n}", timeout=120, env=ENV)
        finally:
            sitl.stop()
    return script_result(r)


def test_mavsdks_geofence_plugin_uploads_reads_back_and_clears_a_polygon_and_a_circle(tmp_path):
    """MAVSDK's Geofence plugin (not MissionRaw's items: its own polygon and circle types) against a vehicle
    awaiting its mission: an inclusion square and an exclusion circle uploaded, read back as sent (degE7's
    1e-7 deg; the radius a float32), cleared, and read back empty; the vehicle's events say each."""
    out = tmp_path / "run"
    gs = _mavsdk_against_await_mission(MAVSDK_GEOFENCE_SCRIPT, out)
    assert gs["upload"] == gs["clear"] == "SUCCESS", gs
    assert gs["after_clear"] == {"polygons": [], "circles": []}, gs
    (kind, square), = gs["got"]["polygons"]
    (want_kind, want_square), = gs["sent"]["polygons"]
    assert kind == want_kind == "INCLUSION" and len(square) == 4
    assert all(math.dist(a, b) < 1.5e-7 for a, b in zip(square, want_square, strict=True)), (square, want_square)
    (got_circle,), (sent_circle,) = gs["got"]["circles"], gs["sent"]["circles"]
    assert got_circle[0] == sent_circle[0] == "EXCLUSION" and got_circle[3] == sent_circle[3] == 3.0, gs
    assert math.dist(got_circle[1:3], sent_circle[1:3]) < 1.5e-7, gs
    events = (out / "events.log").read_text()
    assert "fence: uploaded 5 items" in events and "fence: cleared" in events, events


MAVSDK_ARM_OUTSIDE_SCRIPT = r"""
import json, sys, threading, time
from mavsdk import Mavsdk, Configuration, ComponentType
from mavsdk.plugins.action import Action, ActionError
from mavsdk.plugins.geofence import FenceType, Geofence, GeofenceData, Point, Polygon
from mavsdk.plugins.telemetry import Telemetry

sdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
sdk.add_any_connection(sys.argv[1])
system = sdk.first_autopilot(30.0)
texts = []
tel = Telemetry(system)
tel.subscribe_status_text(lambda s, *_: texts.append([s.type.name, s.text]))
cond, health = threading.Condition(), {"armable": None}
def on_health(h, *_):  # SYS_STATUS's pre-arm bit, as MAVSDK reads it
    with cond:
        health["armable"] = h.is_armable
        cond.notify_all()
tel.subscribe_health(on_health)
def armable(value):
    with cond:
        return cond.wait_for(lambda: health["armable"] is value, 5.0)
fence, act = Geofence(system), Action(system)
def arm():
    try:
        return act.arm().name
    except ActionError as e:
        return e.result.name
north = [Point(47.39790, 8.54555), Point(47.39790, 8.54564), Point(47.39800, 8.54564), Point(47.39800, 8.54555)]
out = {"armable_at_start": armable(True)}
out["upload"] = fence.upload_geofence(GeofenceData([Polygon(north, FenceType.INCLUSION)], [])).name
out["not_armable_outside"] = armable(False)
out["arm_outside"] = arm()
out["clear"] = fence.clear_geofence().name
out["armable_cleared"] = armable(True)
out["arm_cleared"] = arm()
out["disarm"] = act.disarm().name
deadline = time.monotonic() + 10.0  # the STATUSTEXTs come on MAVSDK's own thread: until the disarm's is in
while time.monotonic() < deadline and not any(t.startswith("disarmed") for _, t in texts):
    time.sleep(0.02)
out["texts"] = texts
print("RESULT " + json.dumps(out), flush=True)
sdk.destroy()
"""


def test_mavsdks_arm_outside_an_uploaded_fence_is_denied_saying_why_and_arms_once_it_is_cleared(tmp_path):
    """PX4's pre-arm geofence check against MAVSDK's Action and Geofence plugins: an inclusion square uploaded
    11-23 m north of the vehicle, so it stands outside it; Action.arm() is denied (the vehicle's TEMPORARILY_REJECTED,
    which MAVSDK reports as COMMAND_DENIED, as against a PX4), a CRITICAL STATUSTEXT says why, and nothing is armed;
    with the fence cleared the same arm succeeds (in HOLD on the ground), and the disarm too. ``health.is_armable``
    follows: true at the start, false once the fence leaves the vehicle outside, true again when it is cleared."""
    out = tmp_path / "run"
    gs = _mavsdk_against_await_mission(MAVSDK_ARM_OUTSIDE_SCRIPT, out)
    assert (gs["upload"], gs["arm_outside"], gs["clear"], gs["arm_cleared"], gs["disarm"]) == (
        "SUCCESS", "COMMAND_DENIED", "SUCCESS", "SUCCESS", "SUCCESS"), gs
    # MAVSDK's health.is_armable (SYS_STATUS's pre-arm bit, as PX4 sets it) says so before each arm
    assert gs["armable_at_start"] and gs["not_armable_outside"] and gs["armable_cleared"], gs
    denied = [text for sev, text in gs["texts"] if text.startswith("preflight: arming denied")]
    assert len(denied) == 1 and "outside its fence" in denied[0] and "(GF_ACTION = 2: hold)" in denied[0], gs
    assert ["CRITICAL", denied[0]] in gs["texts"], gs
    kinds = [e["kind"] for e in json.loads((out / "summary.json").read_text())["events"]]
    assert kinds.index("preflight") < kinds.index("armed") and kinds.count("armed") == 1, kinds


# a takeoff to 0.5 m, a waypoint there, a landing: 3.2 s of flight (a waypoint 2 m away at 1.5 m: 9.1 s), as
# long as a test of the transfer, the start or a refusal needs
SMALL_PLAN = """QGC WPL 110
0\t1\t0\t16\t0\t0\t0\t0\t47.397742\t8.545594\t488.0\t1
1\t0\t3\t22\t0\t0\t0\tnan\t47.397742\t8.545594\t0.5\t1
2\t0\t3\t16\t0\t0.5\t0\tnan\t47.3977420\t8.5455940\t0.5\t1
3\t0\t3\t21\t0\t0\t0\tnan\t47.3977420\t8.5455940\t0\t1
"""
# the same with a loiter of 2 s at its waypoint (LOITER_TIME): 5.2 s of flight
LOITER_PLAN = SMALL_PLAN.replace("2\t0\t3\t16\t0\t0.5", "2\t0\t3\t19\t2\t0.5")
# the same at 1.5 m: 5.1 s of flight, for MAVProxy's lockstep flight paced at 1x, which is to last over 5 s (a
# waypoint 1 m north at 1 m: 7.6 s)
HOP_PLAN = """QGC WPL 110
0\t1\t0\t16\t0\t0\t0\t0\t47.397742\t8.545594\t488.0\t1
1\t0\t3\t22\t0\t0\t0\tnan\t47.397742\t8.545594\t1.5\t1
2\t0\t3\t16\t0\t0.5\t0\tnan\t47.3977420\t8.5455940\t1.5\t1
3\t0\t3\t21\t0\t0\t0\tnan\t47.3977420\t8.5455940\t0\t1
"""


def _small_plan_items(target: tuple[int, int] = (0, 0), plan: str = SMALL_PLAN) -> list[Any]:
    """``plan``'s items (SMALL_PLAN's) as MISSION_ITEM_INT messages for ``target`` (system, component)."""
    return [M.MAVLink_mission_item_int_message(*target, k, it.frame, it.command, 0, 1, it.p1, it.p2, it.p3, it.p4,
                                               round(it.lat * 1e7), round(it.lon * 1e7), it.alt, 0)
            for k, it in enumerate(read_plan_text(plan, "small").items)]


def _ground_station(n: int) -> Any:
    """A pymavlink ground station (255:190, MAVLink 2) on instance ``n``'s ground-station port."""
    os.environ["MAVLINK20"] = "1"
    return mavutil.mavlink_connection(f"udpin:127.0.0.1:{GCS_PORT + n}", source_system=255, source_component=190,
                                      dialect="common")


def _mission_start(gcs: Any, target: tuple[int, int]) -> tuple[int, str]:
    """MAV_CMD_MISSION_START to ``target``: its COMMAND_ACK's result and, refused, the STATUSTEXT saying why (its
    50-character chunks joined, the last one shorter)."""
    gcs.mav.command_long_send(*target, M.MAV_CMD_MISSION_START, 0, 0, 0, 0, 0, 0, 0, 0)
    ack = gcs.recv_match(type="COMMAND_ACK", blocking=True, timeout=5,
                         condition=f"COMMAND_ACK.command=={M.MAV_CMD_MISSION_START}")
    assert ack is not None, "no COMMAND_ACK for MISSION_START"
    text, more = "", ack.result != M.MAV_RESULT_ACCEPTED
    while more:
        m = gcs.recv_match(type="STATUSTEXT", blocking=True, timeout=5)
        assert m is not None, text
        text, more = text + m.text, len(m.text) == 50
    return ack.result, text


@pytest.mark.parametrize("link, how", [([], START_ARM), (["--loss", "10"], START_COMMAND)],
                         ids=["perfect-mode-then-arm", "relay-loss-10-mission-start"])
def test_mission_start_flies_a_small_plan_in_real_time(tmp_path, link, how):
    """A pymavlink ground station uploads a takeoff, a waypoint and a landing to ``bsst sitl --await-mission
    --realtime`` and starts it, as PX4's is started: AUTO.MISSION (DO_SET_MODE 4/4) while disarmed, then arm; or
    MAV_CMD_MISSION_START (each ACCEPTED). AUTO.MISSION alone starts nothing: the controller says it waits for
    the start, and the vehicle is armed only after it. The controller downloads the three items and flies them
    on the wall clock; each is reached (MISSION_ITEM_REACHED), the flight completes landed and disarmed, and
    summary.json's ``mission_transfer.started_by`` says how and by whom. With ``--loss 10`` the download crosses
    ``bsst relay`` (the session's, on the wire) and still arrives. (SMALL_PLAN: 3.2 s on the wall clock; landed,
    the vehicle disarms 0.5 s later, not PX4's 2 s: the session's wall clock is the test's CPU.)"""
    items = _small_plan_items()
    out = tmp_path / "rt"
    with instance_slot() as n:
        gcs = _ground_station(n)
        sitl = Proc.bsst("sitl", "--await-mission", "--realtime", "--instance", str(n), "--out", str(out),
                         "--no-plots", "--param", "COM_DISARM_LAND=0.5", *link)
        try:
            target = vehicle_of(gcs)
            upload(gcs, target, items)
            steps = [(M.MAV_CMD_MISSION_START, (0, 0))] if how == START_COMMAND else \
                [(M.MAV_CMD_DO_SET_MODE, (M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4, 4)),
                 (M.MAV_CMD_COMPONENT_ARM_DISARM, (1,))]
            for cmd, params in steps:
                gcs.mav.command_long_send(*target, cmd, 0, *params, *[0] * (7 - len(params)))
                ack = gcs.recv_match(type="COMMAND_ACK", blocking=True, timeout=5,
                                     condition=f"COMMAND_ACK.command=={cmd}")
                assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED, (cmd, ack)
                if cmd == M.MAV_CMD_DO_SET_MODE:  # selected alone, it starts nothing: the controller waits for the arm
                    wait_for(lambda log=out / "events.log": log.exists() and "waiting for its start" in log.read_text(),
                             30, "the controller waiting for the start (events.log)")
            reached: list[int] = []

            def all_reached() -> bool:
                m = gcs.recv_match(type="MISSION_ITEM_REACHED", blocking=True, timeout=0.5)
                if m is not None and m.seq not in reached:
                    reached.append(m.seq)
                return len(reached) == 3

            wait_for(all_reached, 90.0, "MISSION_ITEM_REACHED for the three items", poll_s=0.0)
            rc = sitl.p.wait(timeout=60)
        finally:
            gcs.close()
            sitl.stop()
    assert reached == [0, 1, 2]
    summary = json.loads((out / "summary.json").read_text())
    assert rc == clean_exit(summary), "\n".join(sitl.lines[-30:])
    assert summary["outcome"] == "completed" and summary["clock"] == "realtime"
    assert summary["mission_transfer"]["items"] == 3 and summary["end"]["disarmed"]
    assert summary["mission_transfer"]["started_by"] == {"command": how, "by": f"255:190 127.0.0.1:{GCS_PORT + n} gcs"}
    if how == START_ARM:  # the vehicle flew only once armed: AUTO.MISSION alone left it on the ground, disarmed
        said = [(e["source"], e["kind"], e["text"]) for e in summary["events"]]
        waiting = next(i for i, e in enumerate(said) if "waiting for its start" in e[2])
        started = next(i for i, e in enumerate(said) if e[0] == "vehicle" and "start requested" in e[2])
        armed = next(i for i, e in enumerate(said) if e[0] == "vehicle" and e[1] == "armed")
        assert waiting < started < armed, said[:12]
    assert (out / "relay.json").exists() == bool(link)


@pytest.fixture(scope="module")
def denied_then_flown(tmp_path_factory):
    """One ``bsst sitl --await-mission --param-at 4:COM_OF_LOSS_T=1`` (lockstep) and a pymavlink ground station's
    MISSION_START after each of its uploads: a mission over the day a mission may last (30 holds of an hour), one
    over the session's trace (three holds of 1000 s: 3000 s, over 2000 s at 250 Hz), the small plan (3.2 s: over
    before the --param-at's 4 s), then the plan with a 2 s loiter (5.2 s), which is flown. The (result, STATUSTEXT)
    of each start, the exit status, summary.json and the session's last lines: the two tests below read it."""
    hours = [M.MAVLink_mission_item_int_message(0, 0, 0, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, M.MAV_CMD_NAV_TAKEOFF, 0,
                                                1, 0, 0, 0, math.nan, 473977420, 85455940, 10.0, 0)]
    hours += [M.MAVLink_mission_item_int_message(0, 0, k, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                                                 M.MAV_CMD_NAV_LOITER_TIME, 0, 1, 3600, 0, 0, math.nan, 473977420,
                                                 85455940, 10.0, 0) for k in range(1, 31)]
    hours += [M.MAVLink_mission_item_int_message(0, 0, 31, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, M.MAV_CMD_NAV_LAND,
                                                 0, 1, 0, 0, 0, math.nan, 473977420, 85455940, 0.0, 0)]
    out = tmp_path_factory.mktemp("denied") / "run"
    with instance_slot() as n:
        gcs = _ground_station(n)
        sitl = Proc.bsst("sitl", "--await-mission", "--instance", str(n), "--speed", "0", "--out", str(out),
                         "--no-plots", "--param-at", "4:COM_OF_LOSS_T=1")
        try:
            target = vehicle_of(gcs)
            said = []
            for items in (hours, _small_plan_items(plan=LONG_PLAN), _small_plan_items(),
                          _small_plan_items(plan=LOITER_PLAN)):
                upload(gcs, target, items)
                said.append(_mission_start(gcs, target))
            rc = sitl.p.wait(timeout=120)
        finally:
            gcs.close()
            sitl.stop()
    return said, rc, json.loads((out / "summary.json").read_text()), "\n".join(sitl.lines[-30:])


def test_a_session_denies_the_start_of_missions_its_controller_or_trace_would_refuse_and_flies_the_next(
        denied_then_flown):
    """``bsst sitl --await-mission``: MISSION_START of a mission over the day a mission may last (30 holds of an
    hour) and of one over the session's trace (three holds of 1000 s: 3000 s, over 2000 s at 250 Hz) is DENIED at
    once, a STATUSTEXT saying why, and the session waits on; the next one it can fly (after the small plan, over
    before the session's --param-at: the test below) is ACCEPTED and flown, exit 0. Until the third wave's
    thirty-sixth session both were ACCEPTED: the first ended the session with the controller's refusal (exit 1), the
    second was flown whole past the cap (630 731 rows for 2523 s)."""
    said, rc, summary, last = denied_then_flown
    (hours_result, hours_text), (long_result, long_text), _, (loiter_result, _) = said
    assert hours_result == M.MAV_RESULT_DENIED and hours_text.startswith("MISSION_START: the mission cannot be flown")
    assert "32 items fly at least 108" in hours_text and "over the 86400 s a mission may last" in hours_text
    assert long_result == M.MAV_RESULT_DENIED and "over the 500000 a run keeps in memory" in long_text, long_text
    assert loiter_result == M.MAV_RESULT_ACCEPTED
    assert rc == clean_exit(summary) == 0, last
    assert summary["outcome"] == "completed" and summary["mission_transfer"]["items"] == 3


def test_a_session_denies_the_start_of_a_mission_over_before_its_param_at_and_flies_the_next(denied_then_flown):
    """``bsst sitl --await-mission --param-at 4:COM_OF_LOSS_T=1``: MISSION_START of the small plan (3.2 s to fly:
    over before mission time 4 s) is DENIED at once, a STATUSTEXT naming the --param-at and the mission's length,
    and the session waits on; the plan with a 2 s loiter (5.2 s) uploaded next is ACCEPTED and flown, the change
    sent at 4 s and confirmed, exit 0. Until the third wave's thirty-seventh session the vehicle's start check did
    not know the controller's --param-at: the first was ACCEPTED and the controller's refusal ended the session
    (exit 1). (The session of the test above: the two missions it denies first fly nothing.)"""
    said, rc, summary, last = denied_then_flown
    (result, text), (loiter_result, _) = said[2:]
    assert result == M.MAV_RESULT_DENIED, last
    assert text.startswith("MISSION_START: the mission cannot be flown: --param-at 4:COM_OF_LOSS_T=1"), text
    assert "must be in [0, 3.242) s (the mission's duration)" in text, text
    assert loiter_result == M.MAV_RESULT_ACCEPTED
    assert rc == clean_exit(summary) == 0, last
    assert summary["outcome"] == "completed" and summary["mission_transfer"]["items"] == 3
    [change] = summary["param_at"]
    assert change["sent_t"] == change["t_s"] == 4.0 and change["confirmed"], change


# settings whose own fence and rally points the vehicle holds from its start (a ground station downloads them), on
# their bounds: a fence's points within 100 km of the home each way, a rally point within the 100 m envelope. Read
# back from the wire (degE7 about the home) each comes a little outside (~6 mm: the square's corners, the rally
# point 100 m west), and is put back on its bound (missions.geodetic.onto_bound)
ZONED_SETTINGS = """name = "zoned"
duration_s = 30.0
[trajectory]
kind = "sine"
[geofence]
zones = [{ kind = "polygon", inclusion = true, points = [[1e5, 1e5], [1e5, -1e5], [-1e5, -1e5], [-1e5, 1e5]] }]
[rally]
points = [[0.0, 100.0]]
"""


def test_a_vehicle_holding_a_fence_and_rally_points_on_their_bounds_flies_a_ground_stations_mission(tmp_path):
    """``bsst vehicle SETTINGS --await-mission`` and ``bsst controller SETTINGS --await-mission``, SETTINGS holding a
    fence and rally points on their bounds (:data:`ZONED_SETTINGS`): a pymavlink ground station's MISSION_START of
    the small plan is ACCEPTED and the controller flies it, exit 0, its mission.toml holding the settings' fence and
    rally points within the wire's step. The vehicle's start check reads the held fence and rally points as the
    controller does (:func:`bridge.nodes.uploaded.uploaded_flight`). Until the third wave's thirty-seventh session
    neither read them back: the start was ACCEPTED and the controller's refusal (``geoFence.polygons[0]: ... 141 km
    from the plan's home``) ended its run, exit 1."""
    from missions.geodetic import WIRE_STEP_M

    settings = tmp_path / "zoned.toml"
    settings.write_text(ZONED_SETTINGS)
    with instance_slot() as n:
        gcs = _ground_station(n)
        v = Proc.bsst("vehicle", str(settings), "--await-mission", "--instance", str(n), "--speed", "0",
                      "--out", str(tmp_path / "v"))
        ctl = Proc.bsst("controller", str(settings), "--await-mission", "--instance", str(n),
                        "--out", str(tmp_path / "c"))
        try:
            target = vehicle_of(gcs)
            upload(gcs, target, _small_plan_items())
            said = _mission_start(gcs, target)
            rc = ctl.p.wait(timeout=120)
        finally:
            gcs.close()
            ctl.stop()
            v.stop()
    assert said[0] == M.MAV_RESULT_ACCEPTED and rc == 0, (said, "\n".join(ctl.lines[-20:]))
    flown = prepare(tmp_path / "c" / "mission.toml").mission
    assert flown.geofence is not None and np.allclose(flown.geofence.zones[0].points, [[1e5, 1e5], [1e5, -1e5],
                                                      [-1e5, -1e5], [-1e5, 1e5]], atol=WIRE_STEP_M, rtol=0.0)
    assert np.allclose(flown.rally, [[0.0, 100.0]], atol=WIRE_STEP_M, rtol=0.0)


def test_the_link_model_acts_on_the_transfer_in_lockstep_and_the_flight_is_offlines(tmp_path):
    """``bsst sitl --await-mission --loss 30 --param-at 1:COM_OF_LOSS_T=1`` in lockstep, a pymavlink ground
    station's MISSION_START: the download crosses the mission's link model (seeded: requests are lost and asked
    again), and the flight that follows is offline's with the same link (its model starts fresh at the arm) and
    the same scheduled change, ≤ 1e-4 m, as many rows; the change was sent at mission time 1 s (time 0: the
    flight's first step, the controller's arm once it has the mission) and confirmed. The arm follows the download
    at once: the flight's link (controller.tlog) opens with it, no HEARTBEAT of the vehicle's read before it. Until
    the third wave's thirty-ninth session the flight waited for one, the vehicle's next at 1 Hz (the download's
    link had heard it already; on the same source port the vehicle sends none at once): up to 1 s a session."""
    items = _small_plan_items()
    out = tmp_path / "lossy"
    with instance_slot() as n:
        gcs = _ground_station(n)
        sitl = Proc.bsst("sitl", "--await-mission", "--speed", "0", "--loss", "30", "--param-at", "1:COM_OF_LOSS_T=1",
                         "--instance", str(n), "--out", str(out), "--no-plots")
        try:
            target = vehicle_of(gcs)
            upload(gcs, target, items)
            gcs.mav.command_long_send(*target, M.MAV_CMD_MISSION_START, 0, 0, 0, 0, 0, 0, 0, 0)
            assert sitl.p.wait(timeout=120) == 0, "\n".join(sitl.lines[-30:])
        finally:
            gcs.close()
            sitl.stop()
    summary = json.loads((out / "summary.json").read_text())
    t = summary["mission_transfer"]
    assert summary["outcome"] == "completed" and t["result"] == "accepted" and t["re_requests"] >= 1, t
    assert t["started_by"] == {"command": START_COMMAND, "by": f"255:190 127.0.0.1:{GCS_PORT + n} gcs"}, t
    [change] = summary["param_at"]
    assert change["sent_t"] == change["t_s"] == 1.0 and change["confirmed"], change
    log = mavutil.mavlink_connection(str(out / "controller.tlog"), dialect="common")
    before_arm = []
    while (m := log.recv_match()) is not None and not (m.get_type() == "COMMAND_LONG"
                                                       and m.command == M.MAV_CMD_COMPONENT_ARM_DISARM):
        before_arm.append((m.get_srcSystem(), m.get_type()))
    assert m is not None and (target[0], "HEARTBEAT") not in before_arm, before_arm
    (tmp_path / "small.waypoints").write_text(SMALL_PLAN)
    offline = simulate(tmp_path / "small.waypoints", plots=False, link={"loss_pct": 30},
                       param_at=[parse_change("1:COM_OF_LOSS_T=1")])
    flown = _trace(out / "trace.csv")
    assert len(flown) == len(offline.trace["t"])
    worst = max(math.dist(row[1:], (offline.trace["x"][i], offline.trace["y"][i], offline.trace["z"][i]))
                for i, row in enumerate(flown))
    assert worst <= 1e-4, worst


def test_mavproxy_loads_and_starts_a_waypoint_file(tmp_path):
    """MAVProxy, unmodified, through stdin: ``wp load`` of a QGC WPL 110 file into ``bsst sitl --await-mission``
    (lockstep), then ``long MISSION_START``: ACCEPTED, flown to the end, landed and disarmed, every item reached;
    the run's mission.plan holds what MAVProxy sent: the file's lines, its line 0 (the home) as item 0, a
    waypoint on the ground at the home (MAVProxy sends it so to PX4 too). With no ``--speed`` a ground station's
    mission flies in lockstep at 1x real time, as PX4's and ArduPilot's SITL run (summary.json's ``sitl.speed``
    and ``timing.real_time_factor``; it flew some 20 times faster before): HOP_PLAN, 5.1 s (landed, disarmed 0.5 s
    later, not PX4's 2 s: each second at 1x is the test's CPU)."""
    (tmp_path / "small.txt").write_text(HOP_PLAN)
    out = tmp_path / "mp"
    with instance_slot() as n:
        sitl = Proc.bsst("sitl", "--await-mission", "--instance", str(n), "--out", str(out), "--no-plots",
                         "--param", "COM_DISARM_LAND=0.5")
        mp = MavProxy(f"udpin:127.0.0.1:{GCS_PORT + n}", tmp_path)
        try:
            mp.wait_online()
            mp.say("wp load small.txt")
            mp.wait_line(lambda s: "Got MISSION_ACK: TYPE_MISSION: ACCEPTED" in s, timeout=15)
            mp.say("long MISSION_START 0 0")
            mp.wait_line(lambda s: "Got COMMAND_ACK: MISSION_START: ACCEPTED" in s, timeout=15)
            assert sitl.p.wait(timeout=120) == 0, "\n".join(sitl.lines[-30:])
        finally:
            mp.stop()
            sitl.stop()
    summary = json.loads((out / "summary.json").read_text())
    assert summary["outcome"] == "completed" and summary["end"]["disarmed"]
    assert summary["sitl"]["speed"] == 1.0 and summary["clock"] == "lockstep", summary["sitl"]
    assert summary["timing"]["sim_s"] > 5.0 and summary["timing"]["real_time_factor"] <= 1.01, summary["timing"]
    assert summary["mission_transfer"]["items"] == 4  # MAVProxy sends the file's line 0 (the home) as item 0
    reached = [m.seq for m in tlog_messages(out / "vehicle.tlog", n + 1, ["MISSION_ITEM_REACHED"])]
    assert list(dict.fromkeys(reached)) == [0, 1, 2, 3]
    kept = read_plan_text((out / "mission.plan").read_text(), "kept")
    home = (16, 47.397742, 8.545594, 488.0)  # a waypoint at the home, on the ground (GLOBAL: m AMSL)
    assert [(i.command, round(i.lat, 7), round(i.lon, 7), i.alt) for i in kept.items] == \
        [home] + [(i.command, i.lat, i.lon, i.alt) for i in read_plan_text(HOP_PLAN, "small").items]


def _retype(mp: MavProxy, cmd: str, done: Callable[[str], bool], each_s: float, tries: int) -> str:
    """Type ``cmd`` until a line after it satisfies ``done`` (each try waits ``each_s`` s), as a user types a
    command again when MAVProxy shows no answer: that line."""
    for k in range(tries):
        mark = mp.say(cmd)
        try:
            line = mp.wait_line(done, timeout=each_s, start=mark)
        except AssertionError:  # what MAVProxy said instead (shown with pytest -s)
            print(f"MAVProxy: {cmd!r} try {k + 1} unanswered; it said: {mp.lines[mark:][-8:]}")
            continue
        print(f"MAVProxy: {cmd!r} answered after {k + 1} tries")
        return line
    raise AssertionError(f"MAVProxy: {cmd!r} typed {tries} times, never answered as awaited:\n"
                         + "\n".join(mp.lines[-30:]))


def test_mavproxy_through_a_lossy_slow_link(tmp_path):
    """MAVProxy, unmodified, through ``bsst relay --loss 20 --delay 100`` (both directions) to ``bsst sitl
    --await-mission``: ``wp load`` of a waypoint file, ``wp list`` (the list MAVProxy saves is what it loaded),
    ``long MISSION_START``: the flight completes, landed and disarmed, every item reached.

    MAVProxy sends MISSION_COUNT, MISSION_REQUEST_LIST and a command once, and ignores the vehicle's requests
    for its last item once it has sent it (so a lost last item ends the upload at the vehicle's 5 s timeout,
    "Operation timeout", the mission as it was): a user types the command again when MAVProxy shows no answer,
    and so does this test (``_retype``: at most 6 times; with the relay's default seed, in 8 runs at load 11-15
    wp load and wp list were answered at their first typing, MISSION_START 6 times at its first, twice at its
    third; a start typed again after an ACCEPTED that did not show is DENIED, so its answer is ACCEPTED, the
    vehicle's start event or MAVProxy's "Mode MISSION").
    A download is MAVProxy's to drive: it asks for five items at once and each missing one again after 2 s, so
    the vehicle answers a request for any item of the mission, in any order (PX4 ends a download at the first
    request out of order: over this link every MAVProxy download then failed), and no download holds up a start
    (MAVProxy sends no ACK after ``wp list``)."""
    (tmp_path / "small.txt").write_text(SMALL_PLAN)
    out = tmp_path / "lossy"
    with instance_slot() as n:
        relay = Proc.bsst("relay", "--listen", "127.0.0.1:0", "--to", f"127.0.0.1:{GCS_PORT + n}",
                          "--listen-direction", "down", "--loss", "20", "--delay", "100",
                          "--stats", str(tmp_path / "relay.json"))
        ready = parse_line(relay.wait_line(lambda s: isinstance(parse_line(s), Ready)))
        sitl = Proc.bsst("sitl", "--await-mission", "--speed", "0", "--instance", str(n), "--gcs", ready.listen,
                         "--out", str(out), "--no-plots")
        mp = MavProxy(f"udpin:127.0.0.1:{GCS_PORT + n}", tmp_path)
        try:
            mp.wait_online()
            _retype(mp, "wp load small.txt", lambda s: "MISSION_ACK: TYPE_MISSION: ACCEPTED" in s
                    or "mission: uploaded 4 items" in s, 9.0, 6)
            saved = _retype(mp, "wp list", lambda s: "Saved 4 waypoints to " in s, 8.0, 6)
            _retype(mp, "long MISSION_START 0 0", lambda s: "MISSION_START: ACCEPTED" in s or "Mode MISSION" in s
                    or "mission: start requested" in s, 3.0, 6)
            assert sitl.p.wait(timeout=120) == 0, "\n".join(sitl.lines[-30:])
        finally:
            mp.stop()
            sitl.stop()
            assert relay.stop() == 0
    rows = [ln.split("\t") for ln in (tmp_path / saved.split(" to ")[1].strip()).read_text().splitlines()[1:]]
    want = [ln.split("\t") for ln in SMALL_PLAN.splitlines()[1:]]
    assert len(rows) == len(want) == 4
    for got, sent in zip(rows[1:], want[1:], strict=True):  # (line 0: the home, MAVProxy's own)
        assert [int(c) for c in got[:4]] == [int(c) for c in sent[:4]]
        assert [float(c) for c in got[4:]] == pytest.approx([float(c) for c in sent[4:]], abs=1e-6, nan_ok=True)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["outcome"] == "completed" and summary["end"]["disarmed"]
    assert summary["mission_transfer"]["items"] == 4
    reached = [m.seq for m in tlog_messages(out / "vehicle.tlog", n + 1, ["MISSION_ITEM_REACHED"])]
    assert list(dict.fromkeys(reached)) == [0, 1, 2, 3]
    relay_stats = json.loads((tmp_path / "relay.json").read_text())
    assert relay_stats["up"]["lost"] > 0 and relay_stats["down"]["lost"] > 0, relay_stats


@pytest.mark.parametrize("args, says", [
    (["--await-mission", "examples/box.plan"], "give no mission file"),
    (["--await-mission", "--gcs", "none"], "needs a GCS link"),
    (["--await-mission", "--param-at", "600:COM_OF_LOSS_T=1"], "with --await-mission the time is mission time"),
    ([], "give a mission file (or --await-mission)")])
def test_await_mission_bad_input_is_one_line_and_exit_2(args, says):
    r = run_bsst("sitl", *args, cwd=ROOT, env=ENV, timeout=60)
    assert r.returncode == 2 and says in r.stderr and r.stderr.strip().count("\n") == 0, r.stderr


# -- in this process -------------------------------------------------------------------------------------

def test_the_vehicle_starts_a_mission_only_when_asked_to_await_one():
    """MISSION_START: UNSUPPORTED on a vehicle without --await-mission (as before), DENIED without a mission
    and ACCEPTED with one on a vehicle with it; AUTO.MISSION DENIED without it, selected with it (HEARTBEAT
    AUTO.MISSION), and a ground station's arm then starts the mission (the vehicle stays disarmed: its arm is
    the controller's); a mission cleared under a watch is no more watched (no MISSION_ITEM_REACHED for its items;
    armed and flying it, a clear is refused: tests/test_mission_in_flight.py)."""
    gcs = GcsSocket()
    flight = prepare(Mission(Sine(), duration_s=5.0, name="start"))
    made = []

    def vehicle(await_mission: bool) -> Vehicle:
        v = Vehicle(flight, VehicleConfig(parse_address("udpin:127.0.0.1:0"), parse_address(gcs.url),
                                          await_mission=await_mission))
        made.append(v)
        return v

    exchange = gcs.exchange
    start = M.MAVLink_command_long_message(1, 1, M.MAV_CMD_MISSION_START, 0, 0, 0, 0, 0, 0, 0, 0)
    mode = M.MAVLink_command_long_message(1, 1, M.MAV_CMD_DO_SET_MODE, 0, 1, 4, 4, 0, 0, 0, 0)
    arm = M.MAVLink_command_long_message(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
    items = _small_plan_items(target=(1, 1))
    try:
        plain = vehicle(False)
        assert exchange(plain, start, "COMMAND_ACK").result == M.MAV_RESULT_UNSUPPORTED
        assert exchange(plain, mode, "COMMAND_ACK").result == M.MAV_RESULT_DENIED  # never flown here
        v = vehicle(True)
        assert exchange(v, start, "COMMAND_ACK").result == M.MAV_RESULT_DENIED  # no mission
        exchange(v, M.MAVLink_mission_count_message(1, 1, 3, 0), "MISSION_REQUEST_INT")
        for it in items[:2]:
            exchange(v, it, "MISSION_REQUEST_INT")
        assert exchange(v, items[2], "MISSION_ACK").type == M.MAV_MISSION_ACCEPTED
        legacy = M.MAVLink_set_mode_message(1, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, (4 << 16) | (4 << 24))
        assert exchange(v, legacy, "COMMAND_ACK").result == M.MAV_RESULT_ACCEPTED  # SET_MODE: selects it too
        assert exchange(v, mode, "COMMAND_ACK").result == M.MAV_RESULT_ACCEPTED
        assert v.streaming.heartbeat().custom_mode == (4 << 16) | (4 << 24) and v.missions.selected
        ask = M.MAVLink_command_long_message(1, 1, M.MAV_CMD_REQUEST_MESSAGE, 0, M.MAVLINK_MSG_ID_MISSION_CURRENT,
                                             0, 0, 0, 0, 0, 0)
        assert exchange(v, ask, "MISSION_CURRENT").mission_state == M.MISSION_STATE_NOT_STARTED  # selected alone
        # a download under way (the controller's begins as AUTO.MISSION shows) holds up no start
        assert exchange(v, M.MAVLink_mission_request_list_message(1, 1, 0), "MISSION_COUNT").count == 3
        exchange(v, M.MAVLink_mission_request_int_message(1, 1, 0, 0), "MISSION_ITEM_INT")
        assert v.missions.transfers["gcs"].state.value == "sendlist"
        assert exchange(v, arm, "COMMAND_ACK").result == M.MAV_RESULT_ACCEPTED
        assert v.missions.start_requested and not v.sim.armed
        assert exchange(v, ask, "MISSION_CURRENT").mission_state == M.MISSION_STATE_ACTIVE  # the controller's cue
        for seq in (1, 2):  # the download ends: every item out, and the ground station's final ACK
            exchange(v, M.MAVLink_mission_request_int_message(1, 1, seq, 0), "MISSION_ITEM_INT")
        gcs.sock.sendto(M.MAVLink_mission_ack_message(1, 1, M.MAV_MISSION_ACCEPTED, 0).pack(gcs.mav), v.gcs.local)
        assert any(e.kind == "mission" and "start requested by AUTO.MISSION, then arm" in e.text for e in v.sim.events)
        assert v.missions.started == {"command": START_ARM, "by": str(v.sim.events[-1].by)}
        v.missions.flight_armed()  # (as the controller's arm does): item 0 current, the mission ACTIVE
        assert v.missions.watch is not None and v.missions.mission_state == M.MISSION_STATE_ACTIVE
        clear = exchange(v, M.MAVLink_mission_count_message(1, 1, 0, 0), "MISSION_ACK")  # a ground station clears it
        assert clear.type == M.MAV_MISSION_ACCEPTED
        assert v.missions.watch is None and "cleared" in v.sim.events[-1].text  # no reached for a gone item
        v.missions.flight_step(0.0, (0.0,) * 12, True)
        assert v.missions.watch is None
    finally:
        for v in made:
            v.close()
        gcs.close()


def _vehicle_holding_the_small_plan(gcs: GcsSocket, flight: Any, clock: str = "lockstep") -> Vehicle:
    """A vehicle in this process awaiting a mission (``clock``), the small plan uploaded by ``gcs``."""
    v = Vehicle(flight, VehicleConfig(parse_address("udpin:127.0.0.1:0"), parse_address(gcs.url),
                                      await_mission=True, clock=clock))
    gcs.exchange(v, M.MAVLink_mission_count_message(1, 1, 3, 0), "MISSION_REQUEST_INT")
    items = _small_plan_items(target=(1, 1))
    for it in items[:2]:
        gcs.exchange(v, it, "MISSION_REQUEST_INT")
    assert gcs.exchange(v, items[2], "MISSION_ACK").type == M.MAV_MISSION_ACCEPTED
    return v


def test_another_mode_selected_after_auto_mission_wins_until_the_mission_starts():
    """As on PX4 the latest selection wins: AUTO.MISSION then HOLD, disarmed, shows HOLD and a ground station's arm
    arms in HOLD (no start). AUTO.MISSION then an arm starts the mission; a mode asked for then, while the
    controller is to arm the vehicle, is DENIED saying why (the start stands)."""
    gcs = GcsSocket()
    flight = prepare(Mission(Sine(), duration_s=5.0, name="start"))
    made = []
    exchange = gcs.exchange

    def mode(main: int, sub: int) -> Any:
        return M.MAVLink_command_long_message(1, 1, M.MAV_CMD_DO_SET_MODE, 0, 1, main, sub, 0, 0, 0, 0)

    arm = M.MAVLink_command_long_message(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
    try:
        for then_hold in (True, False):
            v = _vehicle_holding_the_small_plan(gcs, flight)
            made.append(v)
            assert exchange(v, mode(4, 4), "COMMAND_ACK").result == M.MAV_RESULT_ACCEPTED
            assert v.streaming.heartbeat().custom_mode == (4 << 16) | (4 << 24)
            if then_hold:
                assert exchange(v, mode(4, 3), "COMMAND_ACK").result == M.MAV_RESULT_ACCEPTED
                assert v.streaming.heartbeat().custom_mode == (4 << 16) | (3 << 24) and not v.missions.selected
                assert exchange(v, arm, "COMMAND_ACK").result == M.MAV_RESULT_ACCEPTED
                assert v.sim.armed and v.sim.mode == "hold" and not v.missions.start_requested
            else:
                assert exchange(v, arm, "COMMAND_ACK").result == M.MAV_RESULT_ACCEPTED
                assert v.missions.start_requested and not v.sim.armed
                assert exchange(v, mode(4, 3), "COMMAND_ACK").result == M.MAV_RESULT_TEMPORARILY_REJECTED
                assert v.missions.start_requested and v.streaming.heartbeat().custom_mode == (4 << 16) | (4 << 24)
    finally:
        for v in made:
            v.close()
        gcs.close()


def test_an_arm_with_auto_mission_selected_outside_the_fence_starts_nothing_until_gf_action_is_0():
    """PX4 arms at once on a ground station's arm with AUTO.MISSION selected, so its pre-arm geofence check comes
    first: the vehicle stands 1 m from a fence square 2-4 m out, so the arm is TEMPORARILY_REJECTED, the mission not
    started, nothing armed, and a ``preflight`` event says why; with GF_ACTION set to 0 (PARAM_SET) the same arm
    starts the mission."""
    gcs = GcsSocket()
    square = Zone(True, points=((2.0, 2.0), (4.0, 2.0), (4.0, 4.0), (2.0, 4.0)))
    flight = prepare(Mission(Sine(), duration_s=5.0, name="fenced", geofence=Geofence((square,))))
    exchange = gcs.exchange
    arm = M.MAVLink_command_long_message(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
    v = _vehicle_holding_the_small_plan(gcs, flight)
    try:
        select = M.MAVLink_command_long_message(1, 1, M.MAV_CMD_DO_SET_MODE, 0, 1, 4, 4, 0, 0, 0, 0)
        assert exchange(v, select, "COMMAND_ACK").result == M.MAV_RESULT_ACCEPTED
        assert exchange(v, arm, "COMMAND_ACK").result == M.MAV_RESULT_TEMPORARILY_REJECTED
        assert not v.missions.start_requested and not v.sim.armed
        assert v.sim.events[-1].kind == "preflight" and "outside its fence" in v.sim.events[-1].text
        off = M.MAVLink_param_set_message(1, 1, b"GF_ACTION", 0.0, M.MAV_PARAM_TYPE_INT32)
        assert exchange(v, off, "PARAM_VALUE").param_id == "GF_ACTION" and v.sim.fence_action == 0
        assert exchange(v, arm, "COMMAND_ACK").result == M.MAV_RESULT_ACCEPTED
        assert v.missions.start_requested and v.sim.arming_refused is None
    finally:
        v.close()
        gcs.close()


def _fence_square(half: float, target: tuple[int, int] = (1, 1)) -> list[Any]:
    """An inclusion square ``half`` m each way about the vehicle's default home, as a ground station uploads it."""
    home = Home()
    corners = ((-half, -half), (-half, half), (half, half), (half, -half))
    return [M.MAVLink_mission_item_int_message(*target, k, M.MAV_FRAME_GLOBAL_INT,
                                               M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, 0, 1, 4.0, 0, 0, 0,
                                               *(round(d * 1e7) for d in home.global_of(x, -y, 0.0)[:2]), 0.0,
                                               M.MAV_MISSION_TYPE_FENCE)
            for k, (x, y) in enumerate(corners)]


def _rally_points(*points: tuple[float, float]) -> list[Any]:
    """Rally points at ``points`` (m north, m east of the vehicle's default home), as a ground station uploads them."""
    home = Home()
    return [M.MAVLink_mission_item_int_message(1, 1, k, M.MAV_FRAME_GLOBAL_INT, M.MAV_CMD_NAV_RALLY_POINT, 0, 1,
                                               0, 0, 0, 0, *(round(d * 1e7) for d in home.global_of(x, -y, 0.0)[:2]),
                                               0.0, M.MAV_MISSION_TYPE_RALLY)
            for k, (x, y) in enumerate(points)]


def _controller_downloads(ctl: GcsSocket, v: Vehicle, mission_type: int, n: int) -> None:
    """The controller's download (on its own link) of the ``n`` items of ``mission_type`` the vehicle holds."""
    ctl.exchange(v, M.MAVLink_mission_request_list_message(1, 1, mission_type), "MISSION_COUNT")
    for k in range(n):
        ctl.exchange(v, M.MAVLink_mission_request_int_message(1, 1, k, mission_type), "MISSION_ITEM_INT")
    ack = M.MAVLink_mission_ack_message(1, 1, M.MAV_MISSION_ACCEPTED, mission_type)
    ctl.sock.sendto(ack.pack(ctl.mav), v.link.local)  # the download's final ACK: nothing comes back

    def idle() -> bool:
        for m, addr in v.link.poll():
            v._handle(v.link, m, addr)
        return v.missions.transfers["controller"].state.value == "idle"

    wait_for(idle, 5.0, "the controller link's transfer idle", poll_s=0.001)


def _started_downloaded_armed(gcs: GcsSocket, ctl: GcsSocket, flight: Any, before: list[Any],
                              after: list[Any]) -> Vehicle:
    """A vehicle holding the small plan, ``before`` uploaded (a fence's or rally points' items), the mission
    started, the fence and rally points downloaded by the controller, ``after`` uploaded, and the controller's arm."""
    v = _vehicle_holding_the_small_plan(gcs, flight)
    try:
        for items in before:
            _upload_in_process(gcs, v, items)
        start = M.MAVLink_command_long_message(1, 1, M.MAV_CMD_MISSION_START, 0, 0, 0, 0, 0, 0, 0, 0)
        assert gcs.exchange(v, start, "COMMAND_ACK").result == M.MAV_RESULT_ACCEPTED
        for mtype in (M.MAV_MISSION_TYPE_FENCE, M.MAV_MISSION_TYPE_RALLY):
            _controller_downloads(ctl, v, mtype, sum(len(i) for i in before if i[0].mission_type == mtype))
        assert v.sim.fence_recorded
        for items in after:  # after the controller's download, before its arm
            _upload_in_process(gcs, v, items)
        controller = Sender(200, 191, "127.0.0.1", ctl.sock.getsockname()[1], "controller")
        assert v.commander.arm_disarm(1.0, 0.0, controller) == M.MAV_RESULT_ACCEPTED
    except BaseException:
        v.close()
        raise
    return v


def test_a_fence_uploaded_between_the_controllers_download_and_its_arm_is_said_at_the_arm():
    """The controller's download of the fence (on its own link) is what mission.toml holds; a ground station's fence
    uploaded after it, before the controller's arm, is flown all the same (the vehicle watches it), so the vehicle
    says so at that arm: a ``fence`` event after the ``armed`` one, which the geofence policy reads as a change at the
    flight's start (tests/test_fence_upload.py). Until the third wave's thirty-seventh session nothing said it: the
    run read as flown against the downloaded fence (or none). With GF_ACTION 0 that fence is still judged for the
    record (``fence_recorded`` false); one uploaded before the controller's download is the record's: nothing said."""
    gcs = GcsSocket()
    flight = prepare(Mission(Sine(), duration_s=5.0, name="fenced-late"), params={"GF_ACTION": 0})
    ctl = GcsSocket(200, 191, link="link")  # the controller, on the vehicle's own link
    made: list[Vehicle] = []
    try:
        v = _started_downloaded_armed(gcs, ctl, flight, [], [_fence_square(1.0)])
        made.append(v)
        assert not v.sim.fence_recorded and v.sim.fence is not None
        armed, said = v.sim.events[-2:]
        assert (armed.kind, said.kind) == ("armed", "fence"), v.sim.events[-3:]
        assert said.text == ("flown with a fence of 4 items uploaded or cleared after the controller's download, not "
                             "the one mission.toml holds") and said.by is not None and said.by.is_vehicle, said
        v.sim.plant.state = (3.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)  # 3 m north: outside it
        v.sim.advance()
        left = [e for e in v.sim.events if e.kind == "geofence"]
        assert len(left) == 1 and "GF_ACTION = 0: not acted on" in left[0].text and v.sim.mode == "offboard", left
        early = _started_downloaded_armed(gcs, ctl, flight, [_fence_square(1.0)], [])  # downloaded: the one flown
        made.append(early)
        assert early.sim.fence_recorded and early.sim.events[-1].kind == "armed", early.sim.events[-2:]
        early.sim.plant.state = (3.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        early.sim.advance()  # (GF_ACTION 0: the record's own fence is its trace check's, not the vehicle's)
        assert not [e for e in early.sim.events if e.kind == "geofence"]
    finally:
        for v in made:
            v.close()
        gcs.close()
        ctl.close()


def test_rally_points_uploaded_between_the_controllers_download_and_its_arm_are_said_at_the_arm():
    """As a fence (above): rally points a ground station uploads after the controller's download of them (none),
    before its arm, are the ones Return flies to, but mission.toml holds the download's, so the vehicle says so at
    that arm: a ``rally`` event after the ``armed`` one, its own word (the fence, the record's, unsaid). Until the
    third wave's thirty-seventh session nothing said it: a Return to a rally point read as flown to one the record
    did not hold. Rally points uploaded before the controller's download are the record's: nothing said."""
    gcs = GcsSocket()
    flight = prepare(Mission(Sine(), duration_s=5.0, name="rallied-late"))
    ctl = GcsSocket(200, 191, link="link")  # the controller, on the vehicle's own link
    made: list[Vehicle] = []
    try:
        v = _started_downloaded_armed(gcs, ctl, flight, [], [_rally_points((4.0, 0.0), (0.0, 6.0))])
        made.append(v)
        assert len(v.sim.rally) == 2 and v.sim.fence_recorded, v.sim.rally
        armed, said = v.sim.events[-2:]
        assert (armed.kind, said.kind) == ("armed", "rally"), v.sim.events[-3:]
        assert said.text == ("flown with rally points of 2 items uploaded or cleared after the controller's download, "
                             "not the ones mission.toml holds") and said.by is not None and said.by.is_vehicle, said
        early = _started_downloaded_armed(gcs, ctl, flight, [_rally_points((4.0, 0.0))], [])
        made.append(early)
        assert len(early.sim.rally) == 1 and early.sim.events[-1].kind == "armed", early.sim.events[-2:]
    finally:
        for v in made:
            v.close()
        gcs.close()
        ctl.close()


# a takeoff, three holds of 1000 s and a landing: 3000 s, within a mission's day, over bsst sitl's trace (2000 s)
LONG_PLAN = """QGC WPL 110
0\t1\t0\t16\t0\t0\t0\t0\t47.397742\t8.545594\t488.0\t1
1\t0\t3\t22\t0\t0\t0\tnan\t47.397742\t8.545594\t1.5\t1
""" + "".join(f"{k}\t0\t3\t19\t1000\t0\t0\tnan\t47.397742\t8.545594\t1.5\t1\n" for k in (2, 3, 4)) + \
    "5\t0\t3\t21\t0\t0\t0\tnan\t47.397742\t8.545594\t0\t1\n"


def _jump_items() -> list[Any]:
    """SMALL_PLAN's items with a DO_JUMP for item 2 (held, as PX4 holds it; not flown here)."""
    items = _small_plan_items(target=(1, 1))
    items[2] = M.MAVLink_mission_item_int_message(1, 1, 2, M.MAV_FRAME_MISSION, M.MAV_CMD_DO_JUMP, 0, 1, 1, 2, 0, 0,
                                                  0, 0, 0, 0)
    return items


def _upload_in_process(gcs: GcsSocket, v: Vehicle, plan: str | list[Any]) -> None:
    """A ground station's upload of a plan's items, or of ``plan``'s (a mission's, a fence's or rally points': their
    own mission type), accepted."""
    items = _small_plan_items(target=(1, 1), plan=plan) if isinstance(plan, str) else plan
    gcs.exchange(v, M.MAVLink_mission_count_message(1, 1, len(items), items[0].mission_type), "MISSION_REQUEST_INT")
    for it in items[:-1]:
        gcs.exchange(v, it, "MISSION_REQUEST_INT")
    assert gcs.exchange(v, items[-1], "MISSION_ACK").type == M.MAV_MISSION_ACCEPTED


def _refusal(gcs: GcsSocket, v: Vehicle, msg: Any) -> tuple[int, str]:
    """``msg``'s COMMAND_ACK result and the STATUSTEXT that came with it (its 50-character chunks joined)."""
    seen = gcs.exchange_until(v, msg, lambda m: m.get_type() == "STATUSTEXT" and len(m.text) < 50,
                              "a STATUSTEXT saying why")
    ack = next(m for m in seen if m.get_type() == "COMMAND_ACK")
    return ack.result, "".join(m.text for m in seen if m.get_type() == "STATUSTEXT")


def test_a_mission_that_cannot_be_flown_is_refused_by_name_at_auto_mission_mission_start_and_the_arm():
    """As PX4's commander refuses MISSION_START and Mission mode without a valid mission (its navigator's check,
    ``mission_result.valid``): a held mission the controller would refuse (a DO_JUMP) is refused at AUTO.MISSION
    (TEMPORARILY_REJECTED, the mode not shown), at MISSION_START (DENIED), each STATUSTEXT naming what was asked and
    the item; AUTO.MISSION selected with a good mission and then a bad one uploaded, the ground station's arm is
    refused naming the arm. Until the third wave's thirty-sixth session AUTO.MISSION was ACCEPTED and the arm's
    refusal said MISSION_START. A mission over bsst sitl's trace (``trace_cap``) is refused likewise, at once (its
    least length, before it is timed); a vehicle without the cap (bsst vehicle alone) starts it."""
    gcs = GcsSocket()
    flight = prepare(Mission(Sine(), duration_s=5.0, name="start"))
    mode = M.MAVLink_command_long_message(1, 1, M.MAV_CMD_DO_SET_MODE, 0, 1, 4, 4, 0, 0, 0, 0)
    start = M.MAVLink_command_long_message(1, 1, M.MAV_CMD_MISSION_START, 0, 0, 0, 0, 0, 0, 0, 0)
    arm = M.MAVLink_command_long_message(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
    made = []

    def vehicle(cap: bool) -> Vehicle:
        made.append(Vehicle(flight, VehicleConfig(parse_address("udpin:127.0.0.1:0"), parse_address(gcs.url),
                                                  await_mission=True, trace_cap=trace_cap() if cap else None)))
        return made[-1]

    try:
        v = vehicle(True)
        _upload_in_process(gcs, v, _jump_items())
        result, text = _refusal(gcs, v, mode)
        assert result == M.MAV_RESULT_TEMPORARILY_REJECTED, text
        assert text.startswith("mode MISSION: the mission cannot be flown: the vehicle's mission: item 2 (DO_JUMP")
        assert not v.missions.selected and v.streaming.heartbeat().custom_mode != (4 << 16) | (4 << 24)
        result, text = _refusal(gcs, v, start)
        assert result == M.MAV_RESULT_DENIED and text.startswith("MISSION_START: the mission cannot be flown: "), text
        _upload_in_process(gcs, v, SMALL_PLAN)
        assert gcs.exchange(v, mode, "COMMAND_ACK").result == M.MAV_RESULT_ACCEPTED and v.missions.selected
        _upload_in_process(gcs, v, _jump_items())  # (selected, disarmed: a new mission is taken, as on PX4)
        result, text = _refusal(gcs, v, arm)
        assert text.startswith("arm (mode MISSION): the mission cannot be flown: the vehicle's mission: item 2"), text
        assert result == M.MAV_RESULT_DENIED and not v.missions.start_requested and not v.sim.armed
        _upload_in_process(gcs, v, LONG_PLAN)
        result, text = _refusal(gcs, v, start)
        assert result == M.MAV_RESULT_DENIED and "duration_s: at least 300" in text, text
        assert "over the 500000 a run keeps in memory for its summary" in text, text
        plain = vehicle(False)
        _upload_in_process(gcs, plain, LONG_PLAN)
        assert gcs.exchange(plain, start, "COMMAND_ACK").result == M.MAV_RESULT_ACCEPTED
    finally:
        for v in made:
            v.close()
        gcs.close()


@pytest.mark.parametrize("clock", ["lockstep", "realtime"])
def test_an_arm_in_hold_on_the_ground_then_auto_mission_starts_the_mission_and_times_out_alone(clock):
    """MAVSDK's own order, as PX4 flies it: the vehicle awaiting a mission waits in HOLD (PX4 without sticks), a
    ground station's arm arms it there on the ground (lockstep: time stands still, the clock idle), and AUTO.MISSION
    then starts the mission (started_by ``arm, then AUTO.MISSION``; AUTO.MISSION shows, armed; MISSION_CURRENT
    ACTIVE; another mode then DENIED); the controller's arm takes the vehicle from HOLD to OFFBOARD and the lockstep
    flight begins, item 0 current (real time: the wall clock runs throughout). Neither the arm nor its HOLD is an
    intervention or ends the flight, nor does a disarm by command before the start. Armed and never started, it
    disarms itself after COM_DISARM_PRFLT (set to 0.2 s by PARAM_SET), the lockstep clock still idle."""
    gcs = GcsSocket()
    flight = prepare(Mission(Sine(), duration_s=5.0, name="start"))
    exchange, made = gcs.exchange, []
    command = _command

    def vehicle_with_mission() -> Vehicle:
        made.append(_vehicle_holding_the_small_plan(gcs, flight, clock))
        return made[-1]

    hold, mission = (4 << 16) | (3 << 24), (4 << 16) | (4 << 24)
    idle = ClockState.IDLE if clock == "lockstep" else ClockState.FREE_RUNNING  # (real time: the wall clock's)
    arm = command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    try:
        v = vehicle_with_mission()
        assert v.streaming.heartbeat().custom_mode == hold and not v.sim.armed  # waits in HOLD, disarmed
        assert exchange(v, arm, "COMMAND_ACK").result == M.MAV_RESULT_ACCEPTED
        assert v.sim.armed and v.sim.mode == "hold" and v.clock.state is idle
        assert v.streaming.heartbeat().custom_mode == hold and v.commander.pre_start.at is not None
        at = v.commander.pre_start.at
        assert exchange(v, arm, "COMMAND_ACK").result == M.MAV_RESULT_ACCEPTED  # again (a resend): nothing changes
        assert v.clock.state is idle and v.commander.pre_start.at == at
        assert exchange(v, command(M.MAV_CMD_DO_SET_MODE, 1, 4, 4), "COMMAND_ACK").result == M.MAV_RESULT_ACCEPTED
        assert v.missions.started is not None and v.missions.started["command"] == START_ARMED
        beat = v.streaming.heartbeat()
        assert beat.custom_mode == mission and beat.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED
        ask = command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_MISSION_CURRENT)
        assert exchange(v, ask, "MISSION_CURRENT").mission_state == M.MISSION_STATE_ACTIVE
        assert exchange(v, command(M.MAV_CMD_NAV_LAND), "COMMAND_ACK").result == M.MAV_RESULT_TEMPORARILY_REJECTED
        assert exchange(v, arm, "COMMAND_ACK").result == M.MAV_RESULT_ACCEPTED  # an arm now starts no timeout
        assert v.commander.pre_start.at is None and v.clock.state is idle
        controller = Sender(200, 191, "127.0.0.1", 1, "controller")
        assert v.commander.arm_disarm(1.0, 0.0, controller) == M.MAV_RESULT_ACCEPTED  # the controller's arm
        assert v.sim.mode == "offboard" and v.clock.engaged is (clock == "lockstep") and v.missions.watch is not None
        assert v.missions.mission.current == 0 and v.streaming.heartbeat().custom_mode == mission
        events = [RunEvent.at(e.t, e.kind, e.text, "vehicle", e.by, **typed_fields(e)) for e in v.sim.events]
        assert [e.kind for e in events if e.pre_start] == ["armed", "mode"]  # the arm in HOLD, its HOLD
        assert interventions(events, 250.0) == [] and ended_by_command(events) is None
        # armed and never started: the vehicle disarms itself after COM_DISARM_PRFLT
        w = vehicle_with_mission()
        set_param = M.MAVLink_param_set_message(1, 1, b"COM_DISARM_PRFLT", 0.2, M.MAV_PARAM_TYPE_REAL32)
        assert exchange(w, set_param, "PARAM_VALUE").param_value == pytest.approx(0.2)
        assert exchange(w, arm, "COMMAND_ACK").result == M.MAV_RESULT_ACCEPTED and w.sim.armed
        disarm = command(M.MAV_CMD_COMPONENT_ARM_DISARM, 0)
        assert exchange(w, disarm, "COMMAND_ACK").result == M.MAV_RESULT_ACCEPTED and not w.sim.armed
        events = [RunEvent.at(e.t, e.kind, e.text, "vehicle", e.by, **typed_fields(e)) for e in w.sim.events]
        assert events[-1].kind == "disarmed" and events[-1].pre_start  # nothing flew: no intervention, no end
        assert [i["kind"] for i in interventions(events, 250.0)] == ["param"] and ended_by_command(events) is None
        assert exchange(w, arm, "COMMAND_ACK").result == M.MAV_RESULT_ACCEPTED and w.sim.armed
        wait_for(lambda: w._housekeeping() or not w.sim.armed, 5.0, "the vehicle's pre-takeoff disarm")
        last = w.sim.events[-1]
        assert last.kind == "disarmed" and last.pre_start and "COM_DISARM_PRFLT = 0.2 s" in last.text
        assert w.clock.state is idle and w.commander.pre_start.at is None
    finally:
        for v in made:
            v.close()
        gcs.close()


def _command(cmd: int, *params: float) -> Any:
    """A ground station's COMMAND_LONG to the vehicle (system 1, component 1), the params it does not give 0."""
    return M.MAVLink_command_long_message(1, 1, cmd, 0, *params, *[0.0] * (7 - len(params)))


def _held_vehicle() -> tuple[GcsSocket, Vehicle]:
    """A ground station's socket and an in-process vehicle (a 5 s sine, lockstep) sending to it."""
    gcs = GcsSocket()
    return gcs, Vehicle(prepare(Mission(Sine(), duration_s=5.0, name="held")),
                        VehicleConfig(parse_address("udpin:127.0.0.1:0"), parse_address(gcs.url)))


def test_a_ground_stations_arm_in_hold_on_the_ground_times_out_with_no_mission_awaited_too():
    """PX4's pre-takeoff timeout (Commander's auto-disarm while it has not taken off since arming) without
    --await-mission: a ground station's arm in HOLD on the ground disarms itself after COM_DISARM_PRFLT (0.2 s by
    PARAM_SET), an event saying so (not the start's: none is awaited); a TAKEOFF asked for in time stops it."""
    gcs, v = _held_vehicle()
    exchange, command = gcs.exchange, _command

    hold, arm = command(M.MAV_CMD_DO_SET_MODE, 1, 4, 3), command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    try:
        set_param = M.MAVLink_param_set_message(1, 1, b"COM_DISARM_PRFLT", 0.2, M.MAV_PARAM_TYPE_REAL32)
        assert exchange(v, set_param, "PARAM_VALUE").param_value == pytest.approx(0.2)
        assert exchange(v, hold, "COMMAND_ACK").result == M.MAV_RESULT_ACCEPTED
        assert exchange(v, arm, "COMMAND_ACK").result == M.MAV_RESULT_ACCEPTED and v.sim.mode == "hold"
        at = v.commander.pre_start.at
        assert at is not None and v.sim.armed
        assert exchange(v, arm, "COMMAND_ACK").result == M.MAV_RESULT_ACCEPTED and v.commander.pre_start.at == at
        wait_for(lambda: v._housekeeping() or not v.sim.armed, 5.0, "the vehicle's pre-takeoff disarm")
        last = v.sim.events[-1]
        assert last.kind == "disarmed" and last.text == "disarmed: no takeoff within COM_DISARM_PRFLT = 0.2 s of arming"
        assert not last.pre_start and v.commander.pre_start.at is None
        assert exchange(v, arm, "COMMAND_ACK").result == M.MAV_RESULT_ACCEPTED and v.commander.pre_start.at is not None
        takeoff = command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, math.nan)
        assert exchange(v, takeoff, "COMMAND_ACK").result == M.MAV_RESULT_ACCEPTED and v.sim.mode == "takeoff"
        v.commander.pre_start.tick(v.commander.pre_start.at + 1.0)  # past the timeout, but taking off
        assert v.sim.armed and v.commander.pre_start.at is None
    finally:
        v.close()
        gcs.close()


def test_a_takeoff_turned_to_hold_before_it_lifts_times_out_as_an_arm_in_hold():
    """PX4's auto-disarm runs whatever the mode: armed in TAKEOFF on the ground and turned to HOLD before it lifts
    (never off the ground since the arm), the landed HOLD disarms itself after COM_DISARM_PRFLT (0.2 s), as an arm
    in HOLD does. On the old code the timeout started only at an arm in HOLD: it stayed armed."""
    gcs, v = _held_vehicle()
    exchange, command = gcs.exchange, _command

    takeoff, hold = command(M.MAV_CMD_DO_SET_MODE, 1, 4, 2), command(M.MAV_CMD_DO_SET_MODE, 1, 4, 3)
    arm = command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    try:
        set_param = M.MAVLink_param_set_message(1, 1, b"COM_DISARM_PRFLT", 0.2, M.MAV_PARAM_TYPE_REAL32)
        assert exchange(v, set_param, "PARAM_VALUE").param_value == pytest.approx(0.2)
        assert exchange(v, takeoff, "COMMAND_ACK").result == M.MAV_RESULT_ACCEPTED
        assert exchange(v, arm, "COMMAND_ACK").result == M.MAV_RESULT_ACCEPTED and v.sim.mode == "takeoff"
        assert exchange(v, hold, "COMMAND_ACK").result == M.MAV_RESULT_ACCEPTED and v.sim.mode == "hold"
        assert v.sim.plant.on_ground and v.sim.armed
        wait_for(lambda: v._housekeeping() or not v.sim.armed, 5.0, "the vehicle's pre-takeoff disarm")
        last = v.sim.events[-1]
        assert last.kind == "disarmed" and last.text == "disarmed: no takeoff within COM_DISARM_PRFLT = 0.2 s of arming"
    finally:
        v.close()
        gcs.close()


def test_the_watch_reaches_the_box_items_in_order_along_its_flight():
    """goals_of (the route's points, about the home) and ItemWatch along the offline flight of the box: every
    item reached once, in order, the landing last (on the ground)."""
    plan = read_plan_text(BOX_PLAN.read_text(), "box")
    items = tuple(MissionItem(k, it.frame, it.command, it.p1, it.p2, it.p3, it.p4,
                              round(it.lat * 1e7) if it.frame != 2 else 0, round(it.lon * 1e7) if it.frame != 2 else 0,
                              it.alt, 1) for k, it in enumerate(plan.items))
    watch = ItemWatch(goals_of(items, plan.home))
    run = simulate(BOX_PLAN, plots=False)
    tr = run.trace
    got = []
    for i in range(len(tr["t"])):
        X = (tr["x"][i], 0.0, tr["y"][i], 0.0, tr["z"][i])
        got += [(seq, tr["t"][i]) for seq in watch.step(tr["t"][i], X)]
    assert [s for s, _ in got] == list(range(8)) and watch.done
    assert tr["z"][[round(t * 250) for _, t in got][-1]] <= 0.1  # the landing: within 0.1 m of the ground


def test_a_waypoint_before_a_land_here_is_reached_at_its_point_not_at_the_takeoff():
    """A takeoff here to 2 m, a waypoint 5 m north, a land here (latitude and longitude 0): the land's first
    point is the waypoint's, and the two share it. The waypoint's goal is its point (it had none, the land having
    taken the point's name: a ground station heard it reached with the takeoff, 5 m short of it), the land's
    the ground below it; the watch reaches each there, in order."""
    lat, lon = 473977420, 85455940  # the default home (degE7)
    north = lat + 450  # 450e-7 deg of latitude: 5.0 m
    rel = M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
    items = (MissionItem(0, rel, M.MAV_CMD_NAV_TAKEOFF, 0.0, 0.0, 0.0, math.nan, 0, 0, 2.0, 1),
             MissionItem(1, rel, M.MAV_CMD_NAV_WAYPOINT, 0.0, 0.0, 0.0, math.nan, north, lon, 2.0, 1),
             MissionItem(2, rel, M.MAV_CMD_NAV_LAND, 0.0, 0.0, 0.0, math.nan, 0, 0, 0.0, 1))
    goals = goals_of(items, (lat * 1e-7, lon * 1e-7, 488.0))
    assert [g.seq for g in goals] == [0, 1, 2] and all(g.point is not None for g in goals), goals
    (x0, y0, z0), (x1, y1, z1), (x2, y2, z2) = (g.point for g in goals)  # type: ignore[misc]
    assert (x0, y0, z0) == (0.0, 0.0, 2.0) and abs(x1 - 5.0) < 0.01 and abs(y1) < 1e-6 and z1 == 2.0, goals
    assert (x2, y2, z2) == (x1, y1, 0.0), goals
    watch = ItemWatch(goals)
    assert watch.step(1.0, (0.0, 0.0, 0.0, 0.0, 2.0)) == [0]  # up at the start: the takeoff only
    assert watch.step(2.0, (2.5, 0.0, 0.0, 0.0, 2.0)) == [] and watch.step(3.0, (5.0, 0.0, 0.0, 0.0, 2.0)) == [1]
    assert watch.step(4.0, (5.0, 0.0, 0.0, 0.0, 1.0)) == [] and watch.step(5.0, (5.0, 0.0, 0.0, 0.0, 0.0)) == [2]


# a ground station's mission of 10.919 s: up 2 m, 5 m north (450 degE7 of latitude), land (about the default home)
SHORT_ITEMS = (
    MissionItem(0, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, M.MAV_CMD_NAV_TAKEOFF, 0.0, 0.0, 0.0, math.nan, 0, 0, 2.0, 1),
    MissionItem(1, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, M.MAV_CMD_NAV_WAYPOINT, 0.0, 0.0, 0.0, math.nan,
                473977420 + 450, 85455940, 2.0, 1),
    MissionItem(2, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, M.MAV_CMD_NAV_LAND, 0.0, 0.0, 0.0, math.nan, 0, 0, 0.0, 1))
SHORT_HOME = (473977420 * 1e-7, 85455940 * 1e-7, 488.0)


def test_an_at_event_after_an_uploaded_missions_end_is_refused_naming_the_flag(tmp_path):
    """``bsst sitl --await-mission --at 20:gust:2,3`` and a ground station's mission of 10.9 s: the session writes
    the run's mission.toml (:class:`~bridge.record.runlog.RunRecord`), its children read it (no ``--at`` of their
    own), and their start check and download (:func:`bridge.nodes.uploaded.uploaded_flight`) refuse the event naming
    the flag (docs/weather.md), kept in its table as typed (``at``); it named the file's table
    (``.../mission.toml: events[0].t_s: ...``), which the user never wrote. A table whose ``at`` is not its event
    is refused naming the key; an event inside the mission flies, named as its flag again."""
    items, home = SHORT_ITEMS, SHORT_HOME

    def child(at: str) -> Flight:  # the run directory as the session writes it, read as its children read it
        run = tmp_path / at.replace(":", "_")
        run.mkdir()
        RunRecord(run, prepare(at_rest(), at=(at,)).mission).close()
        return prepare(run / "mission.toml")

    flight = child("20:gust:2,3")
    assert flight.mission.events == ({"t_s": 20.0, "kind": "gust", "duration_s": 2.0, "amplitude_mps": 3.0,
                                      "from_deg": 0.0, "at": "20:gust:2,3"},)
    with pytest.raises(ConfigError) as refused:
        uploaded_flight(flight, items, home, source="the vehicle's mission")
    assert str(refused.value) == "--at 20:gust:2,3: t_s: must be in [0, 10.919) s (before the mission's end), got 20"
    _, new = uploaded_flight(child("1:gust:2,3"), items, home)
    assert [(e.t_s, e.at) for e in new.timeline] == [(1.0, "1:gust:2,3")]
    assert new.mission.duration_s == pytest.approx(10.919)
    edited = replace(flight.mission, events=({**flight.mission.events[0], "amplitude_mps": 4.0},))
    with pytest.raises(ConfigError, match=r"mission\.toml: events\[0\]\.at: the table is not the event --at "
                                          r"20:gust:2,3 lays \(t_s = 20\.0, .*amplitude_mps = 3\.0"):
        prepare(edited)


def test_an_at_table_from_python_after_an_uploaded_missions_end_is_refused_naming_its_place(tmp_path):
    """``sitl(..., await_mission=True, at=({...},))`` and a ground station's mission of 10.9 s: a table laid from
    Python keeps its place in ``at`` in the run's mission.toml (its ``at`` key, as a flag's keeps the flag), so the
    children's start check and download refuse its event after the mission's end naming its place, ``at[0]``, as
    the caller's own process does, beside the file's table it is in (``mission.toml: events[1] (at[0], laid from
    Python)``: the file may have been edited by hand). Until the third wave's fortieth session the children named
    ``.../mission.toml: events[1]`` (after the mission's own event), and the caller's process ``command line:
    events[1]``: neither what the user wrote. The caller's own refusal of the table names its place alone."""
    own = {"t_s": 1.0, "kind": "gust", "duration_s": 2.0, "amplitude_mps": 3.0}
    table = {**own, "t_s": 20.0}
    laid = prepare(replace(at_rest(), events=(own,)), at=(table,))
    RunRecord(tmp_path, laid.mission).close()  # the run directory as the session writes it, read as its children do
    child = prepare(tmp_path / "mission.toml")
    for flight, source in ((laid, "command line"), (child, str(tmp_path / "mission.toml"))):
        with pytest.raises(ConfigError) as refused:
            uploaded_flight(flight, SHORT_ITEMS, SHORT_HOME, source="the vehicle's mission")
        assert str(refused.value) == (f"{source}: events[1] (at[0], laid from Python): t_s: must be in [0, 10.919) s "
                                      "(before the mission's end), got 20")
    with pytest.raises(ConfigError) as refused:
        prepare(replace(at_rest(), duration_s=10.0), at=(own, table))
    assert str(refused.value) == "at[1]: t_s: must be in [0, 10) s (before the mission's end), got 20"
    assert [e.get("at") for e in child.mission.events] == [None, "at[0]"]
    _, new = uploaded_flight(prepare(replace(at_rest(), events=(own,)), at=({**own, "t_s": 2.0},)), SHORT_ITEMS,
                             SHORT_HOME)
    assert [(e.t_s, e.at) for e in new.timeline] == [(1.0, None), (2.0, "at[0]")]


def test_a_hand_edited_at_place_is_refused_naming_the_file(tmp_path, capsys):
    """A file's ``[[events]]`` table whose ``at`` is a place in a Python caller's ``at=`` (``at = "at[7]"``, as a
    run's mission.toml keeps one) is not checked against anything, as a flag's is: a hand edit of it flies or is
    refused as the file's own, named where it is, the file and the table, beside the place it claims
    (docs/weather.md). Until the third wave's fortieth session's fix it was refused naming ``at[7]`` alone, no file
    (``bsst: at[7]: speed_mps: ...``). A place not as overrides writes one (``at[07]``, another script's digits) is
    no place: refused naming ``events[0].at``."""
    def mission(at: str, event: str) -> Path:
        path = tmp_path / f"m{len(list(tmp_path.iterdir()))}.toml"
        path.write_text(f'name = "hand"\nduration_s = 5.0\nevents = [{{ t_s = 1.0, {event}, at = "{at}" }}]\n'
                        '[trajectory]\nkind = "sine"\n', encoding="utf-8")
        return path

    path = mission("at[7]", 'kind = "wind", speed_mps = 500.0')
    assert main(["sim", str(path), "--no-plots", "--out", str(tmp_path / "run")]) == 2
    assert capsys.readouterr().err == (f"bsst: {path}: events[0] (at[7], laid from Python): speed_mps: must be in "
                                       "[0, 50] m/s, got 500\n")
    assert not (tmp_path / "run").exists()
    path = mission("at[7]", 'kind = "gps", state = "off"')  # refused by the flight, not the table: named the same
    with pytest.raises(ConfigError) as refused:
        prepare(path)
    assert str(refused.value).startswith(f"{path}: events (t_s = 1, kind = gps; at[7], laid from Python): the "
                                         "truth estimator")
    for at in ("at[07]", "at[\u0667]", "at[-1]"):
        path = mission(at, 'kind = "wind", speed_mps = 5.0')
        with pytest.raises(ConfigError) as refused:
            prepare(path)
        assert str(refused.value).startswith(f"{path}: events[0].at: not an --at flag's T:KIND[:ARGS] nor a place "
                                             "in at= (at[0])")
    assert prepare(mission("at[7]", 'kind = "wind", speed_mps = 5.0')).timeline[0].at == "at[7]"


def test_plan_text_reads_back_and_the_transfer_block_is_typed():
    """The mission's download at the record's top level, as before; the fence's and the rally points' each a record
    of the same keys under ``fence`` and ``rally`` (None: not begun; until the third wave's thirty-seventh session
    the record held the mission's alone)."""
    plan = read_plan_text(BOX_PLAN.read_text(), "box")
    again = read_plan_text(plan_text(plan), "again")
    assert again.items == plan.items  # (QGroundControl's null is math.nan, the same object both times)
    assert again.home == plan.home and again.cruise_m_s == plan.cruise_m_s
    said = {"items": 8, "requests": 11, "re_requests": 3, "duration_s": 0.5, "result": "accepted"}
    assert mission_transfer(said).as_dict() == {"items": 8, "attempts": 11, "re_requests": 3, "duration_s": 0.5,
                                                "result": "accepted", "started_by": None, "fence": None,
                                                "rally": None}
    by = {"command": START_ARM, "by": "255:190 127.0.0.1:14550 gcs"}
    assert mission_transfer(said, by).as_dict()["started_by"] == by
    assert mission_transfer(None) is None and mission_transfer({"items": 1}) is None
    fence = {"items": 4, "requests": 6, "re_requests": 1, "duration_s": 0.25, "result": "accepted"}
    rally = {"items": 0, "requests": 1, "re_requests": 0, "duration_s": 0.01, "result": "timeout"}
    both = mission_transfer({**said, "fence": fence, "rally": rally}).as_dict()
    assert both["items"] == 8 and both["fence"] == {"items": 4, "attempts": 6, "re_requests": 1, "duration_s": 0.25,
                                                    "result": "accepted"}
    assert both["rally"]["result"] == "timeout" and both["rally"]["attempts"] == 1
    assert mission_transfer({**said, "fence": {"items": 4}}).as_dict()["fence"] is None  # (not all said)


def test_a_session_stopped_while_it_awaits_a_mission_reads_the_waiting_states_as_delivered(tmp_path):
    """Stopped before a ground station starts a mission: the vehicle, in lockstep, has sent its state again every
    RESEND_S while the controller waited, and the controller read them all; summary.json's link.down says so
    (none lost), where it once counted every one lost (the controller's figures were not reported)."""
    out = tmp_path / "run"
    with instance_slot() as n:
        gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        gcs.bind(("127.0.0.1", GCS_PORT + n))  # where the vehicle's GCS link sends: its heartbeats, 1 a second
        gcs.settimeout(0.5)
        p = Proc.bsst("sitl", "--await-mission", "--instance", str(n), "--no-plots", "--out", str(out), cwd=ROOT)
        try:
            mav = mavlink.MAVLink(None)
            beats: list[Any] = []

            def two_heartbeats() -> bool:  # two seconds of waiting: some twenty states sent again
                with contextlib.suppress(TimeoutError):
                    beats.extend(m for m in mav.parse_buffer(gcs.recv(65535)) or [] if m.get_type() == "HEARTBEAT")
                return len(beats) >= 3

            wait_for(two_heartbeats, 30.0, "three vehicle heartbeats")
            p.p.send_signal(signal.SIGINT)
            assert p.p.wait(timeout=60) == 1
        finally:
            p.stop()
            gcs.close()
    down = json.loads((out / "summary.json").read_text())["link"]["down"]
    assert down["sent"] >= 10 and down["lost"] == 0 and down["delivered"] + down["in_flight"] == down["sent"], down


# -- a ground station's own flight before the mission it then starts ------------------------------------------------
# MAVSDK flies the vehicle itself first (arm, takeoff, land: the vehicle disarms itself once down, as the vehicle
# asks before a MISSION_START in the air: "land and disarm, then start it"), then uploads a mission (takeoff to
# 3 m, waypoint 1 m north, land: 11.5 s of flight; 6 m north and back took 35 s, which no test reads), arms and
# starts it, and lets it fly to its end (argv[2] "fly") or pauses it once it climbs ("pause":
# MissionRaw.pause_mission, HOLD, a takeover). The hop flies on the wall clock, so the vehicle's clock is ahead of
# the mission's by then.
MAVSDK_HOP_THEN_MISSION = MAVSDK_GROUND_STATION + r"""
import math
from mavsdk.plugins.action import Action
from mavsdk.plugins.mission_raw import MissionItem, MissionRaw
from mavsdk.plugins.telemetry import Telemetry

system = sdk.first_autopilot(30.0)
action, mr, telemetry = Action(system), MissionRaw(system), Telemetry(system)
fence = len(sys.argv) > 3 and sys.argv[3] == "fence"  # the hop breaches GF_MAX_VER_DIST: its failsafe lands it
if fence:
    from mavsdk.plugins.param import Param
    par = Param(system)
    out["limit"] = [par.set_param_int("GF_ACTION", 5).name, par.set_param_float("GF_MAX_VER_DIST", 1.5).name]
out["arm"], out["takeoff"] = action.arm().name, action.takeoff().name
# up, and its takeoff done (HOLD): landed in TAKEOFF it would arm in TAKEOFF again, and the start be DENIED
out["up"] = until(lambda: telemetry.position().relative_altitude_m > (1.0 if fence else 2.0) and (
    fence or telemetry.flight_mode().name == "HOLD"), 30)
out["land"] = "SUCCESS" if fence else action.land().name  # (the failsafe's landing)
out["down"] = until(lambda: not telemetry.armed(), 60)
if fence:  # no limit for the mission; HOLD for its arm (disarmed by its failsafe, it would arm in TAKEOFF again)
    out["limit"] += [par.set_param_float("GF_MAX_VER_DIST", 0.0).name, action.hold().name]
lat, lon = 47.397742, 8.545594  # the vehicle's home (PX4 SITL's)

def item(seq, command, north_m, z):
    return MissionItem(seq, 6, command, int(seq == 0), 1, 0.0, 0.0, 0.0, math.nan,
                       int(round((lat + north_m / 111320.0) * 1e7)), int(round(lon * 1e7)), z, 0)

out["upload"] = mr.upload_mission([item(0, 22, 0.0, 3.0), item(1, 16, 1.0, 3.0), item(2, 21, 1.0, 0.0)]).name
out["arm_again"], out["start"] = action.arm().name, mr.start_mission().name
if sys.argv[2] == "pause":
    out["climbing"] = until(lambda: telemetry.position().relative_altitude_m > 1.5, 60)
    out["pause"] = mr.pause_mission().name
else:
    out["finished"] = until(mr.is_mission_finished, 240)
print("RESULT " + json.dumps(out), flush=True)
sdk.destroy()
"""


def _hop_then_mission(out: Path, then: str, *sitl_args: str, hop: str = "land") -> tuple[int, dict[str, Any]]:
    """``bsst sitl --await-mission`` (``sitl_args``: its clock) into ``out`` and :data:`MAVSDK_HOP_THEN_MISSION`
    against it (``then``: "fly" or "pause"; ``hop``: "land" or "fence", landed by its failsafe): the session's exit
    status and summary.json."""
    with instance_slot() as n:
        sitl = Proc.bsst("sitl", "--await-mission", "--instance", str(n), "--out", str(out), "--no-plots", *sitl_args)
        try:
            r = run_script("-c", MAVSDK_HOP_THEN_MISSION, f"udpin://127.0.0.1:{GCS_PORT + n}", then, hop, timeout=300,
                           env=ENV)
            gs = script_result(r)
            assert gs["up"] and gs["down"] and {gs["arm"], gs["land"], gs["upload"], gs["start"]} == {"SUCCESS"}, gs
            assert gs.get("finished") or gs.get("pause") == "SUCCESS", gs
            assert set(gs.get("limit", ["SUCCESS"])) == {"SUCCESS"}, gs
            status = sitl.p.wait(timeout=120)
        finally:
            sitl.stop()
    return status, json.loads((out / "summary.json").read_text())


# the lockstep sessions' hop on the wall clock landed at 1.5 m/s and disarmed 0.5 s after (PX4's 0.7 m/s, 2 s)
HOP_FAST = ("--param", "MPC_LAND_SPEED=1.5", "--param", "COM_DISARM_LAND=0.5")


@pytest.fixture(scope="module")
def hop_then_mission(tmp_path_factory):
    """The lockstep session of :data:`MAVSDK_HOP_THEN_MISSION` flying its mission to the end: (exit status,
    summary.json, run directory). The hop, on the wall clock, lands at 1.5 m/s (PX4's 0.7) and disarms 0.5 s later
    (PX4's 2 s): each of its seconds is the test's CPU."""
    out = tmp_path_factory.mktemp("hop") / "run"
    status, summary = _hop_then_mission(out, "fly", "--speed", "0", *HOP_FAST)
    return status, summary, out


def test_the_controllers_arm_after_a_ground_stations_hop_flies_every_mission_step_on_the_step_clock(hop_then_mission):
    """After the ground station's hop the lockstep vehicle runs on the wall clock, armed in HOLD on the ground; the
    controller's arm engages lockstep at a control period's start, its state sent then, so the controller's first
    state is the one the vehicle flies with its answer: every mission row on the step clock, no answer refused as
    stale. (Taken mid-period, the arm sent the state of a step the vehicle then flew on without its answer: the
    mission's first row was never the controller's, its answer refused as stale, the next state waited a resend.)"""
    _, summary, out = hop_then_mission
    k0 = int(read_half(out / "controller.bin")["k"][0])
    rows = read_half(out / "vehicle.bin")
    flown = rows["k"] >= k0
    assert k0 > 0 and flown.any()  # the vehicle's clock ran before the mission: the hop
    assert (rows["cmd_k"][flown] == rows["k"][flown]).all(), rows["cmd_k"][flown][:3]
    assert "stale" not in summary["link"]["rejected"], summary["link"]["rejected"]


def _before_the_start(summary: dict[str, Any]) -> list[dict[str, Any]]:
    """The ground station's hop, as summary.json's interventions keep it: before the mission's start, on the
    mission's clock (negative t, step round(t x rate)); the TAKEOFF and the LAND among them."""
    early = [i for i in summary["interventions"] if i.get("before_start")]
    assert all(i["t"] < 0 and i["step"] == round(i["t"] * 250) for i in early), early
    assert {"TAKEOFF", "LAND"} <= {i["what"].split()[0] for i in early if i["kind"] == "mode"}, early
    return early


def test_a_ground_stations_flight_before_an_awaited_mission_is_recorded_before_its_start(hop_then_mission):
    """The ground station's hop before the mission is recorded as what it was, interventions before the mission's
    start (exit 1: a ground station flew the vehicle), and the mission as flown: completed, ended by the mission,
    held in lockstep (reproducible from no step: its start followed a flight on the wall clock). Every event is on
    the mission's clock (the trace's): the vehicle's end action at the mission's end, the hop and the download
    before 0, in time order; events.log wrote what came before on the vehicle's clock and says where the mission's
    time 0 fell on it. (It said ``aborted``, ended by the pre-start TAKEOFF "at t=0.000 s", left lockstep at 0, and
    put the end action 13 s after the trace's end, on the vehicle's clock.)"""
    status, summary, out = hop_then_mission
    assert status == 1
    assert summary["outcome"] == "completed" and summary["ended_by"] == {"who": "mission", "how": "completed"}, \
        summary["ended_by"]
    early = _before_the_start(summary)
    assert early == summary["interventions"], summary["interventions"]  # none in the mission
    lock = summary["lockstep"]
    assert lock["held"] and not lock["reproducible"] and lock["reproducible_until_step"] == 0, lock
    assert "before the mission's start" in lock["because"], lock
    events = summary["events"]
    times = [e["t"] for e in events if e["t"] is not None]
    assert times == sorted(times)
    end = next(e for e in events if e["kind"] == "end" and e["source"] == "vehicle")
    assert abs(end["t"] - summary["duration_s"]) <= 0.01, (end, summary["duration_s"])
    download = next(e for e in events if e["kind"] == "mission" and e["source"] == "controller")
    assert download["t"] < 0, download
    logged = (out / "events.log").read_text()
    assert "clock: the mission's time 0 (the trace's first row) is the vehicle's t=" in logged, logged
    assert f"t={end['t']:.3f} end: mission over" in logged
    # and in summary.json's order, the hop's lines (on the vehicle's clock) first: sorted on the mission's clock once
    # the session closed it (until the third wave's fortieth session in the order said: the notes after the landing)
    said = [f"{e['kind']}: {e['text']}" + (f" [{e['source']}]" if "source" in e else "") for e in events]
    assert [line.partition(" ")[2] for line in logged.splitlines()] == said, logged


def test_a_pause_after_a_ground_stations_hop_ends_the_flight_at_its_trace_row_in_real_time(tmp_path):
    """In real time, the same hop, then MAVSDK pauses the mission it started (HOLD): the pause ended the flight
    (``aborted``, ended by it), at its time on the mission's clock, where its step is the trace's row; the hop is
    before the start, at the vehicle's time of it (it was all at t=0, and ended the flight by its TAKEOFF). (The hop
    lands at 1.5 m/s, not PX4's 0.7: it still lasts over 5 s, with PX4's 2 s before its disarm.)"""
    out = tmp_path / "run"
    status, summary = _hop_then_mission(out, "pause", "--realtime", *HOP_FAST[:2])
    assert status == 1 and summary["outcome"] == "aborted", summary["outcome"]
    early = _before_the_start(summary)
    assert early[0]["t"] < -5.0, early  # the hop took seconds of the vehicle's wall clock
    pause, = (i for i in summary["interventions"] if not i.get("before_start"))
    assert pause["kind"] == "mode" and pause["what"].startswith("HOLD") and pause["t"] > 0, pause
    assert summary["ended_by"]["how"] == f"mode changed at t={pause['t']:.3f} s: {pause['what']}", summary["ended_by"]
    t = [row[0] for row in _trace(out / "trace.csv")]
    assert any(abs(ti - pause["step"] / 250) < 1e-6 for ti in t), (pause, t[0], t[-1])  # its row in the trace


def test_a_failsafe_of_a_ground_stations_flight_before_an_awaited_mission_is_recorded_not_the_missions_outcome(
        tmp_path):
    """The hop breaches GF_MAX_VER_DIST (1.5 m, GF_ACTION 5): the vehicle's failsafe lands and disarms it; the ground
    station lifts the limit, then starts the mission and pauses it. The vehicle flies the mission after its failsafe;
    that failsafe and breach are the hop's, before the mission's start (negative t, said in events.log's closing
    notes), not the mission's: it is ``aborted`` by the pause, its geofence kept (exit 1: a ground station flew the
    vehicle, and paused it). (Until the third wave's thirty-seventh session it read ``failsafe``, and the hop's
    breach broke the mission's geofence policy.)"""
    out = tmp_path / "run"
    status, summary = _hop_then_mission(out, "pause", "--speed", "0", *HOP_FAST, hop="fence")
    assert status == 1 and summary["outcome"] == "aborted", (summary["outcome"], summary["ended_by"])
    assert summary["ended_by"]["how"].startswith("mode changed at t="), summary["ended_by"]
    fs = [e for e in summary["events"] if e["kind"] in ("failsafe", "geofence") and e.get("source") == "vehicle"]
    assert fs and all(e["t"] < 0 for e in fs), fs
    assert next(p for p in summary["policies"] if p["name"] == "geofence")["ok"], summary["policies"]
    notes = [e for e in summary["events"] if e["kind"] == "before_start"]
    assert {e["text"].split(": ")[1].split()[0] for e in notes} == {"failsafe", "geofence"}, notes
    assert "before_start: before the mission's start, not its outcome: failsafe at t=-" in (
        out / "events.log").read_text()


# the hop lands at 3 m/s: over the 2 m/s a touchdown may take, it crashes (docs/sitl.md), and waits for the disarm
MAVSDK_HOP_CRASH = MAVSDK_GROUND_STATION + r"""
from mavsdk.plugins.action import Action
from mavsdk.plugins.telemetry import Telemetry

system = sdk.first_autopilot(30.0)
action, telemetry = Action(system), Telemetry(system)
out["arm"], out["takeoff"] = action.arm().name, action.takeoff().name
out["up"] = until(lambda: telemetry.position().relative_altitude_m > 2.0 and telemetry.flight_mode().name == "HOLD",
                  30)
out["land"] = action.land().name
out["down"] = until(lambda: not telemetry.armed(), 30)
print("RESULT " + json.dumps(out), flush=True)
sdk.destroy()
"""


def test_a_crash_of_a_ground_stations_flight_before_an_awaited_mission_ends_the_session_crashed(tmp_path):
    """The ground station's hop lands at 3 m/s (MPC_LAND_SPEED) and crashes: the vehicle's plant is halted for good
    and refuses every later arm and start, so the controller stops waiting for a mission and the session ends by
    itself, its outcome the crash (ended by the plant), exit 1, every record kept: the crash in events.log, the
    hop's rows in vehicle.bin, its tlog. (Until the third wave's thirty-ninth session the session waited on, with no
    time limit, for a start the vehicle refused; a Ctrl-C then ended it ``aborted``, by the user.) With no trace row
    the events stay on the vehicle's clock, in time order, the session's closing notes last, at the latest of them, in
    summary.json and events.log alike (until the third wave's thirty-ninth session the notes were at t=0, before the
    hop they summed up)."""
    out = tmp_path / "run"
    with instance_slot() as n:
        sitl = Proc.bsst("sitl", "--await-mission", "--instance", str(n), "--out", str(out), "--no-plots",
                         "--speed", "0", "--param", "MPC_LAND_SPEED=3")
        try:
            r = run_script("-c", MAVSDK_HOP_CRASH, f"udpin://127.0.0.1:{GCS_PORT + n}", timeout=120, env=ENV)
            gs = script_result(r)
            assert gs["up"] and gs["down"] and {gs["arm"], gs["takeoff"], gs["land"]} == {"SUCCESS"}, gs
            status = sitl.p.wait(timeout=60)  # by itself: nothing stops it
        finally:
            sitl.stop()
    assert status == 1
    summary = json.loads((out / "summary.json").read_text())
    crash = next(e for e in summary["events"] if e["kind"] == "crashed" and e["source"] == "vehicle")
    assert summary["outcome"] == "crashed", (summary["outcome"], summary["ended_by"])
    assert summary["ended_by"] == {"who": "plant", "how": f"crashed at t={crash['t']:.3f} s: {crash['text']}"}, \
        summary["ended_by"]
    gave_up = next(e for e in summary["events"] if e["kind"] == "aborted" and e["source"] == "controller")
    assert gave_up["text"].startswith("no mission can fly: its plant ended the flight") and gave_up["t"] >= crash["t"]
    assert {"TAKEOFF", "LAND"} <= {i["what"].split()[0] for i in summary["interventions"] if i["kind"] == "mode"}
    logged = (out / "events.log").read_text()
    assert f"t={crash['t']:.3f} crashed: hit the ground at " in logged
    events = summary["events"]  # the closing notes last ("ended" the first), at the latest event's time
    notes = events[next(i for i, e in enumerate(events) if e["kind"] == "ended"):]
    assert {e["source"] for e in notes} == {"session"} and {e["t"] for e in notes} == {events[-1]["t"]}, events
    assert events[-1]["t"] >= gave_up["t"] >= crash["t"] > 0.0  # on the vehicle's clock: no mission's time 0
    said = [line.split(" ", 1) for line in logged.splitlines()]
    times = [float(t.removeprefix("t=")) for t, _ in said]
    assert times == sorted(times) and said[-len(notes)][1].startswith("ended: crashed"), logged
    rows = read_half(out / "vehicle.bin")
    assert len(rows["k"]) > 250 and (out / "vehicle.tlog").stat().st_size > 0  # the hop's seconds, kept

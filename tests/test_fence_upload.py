"""Covers bridge.mavlink.fenceitems, bridge.nodes.vehicle.zones and bridge.autopilot.fencewatch: a fence and rally
points as a ground station uploads them (MAV_MISSION_TYPE_FENCE, _RALLY), checked, held, read as a plan's, the rally
points given to Return, the fence watched in flight (bridge.autopilot.simvehicle); PX4's GF_MAX_HOR_DIST and
GF_MAX_VER_DIST watched by the vehicle in every clock, and its GF_ACTION at a breach (none, warning, hold, return,
terminate, land); and the geofence policy's use of the vehicle's ``geofence`` event. Pure: the protocol over
UDP is tests/test_mission_protocol.py's, MAVSDK's upload and a flight leaving the fence
tests/test_await_mission.py's."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as M

from bridge import simulate
from bridge.autopilot.fencewatch import limits_passed, reposition_refusal
from bridge.autopilot.simvehicle import FAILSAFE
from bridge.core.flight import prepare
from bridge.mavlink.fenceitems import FENCE, RALLY, fence_plan, parse_zone_item, rally_plan
from bridge.mavlink.missionitems import ItemRefused
from bridge.nodes.vehicle.missiontransfer import Mission
from bridge.nodes.vehicle.zones import HeldZones
from bridge.record.events import RunEvent, split_at_start
from bridge.record.policies import Rules, geofence_kept
from missions import MISSION_DIR
from missions.geodetic import Home
from missions.geofence import Geofence, Zone

HOME = Home()  # the vehicle's default home (PX4 SITL's)
POLY_IN, POLY_OUT = M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION
CIRCLE_IN, CIRCLE_OUT = M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, M.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION


def _at(x: float, y: float) -> tuple[int, int]:
    """degE7 of the point x m north, y m west of the home (the paper frame)."""
    lat, lon, _ = HOME.global_of(x, -y, 0.0)
    return round(lat * 1e7), round(lon * 1e7)


def _item(seq: int, command: int, p1: float, x: float, y: float, frame: int = M.MAV_FRAME_GLOBAL_INT,
          mission_type: int = FENCE) -> M.MAVLink_mission_item_int_message:
    lat, lon = _at(x, y)
    return M.MAVLink_mission_item_int_message(1, 1, seq, frame, command, 0, 1, p1, 0.0, 0.0, 0.0, lat, lon, 0.0,
                                              mission_type)


def _square(half: float, command: int = POLY_IN, first: int = 0) -> list[M.MAVLink_mission_item_int_message]:
    corners = ((-half, -half), (-half, half), (half, half), (half, -half))
    return [_item(first + i, command, 4.0, x, y) for i, (x, y) in enumerate(corners)]


def _held(items: list[M.MAVLink_mission_item_int_message], mission_type: int = FENCE) -> Mission:
    return Mission(tuple(parse_zone_item(m, True, mission_type) for m in items))


@pytest.mark.parametrize("item, mission_type, result", [
    (_item(0, POLY_IN, 2.0, 0.0, 0.0), FENCE, M.MAV_MISSION_ERROR),  # PX4's "Fence: too few vertices"
    (_item(0, CIRCLE_IN, 0.0, 0.0, 0.0), FENCE, M.MAV_MISSION_INVALID_PARAM1),
    (_item(0, CIRCLE_OUT, math.nan, 0.0, 0.0), FENCE, M.MAV_MISSION_INVALID_PARAM1),
    (_item(0, M.MAV_CMD_NAV_WAYPOINT, 0.0, 0.0, 0.0), FENCE, M.MAV_MISSION_UNSUPPORTED),
    (_item(0, M.MAV_CMD_NAV_RALLY_POINT, 0.0, 0.0, 0.0), FENCE, M.MAV_MISSION_UNSUPPORTED),
    (_item(0, CIRCLE_IN, 5.0, 0.0, 0.0, mission_type=RALLY), RALLY, M.MAV_MISSION_UNSUPPORTED),
    (_item(0, M.MAV_CMD_NAV_RALLY_POINT, 0.0, 0.0, 0.0, frame=M.MAV_FRAME_LOCAL_NED), RALLY,
     M.MAV_MISSION_UNSUPPORTED_FRAME),
], ids=["two-vertices", "zero-radius", "nan-radius", "waypoint-in-fence", "rally-in-fence", "circle-in-rally",
        "local-frame"])
def test_a_bad_zone_item_gets_its_result(item, mission_type, result) -> None:
    with pytest.raises(ItemRefused) as exc:
        parse_zone_item(item, True, mission_type)
    assert exc.value.result == result


def test_a_fence_reads_as_a_plans_polygons_and_circles() -> None:
    """Four vertices of an inclusion square and an exclusion circle: one polygon and one circle, the corners
    and the centre where they were sent (degE7); a legacy MISSION_ITEM (deg) reads the same."""
    items = [*_square(10.0), _item(4, CIRCLE_OUT, 2.5, 3.0, -3.0)]
    plan = fence_plan(_held(items).items)
    assert [p["inclusion"] for p in plan["polygons"]] == [True] and len(plan["polygons"][0]["polygon"]) == 4
    assert plan["polygons"][0]["polygon"][0] == [items[0].x / 1e7, items[0].y / 1e7]
    assert plan["circles"] == [{"inclusion": False, "circle": {"center": [items[4].x / 1e7, items[4].y / 1e7],
                                                               "radius": 2.5}}]
    legacy = M.MAVLink_mission_item_message(1, 1, 0, M.MAV_FRAME_GLOBAL, CIRCLE_OUT, 0, 1, 2.5, 0, 0, 0,
                                            items[4].x / 1e7, items[4].y / 1e7, 0.0, FENCE)
    assert parse_zone_item(legacy, False, FENCE).x == items[4].x


def test_a_polygon_short_of_its_vertices_is_named() -> None:
    items = [*_square(10.0)[:3], _item(3, CIRCLE_IN, 50.0, 0.0, 0.0)]
    with pytest.raises(ValueError, match="fence item 0: a polygon of 4 vertices"):
        fence_plan(_held(items).items)


def _period_at(sim: Any, x: float, y: float) -> None:
    """One control period of ``sim`` from x, y (m, paper frame), 1 m up at rest."""
    sim.plant.state = (x, 0.0, y, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    sim.advance()


def test_held_zones_give_return_its_rally_points_and_watch_the_fence() -> None:
    """A real vehicle (the sine's): uploaded rally points are its Return's, in the paper frame; a fence is
    watched after each step, its first breach said once as a ``geofence`` event (a new fence afresh); a fence
    that cannot be read is refused with why, and the one held stays."""
    sim = prepare(MISSION_DIR / "sine.toml").make_vehicle()
    zones = HeldZones(sim, (HOME.lat, HOME.lon, HOME.alt))
    rally = [_item(0, M.MAV_CMD_NAV_RALLY_POINT, 0.0, 4.0, -6.0, mission_type=RALLY)]
    assert zones.accept(_held(rally, RALLY), RALLY) is None
    assert np.allclose(sim.rally, [(4.0, -6.0)], atol=0.02), sim.rally
    fence = _held([*_square(5.0), _item(4, CIRCLE_OUT, 1.0, 2.0, 2.0)])
    assert zones.accept(fence, FENCE) is None and zones.items[FENCE] is fence
    sim.arm()  # (the vehicle watches its fence while armed, each control period as it begins)
    for x, y in ((0.0, 0.0), (4.0, -4.0)):
        _period_at(sim, x, y)
    assert not [e for e in sim.events if e.kind == "geofence"]
    _period_at(sim, 2.0, 2.2)  # inside the excluded circle
    _period_at(sim, 6.0, 2.2)  # and out of the square
    left = [e for e in sim.events if e.kind == "geofence"]
    assert len(left) == 1 and "outside its fence" in left[0].text and "GF_ACTION = 2: hold" in left[0].text
    assert sim.mode == FAILSAFE  # GF_ACTION 2, PX4's default: it holds, out of offboard control
    short = _held(_square(5.0)[:3])
    assert "a polygon of 4 vertices" in (zones.accept(short, FENCE) or "")
    assert zones.items[FENCE] is fence
    assert zones.accept(_held(_square(50.0)), FENCE) is None  # a new fence: watched afresh
    _period_at(sim, 6.0, 2.2)
    assert len([e for e in sim.events if e.kind == "geofence"]) == 1  # (inside the new one)
    assert zones.accept(Mission(), RALLY) is None and sim.rally == ()  # a clear: Return goes home


def test_with_gf_action_0_only_a_fence_the_record_does_not_hold_is_watched_and_its_breach_said_not_acted_on() -> None:
    """GF_ACTION 0 (none) watches nothing, as PX4's: outside the mission's own fence (the record's: its trace check
    judges it) and beyond GF_MAX_HOR_DIST no event. An uploaded fence, which the record does not hold
    (``fence_recorded`` false), is still judged: its first breach a ``geofence`` event saying it is not acted on, the
    vehicle flying on in offboard control (until the third wave's thirty-seventh session nothing was said, and the
    run's record passed a breach of a fence uploaded in flight)."""
    sim = prepare(MISSION_DIR / "sine.toml", params={"GF_ACTION": 0, "GF_MAX_HOR_DIST": 3.0}).make_vehicle()
    sim.fence = Geofence((Zone(True, points=((-2.0, -2.0), (-2.0, 2.0), (2.0, 2.0), (2.0, -2.0))),))
    assert sim.fence_recorded  # (the mission's own)
    sim.arm()
    _period_at(sim, 6.0, 0.0)  # out of both, and beyond GF_MAX_HOR_DIST
    assert not [e for e in sim.events if e.kind == "geofence"]
    zones = HeldZones(sim, (HOME.lat, HOME.lon, HOME.alt))
    assert zones.accept(_held(_square(5.0)), FENCE) is None and not sim.fence_recorded
    _period_at(sim, 4.0, 0.0)
    assert not [e for e in sim.events if e.kind == "geofence"]  # (inside the new one)
    _period_at(sim, 6.0, 0.0)
    _period_at(sim, 7.0, 0.0)
    left = [e for e in sim.events if e.kind == "geofence"]
    assert len(left) == 1 and left[0].text.startswith("outside its fence: at x=6.000"), left
    assert left[0].text.endswith("(GF_ACTION = 0: not acted on; said for the run's record, which does not hold this "
                                 "fence)") and sim.mode == "offboard" and sim.armed, left


def test_the_held_zones_alone_say_whether_the_record_holds_the_fence_watched() -> None:
    """``fence_recorded`` follows what the record holds (:class:`HeldZones`, its one writer): the mission's own fence
    is; an upload is not; the controller's download of it makes it the record's; a later upload is not again, and a
    download of the rally points leaves it so."""
    sim = prepare(MISSION_DIR / "sine.toml").make_vehicle()
    zones = HeldZones(sim, (HOME.lat, HOME.lon, HOME.alt))
    assert sim.fence_recorded and zones.recorded == zones.items
    assert zones.accept(_held(_square(5.0)), FENCE) is None and not sim.fence_recorded
    zones.downloaded(FENCE, zones.items[FENCE])
    assert sim.fence_recorded and zones.recorded[FENCE] is zones.items[FENCE]
    assert zones.accept(_held(_square(50.0)), FENCE) is None and not sim.fence_recorded
    zones.downloaded(RALLY, zones.items[RALLY])
    assert not sim.fence_recorded


def test_the_geofence_policy_fails_on_the_vehicles_geofence_event() -> None:
    """No mission fence, but the vehicle said it left an uploaded one: the policy fails at that time, with its
    words; without the event it holds."""
    t = np.arange(0.0, 1.0, 0.004)
    trace = {"x": np.zeros_like(t), "y": np.zeros_like(t)}
    rules = Rules(rate_hz=250.0, timeout_s=0.5, clock="lockstep")
    assert geofence_kept(t, trace, rules).ok
    left = RunEvent.at(0.5, "geofence", "outside the uploaded fence: x")
    v = geofence_kept(t, trace, rules, [left])
    assert (v.ok, v.t, v.why) == (False, 0.5, "outside the uploaded fence: x")


def test_a_fence_changed_in_flight_ends_the_trace_check_against_the_starts_fence_and_the_verdict_says_so() -> None:
    """The mission's fence is the one at the start (a ground station's, as the controller downloaded it): a fence
    uploaded in flight replaces it in the vehicle, so the rows after its ``mission`` event are judged by the
    vehicle's watch (its ``geofence`` event), not against the start's fence, and the verdict that holds says so
    (until the third wave's thirty-sixth session the whole trace was judged against the start's fence). Before
    the change the start's fence still judges; an upload before the flight's arm changes nothing here."""
    t = np.arange(0.0, 1.0, 0.004)
    trace = {"x": np.where(t >= 0.6, 5.0, 0.0), "y": np.zeros_like(t)}  # out of the start's square at 0.6 s
    rules = Rules(rate_hz=250.0, timeout_s=0.5, clock="lockstep", geofence=Geofence((Zone(True, points=(
        (-1.0, 1.0), (1.0, 1.0), (1.0, -1.0), (-1.0, -1.0))),)))
    upload = "uploaded 4 items in 0.01 s, 0 requested again"
    gcs_arm = RunEvent.at(0.0, "armed", "armed, HOLD", "vehicle", pre_start=True)  # awaiting the start: not flying
    arm = RunEvent.at(0.0, "armed", "armed, offboard control", "vehicle")
    bigger = RunEvent.at(0.5, "fence", upload, "vehicle")
    assert geofence_kept(t, trace, rules).t == pytest.approx(0.6)
    v = geofence_kept(t, trace, rules, [arm, bigger])
    assert v.ok and v.as_dict()["note"].startswith("the fence changed in flight at t=0.500 s (uploaded 4"), v
    assert v.as_dict()["note"].endswith("by the vehicle's watch of the new one after")
    unacted = geofence_kept(t, trace, replace(rules, fence_acted=False), [arm, bigger])  # GF_ACTION = 0
    assert unacted.as_dict()["note"].endswith("by the vehicle's watch of the new one (GF_ACTION = 0: it acts on no "
                                              "breach, but says the first, for this record) after"), unacted
    at_arm = RunEvent.at(0.0, "fence", "flown with a fence of 4 items uploaded or cleared after the controller's "
                                       "download, not the one mission.toml holds", "vehicle")  # (after the arm: t = 0)
    v = geofence_kept(t, trace, rules, [arm, at_arm])  # (no row judged against the start's fence)
    assert v.ok and v.as_dict()["note"] == (f"{at_arm.text}: the trace is judged by the vehicle's watch of it, not "
                                            "against mission.toml's fence"), v
    early = [RunEvent.at(0.0, "fence", upload, "vehicle"), gcs_arm, RunEvent.at(0.0, "fence", upload, "vehicle"),
             arm]  # (before the flight's arm: the fence it started with)
    assert not geofence_kept(t, trace, rules, early).ok
    late = RunEvent.at(0.7, "fence", "cleared", "vehicle")
    assert geofence_kept(t, trace, rules, [arm, late]).t == pytest.approx(0.6)  # left the start's fence before it
    left = RunEvent.at(0.8, "geofence", "outside its fence: x")
    assert (geofence_kept(t, trace, rules, [arm, bigger, left]).t,
            geofence_kept(t, trace, rules).as_dict().get("note")) == (0.8, None)


def test_gf_max_limits_are_px4s_distances_from_home() -> None:
    """Horizontal distance from home and height above it, each against its limit; 0 is no limit."""
    home = (1.0, 2.0, 0.5)
    X = (4.0, 0.0, 6.0, 0.0, 3.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)  # 5 m away, 3 m up
    assert [w for w, _ in limits_passed(X, home, 4.9, 2.9)] == ["hor", "ver"]
    assert limits_passed(X, home, 5.1, 3.1) == [] and limits_passed(X, home, 0.0, 0.0) == []
    assert "5.00 m from home, beyond GF_MAX_HOR_DIST = 4.9 m" in limits_passed(X, home, 4.9, 0.0)[0][1]


def test_a_reposition_is_judged_as_px4s_navigator_judges_it() -> None:
    """``Navigator::geofence_allows_position``: with GF_ACTION 2-5 a DO_REPOSITION's point outside the fence, or
    beyond GF_MAX_HOR_DIST / GF_MAX_VER_DIST from home, is not flown (why, each reason said); inside, or with
    GF_ACTION 0 (none) or 1 (warning), any point is (None)."""
    home = (0.0, 0.0, 0.0)
    fence = Geofence((Zone(True, points=((-10.0, -10.0), (-10.0, 10.0), (10.0, 10.0), (10.0, -10.0))),
                      Zone(False, center=(5.0, 5.0), radius_m=2.0)))
    assert reposition_refusal((4.0, -3.0, 3.0), 0.0, home, 20.0, 5.0, fence, 2) is None
    why = reposition_refusal((30.0, 0.0, 3.0), 0.0, home, 0.0, 0.0, fence, 2)
    assert why == "outside its fence: at x=30.000 y=0.000 m, outside every inclusion zone of the geofence"
    assert "inside exclusion circle 1" in str(reposition_refusal((5.0, 5.0, 3.0), 0.0, home, 0.0, 0.0, fence, 5))
    why = reposition_refusal((8.0, 0.0, 6.0), 0.0, home, 7.0, 5.0, None, 3)
    assert why == ("8.00 m from home, beyond GF_MAX_HOR_DIST = 7 m; 6.00 m above home, beyond GF_MAX_VER_DIST = 5 m")
    for action in (0, 1):
        assert reposition_refusal((30.0, 0.0, 60.0), 0.0, home, 7.0, 5.0, fence, action) is None


def test_a_vehicle_beyond_gf_max_hor_dist_is_not_armed_again_until_gf_action_is_0() -> None:
    """PX4's pre-arm geofence check on the limits too: landed (disarmed) 6 m from home with GF_MAX_HOR_DIST = 5 m,
    an arm is denied (a ``preflight`` event saying why, :attr:`arming_refused` kept), for a ground station's arm in
    its selected mode as for the controller's; within the limit, or with GF_ACTION 0, it arms."""
    sim = prepare(MISSION_DIR / "sine.toml", params={"GF_MAX_HOR_DIST": 5.0}).make_vehicle()
    hx, hy, hz = sim.home  # (the sine's start)
    sim.plant.state = (hx + 6.0, 0.0, hy, 0.0, hz, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    for arm in (sim.arm, sim.arm_in_mode):
        arm()
        assert not sim.armed and sim.events[-1].kind == "preflight", sim.events[-1]
        assert sim.events[-1].text == ("arming denied: 6.00 m from home, beyond GF_MAX_HOR_DIST = 5 m "
                                       "(GF_ACTION = 2: hold)") == sim.arming_refused
    sim.change_param("GF_ACTION", 0.0)
    sim.arm()
    assert sim.armed and sim.arming_refused is None and sim.events[-1].kind == "armed"
    near = prepare(MISSION_DIR / "sine.toml", params={"GF_MAX_HOR_DIST": 5.0}).make_vehicle()
    near.plant.state = (hx + 4.9, 0.0, hy, 0.0, hz, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    near.arm()
    assert near.armed and not [e for e in near.events if e.kind == "preflight"]


def test_a_flight_above_gf_max_ver_dist_fails_the_geofence_policy_once() -> None:
    """The sine climbs 0.1 m/s: with GF_MAX_VER_DIST = 2 m (a ``[params]`` entry or ``--param``) the vehicle says
    once, at 20 s, that it is above it, and the geofence policy fails there; by GF_ACTION 2 (PX4's default) it
    holds there (outcome ``failsafe``), by 1 (warning) it flies on (``completed``), by 0 it does not watch (no
    event, the policy holds); GF_MAX_HOR_DIST = 2.5 m, which the 1 m circle about (0, 1) never passes from its
    start, holds; without them, nothing."""
    limits = {"GF_MAX_VER_DIST": 2.0, "GF_MAX_HOR_DIST": 2.5}
    for action, outcome in ((2, "failsafe"), (1, "completed")):
        run = simulate("missions/sine.toml", params={**limits, "GF_ACTION": action}, plots=False)
        left = [e for e in run.summary["events"] if e["kind"] == "geofence"]
        assert len(left) == 1 and "beyond GF_MAX_VER_DIST = 2 m" in left[0]["text"], left
        assert 20.0 <= left[0]["t"] <= 20.1, left
        fence = next(p for p in run.summary["policies"] if p["name"] == "geofence")
        assert not fence["ok"] and fence["t"] == left[0]["t"] and run.summary["outcome"] == outcome
        late = run.trace["t"] > 25.0
        top = run.trace["z"][late].max()
        assert (top < 2.2) if action == 2 else (top > 2.4), top  # held at 2 m, or climbing on
    off = simulate("missions/sine.toml", params={**limits, "GF_ACTION": 0}, plots=False)
    assert not [e for e in off.summary["events"] if e["kind"] == "geofence"] and off.summary["outcome"] == "completed"
    assert next(p for p in off.summary["policies"] if p["name"] == "geofence")["ok"]
    quiet = simulate("missions/sine.toml", plots=False)
    assert next(p for p in quiet.summary["policies"] if p["name"] == "geofence")["ok"]


@pytest.mark.parametrize("action, then, end_xy", [
    (3, "landed: disarmed", (0.0, 0.0)),  # Return: home (the start), then land
    (4, "geofence: flight terminated, motors stopped", None),  # Terminate: the motors stop at once; it falls
    (5, "landed: disarmed", (-0.54, -0.84)),  # Land where it is
])
def test_gf_action_return_terminate_and_land_each_fly_their_failsafe(action: int, then: str,
                                                                     end_xy: tuple[float, float] | None) -> None:
    """Above GF_MAX_VER_DIST = 2 m at 20 s, GF_ACTION 3, 4 and 5 fly the vehicle's failsafe (a ``failsafe`` event
    naming the geofence, outcome ``failsafe``, ended by it): Return flies home (RTL_RETURN_ALT 0: at its height)
    and lands (disarmed COM_DISARM_LAND, 2 s, after its landing), Terminate stops the motors (the fall is an
    ``impact``, disarmed), Land lands where it is."""
    params = {"GF_MAX_VER_DIST": 2.0, "GF_ACTION": action, "RTL_RETURN_ALT": 0.0, "RTL_DESCEND_ALT": 2.0}
    run = simulate("missions/sine.toml", params=params, plots=False)
    s = run.summary
    assert s["outcome"] == "failsafe" and "geofence" in s["ended_by"]["how"], s["ended_by"]
    (fs,) = [e for e in s["events"] if e["kind"] == "failsafe"]
    assert fs["t"] == pytest.approx(20.0, abs=0.01) and fs["text"].startswith("geofence: 2.00 m above home")
    (off,) = [e for e in s["events"] if e["kind"] == "disarmed"]
    down = [e["t"] for e in s["events"] if e["kind"] == "landed"]  # on the ground: COM_DISARM_LAND (2 s) to disarm
    assert off["text"] == then and (off["t"] == pytest.approx(down[0] + 2.0, abs=1e-6) if down else True), off
    assert (down[0] if down else off["t"]) < 24.0, (down, off)
    assert run.trace["z"][-1] == pytest.approx(0.0, abs=1e-6)  # on the ground
    if end_xy is None:
        assert any(e["kind"] == "impact" for e in s["events"]) and off["t"] == fs["t"]
    else:
        assert (run.trace["x"][-1], run.trace["y"][-1]) == pytest.approx(end_xy, abs=0.05)


def test_a_ground_station_downloads_the_missions_own_fence_and_rally_points_before_any_upload() -> None:
    """The vehicle holds the mission's fence (and acts on it by GF_ACTION): before any upload a ground station's
    download gets it, and the rally points, as PX4's items (a polygon's vertices in a row with their count, a
    circle's radius), which read back as the same zones and points to degE7's resolution (1e-7 deg: 6 mm at most
    off by rounding)."""
    from missions.envelope import ENVELOPE_RADIUS_M
    from missions.geofence import geofence_from_plan
    from missions.rally import rally_from_plan

    sim = prepare(MISSION_DIR / "sine.toml").make_vehicle()
    sim.fence = Geofence((Zone(True, points=((-3.0, 3.0), (13.0, 3.0), (13.0, -13.0), (-3.0, -13.0))),
                          Zone(False, center=(5.0, -2.0), radius_m=1.5)))
    sim.rally = ((4.0, -6.0), (-2.0, 1.0))
    zones = HeldZones(sim, (HOME.lat, HOME.lon, HOME.alt))
    fence, rally = zones.items[FENCE].items, zones.items[RALLY].items
    assert [(it.seq, it.command, it.param1) for it in fence] == (
        [(i, M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, 4.0) for i in range(4)]
        + [(4, M.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION, 1.5)])
    back = geofence_from_plan(fence_plan(fence), HOME, "downloaded")
    assert back is not None and len(back.zones) == 2
    assert np.allclose(back.zones[0].points, sim.fence.zones[0].points, atol=6e-3)
    assert np.allclose(back.zones[1].center, (5.0, -2.0), atol=6e-3) and back.zones[1].radius_m == 1.5
    points = rally_from_plan(rally_plan(rally), HOME, "downloaded", ENVELOPE_RADIUS_M)
    assert np.allclose(points, sim.rally, atol=6e-3) and {it.command for it in rally} == {M.MAV_CMD_NAV_RALLY_POINT}
    bare = HeldZones(prepare(MISSION_DIR / "sine.toml").make_vehicle(), (HOME.lat, HOME.lon, HOME.alt))
    assert bare.items[FENCE].items == () and bare.items[RALLY].items == ()  # the sine has neither


def test_a_fence_and_rally_points_on_their_bounds_read_back_from_the_wire() -> None:
    """A mission's fence square on its 100 km bound (each corner at ±1e5 m) and a rally point on the 100 m
    envelope come back from the wire (degE7) up to half a step (~6 mm) outside: read back, each is put back on its
    bound, within the step, and a point a step and more outside is still refused, naming it. Until the third
    wave's thirty-seventh session they were refused as read back: the vehicle offered a fence and rally points
    it held that its controller and a ground station's plan could not read (``geoFence.polygons[0]: ... 141 km
    from the plan's home``)."""
    from bridge.mavlink.fenceitems import fence_items, rally_items
    from missions.envelope import ENVELOPE_RADIUS_M
    from missions.geodetic import WIRE_STEP_M
    from missions.geofence import COORD_M, geofence_from_plan
    from missions.rally import rally_from_plan
    from params import ConfigError

    square = ((COORD_M, COORD_M), (COORD_M, -COORD_M), (-COORD_M, -COORD_M), (-COORD_M, COORD_M))
    fence = Geofence((Zone(True, points=square),))
    sent = fence_items(fence, HOME)
    back = geofence_from_plan(fence_plan(sent), HOME, "downloaded")
    assert back is not None and np.allclose(back.zones[0].points, square, atol=WIRE_STEP_M, rtol=0.0)
    assert max(abs(v) for p in back.zones[0].points for v in p) <= COORD_M
    rally = ((0.0, ENVELOPE_RADIUS_M), (ENVELOPE_RADIUS_M / math.sqrt(2.0), -ENVELOPE_RADIUS_M / math.sqrt(2.0)))
    points = rally_from_plan(rally_plan(rally_items(rally, HOME)), HOME, "downloaded", ENVELOPE_RADIUS_M)
    assert np.allclose(points, rally, atol=WIRE_STEP_M, rtol=0.0)
    assert max(math.hypot(*p) for p in points) <= ENVELOPE_RADIUS_M
    far = rally_items(((0.0, ENVELOPE_RADIUS_M + 2.0 * WIRE_STEP_M),), HOME)
    with pytest.raises(ConfigError, match=r"downloaded: rallyPoints.points\[0\]: latitude .*: 100 m from the plan's "
                                          "home; rally points lie within 100 m of it"):
        rally_from_plan(rally_plan(far), HOME, "downloaded", ENVELOPE_RADIUS_M)
    beyond = fence_items(Geofence((Zone(True, points=((COORD_M + 1.0, 0.0), (0.0, 1.0), (0.0, -1.0))),)), HOME)
    with pytest.raises(ConfigError, match=r"downloaded: geoFence.polygons\[0\]: latitude .*: 100.001 km north, "
                                          r"0.000 km west of the plan's home; a fence's points lie within 100 km"):
        geofence_from_plan(fence_plan(beyond), HOME, "downloaded")


def test_a_fence_uploaded_between_a_ground_stations_hop_and_the_mission_is_not_changed_in_flight() -> None:
    """A ground station's own flight before an awaited mission's start is at negative times (its arm and its landed
    disarm): a fence uploaded after it and before the mission's arm is in the controller's download, the mission's
    fence from its start, judged against; only the mission's arm starts the flight (the real-time controller's may
    come just before its time 0). Until the third wave's thirty-seventh session the hop's arm was the flight's, and such
    a fence was "changed in flight" at its negative time: no row judged against the mission's fence."""
    t = np.arange(0.0, 1.0, 0.004)
    trace = {"x": np.where(t >= 0.6, 5.0, 0.0), "y": np.zeros_like(t)}  # out of the start's square at 0.6 s
    rules = Rules(rate_hz=250.0, timeout_s=0.5, clock="lockstep", geofence=Geofence((Zone(True, points=(
        (-1.0, 1.0), (1.0, 1.0), (1.0, -1.0), (-1.0, -1.0))),)))
    hop = [RunEvent.at(-9.0, "armed", "armed, HOLD", "vehicle"), RunEvent.at(-4.0, "disarmed", "landed: disarmed",
                                                                             "vehicle"),
           RunEvent.at(-2.0, "fence", "uploaded 4 items in 0.01 s, 0 requested again", "vehicle")]
    for arm_t in (0.0, -0.003):  # lockstep's arm at the mission's time 0; real time's a little before it
        events = [*hop, RunEvent.at(arm_t, "armed", "armed, offboard control", "vehicle")]
        v = geofence_kept(t, trace, rules, events, *split_at_start(events))
        assert (v.ok, v.t) == (False, pytest.approx(0.6)), v
    bigger = RunEvent.at(0.5, "fence", "uploaded 4 items in 0.01 s, 0 requested again", "vehicle")
    events = [*hop, RunEvent.at(-0.003, "armed", "armed, offboard control", "vehicle"), bigger]
    v = geofence_kept(t, trace, rules, events, *split_at_start(events))  # one in the mission's flight still is
    assert v.ok and v.as_dict()["note"].startswith("the fence changed in flight at t=0.500 s"), v

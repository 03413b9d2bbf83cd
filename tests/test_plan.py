"""Covers missions.planfiles, missions.route and missions.mission: QGroundControl ``.plan`` and
``QGC WPL 110`` files read, refused with the file, item and command named, turned into a smooth trajectory
(stops, pass-through corners, yaw, time from PX4's limits), fitted to the airframe, and the shipped box flown
offline by ``bsst sim`` to the issue's figures (benchmarks/missions.py prints them)."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import pytest

from bridge import simulate
from bridge.core.flight import prepare
from missions import load_mission
from missions.minsnap import Smooth, demands
from missions.mission import mission_from_table
from missions.planfiles import OTHER_NAMES, SUPPORTED, command_name, read_plan_text
from missions.route import Limits, route_of
from params import ConfigError
from tests.benchkit import benchmark_module
from tests.plans import BOX_PLAN, ITEMS_AND_FRAMES, ROOT, l_plan, write_plan
from tests.sitlkit import run_bsst

# runs `bsst sim` as a subprocess; `bsst margin` flies the batch engine (its kernels loaded first)
pytestmark = [pytest.mark.process, pytest.mark.usefixtures("batch_kernels")]

BOX_WPL = ROOT / "examples" / "box.waypoints"


def refusal(path: Path) -> str:
    with pytest.raises(ConfigError) as exc:
        load_mission(path)
    return str(exc.value)


def test_the_two_shipped_files_are_the_same_flight() -> None:
    a, b = load_mission(BOX_PLAN), load_mission(BOX_WPL)
    assert isinstance(a.trajectory, Smooth) and a.trajectory.lands
    ka, kb = a.trajectory.knots, b.trajectory.knots
    assert len(ka) == len(kb) and all(abs(p.t - q.t) < 1e-9 and math.dist((p.x, p.y, p.z), (q.x, q.y, q.z)) < 1e-6
                                      for p, q in zip(ka, kb))
    assert a.duration_s == pytest.approx(a.trajectory.end_s + 1.0)


def test_the_box_route_stops_and_passes_where_the_plan_says() -> None:
    pf = read_plan_text(BOX_PLAN.read_text(), "box")
    route = route_of(pf, Limits(), 100.0)
    kinds = [(label, stop) for label, _, stop in route.waypoints]
    assert kinds[0] == ("mission.items[0]", True)  # takeoff: stops on top
    assert [s for _, s in kinds[1:6]] == [False] * 5  # the box's corners: passed through
    assert kinds[-1][1] and route.lands
    ref = Smooth(route.knots)
    speed = max(math.hypot(ref.sample(t / 10)[0][1], ref.sample(t / 10)[1][1]) for t in range(int(ref.end_s * 10)))
    assert 4.9 <= speed <= 5.0 + 1e-6  # the plan's 5 m/s is reached, never passed
    climb = max(ref.sample(t / 10)[2][1] for t in range(int(ref.end_s * 10)))
    assert 2.9 <= climb <= 3.0 + 1e-6  # MPC_Z_V_AUTO_UP


def test_the_other_items_and_frames() -> None:
    """A waypoint in GLOBAL (AMSL) holding 2 s with a yaw given (90 deg: east), NAV_LOITER_TIME 3 s in
    GLOBAL_RELATIVE_ALT_INT, a waypoint in GLOBAL_INT passed through, NAV_RETURN_TO_LAUNCH in frame MISSION (as
    QGroundControl writes it and PX4 takes it): each where and as the plan says, about the home, 10 m up."""
    route = route_of(read_plan_text(ITEMS_AND_FRAMES, "frames"), Limits(), 100.0)
    assert [(label, stop) for label, _, stop in route.waypoints] == [
        ("item 1", True), ("item 2", True), ("item 3", True), ("item 4", False), ("item 5", True), ("item 5", True)]
    assert route.lands
    at = {label: route.knots[k] for label, k, _ in route.waypoints}  # (item 5: its last, on the ground)
    north, east = 10.0, 10.0  # the file's 1e-7 deg: within 5 mm
    for label, (x, y) in {"item 2": (north, 0.0), "item 3": (north, -east), "item 4": (0.0, -east)}.items():
        assert (at[label].x, at[label].y, at[label].z) == pytest.approx((x, y, 10.0), abs=5e-3), label
    assert at["item 2"].psi == pytest.approx(-math.pi / 2)  # 90 deg clockwise from north, the paper frame's psi
    for (_, k, _), hold in zip(route.waypoints[1:3], (2.0, 3.0), strict=True):  # the hold, the loiter
        here, then = route.knots[k], route.knots[k + 1]
        assert (then.t - here.t, then.x, then.y, then.z) == pytest.approx((hold, here.x, here.y, here.z))
    home_high, home = route.knots[-2], route.knots[-1]  # RTL: over the home at its altitude, then down
    assert (home_high.x, home_high.y, home_high.z, home.x, home.y, home.z) == (0.0, 0.0, 10.0, 0.0, 0.0, 0.0)


def test_a_slower_cruise_is_a_longer_flight() -> None:
    pf = read_plan_text(BOX_PLAN.read_text().replace('"hoverSpeed": 5', '"hoverSpeed": 2'), "box")
    slow = route_of(pf, Limits(MPC_XY_CRUISE=2.0), 100.0)
    fast = route_of(read_plan_text(BOX_PLAN.read_text(), "box"), Limits(), 100.0)
    assert slow.knots[-1].t == fast.knots[-1].t  # DO_CHANGE_SPEED 5 m/s after takeoff sets the box's speed
    pf = read_plan_text(BOX_PLAN.read_text().replace('5,\n                    -1', '2,\n                    -1'), "box")
    assert route_of(pf, Limits(), 100.0).knots[-1].t > fast.knots[-1].t + 10.0


def test_every_command_a_refusal_names_is_named_as_mavlinks_common_xml_names_it():
    """The names a plan's refusal gives its commands are MAVLink's (``MAV_CMD_`` dropped), and a command we fly or
    know the name of is never the bare ``MAV_CMD (82)`` (NAV_SPLINE_WAYPOINT was, a user's tour)."""
    from pymavlink.dialects.v20 import common  # the reference, not our code's dependency

    for cmd, name in {**SUPPORTED, **OTHER_NAMES}.items():
        assert common.enums["MAV_CMD"][cmd].name == f"MAV_CMD_{name}", cmd
    assert command_name(82) == "NAV_SPLINE_WAYPOINT (82)" and command_name(4242) == "MAV_CMD (4242)"


@pytest.mark.parametrize("edit, words", [
    (lambda d: d["mission"]["items"].insert(2, {"type": "ComplexItem", "complexItemType": "survey"}),
     ["mission.items[2]", "ComplexItem", "survey"]),
    (lambda d: d["mission"]["items"][2].update(command=177), ["mission.items[2]", "DO_JUMP (177)", "not supported"]),
    (lambda d: d["mission"]["items"][3].update(command=17), ["mission.items[3]", "NAV_LOITER_UNLIM (17)"]),
    (lambda d: d["mission"]["items"][2]["params"].__setitem__(4, None), ["mission.items[2]", "NAV_WAYPOINT (16)",
                                                                        "coordinates", "got lat null, lon "]),
    (lambda d: d["mission"]["items"][2]["params"].__setitem__(4, 47.5), ["mission.items[2]", "NAV_WAYPOINT (16)",
                                                                        "envelope"]),
    (lambda d: d["mission"]["items"][2].update(frame=10), ["mission.items[2]", "GLOBAL_TERRAIN_ALT (10)"]),
    (lambda d: d["mission"]["items"][2]["params"].__setitem__(6, -5), ["mission.items[2]", "below the ground"]),
    (lambda d: d["mission"]["items"].append(dict(d["mission"]["items"][2])), ["mission.items[8]",
                                                                              "after NAV_LAND (21)"]),
    (lambda d: d["mission"]["items"][1]["params"].__setitem__(1, 50), ["mission.items[1]", "DO_CHANGE_SPEED (178)",
                                                                      "speed"]),
    # the message gives the range of the speed param1 names, and both values meaning no change (-2 flies too); until
    # the third wave's thirty-ninth session it left -2 out, and docs/missions.md said (0, 12] for every kind
    (lambda d: d["mission"]["items"][1]["params"].__setitem__(1, 0.05),
     ["DO_CHANGE_SPEED (178)", "speed (param2) 0.05 m/s: must be in [0.1, 12] (the range of MPC_XY_CRUISE, which "
      "param1 1 sets), or -1 or -2 (no change)"]),
    (lambda d: d["mission"]["items"][1]["params"].__setitem__(slice(0, 2), [3, 5]),
     ["DO_CHANGE_SPEED (178)", "speed (param2) 5 m/s: must be in [0.1, 4] (the range of MPC_Z_V_AUTO_DN"]),
    (lambda d: d["mission"]["items"][2].update(autoContinue=False), ["mission.items[2]", "autoContinue"]),
    # a missing autoContinue is refused as QGroundControl's loader refuses it (it flew as if true until the third
    # wave's thirty-seventh session)
    (lambda d: d["mission"]["items"][3].pop("autoContinue"), ["mission.items[3]", "NAV_WAYPOINT (16)",
                                                             "autoContinue: missing; expected true or false"]),
    # a value of the wrong type is named as such (a string "true" was once "autoContinue false"); a huge altitude is
    # given in a few digits (it was written out in 300)
    (lambda d: d["mission"]["items"][2].update(autoContinue="true"), ["mission.items[2]", "NAV_WAYPOINT (16)",
                                                                     "autoContinue: expected true or false",
                                                                     "got 'true'"]),
    (lambda d: d["mission"]["items"][2]["params"].__setitem__(6, -1e300), ["mission.items[2]", "altitude -1e+300 m",
                                                                          "below the ground"]),
    (lambda d: d["mission"]["items"][2]["params"].__setitem__(6, 1e300), ["mission.items[2]", "1e+300 m from the home",
                                                                         "envelope"]),
    (lambda d: d.update(fileType="Fence"), ["not a QGroundControl plan"]),
    (lambda d: d["mission"].update(plannedHomePosition=[None, 8.5, 488]), ["plannedHomePosition"]),
    # every number of a plan finite (Python's json reads Infinity and NaN; QGroundControl writes NaN as null)
    (lambda d: d["mission"].update(hoverSpeed=math.inf), ["mission.hoverSpeed", "finite number or null, got inf"]),
    (lambda d: d["mission"].update(cruiseSpeed=-math.inf), ["mission.cruiseSpeed", "got -inf"]),
    (lambda d: d["mission"].update(hoverSpeed=10**400), ["mission.hoverSpeed", "an integer of 401 digits"]),
    (lambda d: d["mission"]["items"][2]["params"].__setitem__(3, math.inf), ["mission.items[2]", "NAV_WAYPOINT (16)",
                                                                            "params[3] (param4)", "got inf"]),
    (lambda d: d["mission"]["items"][2]["params"].__setitem__(4, 10**400), ["mission.items[2]", "params[4] (x/lat)",
                                                                           "an integer of 401 digits"]),
    (lambda d: d["mission"]["items"][2].update(command=10**400), ["mission.items[2]", "[0, 65535]",
                                                                  "an integer of 401 digits"]),
    (lambda d: d["mission"].update(plannedHomePosition=[math.inf, 8.5, 488]), ["plannedHomePosition", "inf"]),
    (lambda d: d.update(geoFence={"circles": [{"circle": {"center": [10**400, 8.5], "radius": 5}, "inclusion": True}],
                                  "polygons": [], "version": 2}), ["geoFence.circles[0]",
                                                                   "latitude an integer of 401 digits"]),
    (lambda d: d.update(rallyPoints={"points": [[47.3978, 8.5456, math.inf]], "version": 2}),
     ["rallyPoints.points[0]", "finite"]),
    # a geoFence with zones but no version: QGroundControl's loader ignores it (no fence), so it is refused; rally
    # points with none: its loader refuses them (both were read as version 2 until the forty-fifth session)
    (lambda d: d.update(geoFence={"circles": [{"circle": {"center": [47.397742, 8.545594], "radius": 50},
                                               "inclusion": True}], "polygons": []}),
     ["geoFence.version: missing: QGroundControl's plan loader (GeoFenceController::load) takes a geoFence without a "
      "version for old data and ignores it: the plan it loads has no fence, where this one draws zones; give "
      '"version": 2']),
    (lambda d: d.update(rallyPoints={"points": [[47.3978, 8.5456, 490]]}),
     ["rallyPoints.version: missing: QGroundControl's plan loader (RallyPointController::load) requires it and "
      "refuses the plan"]),
    # a version 2 geoFence without circles or polygons, rallyPoints without points: QGroundControl's loader refuses
    # the plan (JsonHelper::validateKeys); read as none until the forty-fifth session
    (lambda d: d.update(geoFence={"version": 2, "polygons": []}),
     ["geoFence.circles: missing: QGroundControl's plan loader (GeoFenceController::load) requires circles and "
      'polygons in a version 2 geoFence and refuses the plan; give "circles": [] for none']),
    (lambda d: d.update(geoFence={"version": 2, "circles": [{"circle": {"center": [47.397742, 8.545594],
                                                                        "radius": 50}, "inclusion": True}]}),
     ["geoFence.polygons: missing: QGroundControl's plan loader (GeoFenceController::load) requires circles and "
      'polygons in a version 2 geoFence']),
    (lambda d: d.update(geoFence={"version": 2}), ["geoFence.circles: missing: "]),
    (lambda d: d.update(rallyPoints={"version": 2}),
     ["rallyPoints.points: missing: QGroundControl's plan loader (RallyPointController::load) requires points in a "
      'version 2 rallyPoints and refuses the plan; give "points": [] for none']),
    # a hold time is flown: null (NaN) is refused as -5 is; a null yaw (param4) is QGroundControl's "not given"
    (lambda d: d["mission"]["items"][2].update(command=19, params=[None, 0, 0, None, 47.3979219, 8.5458597, 10]),
     ["mission.items[2]", "NAV_LOITER_TIME (19)", "hold time (param1) null", "[0, 3600]"]),
    (lambda d: d["mission"]["items"][2]["params"].__setitem__(0, None), ["NAV_WAYPOINT (16)",
                                                                        "hold time (param1) null"]),
    # the format's version is the number 1 (mission: 2), not the string
    (lambda d: d.update(version="1"), ['version: expected the number 1, got the string "1"']),
    (lambda d: d.update(version=True), ["version: expected the number 1, got the boolean true"]),
    (lambda d: d.update(version=2), ["version: version 2 not supported (1 is)"]),
    (lambda d: d["mission"]["items"][1].update(command=None), ["got null and"]),  # JSON's word (it said None)
    (lambda d: d["mission"].update(plannedHomePosition=None), ["plannedHomePosition", "got null"]),
    (lambda d: d["mission"].update(version="2"), ['mission.version: expected the number 2, got the string "2"']),
    # a fence or rally points under a mistyped key or another version: refused (they flew none, exit 0: a user's tour)
    (lambda d: d.update(geoFence={"version": 2, "polygons": [], "circels": [{"inclusion": True, "circle": {
        "center": [47.397742, 8.545594], "radius": 5}}]}), ["geoFence.circels: unknown key; geoFence has version, "
                                                           "polygons, circles, breachReturn"]),
    (lambda d: d.update(geoFence={"version": 1, "polygon": [[47.3977, 8.5455], [47.3978, 8.5455], [47.3978, 8.5456]]}),
     ["geoFence.version: version 1 not supported (2 is, as QGroundControl writes it)"]),
    (lambda d: d.update(rallyPoints={"version": 2, "point": [[47.3978, 8.5456, 490]]}), ["rallyPoints.point: unknown"]),
    (lambda d: d.update(rallyPoints={"version": 3, "points": []}), ["rallyPoints.version: version 3 not supported"]),
    # a plan's or its mission's key mistyped: refused (the one meant was not given: no fence, the default speed)
    (lambda d: d.update(geofence=d.pop("geoFence")), ["geofence: unknown key; did you mean 'geoFence'?"]),
    (lambda d: d["mission"].update(hoverspeed=d["mission"].pop("hoverSpeed")),
     ["mission.hoverspeed: unknown key; did you mean 'hoverSpeed'?"]),
])
def test_refusals_name_the_file_the_item_and_its_command(tmp_path: Path, edit, words: list[str]) -> None:
    p = write_plan(tmp_path, edit)
    why = refusal(p)
    assert why.startswith(str(p)) and "\n" not in why
    for w in words:
        assert w in why


def test_a_geofence_without_a_version_or_zones_is_read_as_qgroundcontrol_reads_it(tmp_path: Path) -> None:
    """No version and no zone: QGroundControl's GeoFenceController::load ignores it and loads the plan with no fence;
    so does this reader (refusing it would refuse what loses nothing). With a zone it is refused (above)."""
    p = write_plan(tmp_path, lambda d: d.update(geoFence={"circles": [], "polygons": []}))
    assert load_mission(p).geofence is None


def test_a_plan_naming_a_key_twice_is_refused(tmp_path: Path) -> None:
    """A hand-edited plan with ``"version": 1`` and then ``"version": 2`` in one object: refused, naming the key
    (JSON keeps the last, so it was refused as "version 2", of a file that also said 1)."""
    text = BOX_PLAN.read_text()
    bad = tmp_path / "dup.plan"
    bad.write_text(text.replace('"fileType": "Plan",', '"fileType": "Plan", "fileType": "Plan",', 1))
    assert bad.read_text() != text
    assert refusal(bad) == (f"{bad}: not a QGroundControl plan (key 'fileType' given twice in one object; JSON would "
                            "keep the last)")


def test_waypoint_file_refusals(tmp_path: Path) -> None:
    lines = BOX_WPL.read_text().splitlines()
    bad = tmp_path / "bad.waypoints"
    bad.write_text("\n".join(lines[:4] + [lines[4].replace("\t16\t", "\t201\t", 1)] + lines[5:]) + "\n")
    why = refusal(bad)
    assert why.startswith(str(bad)) and "item 3 (DO_SET_ROI (201))" in why
    bad.write_text("QGC WPL 120\n" + "\n".join(lines[1:]))
    assert "QGC WPL 110" in refusal(bad)
    bad.write_text("\n".join(lines[:4] + [lines[4].replace("nan", "x")]))
    assert refusal(bad) == f"{bad}: line 5: param4 'x': expected a number (or nan: not given)"  # its field named
    bad.write_text("\n".join(lines[1:]))  # no header: read as a waypoint file (it was "not valid JSON")
    assert refusal(bad) == f'{bad}: not a waypoint file (the first line must be "QGC WPL 110")'
    for empty in ("", " \n\n"):
        bad.write_text(empty)
        assert refusal(bad) == f"{bad}: empty (a QGroundControl .plan or a QGC WPL 110 waypoint file)"
    bad.write_text("\n".join(lines[:1] + ["", "  "] + lines[1:4] + ["", lines[4].replace("nan", "x")]))
    assert f"{bad}: line 8: " in refusal(bad)  # blank lines are counted: the file's 8th line
    bad.write_text("\n".join(lines[:1] + [""] + [lines[1].replace("\t16\t", "\t999\t", 1)] + lines[2:]))
    assert refusal(bad) == f"{bad}: line 3 (the home): command MAV_CMD (999), expected NAV_WAYPOINT (16)"
    bad.write_text("\n".join(lines[:4] + [lines[4].replace("\t16\t0\t", "\t16\tnan\t", 1)] + lines[5:]))
    assert refusal(bad) == (f"{bad}: item 3 (NAV_WAYPOINT (16)): hold time (param1) nan: expected a number of "
                            "seconds in [0, 3600] (0: no hold)")
    for word in ("inf", "-Infinity", "1" + "0" * 400):  # nan is QGroundControl's "not given"; inf is no number
        bad.write_text("\n".join(lines[:4] + [lines[4].replace("nan", word)] + lines[5:]))
        assert refusal(bad).startswith(f"{bad}: line 5: param4 "), word
    bad.write_text("\n".join(lines[:4] + [lines[4].replace("\t16\t", "\t" + "1" * 5000 + "\t", 1)] + lines[5:]))
    assert refusal(bad).startswith(f"{bad}: line 5: expected an integer of at most 10 digits, got '1111")


def test_a_toml_mission_names_a_plan(tmp_path: Path) -> None:
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "box.plan").write_text(BOX_PLAN.read_text())
    m = mission_from_table({"name": "boxed", "profile": "x500", "trajectory": {"kind": "plan", "file": "sub/box.plan"},
                            "link": {"delay_ms": 5}}, str(tmp_path / "m.toml"))
    direct = load_mission(BOX_PLAN)
    assert m.trajectory == direct.trajectory and m.duration_s == direct.duration_s and m.link == {"delay_ms": 5}
    again = mission_from_table({"trajectory": {"kind": "plan", "file": "sub/box.plan", "MPC_XY_CRUISE": 3.0,
                                               "MPC_ACC_HOR": 1.0}, "duration_s": 300.0}, str(tmp_path / "m.toml"))
    assert again.duration_s == 300.0 and again.trajectory.end_s > direct.trajectory.end_s
    with pytest.raises(ConfigError, match="no such file"):
        mission_from_table({"trajectory": {"kind": "plan", "file": "nope.plan"}}, str(tmp_path / "m.toml"))
    with pytest.raises(ConfigError, match="MPC_ACC_HOR"):
        mission_from_table({"trajectory": {"kind": "plan", "file": "sub/box.plan", "MPC_ACC_HOR": 0.0}},
                           str(tmp_path / "m.toml"))
    flown = mission_from_table(m.to_dict(), "<flown>")  # the run's mission.toml: the same trajectory to the bit
    assert flown.trajectory == m.trajectory and flown.trajectory.sample(40.123) == m.trajectory.sample(40.123)


def test_too_hard_for_the_airframe_is_slowed_or_refused(tmp_path: Path) -> None:
    table = {"trajectory": {"kind": "plan", "file": str(BOX_PLAN)}, "gains": {"limits": {"tilt_max": 0.15}}}
    fast = mission_from_table(table, "<m>")
    flight = prepare(fast)  # 0.8 x 0.15 rad of tilt allowed: the box's corners at 5 m/s need more
    slow = flight.mission.trajectory
    assert isinstance(slow, Smooth) and slow.stretched_by > 1.0 and slow.end_s > fast.trajectory.end_s
    d = demands(slow, flight.profile.mass, flight.profile.gravity)
    assert d.thrust_n <= 0.8 * flight.profile.u_max[0] and d.tilt_rad <= 0.8 * flight.gains.tilt_max
    assert demands(slow, flight.profile.mass, flight.profile.gravity, 1 / 1.0101).tilt_rad > 0.8 * 0.15  # the least
    assert flight.mission.duration_s - slow.end_s == pytest.approx(fast.duration_s - fast.trajectory.end_s)
    assert prepare(flight.mission).mission == flight.mission  # fitted once: the flown mission.toml stays
    assert prepare(load_mission(BOX_PLAN)).mission == load_mission(BOX_PLAN)  # the shipped box fits as it is
    weak = tmp_path / "weak.toml"  # the paper's airframe with thrust for 1.1 g: hover alone needs over 80 %
    weak.write_text((ROOT / "plant" / "profiles" / "paper.toml").read_text().replace('name = "paper"', 'name = "weak"')
                    .replace("u1 = 43.164", "u1 = 11.87"))
    with pytest.raises(ConfigError, match="refused: it needs .* slowed 4 times it still needs more"):
        prepare(mission_from_table({**table, "profile": str(weak)}, "<m>"))


def test_box_plan_flown_offline_meets_the_figures() -> None:
    fig = benchmark_module("missions").figures(BOX_PLAN)
    assert fig["outcome"] == "completed" and fig["landed_and_disarmed"]
    assert all(w["closest_m"] <= 0.1 for w in fig["waypoints"]) and len(fig["waypoints"]) >= 6
    assert fig["rms_3d_all_m"] <= 1e-3
    assert len(fig["pass_through"]) >= 4 and all(j["jump_m_s"] <= 1e-6 and j["speed_m_s"] > 0.5
                                                 for j in fig["pass_through"])


# examples/box.waypoints cut to an L, as tests.plans.l_plan cuts box.plan: home, takeoff to 3 m, the speed change,
# 10 m north, 10 m east (passed through the corner), land: 20 s of flight where the box has 90
L_WAYPOINTS = """QGC WPL 110
0\t1\t0\t16\t0\t0\t0\t0\t47.397742\t8.545594\t488.0\t1
1\t0\t3\t22\t0\t0\t0\tnan\t47.397742\t8.545594\t3\t1
2\t0\t2\t178\t1\t5\t-1\t0\t0\t0\t0\t1
3\t0\t3\t16\t0\t0\t0\tnan\t47.397832\t8.545594\t3\t1
4\t0\t3\t16\t0\t0\t0\tnan\t47.397832\t8.545727\t3\t1
5\t0\t3\t21\t0\t0\t0\tnan\t47.397832\t8.545727\t0\t1
"""


def test_bsst_sim_flies_a_plan_and_refuses_a_bad_one(tmp_path: Path) -> None:
    """A QGC WPL 110 file flown by the command line to its landing (the L: the shipped box.waypoints is the box.plan
    flown to its figures offline, test_the_two_shipped_files_are_the_same_flight); a bad .plan refused."""
    wpl = tmp_path / "l.waypoints"
    wpl.write_text(L_WAYPOINTS)
    assert load_mission(wpl).trajectory == load_mission(l_plan(tmp_path)).trajectory  # the L, to the bit
    env = dict(os.environ, MPLBACKEND="Agg")
    out = tmp_path / "run"
    p = run_bsst("sim", str(wpl), "--out", str(out), "--no-plots", cwd=ROOT, env=env, timeout=300)
    assert p.returncode == 0, p.stderr
    summary = json.loads((out / "summary.json").read_text())
    # disarmed, then the mode PX4 takes after a LAND's disarm (the user's: bridge.autopilot.intention)
    assert summary["outcome"] == "completed" and [e["kind"] for e in summary["events"][-2:]] == ["disarmed", "mode"]
    assert 'kind = "smooth"' in (out / "mission.toml").read_text()
    bad = write_plan(tmp_path, lambda d: d["mission"]["items"][2].update(command=177))
    p = run_bsst("sim", str(bad), "--no-plots", cwd=ROOT, env=env, timeout=120)
    assert p.returncode == 2 and p.stderr.strip().count("\n") == 0 and "DO_JUMP (177)" in p.stderr


def test_lockstep_sitl_flies_the_plan_as_offline(tmp_path: Path) -> None:
    from bridge.session import sitl  # here: the other tests of this module start no SITL session

    plan = l_plan(tmp_path)
    offline = simulate(plan, plots=False)
    assert offline.summary["outcome"] == "completed" and len(offline.trace["t"]) >= 20 * 250
    lock = sitl(plan, out=tmp_path / "sitl", plots=False, instance=None)
    assert lock.summary["outcome"] == "completed" and lock.summary["clock"] == "lockstep"
    n = len(offline.trace["t"])
    assert len(lock.trace["t"]) == n
    worst = max(math.dist((offline.trace["x"][i], offline.trace["y"][i], offline.trace["z"][i]),
                          (lock.trace["x"][i], lock.trace["y"][i], lock.trace["z"][i])) for i in range(n))
    assert worst <= 1e-4
    # in time order (the session's closing notes at the trace's last row, before the landing's disarm), as offline
    assert [e["kind"] for e in lock.summary["events"][-2:]] == ["disarmed", "mode"] and abs(lock.trace["z"][-1]) <= 0.05
    # the plan's end: its LAND from the ground, landed at once, disarmed COM_DISARM_LAND (2 s) later, in both (offline
    # once disarmed at the touchdown)
    ends = [[(round(e["t"], 3), e["kind"]) for e in r.summary["events"]
             if e["kind"] == "landed" or e["text"].startswith(("mission over: LAND", "landed: disarmed"))]
            for r in (offline, lock)]  # (the session's controller says its own "end" too)
    assert ends[0] == ends[1] and [k for _, k in ends[0]] == ["end", "landed", "disarmed"], ends
    assert ends[0][2][0] == pytest.approx(ends[0][1][0] + 2.0), ends


def test_a_plan_is_swept_and_its_delay_margin_searched(tmp_path: Path, capsys) -> None:
    """``bsst sweep`` and ``bsst margin`` take a plan file as they take a TOML mission (the L of
    :func:`l_plan`): the sweep's two cells complete and say what they flew, the margin search brackets a
    delay; both write the plan's resolved mission next to their results."""
    from bridge.cli import main  # noqa: PLC0415 - the command line in this process

    plan = l_plan(tmp_path)
    assert main(["sweep", str(plan), "--delay", "0,20", "--out", str(tmp_path / "sweep"), "--no-plots",
                 "--jobs", "1"]) == 0
    cells = (tmp_path / "sweep" / "cells.csv").read_text().splitlines()
    assert len(cells) == 3 and all(",completed," in row for row in cells[1:]), cells
    assert 'kind = "smooth"' in (tmp_path / "sweep" / "mission.toml").read_text()
    assert main(["margin", str(plan), "--over", "delay_ms", "--until", "rms=0.1", "--resolution", "8",
                 "--check-below", "0", "--out", str(tmp_path / "margin")]) == 0
    found = json.loads((tmp_path / "margin" / "margin.json").read_text())
    law = found["controllers"][0]  # margin.json: one entry per law, one law here
    assert law["margin"] is not None and law["margin"] < law["bracket"][1], found
    capsys.readouterr()


def test_a_duration_that_ends_inside_the_plan_is_refused(tmp_path: Path) -> None:
    """A mission's ``duration_s`` shorter than its plan is refused, naming both lengths, as a step's point past it
    is; ``duration_s`` at the plan's end or past it flies. Until the fix-linkdup branch ``bsst sim`` flew the plan's
    first 3 s, said completed, exit 0, its waypoints never reached, and the run's ``mission.toml`` (the plan's knots
    past 3 s) was refused when flown again. A fleet's vehicle's plan: the mission's duration_s is not the plan's."""
    l_plan(tmp_path)
    source = str(tmp_path / "m.toml")
    plan = {"kind": "plan", "file": "l.plan"}
    end = mission_from_table({"trajectory": plan}, source).trajectory.end_s
    with pytest.raises(ConfigError) as exc:
        mission_from_table({"duration_s": 3.0, "trajectory": plan}, source)
    assert str(exc.value) == (f"{source}: trajectory.file: l.plan flies {end:g} s, then 1 s at rest ({end + 1:g} s "
                              f"flown whole), longer than the mission's duration_s = 3 s, which would end the flight "
                              f"inside the plan; drop duration_s to fly the plan's own length (or give at least "
                              f"{end:g} s)")
    assert mission_from_table({"duration_s": end, "trajectory": plan}, source).duration_s == end
    fleet = {"duration_s": 3.0, "trajectory": {"kind": "step", "setpoints": [{"t": 0.0, "x": 0.0, "y": 0.0, "z": 1.0}]},
             "vehicles": [{"id": 1, "offset": [0.0, 0.0, 0.0]}, {"id": 2, "trajectory": plan}]}
    with pytest.raises(ConfigError) as fleet_exc:  # a vehicle's plan: duration_s is the mission's own trajectory's
        mission_from_table(fleet, source)
    assert str(fleet_exc.value).startswith(f"{source}: vehicles[1].trajectory.file: l.plan flies {end:g} s, ")
    assert str(fleet_exc.value).endswith(f"inside the plan; give a duration_s of at least {end:g} s")
    mission = tmp_path / "cut.toml"
    mission.write_text('name = "cut"\nduration_s = 3\n[trajectory]\nkind = "plan"\nfile = "l.plan"\n')
    p = run_bsst("sim", mission, "--out", tmp_path / "run", "--no-plots", timeout=120)
    assert p.returncode == 2 and p.stderr.strip() == f"bsst: {mission}: {str(exc.value).split(': ', 1)[1]}", p.stderr
    assert not (tmp_path / "run").exists()


def test_an_empty_plan_file_is_an_empty_path_not_the_missions_folder(tmp_path: Path) -> None:
    """An empty ``trajectory.file`` is refused as ``bsst sim ""`` is (params.path_problem, one check): it read as the
    mission's folder (``m: is a directory, expected a mission plan``)."""
    source = str(tmp_path / "m.toml")
    with pytest.raises(ConfigError) as exc:
        mission_from_table({"trajectory": {"kind": "plan", "file": ""}}, source)
    assert str(exc.value) == f"{source}: trajectory.file: an empty path (give the plan's file, relative to the " \
                             "mission's folder)"


def test_a_plan_named_as_a_mission_says_its_suffix(tmp_path: Path) -> None:
    """A plan saved as ``box.json`` (or a waypoint file as ``box.wp``) was refused as TOML alone (``not valid TOML
    (Invalid statement (at line 1, column 1))``): a ground station's file is read by its suffix, which the line now
    says (a user's tour)."""
    for name, src, says in (("box.json", BOX_PLAN, "it reads as a QGroundControl plan: name it .plan"),
                            ("box.wp", BOX_WPL, "it reads as a QGC WPL waypoint file: name it .waypoints")):
        p = tmp_path / name
        p.write_bytes(src.read_bytes())
        why = refusal(p)
        assert why.startswith(f"{p}: not valid TOML (") and why.endswith(f"); {says}"), why
    (tmp_path / "m.toml").write_text("name = \n")
    assert "it reads as" not in refusal(tmp_path / "m.toml")

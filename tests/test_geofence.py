"""Covers missions.geofence, missions.rally and bridge.record.policies: a plan's ``geoFence`` read into the
mission's ``[geofence]``, PX4's rule for a position (inside an inclusion zone, outside every exclusion zone), the
refusals of a malformed fence, a run that leaves the fence saying where and when (the ``geofence`` policy); a
plan's ``rallyPoints`` read into ``[rally]`` (docs/missions.md, "The geofence", "Rally points")."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from bridge import simulate
from bridge.cli.runreport import report_run
from missions import Mission, Sine, load_mission
from missions.geofence import Geofence, Zone, geofence_from_table
from missions.mission import mission_from_table
from params import ConfigError, Table
from tests.plans import OUTSIDE_WHY, fenced_l, l_latlon, l_rectangle, outside_fence_plan

SQUARE = Zone(True, points=((0.0, 0.0), (4.0, 0.0), (4.0, 4.0), (0.0, 4.0)))
L_SHAPE = Zone(True, points=((0.0, 0.0), (4.0, 0.0), (4.0, 1.0), (1.0, 1.0), (1.0, 4.0), (0.0, 4.0)))  # concave


def test_a_polygon_and_a_circle_contain_what_they_should() -> None:
    x, y = np.array([2.0, 5.0, 0.5, 3.0, -0.1]), np.array([2.0, 2.0, 3.0, 3.0, 2.0])
    assert SQUARE.contains(x, y).tolist() == [True, False, True, True, False]
    assert L_SHAPE.contains(x, y).tolist() == [False, False, True, False, False]  # (2, 2) is in the notch
    circle = Zone(False, center=(1.0, 1.0), radius_m=1.5)
    assert circle.contains(x, y).tolist() == [True, False, False, False, True]


def test_px4s_rule_inside_some_inclusion_zone_and_outside_every_exclusion_zone() -> None:
    t = [0.0, 1.0, 2.0, 3.0]
    two = Geofence((SQUARE, Zone(True, center=(10.0, 0.0), radius_m=1.0)))
    assert two.first_breach(t, [1.0, 10.0, 10.5, 2.0], [1.0, 0.0, 0.5, 2.0]) is None  # in one or the other
    breach = two.first_breach(t, [1.0, 6.0, 10.0, 2.0], [1.0, 0.0, 0.0, 2.0])
    assert breach is not None and breach[0] == 1.0 and "outside every inclusion zone" in breach[1]
    holed = Geofence((SQUARE, Zone(False, center=(2.0, 2.0), radius_m=0.5)))
    breach = holed.first_breach(t, [1.0, 2.2, 3.0, 3.0], [1.0, 2.0, 3.0, 3.0])
    assert breach == (1.0, "at x=2.200 y=2.000 m, inside exclusion circle 1 of the geofence")
    only_out = Geofence((Zone(False, points=((5.0, 5.0), (6.0, 5.0), (6.0, 6.0))),))  # no inclusion zone
    assert only_out.first_breach(t, [0.0, 100.0, -50.0, 3.0], [0.0, 0.0, 9.0, 3.0]) is None


@pytest.mark.parametrize("zone, words", [
    ({"kind": "ring", "inclusion": True}, "kind: must be one of polygon, circle"),
    ({"kind": "polygon", "inclusion": True, "points": [[0, 0], [1, 0]]}, "points: expected 3 to 1000 points"),
    ({"kind": "polygon", "inclusion": True, "points": [[0, 0], [1, 0], [1, float("nan")]]}, "point 2: expected"),
    ({"kind": "circle", "inclusion": False, "center": [0, 0], "radius_m": 0.0}, "radius_m: must be in (0, 100000]"),
    ({"kind": "circle", "inclusion": "yes", "center": [0, 0], "radius_m": 1.0}, "inclusion: expected true or false"),
    ({"kind": "circle", "inclusion": True, "center": [0, 0], "radius_m": 1.0, "height": 3}, "unknown key"),
])
def test_a_malformed_zone_is_refused_naming_its_key(zone: dict, words: str) -> None:
    with pytest.raises(ConfigError) as e:
        geofence_from_table(Table({"zones": [zone]}, "m.toml", "geofence"))
    assert str(e.value).startswith("m.toml: geofence.zones[0].") and words in str(e.value), str(e.value)


RALLY = [(5.0, 5.0, 500.0), (-2.0, 0.0, 490.0)]  # m north, m east of the L's home; m AMSL


@pytest.fixture(scope="module")
def fenced_and_rallied(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Any]:
    """The L with a polygon 3 m round it, an exclusion circle off its east leg and two rally points (:data:`RALLY`),
    flown offline once (its run directory next to the plan): the plan, and the run. The fence's test and the rally
    points' read the one flight (each flew its own: the rally points change nothing the fence's test reads)."""
    where = tmp_path_factory.mktemp("fenced")
    plan = fenced_l(where, {"polygons": [{"inclusion": True, "version": 1, "polygon": l_rectangle(-3, 13, 3, 13)}],
                            "circles": [{"inclusion": False, "version": 1,
                                         "circle": {"center": l_latlon(5.0, 20.0), "radius": 2.0}}]}, "fenced.plan")
    data = json.loads(plan.read_text())
    data["rallyPoints"] = {"version": 2, "points": [[*l_latlon(north, east), alt] for north, east, alt in RALLY]}
    plan.write_text(json.dumps(data))
    return plan, simulate(plan, out=where / "run", plots=False)


def test_a_plans_fence_is_read_about_its_home_and_kept_in_mission_toml(fenced_and_rallied) -> None:
    """A polygon 3 m round the L and an exclusion circle: in the paper frame (x north, y west), to the
    projection's millimetre; ``mission.toml`` of the run holds the fence, and flying it again judges the same."""
    plan, run = fenced_and_rallied
    fence = load_mission(plan).geofence
    poly, circle = fence.zones
    assert poly.inclusion and not circle.inclusion and circle.radius_m == 2.0
    assert np.allclose(poly.points, [(-3, 3), (13, 3), (13, -13), (-3, -13)], atol=2e-3), poly.points
    assert np.allclose(circle.center, (5.0, -20.0), atol=2e-3)
    assert run.summary["outcome"] == "completed" and all(p["ok"] for p in run.summary["policies"])
    again = mission_from_table(tomllib.loads((plan.parent / "run" / "mission.toml").read_text()), "m.toml")
    assert again.geofence == fence


def test_a_run_that_leaves_the_fence_says_where_and_when_and_exits_1(tmp_path: Path, capsys) -> None:
    """The fence covers the L's north leg only (to 5 m east): the east leg leaves it. The vehicle holds the plan's
    fence as PX4 does and acts by GF_ACTION: 2 (PX4's default) holds where it left it, for COM_FAIL_ACT_T, then
    lands (its failsafe: outcome ``failsafe``, ended by the geofence); 1 (warning) flies on. Either way the
    ``geofence`` policy names the first row outside, the vehicle's ``geofence`` event is at that row, and the run
    exits 1."""
    plan = fenced_l(tmp_path, {"polygons": [{"inclusion": True, "version": 1, "polygon": l_rectangle(-3, 13, 3, 5)}]},
                    "leaves.plan")
    for action, outcome in ((2, "failsafe"), (1, "completed")):
        run = simulate(plan, out=tmp_path / f"run{action}", plots=False, params={"GF_ACTION": action})
        assert run.summary["outcome"] == outcome, run.summary["ended_by"]
        verdict = next(p for p in run.summary["policies"] if p["name"] == "geofence")
        assert not verdict["ok"] and "outside every inclusion zone of the geofence" in verdict["why"]
        i = int(np.searchsorted(run.trace["t"], verdict["t"] - 1e-9))
        assert -run.trace["y"][i] > 5.0 and -run.trace["y"][i - 1] <= 5.0 + 1e-3  # the first row past 5 m east
        (left,) = [e for e in run.summary["events"] if e["kind"] == "geofence"]
        assert left["t"] == pytest.approx(verdict["t"], abs=1e-6) and f"GF_ACTION = {action}" in left["text"]
        assert report_run(run, "sim") == 1
        assert "geofence" in capsys.readouterr().err
        east = -run.trace["y"][i:]
        if action == 2:  # held where it left (a 2 m overshoot braking from the leg's speed), then landed there
            assert "failsafe" in run.summary["ended_by"]["how"] and "geofence" in run.summary["ended_by"]["how"]
            assert east.max() < 7.5 and abs(east[-1] - east[0]) < 0.5, (east.max(), east[0], east[-1])
            kinds = [e["kind"] for e in run.summary["events"]]
            assert kinds.index("landing") > kinds.index("failsafe")  # (landing when the mission's time is up)
        else:  # flown on down the east leg, to its end 10 m east
            assert east.max() > 9.9


def test_a_flight_that_starts_outside_its_fence_is_not_armed(tmp_path: Path, capsys) -> None:
    """PX4's pre-arm geofence check: the fence begins 2 m north of the L's start, so with GF_ACTION > 0 (1, warning,
    included: PX4 denies for any action but none) the vehicle does not arm. Offline nothing flies: outcome
    ``denied``, ended by the vehicle saying why (its ``preflight`` event), exit 1 (``bsst sitl`` of the same plan:
    tests/test_sitl.py). GF_ACTION 0 arms and flies (the geofence policy still fails the run)."""
    plan = outside_fence_plan(tmp_path)
    why = OUTSIDE_WHY
    for action in (1, 2):
        run = simulate(plan, out=tmp_path / f"run{action}", plots=False, params={"GF_ACTION": action})
        assert run.summary["outcome"] == "denied" and len(run.trace["t"]) == 0, run.summary["ended_by"]
        assert run.summary["ended_by"]["who"] == "vehicle", run.summary["ended_by"]
        assert run.summary["ended_by"]["how"].startswith(f"{why} (GF_ACTION = {action}: "), run.summary["ended_by"]
        assert [e["kind"] for e in run.summary["events"]] == ["preflight"], run.summary["events"]
        assert report_run(run, "sim") == 1
        assert "input  n/a (nothing flew)" in capsys.readouterr().out
    flown = simulate(plan, plots=False, params={"GF_ACTION": 0})
    assert flown.summary["outcome"] == "completed" and len(flown.trace["t"]) > 0


def test_a_malformed_plan_fence_is_one_error_naming_the_file_and_key(tmp_path: Path) -> None:
    bad = fenced_l(tmp_path, {"polygons": [{"inclusion": True, "polygon": [[95.0, 8.5], [47.4, 8.5], [47.4, 8.6]]}]},
                   "bad.plan")
    with pytest.raises(ConfigError) as e:
        load_mission(bad)
    assert str(e.value) == f"{bad}: geoFence.polygons[0]: latitude 95, longitude 8.5: not a place on earth"
    bad = fenced_l(tmp_path, {"circles": [{"inclusion": True, "circle": {"radius": 3.0}}]}, "bad2.plan")
    with pytest.raises(ConfigError) as e:
        load_mission(bad)
    assert "geoFence.circles[0]: expected inclusion and circle {center [lat, lon], radius}" in str(e.value)
    bad = fenced_l(tmp_path, {"polygons": [{"inclusion": True, "polygon": [[47.4, 8.5], [47.4, 8.6]]}]}, "bad3.plan")
    with pytest.raises(ConfigError) as e:
        load_mission(bad)
    assert str(e.value) == (f"{bad}: geoFence.polygons[0]: polygon: expected 3 to 1000 points [lat, lon], "
                            "got [[47.4, 8.5], [47.4, 8.6]]")
    far = [[48.397, 8.545], [48.398, 8.545], [48.398, 8.546]]  # a degree north of the L's home: 111 km
    bad = fenced_l(tmp_path, {"polygons": [{"inclusion": True, "polygon": far}]}, "far.plan")
    with pytest.raises(ConfigError) as e:  # said in the plan's terms: it quoted the metres, under a key "points"
        load_mission(bad)
    assert str(e.value) == (f"{bad}: geoFence.polygons[0]: latitude 48.397, longitude 8.545: 111.112 km north, "
                            "0.044 km west of the plan's home; a fence's points lie within 100 km of it each way")
    for table, typo, key in (("geofence", "zone", "zones"), ("rally", "point", "points")):
        with pytest.raises(ConfigError) as e:
            mission_from_table({"duration_s": 1.0, "trajectory": {"kind": "sine"}, table: {typo: []}}, "m.toml")
        assert str(e.value) == f"m.toml: {table}.{typo}: unknown key in [{table}]; did you mean '{key}'?"


def test_a_plans_rally_points_are_read_about_its_home_and_kept_in_mission_toml(tmp_path: Path,
                                                                               fenced_and_rallied) -> None:
    """``rallyPoints`` [[lat, lon, alt], ...]: each point's x, y in the paper frame (its height not used: Return
    lands on the flat ground there); mission.toml holds ``[rally]``, which reads back the same."""
    flown, run = fenced_and_rallied
    m = load_mission(flown)
    assert np.allclose(m.rally, [(5.0, -5.0), (-2.0, 0.0)], atol=2e-3), m.rally
    again = mission_from_table(tomllib.loads((flown.parent / "run" / "mission.toml").read_text()), "m.toml")
    assert again.rally == m.rally and run.summary["outcome"] == "completed"
    data = json.loads(flown.read_text())
    plan = tmp_path / "rally.plan"
    data["rallyPoints"]["points"][1] = [*l_latlon(150.0, 0.0), 490.0]
    plan.write_text(json.dumps(data))
    with pytest.raises(ConfigError) as e:
        load_mission(plan)
    assert str(e.value) == (f"{plan}: rallyPoints.points[1]: latitude {l_latlon(150.0, 0.0)[0]:g}, longitude "
                            f"{l_latlon(150.0, 0.0)[1]:g}: 150 m from the plan's home; rally points lie within 100 m "
                            "of it")  # the plan's own terms (it said "expected [x, y]" of the metres it became)
    with pytest.raises(ConfigError) as e:
        mission_from_table({"duration_s": 1.0, "trajectory": {"kind": "sine"}, "rally": {"points": [[1.0]]}}, "m.toml")
    assert str(e.value).startswith("m.toml: rally.points: point 0: expected [x, y]"), str(e.value)


def test_the_vehicle_watches_its_fence_by_its_estimate_as_px4s_geofence_does() -> None:
    """PX4's geofence reads the estimate, not the truth. A GPS jump of 12 m north at 3 s under the raw estimator
    puts the position the vehicle knows outside an 8 m square: it holds there (GF_ACTION 2) at the next fix, its
    event and the run's ``geofence`` verdict saying "by its estimate", while the true position never leaves the
    square. Under the EKF the same jump is gated out and the flight completes; under truth nothing changes (the
    tests above)."""
    square = Zone(True, points=((-8.0, -8.0), (8.0, -8.0), (8.0, 8.0), (-8.0, 8.0)))
    fenced = Mission(Sine(), duration_s=8.0, name="jump", geofence=Geofence((square,)))
    jump = {"sensors": {"set": "gnss"}, "at": ("3:gps:jump=12,0,0",), "params": {"GF_ACTION": 2}, "plots": False}
    raw = simulate(fenced, estimator="raw", **jump)
    [left] = [e for e in raw.summary["events"] if e["kind"] == "geofence"]
    assert 3.0 < left["t"] < 3.5 and "(by its estimate)" in left["text"], left
    assert raw.summary["outcome"] == "failsafe" and "(by its estimate)" in raw.summary["ended_by"]["how"]
    assert np.abs(raw.trace["x"]).max() < 8.0 and np.abs(raw.trace["y"]).max() < 8.0  # truly inside throughout
    ekf = simulate(fenced, estimator="ekf", **jump)
    assert ekf.summary["outcome"] == "completed", ekf.summary["ended_by"]

"""Covers missions.route and bridge.mavlink.missionitems: a NAV_LAND (NAV_TAKEOFF) with no latitude and longitude
lands (takes off) where it is.

QGroundControl writes a value not given as null (a .plan) or nan (a waypoint file), and a legacy MISSION_ITEM
carries it as NaN; PX4 takes a NAV_LAND whose latitude and longitude are NaN as "descend at current position" (its
own land-here item is one: ``MissionBlock::set_land_item``) and its parser keeps the NaN. Until the forty-fifth
session the plan reader refused it (``coordinates must be numbers, got lat null, lon null``, exit 2) and the mission
upload answered it MAV_MISSION_INVALID_PARAM5_X. Now a plan file, a waypoint file and an upload (MISSION_ITEM's NaN,
MISSION_ITEM_INT's INT32_MAX, MAVLink's "optional") fly it as a land over the point the vehicle is at; one of the
two given alone is still refused, naming both. A NAV_TAKEOFF with neither (MAVSDK's and scripts' takeoffs) was still
refused so after that (the same message; INVALID_PARAM5_X), though PX4 flies it over the position it holds
(``FlightTaskAuto``: "No position provided in xy. Lock position"); since the forty-fifth session it takes off where
it is, by the same code as the land.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as M

from bridge.cli import main
from bridge.mavlink.missionitems import INT32_MAX, NOT_GIVEN, ItemRefused, item_message, parse_item, plan_of
from bridge.session import instance_slot
from missions.geodetic import Home
from missions.route import Limits, stops_of
from params import ConfigError
from tests.gcskit import command_ack, gcs_link, vehicle_of
from tests.sitlkit import Proc, clean_exit

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast

HOME = (47.397742, 8.545594, 488.0)  # the vehicle's default home (deg, deg, m AMSL)
NORTH = 2.0 / 111_194.9  # deg of latitude: about 2 m
WAYPOINT = Home(*HOME).paper(HOME[0] + NORTH, HOME[1], HOME[2])[:2]  # the waypoint's x, y (m, paper frame)


def _plan(land: tuple[Any, Any], takeoff: tuple[Any, Any] = (0, 0)) -> dict[str, Any]:
    """A takeoff to 1 m at ``takeoff`` (lat, lon; 0, 0: here), a waypoint 2 m north at 1 m, a landing at ``land``."""
    def item(k: int, cmd: int, lat: Any, lon: Any, alt: float) -> dict[str, Any]:
        return {"autoContinue": True, "command": cmd, "doJumpId": k + 1, "frame": 3, "type": "SimpleItem",
                "params": [0, 0, 0, None, lat, lon, alt]}

    return {"fileType": "Plan", "version": 1, "groundStation": "QGroundControl",
            "geoFence": {"version": 2, "circles": [], "polygons": []}, "rallyPoints": {"version": 2, "points": []},
            "mission": {"version": 2, "firmwareType": 12, "vehicleType": 2, "cruiseSpeed": 15, "hoverSpeed": 5,
                        "plannedHomePosition": list(HOME),
                        "items": [item(0, 22, *takeoff, 1.0), item(1, 16, HOME[0] + NORTH, HOME[1], 1.0),
                                  item(2, 21, *land, 0.0)]}}


def _here_file(tmp_path: Path, kind: str, stem: str, takeoff: tuple[Any, Any]) -> Path:
    """:func:`_plan`'s mission with its land here (null, null), as a .plan or as a waypoint file (null there: nan),
    written as tmp_path/stem.plan or .waypoints."""
    if kind == "plan":
        path = tmp_path / f"{stem}.plan"
        path.write_text(json.dumps(_plan((None, None), takeoff=takeoff), indent=4))
        return path
    lat, lon = ("nan" if v is None else str(v) for v in takeoff)
    path = tmp_path / f"{stem}.waypoints"
    path.write_text("QGC WPL 110\n"
                    f"0\t1\t0\t16\t0\t0\t0\t0\t{HOME[0]}\t{HOME[1]}\t{HOME[2]}\t1\n"
                    f"1\t0\t3\t22\t0\t0\t0\tnan\t{lat}\t{lon}\t1.0\t1\n"
                    f"2\t0\t3\t16\t0\t0\t0\tnan\t{HOME[0] + NORTH!r}\t{HOME[1]}\t1.0\t1\n"
                    "3\t0\t3\t21\t0\t0\t0\tnan\tnan\tnan\t0\t1\n")
    return path


def _last_row(run: Path) -> dict[str, float]:
    lines = (run / "trace.csv").read_text().splitlines()
    return {k: float(v) for k, v in zip(lines[0].split(","), lines[-1].split(","), strict=False)}


def _landed_at(run: Path, at: tuple[float, float]) -> None:
    """The trace's last row is on the ground within 5 cm of ``at`` (x, y m, paper frame)."""
    end = _last_row(run)
    assert math.dist((end["x"], end["y"]), at) < 0.05, (end["x"], end["y"], at)
    assert end["z"] < 0.01, end["z"]


def _landed_at_the_waypoint(run: Path) -> None:
    _landed_at(run, WAYPOINT)
    summary = json.loads((run / "summary.json").read_text())
    assert summary["outcome"] == "completed" and summary["end"]["disarmed"], summary["outcome"]


@pytest.mark.parametrize("kind", ["plan", "waypoints"])
def test_a_files_land_with_no_position_lands_where_it_is(capsys: Any, tmp_path: Path, kind: str) -> None:
    """A .plan's null, null and a waypoint file's nan, nan: the flight lands under the waypoint, not at the home."""
    path = _here_file(tmp_path, kind, "here", (0, 0))
    out = tmp_path / "run"
    assert main(["sim", str(path), "--no-plots", "--out", str(out)]) == 0, capsys.readouterr().err
    _landed_at_the_waypoint(out)


def test_a_land_with_one_of_the_two_given_is_refused_naming_both(capsys: Any, tmp_path: Path) -> None:
    path = tmp_path / "half.plan"
    path.write_text(json.dumps(_plan((None, HOME[1]))))
    assert main(["sim", str(path), "--no-plots", "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"bsst: {path}: mission.items[2] (NAV_LAND (21)): latitude null, longitude {HOME[1]}: give both "
                   "(the landing point) or neither (both null: land where it is)"], err


def _legacy(seq: int, cmd: int, lat: float, lon: float, alt: float) -> Any:
    return M.MAVLink_mission_item_message(0, 0, seq, M.MAV_FRAME_GLOBAL_RELATIVE_ALT, cmd, 0, 1, 0.0, 0.0, 0.0,
                                          math.nan, lat, lon, alt, 0)


def _int(seq: int, cmd: int, x: int, y: int, alt: float) -> Any:
    return M.MAVLink_mission_item_int_message(0, 0, seq, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, cmd, 0, 1, 0.0, 0.0,
                                              0.0, math.nan, x, y, alt, 0)


def _held_as_not_given(seq: int, cmd: int, alt: float) -> None:
    """``cmd``'s MISSION_ITEM at NaN, NaN and MISSION_ITEM_INT at INT32_MAX, INT32_MAX: each held as NOT_GIVEN,
    downloaded as each form writes "not given" (NaN; INT32_MAX), given to the route as NaN, NaN."""
    for msg, int_mode in ((_legacy(seq, cmd, math.nan, math.nan, alt), False),
                          (_int(seq, cmd, INT32_MAX, INT32_MAX, alt), True)):
        it = parse_item(msg, int_mode)
        assert (it.x, it.y) == NOT_GIVEN
        back = item_message(it, (255, 190), False, False)
        assert math.isnan(back.x) and math.isnan(back.y)
        back = item_message(it, (255, 190), False, True)
        assert (back.x, back.y) == (INT32_MAX, INT32_MAX)
        plan = plan_of((it,), HOME, "held")
        assert math.isnan(plan.items[0].lat) and math.isnan(plan.items[0].lon)


def _refused(*cases: tuple[Any, bool, int]) -> None:
    """Each (message, whether a MISSION_ITEM_INT, MAV_MISSION_RESULT): the parser refuses it with that result."""
    for msg, int_mode, result in cases:
        with pytest.raises(ItemRefused) as exc:
            parse_item(msg, int_mode)
        assert exc.value.result == result


def test_the_parser_takes_a_land_with_no_position_and_sends_it_back_as_given() -> None:
    """MISSION_ITEM NaN, NaN and MISSION_ITEM_INT INT32_MAX, INT32_MAX on a NAV_LAND: held as NOT_GIVEN, downloaded
    as each form writes "not given", and flown as a land here (plan_of: NaN, NaN). On a waypoint, or one of the two
    alone, refused as before."""
    _held_as_not_given(2, M.MAV_CMD_NAV_LAND, 0.0)
    _refused((_legacy(2, M.MAV_CMD_NAV_LAND, math.nan, HOME[1], 0.0), False, M.MAV_MISSION_INVALID_PARAM5_X),
             (_legacy(2, M.MAV_CMD_NAV_LAND, HOME[0], math.nan, 0.0), False, M.MAV_MISSION_INVALID_PARAM6_Y),
             (_legacy(2, M.MAV_CMD_NAV_WAYPOINT, math.nan, math.nan, 1.0), False, M.MAV_MISSION_INVALID_PARAM5_X),
             (_int(2, M.MAV_CMD_NAV_WAYPOINT, INT32_MAX, INT32_MAX, 1.0), True, M.MAV_MISSION_INVALID_PARAM5_X))


def _upload_and_fly(tmp_path: Path, items: list[Any]) -> tuple[dict[str, Any], Path]:
    """A pymavlink ground station uploads ``items`` to ``bsst sitl --await-mission`` (lockstep), which must accept
    them, and starts the mission; the run's summary and folder once it is flown."""
    out = tmp_path / "run"
    with instance_slot() as n:
        gcs = gcs_link(n)
        sitl = Proc.bsst("sitl", "--await-mission", "--speed", "0", "--instance", str(n), "--out", str(out),
                         "--no-plots", "--param", "COM_DISARM_LAND=0.5")
        try:
            target = vehicle_of(gcs)
            gcs.mav.mission_count_send(*target, len(items), 0)
            while (m := gcs.recv_match(type=["MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"], blocking=True,
                                       timeout=10)) is not None and m.get_type() != "MISSION_ACK":
                items[m.seq].target_system, items[m.seq].target_component = target
                gcs.mav.send(items[m.seq])  # (legacy items: the vehicle asks with MISSION_REQUEST, as PX4 does)
            assert m is not None and m.type == M.MAV_MISSION_ACCEPTED, m  # INVALID_PARAM5_X on the old code
            gcs.mav.command_long_send(*target, M.MAV_CMD_MISSION_START, 0, 0, 0, 0, 0, 0, 0, 0)
            assert command_ack(gcs, M.MAV_CMD_MISSION_START).result == M.MAV_RESULT_ACCEPTED
            rc = sitl.p.wait(timeout=120)
        finally:
            gcs.close()
            sitl.stop()
    summary = json.loads((out / "summary.json").read_text())
    assert rc == clean_exit(summary), "\n".join(sitl.lines[-30:])
    assert summary["outcome"] == "completed", summary["outcome"]
    return summary, out


def test_an_uploaded_land_with_no_position_is_flown_where_it_is(tmp_path: Path) -> None:
    """Legacy MISSION_ITEMs (a takeoff here, the waypoint, a land at NaN, NaN): ACCEPTED, flown, landed under the
    waypoint."""
    items = [_legacy(0, M.MAV_CMD_NAV_TAKEOFF, 0.0, 0.0, 1.0),
             _legacy(1, M.MAV_CMD_NAV_WAYPOINT, HOME[0] + NORTH, HOME[1], 1.0),
             _legacy(2, M.MAV_CMD_NAV_LAND, math.nan, math.nan, 0.0)]
    _, out = _upload_and_fly(tmp_path, items)
    # the waypoint as a MISSION_ITEM carried it: float32 degrees (about 0.2 m apart)
    _landed_at(out, Home(*HOME).paper(float(np.float32(HOME[0] + NORTH)), float(np.float32(HOME[1])), HOME[2])[:2])


def _took_off_over_the_home(run: Path) -> None:
    """The trace's first row 0.5 m up is over the home (the takeoff climbs straight up where the vehicle is)."""
    lines = (run / "trace.csv").read_text().splitlines()
    head = lines[0].split(",")
    rows = ({k: float(v) for k, v in zip(head, line.split(","), strict=False)} for line in lines[1:])
    up = next(r for r in rows if r["z"] >= 0.5)
    assert math.hypot(up["x"], up["y"]) < 0.05, (up["x"], up["y"])


@pytest.mark.parametrize("kind", ["plan", "waypoints"])
def test_a_files_takeoff_with_no_position_takes_off_where_it_is(capsys: Any, tmp_path: Path, kind: str) -> None:
    """A .plan's takeoff at null, null and a waypoint file's at nan, nan (then the waypoint, a land here): flown,
    straight up over the home, landed under the waypoint. The old code refused it (``coordinates must be numbers``,
    exit 2)."""
    path = _here_file(tmp_path, kind, "up", (None, None))
    out = tmp_path / "run"
    assert main(["sim", str(path), "--no-plots", "--out", str(out)]) == 0, capsys.readouterr().err
    _took_off_over_the_home(out)
    _landed_at_the_waypoint(out)


def test_a_takeoff_with_one_of_the_two_given_is_refused_naming_both(capsys: Any, tmp_path: Path) -> None:
    path = tmp_path / "half.plan"
    path.write_text(json.dumps(_plan((None, None), takeoff=(HOME[0], None))))
    assert main(["sim", str(path), "--no-plots", "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"bsst: {path}: mission.items[0] (NAV_TAKEOFF (22)): latitude {HOME[0]}, longitude null: give "
                   "both (the takeoff point) or neither (both null: take off where it is)"], err


@pytest.mark.parametrize("at", [(None, None), (0, 0)], ids=["null", "zero"])
def test_a_takeoff_here_without_an_altitude_is_refused_naming_what_the_file_gives(capsys: Any, tmp_path: Path,
                                                                                  at: tuple[Any, Any]) -> None:
    """A takeoff here (null, null or 0, 0) whose altitude is null: refused naming its altitude and the latitude and
    longitude the file gives. Until the forty-fifth session's review the refusal named the home's, which the route
    puts in their place to find the altitude (``coordinates must be numbers, got lat 47.397742, lon 8.545594, alt
    null`` of a file holding null, null, null)."""
    plan = _plan((None, None), takeoff=at)
    plan["mission"]["items"][0]["params"][6] = None
    path = tmp_path / "noalt.plan"
    path.write_text(json.dumps(plan))
    assert main(["sim", str(path), "--no-plots", "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    shown = "null" if at[0] is None else "0.0"
    assert err == [f"bsst: {path}: mission.items[0] (NAV_TAKEOFF (22)): takeoff altitude null: not a number "
                   f"(latitude {shown}, longitude {shown}: it takes off where it is)"], err


def test_the_parser_takes_a_takeoff_with_no_position_and_sends_it_back_as_given() -> None:
    """MISSION_ITEM NaN, NaN and MISSION_ITEM_INT INT32_MAX, INT32_MAX on a NAV_TAKEOFF: held as NOT_GIVEN,
    downloaded as each form writes "not given", given to the route as NaN, NaN; one of the two alone refused."""
    _held_as_not_given(0, M.MAV_CMD_NAV_TAKEOFF, 1.0)
    _refused((_legacy(0, M.MAV_CMD_NAV_TAKEOFF, math.nan, HOME[1], 1.0), False, M.MAV_MISSION_INVALID_PARAM5_X),
             (_int(0, M.MAV_CMD_NAV_TAKEOFF, int(HOME[0] * 1e7), INT32_MAX, 1.0), True, M.MAV_MISSION_INVALID_PARAM6_Y))


def test_an_uploaded_takeoff_with_no_position_is_flown_where_it_is(tmp_path: Path) -> None:
    """MISSION_ITEM_INTs as MAVSDK sends them (a takeoff at INT32_MAX, INT32_MAX, MAVLink's "not given"; the
    waypoint; a land likewise): ACCEPTED (INVALID_PARAM5_X on the old code), flown straight up over the home, landed
    under the waypoint."""
    items = [_int(0, M.MAV_CMD_NAV_TAKEOFF, INT32_MAX, INT32_MAX, 1.0),
             _int(1, M.MAV_CMD_NAV_WAYPOINT, round((HOME[0] + NORTH) * 1e7), round(HOME[1] * 1e7), 1.0),
             _int(2, M.MAV_CMD_NAV_LAND, INT32_MAX, INT32_MAX, 0.0)]
    _, out = _upload_and_fly(tmp_path, items)
    _took_off_over_the_home(out)
    _landed_at(out, Home(*HOME).paper(round((HOME[0] + NORTH) * 1e7) / 1e7, round(HOME[1] * 1e7) / 1e7, HOME[2])[:2])


@pytest.mark.parametrize("at", [(None, None), (HOME[0] + NORTH, HOME[1])], ids=["here", "north"])
def test_a_mission_that_starts_with_a_landing_is_refused_as_px4_refuses_it(capsys: Any, tmp_path: Path,
                                                                           at: tuple[Any, Any]) -> None:
    """A plan whose first item that flies is a NAV_LAND, the vehicle on the ground: refused naming the item and
    PX4's words (its FeasibilityChecker: "Mission rejected: starts with landing"), exit 2, nothing written. Before,
    a land here was refused as "no position to fly to (no NAV_ item)", and a land 2 m north was planned as a slide
    along the ground: the vehicle never moved, and the run said completed, exit 0, its 3-D RMS error 2 m. The same
    refusal stops an upload's MISSION_START (plan_of: the vehicle's start check)."""
    plan = _plan(at)
    plan["mission"]["items"] = plan["mission"]["items"][2:]
    path = tmp_path / "land.plan"
    path.write_text(json.dumps(plan))
    out = tmp_path / "run"
    assert main(["sim", str(path), "--no-plots", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"bsst: {path}: mission.items[0] (NAV_LAND (21)): a landing as the first item that flies, the "
                   "vehicle still on the ground (PX4 rejects a mission whose item 0 is one: \"Mission rejected: "
                   "starts with landing\"); take off first (NAV_TAKEOFF)"], err
    assert not out.exists()
    held = plan_of((parse_item(_int(0, M.MAV_CMD_NAV_LAND, INT32_MAX, INT32_MAX, 0.0), True),), HOME, "held")
    with pytest.raises(ConfigError, match="starts with landing"):
        stops_of(held, Limits(), 100.0)


def test_a_leg_along_the_ground_is_refused_naming_it(capsys: Any, tmp_path: Path) -> None:
    """A first waypoint at 0 m, 2 m north of the home: the vehicle on the ground cannot fly there. Refused naming
    the item and the leg, exit 2. Before, it was planned as a slide along the ground at 0 m: the vehicle stood at
    the home throughout and the run said completed, exit 0, every policy holding, its 3-D RMS error 2 m."""
    plan = _plan((None, None))
    plan["mission"]["items"] = plan["mission"]["items"][1:2]
    plan["mission"]["items"][0]["params"][6] = 0.0
    path = tmp_path / "slide.plan"
    path.write_text(json.dumps(plan))
    out = tmp_path / "run"
    assert main(["sim", str(path), "--no-plots", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"bsst: {path}: mission.items[0] (NAV_WAYPOINT (16)): flies 2.00 m "
                                               "along the ground (from x=0.00 y=0.00 m to x=2.00 y="), err
    assert err[0].endswith("a vehicle on the ground cannot; climb first (NAV_TAKEOFF, or a waypoint above the "
                           "ground)"), err
    assert not out.exists()


def test_a_takeoff_after_an_item_that_flies_is_refused_as_px4_refuses_it(capsys: Any, tmp_path: Path) -> None:
    """A takeoff here, the waypoint, then a second takeoff here to 3 m: PX4's FeasibilityChecker::checkTakeoff rejects
    it ("Mission rejected: takeoff not first waypoint item"). Refused naming the item and the one before it, exit 2.
    Before, it flew (a climb from 1 m to 3 m over the waypoint) and said completed, exit 0."""
    plan = _plan((None, None), takeoff=(None, None))
    again = json.loads(json.dumps(plan["mission"]["items"][0]))
    again["params"][6] = 3.0
    plan["mission"]["items"].insert(2, again)
    path = tmp_path / "again.plan"
    path.write_text(json.dumps(plan))
    out = tmp_path / "run"
    assert main(["sim", str(path), "--no-plots", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"bsst: {path}: mission.items[2] (NAV_TAKEOFF (22)): a takeoff after mission.items[1], an item "
                   "that flies (PX4 rejects it: \"Mission rejected: takeoff not first waypoint item\"); make it the "
                   "first item that flies"], err
    assert not out.exists()


def test_a_first_waypoint_from_the_ground_is_climbed_to_straight_up_as_px4_does(capsys: Any, tmp_path: Path) -> None:
    """No NAV_TAKEOFF: the waypoint 2 m north at 1 m, then a land here. PX4's mission (Mission::do_need_vertical_
    takeoff) climbs straight up over where the vehicle stands to the higher of the waypoint's altitude and
    MIS_TAKEOFF_ALT (2.5 m), then flies to it. Before, the route climbed along the straight line from the home to the
    waypoint: 0.5 m up, the vehicle was already 0.58 m north, and it never rose above 1 m."""
    plan = _plan((None, None))
    plan["mission"]["items"] = plan["mission"]["items"][1:]
    path = tmp_path / "nota.plan"
    path.write_text(json.dumps(plan))
    out = tmp_path / "run"
    assert main(["sim", str(path), "--no-plots", "--out", str(out)]) == 0, capsys.readouterr().err
    _took_off_over_the_home(out)
    lines = (out / "trace.csv").read_text().splitlines()
    z = lines[0].split(",").index("z")
    assert max(float(line.split(",")[z]) for line in lines[1:]) > 2.49
    _landed_at_the_waypoint(out)

"""Covers bridge.record.wallclock, bridge.session.fleet and bridge.swarm: a SITL fleet's vehicle that flies on.

Real processes: ``bridge.swarm.sitl`` flies two vehicles in lockstep at real time's pace (a vehicle and a controller
process each, free ports), their ground-station links to one UDP port. Vehicle 2 hovers 1.6 m under vehicle 1. A
ground station (MAVSDK's native binding, or MAVProxy typed to) takes vehicle 2 over with a takeoff to 2.5 m: it
leaves the shared step clock and climbs, on the wall clock, into vehicle 1. Its session keeps it flying under the
ground station until the rest of the fleet is done, and the fleet judges its record: the contact is found (both
``collision``, ``continued``), the separation does not hold, exit 1. Before, its session stopped it 40 ms after
the takeover and the fleet took it as standing where it left the shared clock: separation held.
A failsafe landing still going at the mission's end (a blackout of both links), flown on the wall clock onto the
vehicle below: judged on its record, the contact said as found afterwards, not as ending both flights there.
In real time (``--realtime``) the same takeover: vehicle 2 flies on under the ground station too, recorded, judged on
its record, said in ``separation.taken_over`` (before, its session stopped it at once and the fleet took it as
standing where it was stopped: separation held, nothing said).
"""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

import pytest

from bridge.cli.runreport import report_fleet
from bridge.record.separation import CONTINUED, WALL_CLOCK
from bridge.session.children import free_udp_port
from bridge.swarm import FleetRun, simulate, sitl
from tests.sitlkit import ENV, MAVSDK_GROUND_STATION, run_script, script_result

pytestmark = pytest.mark.process  # starts processes, opens sockets

TAKEOVER = Path(__file__).resolve().parents[1] / "examples" / "swarm-takeover.toml"  # vehicle 2 under vehicle 1
# s of vehicle 1's hover over vehicle 2 cut (9-12 s): taken over at ~3.74 s quiet, in contact by ~4.7 s (4.64-4.66 s
# at load 10, forty-fifth session), at 5.33 and 6.24 s in real time with the file's three tests on two workers;
# vehicle 1 leaves it from 9 s (10 s until the forty-fifth session: a second more of both paced pairs, ~0.3 CPU-s a
# test, after the contact)
CUT_S = 3.0
END_S = 14.0 - CUT_S  # the cut mission's end
# the takeovers' control rate, Hz: the example's 250 stepped each paced pair ~0.08 CPU-s a second more
# (tests/test_swarm_gcs.py); a step of 8 ms is within the 10 ms to which where vehicle 2 left the shared clock
# (``from_t``, a step's time) must match the takeover's time
TAKEOVER_HZ = 125.0


def _cut(tmp_path: Path, hold: bool) -> Path:
    """The example with vehicle 1's hover over vehicle 2 cut to 2-9 s, its leg along x and the mission's end
    :data:`CUT_S` earlier (vehicle 2 under it from 4 s, as in the example): the example's three seconds more of hover
    checked nothing. ``hold``: its end holds (``[end] action = "hold"``): vehicle 1's end landing (down from 2.6 m
    and COM_DISARM_LAND after), beside which vehicle 2, taken over, flew on on the wall clock, ~6 s of both paced
    pairs, checked nothing either."""
    text = TAKEOVER.read_text()
    later = {"duration_s = 14.0": f"duration_s = {END_S}", "t = 12.0, x = 0.0, y = 0.0, z = 2.6":
             f"t = {12.0 - CUT_S}, x = 0.0, y = 0.0, z = 2.6", "t = 14.0, x = 3.0": f"t = {END_S}, x = 3.0",
             "t = 14.0, x = 0.0, y = 0.0, z = 1.0": f"t = {END_S}, x = 0.0, y = 0.0, z = 1.0"}
    for was, now in later.items():
        assert text.count(was) == 1, was  # (the example as these tests know it)
        text = text.replace(was, now)
    mission = tmp_path / "swarm-takeover.toml"
    mission.write_text(text + ('\n[end]\naction = "hold"\n' if hold else ""))
    return mission


def _fly(tmp_path: Path, port: int, **kw: Any) -> tuple[threading.Thread, dict[str, Any], Path]:
    """The fleet (:func:`_cut`, its end held) in lockstep at real time's pace, its control at :data:`TAKEOVER_HZ`,
    its ground-station links to ``port``, in a thread."""
    mission = _cut(tmp_path, hold=True)
    result: dict[str, Any] = {}

    def fly() -> None:
        try:
            result["run"] = sitl(mission, instance=None, gcs=f"127.0.0.1:{port}", speed=1.0, out=tmp_path / "run",
                                 plots=False, rate_hz=TAKEOVER_HZ, **kw)
        except BaseException as exc:  # noqa: BLE001  (named by the caller's assertion)
            result["error"] = exc

    flight = threading.Thread(target=fly, daemon=True)
    flight.start()
    return flight, result, mission


def _judged_into_its_neighbour(result: dict[str, Any], mission: Path, capsys: Any) -> None:
    """The fleet judged vehicle 2's climb on its record: the contact found, the separation broken, exit 1."""
    assert "error" not in result, result.get("error")
    run = result["run"]
    assert isinstance(run, FleetRun)
    s = run.summary
    v1, v2 = s["vehicles"]
    assert "TAKEOFF" in v2["ended_by"]["how"] and "gcs" in v2["ended_by"]["who"], v2["ended_by"]
    taken = next(e["t"] for e in run.runs[1].summary["events"] if e["kind"] == "mode" and "TAKEOFF" in e["text"])
    for v, other in ((v1, 2), (v2, 1)):  # found afterwards on the records: the flights went on
        assert v["outcome"] == "collision" and v["contact"]["with"] == other, v
        assert v["contact"]["continued"] == WALL_CLOCK and v["contact"]["t"] > taken, (v, taken)
    policy = s["policies"][0]
    assert policy["name"] == "separation" and not policy["ok"] and policy["t"] > taken, policy
    flown = s["separation"]["wall_clock"]
    assert [f["id"] for f in flown] == [2] and flown[0]["from_t"] == pytest.approx(taken, abs=0.01), flown
    assert flown[0]["to_t"] >= END_S and s["separation"]["whole_flight"] is True, flown  # flown on to the end
    assert s["sitl"]["note"] == WALL_CLOCK
    assert max(run.runs[1].trace["z"]) > 1.9  # its record holds the climb
    off = simulate(mission, plots=False, rate_hz=TAKEOVER_HZ)  # as planned, the separation holds
    assert off.outcome == "completed" and off.summary["policies"][0]["ok"]
    capsys.readouterr()
    assert report_fleet(run, "sitl") == 1
    out, err = capsys.readouterr()
    assert "vehicle 2 flew on the wall clock from t=" in out and "judged only until" not in out, out
    assert "the flights went on: found afterwards" in err and "both flights ended there" not in err, err


MAVSDK_TAKEOFF = MAVSDK_GROUND_STATION + r"""
from mavsdk.plugins.action import Action
from mavsdk.plugins.telemetry import Telemetry
out["two_found"] = until(lambda: sum(s.has_autopilot() for s in sdk.get_systems()) >= 2, 90)
by = {s.get_system_id(): s for s in sdk.get_systems() if s.has_autopilot()}
tel = {i: Telemetry(s) for i, s in by.items()}
def under():  # vehicle 2 (about its own start, 2 m west of vehicle 1's) under vehicle 1
    a, b = (tel[i].position_velocity_ned().position for i in (1, 2))
    return a.down_m < -2.5 and b.east_m > 1.95 and b.down_m < -0.95
out["under"] = until(under, 90)
out["takeoff"] = Action(by[2]).takeoff().name
out["climbed"] = until(lambda: tel[2].position_velocity_ned().position.down_m < -1.9, 30)
print("RESULT " + json.dumps(out), flush=True)
sdk.destroy()
"""


def _taken_off(tmp_path: Path, realtime: bool) -> tuple[dict[str, Any], Path]:
    """The fleet flown (:func:`_fly`) while MAVSDK takes vehicle 2 off into vehicle 1 (:data:`MAVSDK_TAKEOFF`, which
    must have found both, seen 2 under 1, had its takeoff accepted and seen it climb): the flight's result, the
    mission."""
    port = free_udp_port()
    flight, result, mission = _fly(tmp_path, port, realtime=realtime)
    try:
        r = run_script("-c", MAVSDK_TAKEOFF, f"udpin://127.0.0.1:{port}", timeout=240, env=ENV)
    finally:
        flight.join(240)
    out = script_result(r)
    assert out["two_found"] and out["under"] and out["takeoff"] == "SUCCESS" and out["climbed"], out
    return result, mission


def test_mavsdk_takes_a_fleet_vehicle_off_into_its_neighbour_and_the_fleet_judges_its_climb(
        tmp_path: Path, capsys: Any) -> None:
    result, mission = _taken_off(tmp_path, realtime=False)
    _judged_into_its_neighbour(result, mission, capsys)
    events = (tmp_path / "run" / "vehicle-2" / "events.log").read_text()
    assert "flies on under it, on the wall clock" in events, events


def test_in_real_time_a_vehicle_taken_over_flies_on_under_its_ground_station_and_is_judged(
        tmp_path: Path, capsys: Any) -> None:
    result, mission = _taken_off(tmp_path, realtime=True)
    assert "error" not in result, result.get("error")
    run = result["run"]
    s = run.summary
    assert s["clock"] == "realtime" and "TAKEOFF" in s["vehicles"][1]["ended_by"]["how"]
    taken = next(e["t"] for e in run.runs[1].summary["events"] if e["kind"] == "mode" and "TAKEOFF" in e["text"])
    for v, other in zip(s["vehicles"], (2, 1)):  # its climb into vehicle 1, on its record
        assert v["outcome"] == "collision" and v["contact"]["with"] == other, v
        assert v["contact"]["continued"] == CONTINUED and v["contact"]["t"] > taken, (v, taken)
    policy = s["policies"][0]
    assert policy["name"] == "separation" and not policy["ok"] and policy["t"] > taken, policy
    (flown,) = s["separation"]["taken_over"]
    assert flown["id"] == 2 and flown["from_t"] == pytest.approx(taken, abs=0.01) and flown["to_t"] >= END_S, flown
    assert flown["judged_until_t"] is None and s["separation"]["whole_flight"] is True
    assert run.runs[1].summary["sitl"]["flew_on"] is True and max(run.runs[1].trace["z"]) > 1.9
    capsys.readouterr()
    assert report_fleet(run, "sitl") == 1
    printed = capsys.readouterr().out
    assert "vehicle 2 taken over by a ground station (" in printed and "flew on under it to t=" in printed, printed


def test_a_failsafe_landing_going_at_the_missions_end_is_judged_on_its_record(tmp_path: Path, capsys: Any) -> None:
    """Both links black from 9 s (the example's 12 s, :func:`_cut`): each vehicle's failsafe descends from 9.5 s,
    vehicle 1 from 2.6 m onto vehicle 2, landed under it, after the mission's end (11 s), on the wall clock: the
    contact is found on the records, after the mission, and said as found afterwards (before: "both flights ended
    there", which they had not)."""
    run = sitl(_cut(tmp_path, hold=False), instance=None, out=tmp_path / "run", plots=False,
               link={"blackouts": [[12.0 - CUT_S, 10.0]]})
    assert isinstance(run, FleetRun)
    s = run.summary
    for v in s["vehicles"]:
        assert v["outcome"] == "collision" and v["contact"]["continued"] == WALL_CLOCK and v["contact"]["t"] > END_S, v
    flown = s["separation"]["wall_clock"]
    assert [f["id"] for f in flown] == [1, 2] and all(f["at_rest"] and f["from_t"] == END_S for f in flown), flown
    assert s["separation"]["whole_flight"] is True and not s["policies"][0]["ok"]
    capsys.readouterr()
    assert report_fleet(run, "sitl") == 1
    err = capsys.readouterr().err
    assert "the flights went on: found afterwards" in err and "both flights ended there" not in err, err

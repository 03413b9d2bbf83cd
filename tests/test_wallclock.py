"""Covers bridge.record.wallclock and bridge.cli.runreport: a lockstep fleet's records as separation is judged on them.

Pure (finished records in memory, no processes): a vehicle on the shared clock to its end is judged as before (its
end landing up to the step it left, then where its gate said it stayed); one that flew on, on the wall clock, is
judged on every row it recorded, matched by step, a contact there said as found afterwards; after its last row it
stays there when at rest (disarmed, its mission completed, crashed), and is nowhere known when its record ended in
flight while another's went on: the fleet summary then says who was judged only until when and why, the
``separation`` policy does not hold, the printed summary says so and the exit status is 1. A real-time fleet's
vehicle disarmed in the air stays on the ground below its last row, as a lockstep one does.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from bridge.cli.runreport import report_fleet
from bridge.record.runlog import Run
from bridge.record.separation import CONTINUED, NOWHERE, WALL_CLOCK, Watch, judge_traces
from bridge.record.wallclock import at_rest, clocked_records, judged_on_wall_clock, taken_over_records

RATE = 10.0


def _run(xs: list[float], y: float, left: tuple[int, list[float]] | None, events: list[tuple[str, str]],
         outcome: str = "aborted", after: list[tuple[float, float, float]] | None = None) -> Run:
    """A session's finished record: its rows along x at ``y``, 1 m up; its gate's ``left``; its vehicle's
    (kind, source) events."""
    trace = {"t": np.arange(len(xs)) / RATE, "x": np.array(xs), "y": np.full(len(xs), y), "z": np.ones(len(xs))}
    summary: dict[str, Any] = {
        "outcome": outcome, "events": [{"t": 0.0, "kind": k, "text": k, "source": s} for k, s in events],
        "lockstep": {"held": left is None,
                     **({"left_at_s": left[0] / RATE, "why": "HOLD set by a ground station"} if left else {})},
        "sitl": {"gate": {"left": None if left is None else {"step": left[0], "position": left[1]}}}}
    return Run(trace, summary, None, after or [])


def _fleet_summary(runs: list[Run], watch: Watch) -> dict[str, Any]:
    vehicles = [{"id": i + 1, "sysid": i + 1, "outcome": r.summary["outcome"], "ok": False, "rms_3d": None,
                 "profile": "paper", "trajectory": "own", "offset": [0, 0, 0], "ended_by": None}
                for i, r in enumerate(runs)]
    return {"mission": "m", "clock": "lockstep", "rate_hz": RATE, "duration_s": 1.0, "outcome": "aborted",
            "vehicles": vehicles, "separation": watch.summary(), "policies": [watch.verdict()]}


def test_at_rest_is_disarmed_last_or_an_outcome_that_stays() -> None:
    said = [("armed", "vehicle"), ("disarmed", "vehicle")]
    assert at_rest({"outcome": "failsafe", "events": [{"kind": k, "source": s} for k, s in said]})
    assert not at_rest({"outcome": "aborted", "events": [{"kind": "armed", "source": "vehicle"},
                                                          {"kind": "disarmed", "source": "controller"}]})
    assert at_rest({"outcome": "completed", "events": []}) and at_rest({"outcome": "crashed"})


def test_a_record_flown_on_is_judged_row_by_row_and_its_end_in_flight_is_said_not_judged(capsys: Any) -> None:
    # 1: on the shared clock to step 9 (its end landing rows 6..9), staying at x=0 after; 2: left at step 3, flew on
    # to step 7 along y=3 and was stopped still armed (a ground station's); 3: left at step 2, flew on to x=0 at
    # step 8 beside vehicle 1's place and disarmed there
    one = _run([0.0] * 6, 0.0, (9, [0.0, 0.0, 1.0]), [("armed", "vehicle"), ("disarmed", "vehicle")], "completed",
               after=[(0.0, 0.0, 1.0)] * 4)
    two = _run([5.0] * 8, 3.0, (3, [5.0, 3.0, 1.0]), [("armed", "vehicle")])
    three = _run([4.0, 4.0, 4.0, 3.0, 2.0, 1.5, 1.0, 0.5, 0.4], 0.0, (2, [4.0, 0.0, 1.0]),
                 [("armed", "vehicle"), ("disarmed", "vehicle")], "failsafe")
    runs = [one, two, three]
    rec = clocked_records(runs, [1, 2, 3], RATE)
    assert rec.walls == [None, 3, 2] and rec.ends == [9, 7, 8]
    # 3 disarmed 1 m up after it flew on: on the ground below its last row from then, as a vehicle on the clock
    assert rec.finals[0] == (0.0, 0.0, 1.0) and rec.finals[1] == NOWHERE and rec.finals[2] == (0.4, 0.0, 0.0)
    assert len(rec.afters[0]) == 3  # the end landing up to the step it left, where its gate's word takes over
    watch = Watch([1, 2, 3], [0.3, 0.3, 0.3], 0.5)
    contacts = judge_traces(watch, [r.trace for r in runs], RATE, rec.finals, None, rec.afters, rec.walls)
    assert contacts[0]["with"] == 3 and contacts[0]["step"] == 7 and contacts[0]["continued"] == WALL_CLOCK
    assert 1 not in contacts  # vehicle 2 far off while recorded, nowhere known after
    assert [u[0].id for u in rec.unjudged()] == [2]
    summary = _fleet_summary(runs, watch)
    judged_on_wall_clock(summary, rec)
    sep = summary["separation"]
    assert sep["whole_flight"] is False
    assert [(f["id"], f["from_t"], f["to_t"], f["at_rest"], f["judged_until_t"]) for f in sep["wall_clock"]] == \
        [(2, 0.3, 0.7, False, 0.7), (3, 0.2, 0.8, True, None)]
    policy = summary["policies"][0]  # broken already (vehicles 1 and 3): broken it stays, and not judged throughout
    assert policy["ok"] is False and policy["judged"] is False and "vehicles 1 and 3" in policy["why"]
    assert policy["not_judged"].startswith("not judged over the whole flight: vehicle 2 only until t=0.700 s")


def test_a_fleet_that_held_while_judged_is_not_said_to_hold_when_one_was_not_judged_throughout(capsys: Any) -> None:
    one = _run([0.0] * 10, 0.0, (9, [0.0, 0.0, 1.0]), [("armed", "vehicle"), ("disarmed", "vehicle")], "completed")
    two = _run([5.0] * 5, 3.0, (2, [5.0, 3.0, 1.0]), [("armed", "vehicle")])
    rec = clocked_records([one, two], [1, 2], RATE)
    watch = Watch([1, 2], [0.3, 0.3], 0.5)
    assert judge_traces(watch, [one.trace, two.trace], RATE, rec.finals, None, rec.afters, rec.walls) == {}
    summary = _fleet_summary([one, two], watch)
    assert summary["policies"] == [{"name": "separation", "ok": True}]  # what it said before
    judged_on_wall_clock(summary, rec)
    policy = summary["policies"][0]
    assert policy["ok"] is False and policy["t"] == pytest.approx(0.4) and policy["why"] == policy["not_judged"]
    assert "vehicle 2 only until t=0.400 s, still flying when its record ended (HOLD set by a ground station), " \
           "while the fleet's record goes on to t=0.900 s" in policy["why"]

    class Fleet:  # a FleetRun's parts the report reads: its vehicles' runs (their events printed), no directory
        path = None
        runs = [one, two]

    Fleet.summary = summary  # type: ignore[attr-defined]
    assert report_fleet(Fleet, "sitl") == 1
    out, err = capsys.readouterr()
    assert "vehicle 2 flew on the wall clock from t=0.200 s to t=0.400 s (HOLD set by a ground station): judged on " \
           "its record, matched by mission time (approximate); judged only until t=0.400 s" in out, out
    assert "bsst sitl: policy separation not judged over the whole flight: vehicle 2 only until t=0.400 s" in err
    assert "violated" not in err, err
    # each vehicle that left lockstep named on stderr, as one vehicle's run names it (a fleet's: from the third
    # wave's fortieth session)
    assert "bsst sitl: vehicle 2: not a lockstep run: the vehicle left lockstep at t=0.200 s (HOLD set by a ground " \
           "station)" in err, err


def test_a_fleet_on_the_shared_clock_throughout_is_judged_as_before() -> None:
    one = _run([0.0] * 10, 0.0, (9, [0.0, 0.0, 1.0]), [("armed", "vehicle"), ("disarmed", "vehicle")], "completed")
    two = _run([0.0] * 4, 1.0, (3, [0.0, 1.0, 0.0]), [("armed", "vehicle"), ("disarmed", "vehicle")], "aborted")
    rec = clocked_records([one, two], [1, 2], RATE)
    assert rec.flown == [] and rec.walls == [None, None] and rec.finals == [(0.0, 0.0, 1.0), (0.0, 1.0, 0.0)]


@pytest.mark.parametrize(("outcome", "said", "touched"), [
    ("aborted", [("armed", "vehicle"), ("disarmed", "vehicle")], False),  # a ground station's disarm: below
    ("diverged", [("armed", "vehicle"), ("disarmed", "vehicle")], True),  # its plant ended it: where it ended
    ("aborted", [("armed", "vehicle")], True)])  # still armed when its record ended: at its last row
def test_a_real_time_vehicle_disarmed_in_the_air_stays_on_the_ground_below(outcome: str, said: list[tuple[str, str]],
                                                                           touched: bool) -> None:
    # 1 hovers at (0, 0, 1 m) for 3 s and its record ends; 2 flies along y=0 at 1 m through x=0 at 4 s. Until the
    # third wave's thirty-ninth session a disarmed 1 hung at its last row: a collision for both, found afterwards
    one = _run([0.0] * 30, 0.0, None, said, outcome)
    two = _run([4.0 - 0.1 * j for j in range(81)], 0.0, None, [("armed", "vehicle")], "completed")
    rec = taken_over_records([one, two], [1, 2], RATE)
    assert rec.finals[1] is None and rec.flown == []
    assert rec.finals[0] == ((0.0, 0.0, 0.0) if not touched else None)
    watch = Watch([1, 2], [0.3, 0.3], 0.5)
    contacts = judge_traces(watch, [one.trace, two.trace], RATE, rec.finals, None, rec.afters, rec.walls,
                            own_clocks=True)
    if touched:
        assert contacts[0]["step"] == contacts[1]["step"] == 34 and contacts[0]["continued"] == CONTINUED
        return
    assert contacts == {}
    pair = watch.summary()["pairs"][0]
    assert pair["closest_m"] == pytest.approx(0.4) and pair["t"] == pytest.approx(4.0)  # 1 m below 2's path

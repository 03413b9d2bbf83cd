"""Covers bridge.record.missionclock: where the vehicle's clock and the mission's meet in a session's record.

Pure: the times a read's events are recorded at, the note once the mission's time 0 is known, and the events moved
onto the mission's clock (a ground station's flight before an awaited mission's start: before 0). The sessions
themselves: tests/test_await_mission.py (MAVSDK's hop, then the mission).
"""

from __future__ import annotations

import math

import pytest

from bridge.record.events import RunEvent
from bridge.record.missionclock import MissionClock


def test_what_came_before_the_missions_time_0_is_on_the_vehicles_clock_then_before_0():
    """Before k0 the vehicle's events keep its clock, the others' (no time on it) the vehicle's latest event, the
    vehicle's of a read first; once k0 is known the note says where it fell, the latest-said times move with it,
    the vehicle's later events are put on the mission's clock as they come, and those before move before 0."""
    clock = MissionClock(vehicle_first=True)
    read = clock.stamps([(False, 0.0), (True, 4.0), (True, 12.0), (False, -math.inf)])
    assert read == [12.0, 4.0, 12.0, -math.inf]  # the controller's download after the vehicle's start request
    recorded = [RunEvent(4.0, "mode", "LAND", "vehicle"), RunEvent(12.0, "mission", "downloaded", "controller")]
    clock.vehicle_said.update(mode=4.0, start=12.0)  # (the read's, as the session's order of it keeps them)
    assert clock.stamps([(False, 1.0)]) == [12.0]  # a later read's: at the vehicle's latest of the earlier ones
    note = clock.learn(3250, 250.0, len(recorded))
    assert note is not None and note.startswith(
        "the mission's time 0 (the trace's first row) is the vehicle's t=13.000 s (its step 3250)"), note
    assert clock.vehicle_said == {"mode": -9.0, "start": -1.0}
    assert clock.stamps([(True, 46.476), (False, 33.476)]) == [pytest.approx(33.476), 33.476]
    end = RunEvent(33.476, "end", "mission over", "vehicle")
    moved = clock.on_mission_clock([*recorded, end])
    assert [e.t for e in moved] == [-9.0, -1.0, 33.476]
    assert [e.before_start for e in moved] == [True, True, False]


def test_one_clock_in_lockstep_with_nothing_flown_before_and_0_in_real_time_with_no_mission_awaited():
    """A lockstep vehicle's clock stands still until the flight: k0 is 0, no note, nothing moves. In real time with
    no mission awaited, what comes before k0 (the controller's arm) is at 0, as it always was."""
    lockstep = MissionClock(vehicle_first=True)
    assert lockstep.stamps([(True, 0.0)]) == [0.0] and lockstep.learn(0, 250.0, 1) is None
    armed = [RunEvent(0.0, "armed", "armed, offboard control", "vehicle")]
    assert lockstep.on_mission_clock(armed) == armed
    realtime = MissionClock(vehicle_first=False)
    assert realtime.stamps([(True, 0.3), (False, 0.0)]) == [0.0, 0.0]
    realtime.vehicle_said["armed"] = 0.0
    assert realtime.learn(80, 250.0, 1) is None and realtime.vehicle_said == {"armed": 0.0}
    assert realtime.stamps([(True, 0.5)]) == [pytest.approx(0.18)]
    assert realtime.on_mission_clock(armed) == armed

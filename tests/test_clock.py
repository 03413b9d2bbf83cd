"""Covers bridge.core.clock and bridge.nodes.vehicle.catchup: the arithmetic of the real-time clocks, and a stalled
vehicle's catch-up (pure: times are given, not read)."""

from __future__ import annotations

import pytest

from bridge.core.clock import REBASE_S, STALL_S, STALLS_KEPT, FixedRate, Pace, Stalls
from bridge.nodes.vehicle.catchup import CatchUp


def test_pace_runs_speed_times_real_time_from_its_restart():
    p = Pace(rate_hz=1000.0, speed=2.0)
    p.restart(now=10.0, n=500)
    assert p.due(500) == 10.0
    assert p.due(1500) == pytest.approx(10.5)  # 1000 steps of 1 ms at twice real time
    assert p.time_s(10.25) == pytest.approx(0.5 + 0.5)  # it runs on between steps


def test_pace_rebases_a_stall_but_not_a_late_wake_up():
    p = Pace(rate_hz=1000.0)
    p.restart(now=0.0, n=0)
    assert not p.rebase_if_stalled(now=0.1 + REBASE_S, due=0.1)  # at the limit: caught up
    assert p.due(100) == pytest.approx(0.1) and p.rebased == 0
    assert p.rebase_if_stalled(now=5.0, due=0.1)  # stalled: step 100 is due now, and so on
    assert p.due(100) == pytest.approx(5.0) and p.due(200) == pytest.approx(5.1) and p.rebased == 1


def test_fixed_rate_keeps_its_phase_and_skips_what_it_missed():
    c = FixedRate(t0=2.0, rate_hz=250.0)
    assert c.due(10) == pytest.approx(2.04)
    assert c.catch_up(10, now=2.04 + 0.0039) == 10  # late by less than a period: run it
    assert c.skipped == 0
    j = c.catch_up(10, now=2.04 + 0.0101)  # 2.5 periods late: ticks 10 and 11 are lost
    assert j == 12 and c.skipped == 2
    assert c.due(j) == pytest.approx(2.048)  # the schedule is kept, not re-based on the late tick


def test_ticks_due_before_a_schedule_set_back_are_skipped_not_counted():
    """A schedule set back 5 ticks (the mission's first state come late, docs/sitl.md "Stalls": its tick 0 where that
    state was due, 5 periods before the tick that read it): ticks 1-5 were due by then, never the process's to wake
    for, and are no overruns when the catch-up skips them; one past them it woke late for is (until the forty-fifth
    session's review each was counted, 17-32 for a SiK radio's late first state). So are the first schedule's ticks
    due before it was set."""
    c = FixedRate(t0=2.0, rate_hz=250.0, skipped=3, behind=5)  # tick 5 due at 2.02: when it was set
    assert c.catch_up(1, now=2.0201) == 5 and c.skipped == 3  # ticks 1-4 due before it: not counted
    c = FixedRate(t0=2.0, rate_hz=250.0, behind=5)
    assert c.catch_up(1, now=2.0281) == 7 and c.skipped == 1  # 1-5 not counted, 6 woken late for: counted
    c = FixedRate(t0=2.0, rate_hz=250.0, behind=1)  # set at 2.006 (the first schedule, its ticks 0 and 1 past)
    assert c.catch_up(0, now=2.0121) == 3 and c.skipped == 1  # 0 and 1 not counted, 2 woken late for: counted
    c = FixedRate(t0=2.0, rate_hz=250.0)  # nothing behind: every tick skipped counted
    assert c.catch_up(0, now=2.0121) == 3 and c.skipped == 3


def test_a_stall_is_one_record_however_many_late_wake_ups_its_catch_up_makes():
    s = Stalls()
    s.note(1.000, STALL_S)  # at the threshold: the machine's ordinary jitter, not a stall
    s.note(1.000, 0.5 * STALL_S)
    assert s.report() == {"count": 0, "worst_ms": 0.0, "at": []}
    # a 100 ms stall at t = 2 s: the 1 kHz steps due in it are each woken late as the pace catches up
    for n in range(100):
        s.note(2.0 + n * 1e-3, 0.1 - n * 1e-3 + 20e-6 * n)
    s.note(2.3, 0.012)  # a second, shorter one after it
    assert s.report() == {"count": 2, "worst_ms": 100.0, "at": [[2.0, 100.0], [2.3, 12.0]]}


def test_stalls_past_the_kept_ones_are_counted_not_listed():
    s = Stalls()
    for i in range(STALLS_KEPT + 5):
        s.note(float(i), 0.05 + i * 1e-4)
    r = s.report()
    assert r["count"] == STALLS_KEPT + 5 and len(r["at"]) == STALLS_KEPT
    assert r["worst_ms"] == pytest.approx(1e3 * (0.05 + (STALLS_KEPT + 4) * 1e-4), abs=0.05)


def test_what_a_stalled_vehicle_read_late_waits_for_the_physics_to_catch_up_to_when_it_was_read():
    """1 kHz physics from wall time 0; the wait for step 100 (due 0.100) returns at 0.200 with a target read
    then: the steps due before 0.200, flown in the catch-up, go without it; the step due at 0.200 takes it."""
    pace = Pace(rate_hz=1000.0)
    pace.restart(now=0.0, n=0)
    c = CatchUp(pace)
    assert not c.overslept(pace.due(50), pace.due(50) + 0.5 * STALL_S, ["on time"])  # a wait that ended in time
    assert c.overslept(pace.due(100), 0.200, ["read at 0.200"])
    c.woke(pace.due(100), 0.200)
    assert c.stalls.report() == {"count": 1, "worst_ms": 100.0, "at": [[0.1, 100.0]]}
    for n in range(101, 200):  # the catch-up: each step late, none takes what was read at 0.200
        c.woke(pace.due(n), 0.200 + (n - 100) * 30e-6)
        assert c.release(pace.due(n)) == []
    assert c.release(pace.due(200)) == ["read at 0.200"] and c.release(pace.due(201)) == []
    assert c.stalls.report()["count"] == 1  # the catch-up's late steps are the one stall
    assert c.overslept(pace.due(300), 0.4, []) and c.release(10.0) == []  # an empty wait holds nothing


def test_a_vehicle_that_sleeps_to_its_periods_end_flies_the_steps_due_meanwhile_and_no_stall():
    """Real time, 4 physics steps a 4 ms control period: mid-period the vehicle sleeps to the period's end (or a
    message), not to each step. Woken at the end, the steps due before it are late by choice, not a stall; what a
    wait read after its step was due waits for the first step due after it was read, as a wake per step had it."""
    pace = Pace(rate_hz=1000.0)
    pace.restart(now=0.0, n=0)
    c = CatchUp(pace)
    c.asleep_to = pace.due(4)  # the wait for step 1 slept to the period's end
    assert not c.overslept(pace.due(1), 0.0005, ["target"], True)  # read before step 1 was due: taken now
    assert c.overslept(pace.due(1), 0.0041, ["read at 4.1 ms"], True)  # woke after step 1's due: held
    for n in (1, 2, 3, 4):  # the steps due by the wake, flown then: none takes it, none is a stall
        c.woke(pace.due(n), 0.0041 + n * 1e-5)
        assert c.release(pace.due(n)) == []
    assert c.release(pace.due(5)) == ["read at 4.1 ms"]
    assert c.stalls.report()["count"] == 0
    c.asleep_to = pace.due(8)  # the next period's: it woke 20 ms after the end it slept for, a stall from there
    c.woke(pace.due(6), pace.due(8) + 2 * STALL_S)
    assert c.stalls.report() == {"count": 1, "worst_ms": 20.0, "at": [[0.008, 20.0]]}

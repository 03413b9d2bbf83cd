"""Covers bridge.record.policies and bridge.record.endedby.

The safety policies of :mod:`bridge.record.policies`, each on a synthetic trace and events that
break it and on ones that keep it; the honest records (sender, lockstep, who ended a flight);
and the exit status a violation gives ``bsst sim`` / ``bsst sitl``. Events are
:class:`~bridge.record.events.RunEvent` with their sender as a field (``by``).

Every shipped mission, offline and in SITL, is checked against the same policies where it is
flown (tests/test_scenarios.py, tests/test_sitl.py).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from bridge.autopilot.vehicleevents import ITSELF, Sender
from bridge.cli.commands import report_run
from bridge.record.endedby import arming_denied_end, ended_by_command
from bridge.record.events import RunEvent
from bridge.record.policies import (
    CONTROLLER_ID,
    POLICIES,
    Rules,
    arm_authority,
    check,
    failsafe_in_time,
    lockstep_record,
    lockstep_recorded,
    no_actuation_disarmed,
    run_ok,
    time_steady,
    violation_text,
)
from bridge.record.runlog import Run

RATE = 250.0
P = 1.0 / RATE
OFFLINE = Rules(rate_hz=RATE, timeout_s=0.5, clock="offline", armed_at_start=True)
LOCKSTEP = Rules(rate_hz=RATE, timeout_s=0.5, clock="lockstep")
REALTIME = Rules(rate_hz=RATE, timeout_s=0.5, clock="realtime", hold_slack_s=0.25 + P)


def trace(seconds: float, thrust: float = 10.0, age: float = 0.0, t0: float = 0.0) -> dict[str, np.ndarray]:
    """A trace of ``seconds`` at RATE: constant realised wrench, every row with a command of ``age``."""
    n = int(round(seconds * RATE))
    t = t0 + np.arange(n) / RATE
    out = {"t": t, "state_age_s": np.full(n, age)}
    for i, v in enumerate((thrust, 0.1, -0.1, 0.0), start=1):
        out[f"u{i}_act"] = np.full(n, v)
    return out


CONTROLLER = Sender(200, 191, "127.0.0.1", 40000, "controller")
GCS = Sender(255, 190, "127.0.0.1", 14550, "gcs")


def ev(t: float, kind: str, text: str = "", source: str = "vehicle", by: Sender | None = None) -> RunEvent:
    return RunEvent(t, kind, text, source, by)


def verdict(name: str, tr: dict, events: list, rules: Rules, **kw):
    v = {x.name: x for x in check(tr, events, rules, **kw)}[name]
    assert v.ok == (v.why is None)
    return v


# -- no actuation while disarmed -------------------------------------------------------------------
def test_no_actuation_while_disarmed() -> None:
    tr = trace(3.0)
    events = [ev(1.0, "disarmed", "landed: disarmed", by=ITSELF), ev(2.0, "armed", "armed, offboard control")]
    off = (tr["t"] > 1.0) & (tr["t"] < 2.0)
    for c in ("u1_act", "u2_act", "u3_act", "u4_act"):
        tr[c][off] = 0.0
    assert verdict("no_actuation_disarmed", tr, events, OFFLINE).ok  # armed again at 2 s: thrust is allowed
    tr["u1_act"][np.argmax(tr["t"] > 1.5)] = 0.2  # one row of thrust while disarmed
    v = verdict("no_actuation_disarmed", tr, events, OFFLINE)
    assert not v.ok and v.t == pytest.approx(1.5 + P, abs=P) and "disarmed since t=1.000" in v.why
    # a session's vehicle is disarmed until its first arm: thrust before it is a violation
    tr = trace(1.0)
    v = no_actuation_disarmed(tr["t"], [tr[f"u{i}_act"] for i in range(1, 5)], [ev(0.5, "armed")], LOCKSTEP)
    assert not v.ok and v.t == 0.0


def test_rotors_spinning_down_after_a_disarm_may_only_slow() -> None:
    tr = trace(2.0)
    after = tr["t"] > 1.0
    decay = np.exp(-(tr["t"][after] - 1.0) / 0.02)
    for c in ("u1_act", "u2_act", "u3_act"):
        tr[c][after] = tr[c][after] * decay
    events = [ev(1.0, "disarmed", "failsafe: motors stopped", by=ITSELF)]
    lag = Rules(rate_hz=RATE, timeout_s=0.5, armed_at_start=True, spin_down=True)
    assert not verdict("no_actuation_disarmed", tr, events, OFFLINE).ok  # without a lag: not zero, refused
    assert verdict("no_actuation_disarmed", tr, events, lag).ok
    tr["u1_act"][np.argmax(tr["t"] > 1.5)] = 5.0  # thrust rises again while disarmed
    assert not verdict("no_actuation_disarmed", tr, events, lag).ok


# -- failsafe within the timeout plus one step ---------------------------------------------------------
def test_failsafe_within_the_timeout_plus_one_step_of_the_last_target() -> None:
    tr = trace(3.0)
    tr["state_age_s"][tr["t"] >= 1.0] = math.nan  # the last command at 0.996 s
    last = 1.0 - P
    ok = [ev(last + 0.5 + P, "failsafe", "no actuator target for 0.504 s: level and descend")]
    assert verdict("failsafe_in_time", tr, ok, OFFLINE).ok
    late = [ev(last + 0.5 + 3 * P, "failsafe", "no actuator target for 0.512 s: level and descend")]
    v = verdict("failsafe_in_time", tr, late, OFFLINE)  # the rows show it flying on past the deadline
    assert not v.ok and v.t == pytest.approx(last + 0.5 + 2 * P) and "since t=0.996 s" in v.why
    v = verdict("failsafe_in_time", trace(0.5), [ev(0.0, "armed"), ev(1.2, "failsafe")], LOCKSTEP)
    assert not v.ok and v.t == 1.2 and "last valid target at t=0.496" in v.why  # the rows end first
    v = verdict("failsafe_in_time", tr, [], OFFLINE)  # no failsafe at all, flying on for 2 s without a target
    assert not v.ok and v.t == pytest.approx(last + 0.5 + 2 * P, abs=1e-9) and "still no failsafe" in v.why
    # an up link of up to 20 ms: the last command may act that much later
    delayed = Rules(rate_hz=RATE, timeout_s=0.5, armed_at_start=True, command_slack_s=0.02)
    assert verdict("failsafe_in_time", tr, [ev(last + 0.52 + P, "failsafe")], delayed).ok
    assert not verdict("failsafe_in_time", tr, [ev(last + 0.52 + P, "failsafe")], OFFLINE).ok


def test_a_session_arm_restarts_the_timeout_and_a_disarm_ends_it() -> None:
    tr = trace(3.0, age=math.nan)  # no command ever
    assert not verdict("failsafe_in_time", tr, [ev(0.0, "armed")], LOCKSTEP).ok
    assert verdict("failsafe_in_time", tr, [ev(0.0, "armed"), ev(0.504, "failsafe")], LOCKSTEP).ok
    assert verdict("failsafe_in_time", tr, [ev(0.0, "armed"), ev(0.3, "disarmed", "disarmed by command")],
                   LOCKSTEP).ok
    assert verdict("failsafe_in_time", tr, [], LOCKSTEP).ok  # never armed: nothing to fail safe from


def test_real_time_reads_the_command_in_force() -> None:
    """Real time: ``state_age_s`` is that of the command in force; one stamp held on (its age
    growing) is no new target once the guard's hold is over."""
    tr = trace(3.0, age=0.0005)
    frozen = tr["t"] >= 1.0
    tr["state_age_s"][frozen] = tr["t"][frozen] - (1.0 - P)  # the command of the state at 0.996 s, in force on
    fs = (1.0 - P) + 0.25 + P + 0.5 + P  # the guard may repeat it for stop_ms; then timeout + one step
    assert verdict("failsafe_in_time", tr, [ev(0.0, "armed"), ev(fs, "failsafe")], REALTIME).ok
    v = verdict("failsafe_in_time", tr, [ev(0.0, "armed"), ev(fs + 2 * P, "failsafe")], REALTIME)
    assert not v.ok and v.t == pytest.approx(1.756) and "since t=1.250 s" in v.why  # the first row past it
    # read as lockstep answers (every row a command sent), the same trace would never need a failsafe
    assert verdict("failsafe_in_time", tr, [ev(0.0, "armed")], LOCKSTEP).ok


# -- authority ---------------------------------------------------------------------------------------
def test_arms_and_disarms_need_authority() -> None:
    def events(by: Sender | None) -> list:
        return [ev(0.0, "armed", "armed, offboard control", by=by)]

    assert arm_authority(events(CONTROLLER), LOCKSTEP).ok
    assert arm_authority(events(GCS), LOCKSTEP).ok  # any ground station
    assert arm_authority(events(Sender(7, 1, "127.0.0.1", 9, "gcs")), LOCKSTEP).ok
    assert arm_authority(events(ITSELF), LOCKSTEP).ok
    assert arm_authority(events(None), LOCKSTEP).ok  # names no one: not judged
    v = arm_authority(events(Sender(1, 1, "127.0.0.1", 40001, "controller")), LOCKSTEP)
    assert not v.ok and v.t == 0.0 and "only 200:191" in v.why and "by 1:1 127.0.0.1:40001 controller" in v.why
    v = arm_authority([ev(2.5, "disarmed", "disarmed by command", by=Sender(200, 190, "127.0.0.1", 5, "controller"))],
                      LOCKSTEP)
    assert not v.ok and v.t == 2.5
    v = arm_authority(events(Sender(200, 191, "127.0.0.1", 5, "radio")), LOCKSTEP)
    assert not v.ok and "not a link the vehicle has" in v.why
    assert arm_authority(events(CONTROLLER), Rules(rate_hz=RATE, timeout_s=0.5, controller_id=(42, 1))).ok is False
    # the controller's own events (source controller) are not the vehicle's
    assert verdict("arm_authority", trace(1.0), [ev(0.0, "armed", "x", "controller", Sender(1, 1, "h", 1,
                                                                                          "controller"))],
                   LOCKSTEP).ok
    # the sender is the field: a text that looks like one names nobody
    assert arm_authority([ev(0.0, "armed", "armed [by 1:1 127.0.0.1:9 controller]")], LOCKSTEP).ok


def test_an_events_sender_is_shown_not_parsed() -> None:
    e = ev(2.0, "disarmed", "disarmed by command", by=GCS)
    assert e.shown == "disarmed by command [by 255:190 127.0.0.1:14550 gcs]"
    assert e.as_dict() == {"t": 2.0, "kind": "disarmed", "text": e.shown, "source": "vehicle"}
    assert RunEvent(1.0, "armed", "armed").as_dict() == {"t": 1.0, "kind": "armed", "text": "armed"}  # offline
    assert ev(3.0, "disarmed", "landed: disarmed", by=ITSELF).shown == "landed: disarmed [by vehicle]"
    assert RunEvent.at(float("nan"), "k", "x").t is None and RunEvent.at(1.23456789, "k", "x").t == 1.234568


# -- lockstep --------------------------------------------------------------------------------------------
LEFT = "controller silent for 0.5 s of wall time: leaving lockstep, running on the wall clock"


def test_lockstep_is_never_left_without_a_record() -> None:
    events = [ev(0.0, "armed"), ev(1.2, "lockstep", LEFT)]
    record = lockstep_record(events)
    assert record == {"held": False, "left_at_s": 1.2, "why": LEFT, "times": 1}
    assert lockstep_recorded(events, LOCKSTEP, record, 1.2).ok
    v = lockstep_recorded(events, LOCKSTEP, {"held": True}, 1.2)
    assert not v.ok and v.t == 1.2 and "record says it held" in v.why
    assert not lockstep_recorded(events, LOCKSTEP, None, None).ok
    assert not lockstep_recorded(events, LOCKSTEP, {**record, "left_at_s": 3.0}, None).ok
    # rows off the step clock and no event: the vehicle left silently, whatever the record says
    v = lockstep_recorded([ev(0.0, "armed")], LOCKSTEP, {"held": False, "left_at_s": 0.8}, 0.8)
    assert not v.ok and "without a lockstep event" in v.why
    assert lockstep_record([ev(0.0, "armed")], 0.8)["held"] is False
    assert lockstep_record([ev(0.0, "armed")]) == {"held": True}
    assert lockstep_recorded([ev(0.0, "armed")], LOCKSTEP, {"held": True}, None).ok
    assert lockstep_recorded(events, REALTIME, None, None).ok  # real time has no lockstep to leave


# -- time -------------------------------------------------------------------------------------------------
def test_the_missions_time_never_jumps() -> None:
    tr = trace(2.0)
    assert time_steady(tr["t"], OFFLINE).ok
    assert time_steady(trace(2.0, t0=0.04)["t"], OFFLINE).ok  # real time's first rows may be left out
    gap = np.delete(tr["t"], 100)
    v = time_steady(gap, OFFLINE)
    assert not v.ok and v.t == pytest.approx(99 * P) and "to 0.404" in v.why
    rep = np.insert(tr["t"], 50, tr["t"][50])
    assert not time_steady(rep, OFFLINE).ok
    back = tr["t"].copy()
    back[300:] -= 0.5
    assert not time_steady(back, OFFLINE).ok
    nan = tr["t"].copy()
    nan[10] = math.nan
    assert not time_steady(nan, OFFLINE).ok
    # real time writes no rows while the vehicle is disarmed (landed by its failsafe, re-armed by resume):
    # a gap over disarmed steps only is no jump; one that starts before the disarm is
    landed = np.concatenate([tr["t"][:300], tr["t"][300:] + 1.0])  # no rows for 1 s after 1.196 s
    events = [ev(0.0, "armed"), ev(1.198, "disarmed", "landed: disarmed", by=ITSELF), ev(2.199, "armed")]
    assert time_steady(landed, REALTIME, events).ok
    assert not time_steady(landed, REALTIME, events[:1]).ok
    assert not time_steady(landed, REALTIME, [ev(0.0, "armed"), ev(1.5, "disarmed"), ev(2.199, "armed")]).ok
    assert verdict("time_steady", {**trace(2.0), "t": landed}, events, REALTIME).ok  # check() gives it the events


def test_failsafe_policy_reads_failsafe_events_only_from_the_vehicle() -> None:
    tr = trace(3.0)
    tr["state_age_s"][tr["t"] >= 1.0] = math.nan
    # the controller says "failsafe" when it sees one; the vehicle must say it itself
    assert not failsafe_in_time(tr["t"], tr["state_age_s"], [], OFFLINE).ok
    assert not verdict("failsafe_in_time", tr, [ev(1.5, "failsafe", "seen", "controller")], OFFLINE).ok


# -- the records of who ended a flight, and the exit status ---------------------------------------------
def test_who_ended_a_flight_by_command() -> None:
    events = [ev(0.0, "armed", "armed, offboard control", by=CONTROLLER),
              ev(2.0, "disarmed", "disarmed by command", by=GCS),
              ev(6.0, "disarmed", "disarmed by command", by=CONTROLLER)]
    e, who = ended_by_command(events, before_s=6.0)
    assert e.t == 2.0 and who == GCS and str(who) == "255:190 127.0.0.1:14550 gcs"
    assert ended_by_command(events[:1] + events[2:], before_s=6.0) is None  # the controller's own, at the end
    assert ended_by_command([ev(3.0, "disarmed", "landed: disarmed", by=ITSELF)]) is None  # not a command
    e, who = ended_by_command([ev(3.0, "disarmed", "disarmed by command")])
    assert who is None  # it names no sender


def test_a_denied_flight_is_the_vehicles_only_when_its_last_denial_answered_the_controller() -> None:
    """``denied`` names the vehicle's last ``preflight`` event; in a session only when that denial answered the
    configured controller's arm: a ground station's denied arm, followed by a controller that gave up for another
    reason (its arm unanswered), is not a denied flight. Any arm at all makes it none."""
    gcs = ev(1.0, "preflight", "arming denied: battery critical", by=GCS)
    ctl = ev(2.0, "preflight", "arming denied: outside its fence", by=CONTROLLER)
    assert arming_denied_end([gcs], CONTROLLER_ID) is None
    assert arming_denied_end([gcs, ctl], CONTROLLER_ID) == {"who": "vehicle",
                                                            "how": "arming denied: outside its fence (t=2.000 s)"}
    assert arming_denied_end([ctl, gcs], CONTROLLER_ID) is None  # the last denial was the ground station's
    offline = ev(0.0, "preflight", "arming denied: outside its fence")  # the loop's own arm: no sender
    assert arming_denied_end([offline], CONTROLLER_ID)["how"].startswith("arming denied: outside")
    assert arming_denied_end([gcs]) is not None  # without a controller to answer: the denial is the end
    assert arming_denied_end([ctl, ev(3.0, "armed", "armed, offboard control", by=CONTROLLER)], CONTROLLER_ID) is None


def test_only_an_armed_exit_from_offboard_is_a_takeover() -> None:
    """Issue 22, defect 2: a mode event ends a flight only when it took the armed vehicle out of OFFBOARD
    (its typed ``armed`` and ``mode``, never its text); a selection made disarmed, OFFBOARD again, or the
    vehicle's own HOLD after a takeoff end nothing."""
    def mode(t: float, m: str, armed: bool, by: Sender = GCS) -> RunEvent:
        return RunEvent(t, "mode", "anything", "vehicle", by, mode=m, armed=armed)

    armed = ev(0.0, "armed", "armed, offboard control", by=CONTROLLER)
    assert ended_by_command([mode(0.0, "hold", False), armed]) is None
    assert ended_by_command([mode(0.0, "offboard", False), armed]) is None
    assert ended_by_command([armed, mode(2.0, "offboard", True)]) is None
    assert ended_by_command([armed, mode(2.0, "hold", True, ITSELF)]) is None
    e, who = ended_by_command([armed, mode(2.0, "land", True)])
    assert e.t == 2.0 and who == GCS
    # a selection made disarmed does not end the armed stretch the failsafe policy watches either
    tr = trace(3.0, age=math.nan)
    assert not verdict("failsafe_in_time", tr, [mode(0.0, "hold", False), armed], LOCKSTEP).ok
    assert verdict("failsafe_in_time", tr, [armed, mode(0.3, "hold", True)], LOCKSTEP).ok


def test_a_violation_or_a_lockstep_left_exits_1_and_is_named(capsys) -> None:
    policies = [{"name": n, "ok": True} for n in POLICIES]
    base = {"mission": "m", "controller": "bsst", "profile": "paper", "clock": "lockstep", "rate_hz": RATE,
            "duration_s": 1.0, "outcome": "completed", "rms_from_s": 0.5, "rms_3d": 1e-5, "axes": {}, "inputs": {},
            "link": {}, "events": [], "ended_by": {"who": "mission", "how": "completed"}, "policies": policies,
            "lockstep": {"held": True}}
    assert run_ok(base) and report_run(Run({}, base, None), "sitl") == 0
    assert "policies: all 7 hold" in capsys.readouterr().out
    broken = [dict(p) for p in policies]
    broken[1].update(ok=False, t=15.6, why="failsafe at t=15.600 s, 0.604 s after the last valid target")
    s = {**base, "policies": broken}
    assert not run_ok(s) and report_run(Run({}, s, None), "sim") == 1
    out, err = capsys.readouterr()
    assert err == f"bsst sim: policy {violation_text(broken[1])}\n"
    assert "failsafe_in_time violated at t=15.600 s" in err and "policy failsafe_in_time violated" in out
    left = {**base, "lockstep": {"held": False, "left_at_s": 1.2, "why": LEFT, "times": 1}}
    assert not run_ok(left) and report_run(Run({}, left, None), "sitl") == 1
    out, err = capsys.readouterr()
    assert "left lockstep at t=1.200 s: controller silent" in out
    assert err == f"bsst sitl: not a lockstep run: the vehicle left lockstep at t=1.200 s ({LEFT})\n"
    assert not run_ok({**base, "outcome": "aborted"})
    stalled = {**base, "clock": "realtime", "lockstep": None,
               "timing": {"stalls": {"threshold_ms": 10.0, "count": 1, "worst_ms": 97.0,
                                     "at": [{"t": 2.5, "ms": 97.0, "side": "vehicle"}]}}}
    assert not run_ok(stalled) and report_run(Run({}, stalled, None), "sitl") == 1
    out, err = capsys.readouterr()
    said = ("not flown as asked: the machine stalled the real-time loop 1 time(s), worst 97 ms "
            "(vehicle 97 ms at t=2.500 s)")
    assert said in out and err.startswith(f"bsst sitl: {said}")
    calm = {**stalled, "timing": {"stalls": {"threshold_ms": 10.0, "count": 0, "worst_ms": 0.0, "at": []}}}
    assert run_ok(calm) and report_run(Run({}, calm, None), "sitl") == 0

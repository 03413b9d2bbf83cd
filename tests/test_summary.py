"""Covers bridge.record and bridge.mavlink.receive: a session's summary.json (bridge.record's summary, linkblock, events
and columns) built from hand-made inputs (and the sender's count of its states, StepSends), without processes.

Each case is what a session could see (the joined trace, each child's end, the events); the summary's
outcome, ``ended_by``, ``link``, ``timing``, ``lockstep`` and policy blocks are checked against it.
Real sessions, whose summaries these functions build, are in test_sitl.py and test_failsafe_actions.py.
"""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

from bridge.autopilot.vehicleevents import ITSELF, ParamChanged, Sender
from bridge.cli.runreport import link_lines
from bridge.core.flight import prepare
from bridge.mavlink.receive import StepSends
from bridge.record.columns import (
    CONTROLLER_COLUMNS,
    TRACE_COLUMNS,
    VEHICLE_COLUMNS,
    ControllerRow,
    TraceRow,
    VehicleRow,
    trace_row,
)
from bridge.record.events import RunEvent, in_time_order
from bridge.record.joiner import Joined
from bridge.record.linkblock import Cut, link_block, steps_outside
from bridge.record.policies import POLICIES, run_ok
from bridge.record.summary import (
    ChildEnd,
    SessionFacts,
    controller_completed,
    outcome_of,
    session_summary,
    stalls_block,
    timing_block,
)
from missions import Mission, Sine

FLIGHT = prepare(Mission(Sine(z0=1.0), duration_s=1.0, name="hand-made"))
RATE = FLIGHT.mission.rate_hz
STEPS = FLIGHT.mission.steps
CONTROLLER = Sender(200, 191, "127.0.0.1", 40000, "controller")
GCS = Sender(255, 190, "127.0.0.1", 14550, "gcs")
ARMED = RunEvent(0.0, "armed", "armed, offboard control", "vehicle", CONTROLLER)
VEHICLE_STATS = {"accepted": STEPS, "odometry_sent": STEPS, "rejected": {"sender": 2}, "rejected_from_controller": 0,
                 "resends": 3, "answered_again": 1, "spin_skipped": 4,
                 "up": {"sent": STEPS, "delivered": STEPS, "lost": 0, "delay_ms": {"max": 0.0}}}
CONTROLLER_STATS = {"commands": STEPS, "states": STEPS, "stale_ticks": 0, "overruns": 0, "rejected": {},
                    "rejected_from_vehicle": 0,
                    "down": {"sent": STEPS, "delivered": STEPS, "lost": 0, "delay_ms": {"max": 0.0}}}


def rows(n: int = STEPS) -> list[TraceRow]:
    """``n`` rows on the reference (zero error), hovering thrust, each step answered by a fresh command."""
    out = []
    for k in range(n):
        t = k / RATE
        ref = FLIGHT.mission.trajectory.sample(t)
        state = (ref[0][0], ref[1][0], ref[2][0]) + (0.0,) * 9
        out.append(trace_row(t, state, ref, (9.81, 0.0, 0.0, 0.0), (0.5,) * 4, (9.81, 0.0, 0.0, 0.0), 0.0,
                             (0.0, 0.0), state, 0.0))
    return out


def joined(n: int = STEPS, pace: float = 2.0) -> Joined:
    """The join of ``n`` rows flown at ``pace`` x real time, with up/down times of 0.1 / 0.2 ms."""
    return Joined(rows(n), k0=5, first_sent=100.0, last_sent=100.0 + (n - 1) / RATE / pace, commands=n,
                  up_ms=[0.1] * n, down_ms=[0.2] * n, rtt_ms=[0.3] * n)


def ends(rc: int | None = 0, outcome: str | None = "completed", reason: str | None = None,
         exit_text: str = "exited with status 0") -> tuple[ChildEnd, ChildEnd]:
    return (ChildEnd("vehicle", 0, "exited with status 0", VEHICLE_STATS),
            ChildEnd("controller", rc, exit_text, CONTROLLER_STATS, outcome, reason))


def facts(**kw) -> SessionFacts:
    return SessionFacts(**{"clock": "lockstep", "wall_s": 3.0, "sitl": {"instance": 7}, **kw})


def test_a_clean_lockstep_completion() -> None:
    vehicle, controller = ends()
    out = session_summary(FLIGHT, facts(), joined(), [ARMED], vehicle, controller)
    s = out.summary
    assert s["outcome"] == "completed" and s["ended_by"] == {"who": "mission", "how": "completed"}
    assert s["lockstep"] == {"held": True}
    assert [p["name"] for p in s["policies"]] == list(POLICIES) and all(p["ok"] for p in s["policies"])
    assert s["rms_3d"] == 0.0 and s["clock"] == "lockstep"
    assert s["sitl"] == {"instance": 7, "vehicle_exit": "exited with status 0",
                         "controller_exit": "exited with status 0"}
    # the events as written: the sender shown, the session's closing note last, at the trace's last row
    assert s["events"][0] == {"t": 0.0, "kind": "armed", "source": "vehicle",
                              "text": "armed, offboard control [by 200:191 127.0.0.1:40000 controller]"}
    assert [(e.kind, e.text, e.t) for e in out.notes] == [("ended", "completed: by mission: completed",
                                                          round((STEPS - 1) / RATE, 6))]
    assert s["events"][-1] == out.notes[0].as_dict()
    assert list(out.arrays) == list(TRACE_COLUMNS) and len(out.arrays["t"]) == STEPS


def test_the_events_are_listed_in_time_order_the_closing_notes_among_them() -> None:
    """The session's closing notes are stamped at the trace's last row but made last, after the vehicle's end landing
    (its ``end``, ``landed``, ``disarmed``, ``mode``): summary.json lists every event in time order (a printed
    summary showed ``ended`` at 0.996 s after the disarm at 3 s); events of one time keep the order recorded (the
    vehicle's ``end`` before the controller's answer to it); one with no time keeps its place."""
    vehicle, controller = ends()
    end = RunEvent(1.0, "end", "mission over: LAND", "vehicle")
    answer = RunEvent(1.0, "end", "mission over: the vehicle lands", "controller")
    landed = RunEvent(1.3, "landed", "landing detected", "vehicle")
    untimed = RunEvent(None, "warning", "refused lately", "controller")
    disarmed = RunEvent(3.3, "disarmed", "landed: disarmed", "vehicle", ITSELF)
    recorded = [ARMED, end, answer, landed, untimed, disarmed]
    out = session_summary(FLIGHT, facts(), joined(), recorded, vehicle, controller)
    last_row = round((STEPS - 1) / RATE, 6)
    assert [(e["t"], e["kind"], e.get("source")) for e in out.summary["events"]] == [
        (0.0, "armed", "vehicle"), (last_row, "ended", "session"), (1.0, "end", "vehicle"), (1.0, "end", "controller"),
        (1.3, "landed", "vehicle"), (None, "warning", "controller"), (3.3, "disarmed", "vehicle")]
    assert in_time_order([untimed, landed, ARMED]) == [untimed, ARMED, landed]  # (recorded before any time: first)


def test_the_closing_notes_are_not_before_the_vehicle_leaving_lockstep_at_the_missions_end() -> None:
    """The vehicle leaves lockstep at the mission's end (1.000 s: its controller silent over it), the step after the
    trace's last row (0.996 s): the notes reporting it are stamped at it, after it (``bsst sitl missions/sine.toml
    --blackout 27.5:3``: ``lockstep: not a lockstep run: the vehicle left lockstep at t=30.000 s`` at 29.996, before
    the vehicle's own ``t=30.000 lockstep:``, until the third wave's fortieth session's fix). An event a period later
    is after the notes; a vehicle's ``end`` there, leaving nothing, after them as before
    (:func:`test_the_events_are_listed_in_time_order_the_closing_notes_among_them`)."""
    vehicle, controller = ends(rc=1)
    left = RunEvent(1.0, "lockstep", "controller silent for 0.5 s of wall time", "vehicle")
    later = RunEvent(1.004, "landed", "landing detected", "vehicle")
    out = session_summary(FLIGHT, facts(off_clock_t=1.0), joined(), [ARMED, left, later], vehicle, controller)
    assert joined().rows[-1].t < 1.0 and [(n.kind, n.t) for n in out.notes] == [("ended", 1.0), ("lockstep", 1.0)]
    assert "left lockstep at t=1.000 s" in out.notes[1].text
    assert [(e["t"], e["kind"], e["source"]) for e in out.summary["events"]][1:] == [
        (1.0, "lockstep", "vehicle"), (1.0, "ended", "session"), (1.0, "lockstep", "session"),
        (1.004, "landed", "vehicle")]


def test_the_link_block_in_lockstep_is_the_models_with_the_socket_times() -> None:
    link = link_block(joined(), VEHICLE_STATS, CONTROLLER_STATS, None)
    assert link["up"] == {**VEHICLE_STATS["up"], "socket_ms": {"p50": 0.1, "p95": 0.1, "p99": 0.1, "max": 0.1}}
    assert link["down"]["socket_ms"]["max"] == 0.2
    assert link["rejected"] == {"sender": 2} and link["rejected_by"] == {"vehicle": {"sender": 2}, "controller": {}}
    assert link["rejected_from_peer"] == {"vehicle": 0, "controller": 0}
    assert link["rejected_from_others"] == {"vehicle": 2, "controller": 0}


def test_the_link_block_through_a_relay_and_without_statistics() -> None:
    side = {"sent": 10, "delivered": 9, "lost": 1, "duplicated": 0, "reordered": 0, "in_flight": 0,
            "lost_by": {"random": 1}, "delay_ms": {"max": 20.0}, "measured_ms": {"max": 20.3}}
    relay = {"up": side, "down": side, "refused": {"stranger_front": 1}}
    link = link_block(joined(), {}, {}, relay)
    assert link["up"]["delivered"] == 9 and link["up"]["model_delay_ms"] == {"max": 20.0}
    assert link["up"]["relay_added_ms"] == {"max": 20.3} and link["up"]["delay_ms"]["max"] == 0.1
    assert link["relay_refused"] == {"stranger_front": 1}
    # a controller killed before its stats: its rows joined stand for what it sent and received
    bare = link_block(joined(40), {"accepted": 38, "odometry_sent": 45}, {}, None)
    assert bare["up"] == {"sent": 40, "delivered": 38, "lost": 2, "duplicated": 0, "reordered": 0,
                          "refused": 0, "in_flight": 0, "shed": 0, "dropped_by_kernel": 0, "kernel_counts": False,
                          "delay_ms": {"p50": 0.1, "p95": 0.1, "p99": 0.1, "max": 0.1}}
    assert bare["down"]["sent"] == 45 and bare["down"]["lost"] == 5


def test_a_delay_no_message_measured_is_null_not_zero() -> None:
    """A real-time run that ended before its first step (``--link-profile sik-57600``: the vehicle's failsafe at
    t = 0) measured no per-step message: its ``delay_ms`` is null, printed ``n/a``, as offline's is. Until the third
    wave's forty-third session it was 0 ms each, ``link up: ... delivered 114 ... delay p50 0.00 ms`` of a link whose
    relay added 108 ms."""
    side = {"sent": 119, "delivered": 114, "lost": 1, "duplicated": 0, "reordered": 41, "in_flight": 4,
            "lost_by": {"random": 1}, "delay_ms": {"p50": 107.7}, "measured_ms": {"p50": 107.8}}
    none = Joined()
    link = link_block(none, {}, {}, {"up": side, "down": side})
    assert link["up"]["delay_ms"] == link["down"]["delay_ms"] == {"p50": None, "p95": None, "p99": None, "max": None}
    assert "delay p50 n/a ms p99 n/a ms max n/a ms" in link_lines(link)[0]
    # in lockstep the socket's times, alike
    assert link_block(none, VEHICLE_STATS, CONTROLLER_STATS, None)["up"]["socket_ms"]["p50"] is None


def test_a_side_killed_without_tlogs_leaves_its_links_counts_unknown_and_says_why() -> None:
    """A vehicle killed (no stats) in a run with no readable pair of tlogs: neither direction can be counted, so
    both are null and ``unknown`` says why, printed as ``n/a`` (until the third wave's forty-second session the
    controller's counts stood alone: ``down: sent 0 delivered 40 lost -40``)."""
    cut = Cut("vehicle", "killed by SIGKILL", None)
    link = link_block(joined(40), {}, {**CONTROLLER_STATS, "down": None}, None, cut)  # real time: no model
    for d in ("up", "down"):
        assert {k: link[d][k] for k in ("sent", "delivered", "lost")} == dict.fromkeys(("sent", "delivered", "lost"))
        assert link[d]["unknown"].startswith("the vehicle ended without its stats (killed by SIGKILL) and the run "
                                             "holds no readable vehicle.tlog and controller.tlog"), link[d]
    lines = link_lines(link)
    assert lines[0].startswith("link up  : sent n/a delivered n/a lost n/a dup n/a reordered n/a"), lines
    assert lines[1] == f"link up  : unknown: {link['up']['unknown']}\n", lines


def test_the_timing_block() -> None:
    t = timing_block(joined(pace=2.0), RATE, 3.0, VEHICLE_STATS, CONTROLLER_STATS)
    assert t["sim_s"] == STEPS / RATE and t["wall_s"] == 3.0
    assert t["step_rate_hz"] == pytest.approx(2 * RATE) and t["real_time_factor"] == pytest.approx(2.0)
    assert t["lockstep_resends"] == 3 and t["answered_again"] == 1 and t["missing_rows"] == 0
    assert t["spin_skipped"] == {"vehicle": 4, "controller": 0}
    assert t["state_to_command_ms"]["max"] == 0.3
    assert t["way_down"] is None  # lockstep: no way down counted
    realtime = timing_block(joined(), RATE, 3.0, VEHICLE_STATS,
                            {**CONTROLLER_STATS, "way_down": {"ms": 20.104, "within_ms": 0.061}})
    assert realtime["way_down"] == {"ms": 20.104, "within_ms": 0.061}  # the controller's, as it said it
    empty = timing_block(Joined(), RATE, 1.0, {}, {})
    assert empty["flight_wall_s"] is None and empty["step_rate_hz"] is None and empty["sim_s"] == 0.0


def test_a_ground_stations_disarm_in_flight_ends_it_aborted_and_named() -> None:
    vehicle, controller = ends(rc=1, outcome="aborted", reason="the vehicle was disarmed during the mission")
    events = [ARMED, RunEvent(0.5, "disarmed", "disarmed by command", "vehicle", GCS)]
    s = session_summary(FLIGHT, facts(), joined(int(0.5 * RATE)), events, vehicle, controller).summary
    assert s["outcome"] == "aborted"
    assert s["ended_by"] == {"who": "255:190 127.0.0.1:14550 gcs",
                             "how": "disarmed in flight by command at t=0.500 s"}


def test_the_controllers_own_reason_and_a_short_completion() -> None:
    vehicle, controller = ends(rc=1, outcome="aborted", reason="vehicle silent for 2 s",
                               exit_text="exited with status 1")
    s = session_summary(FLIGHT, facts(), joined(100), [ARMED], vehicle, controller).summary
    assert s["outcome"] == "aborted" and s["ended_by"] == {"who": "controller", "how": "vehicle silent for 2 s"}
    # a controller saying completed whose trace stops short of the mission's end did not complete it
    vehicle, controller = ends()
    s = session_summary(FLIGHT, facts(), joined(100), [ARMED], vehicle, controller).summary
    assert s["outcome"] == "aborted"
    assert s["ended_by"] == {"who": "controller", "how": f"ended the mission after {100 / RATE:.3f} s of its 1 s"}


def test_a_controller_that_died_leaves_the_vehicles_failsafe() -> None:
    vehicle, controller = ends(rc=-9, outcome=None, exit_text="killed by SIGKILL")
    events = [ARMED, RunEvent(0.8, "failsafe", "no actuator target for 0.504 s: land", "vehicle")]
    s = session_summary(FLIGHT, facts(died="controller"), joined(), events, vehicle, controller).summary
    assert s["outcome"] == "failsafe"
    assert s["ended_by"] == {"who": "controller", "how": "died (killed by SIGKILL); the vehicle's failsafe took over"}


def test_a_vehicle_that_left_lockstep_is_recorded_and_noted() -> None:
    vehicle, controller = ends(rc=1)
    left = RunEvent(0.6, "lockstep", "controller silent for 0.5 s of wall time", "vehicle")
    out = session_summary(FLIGHT, facts(off_clock_t=0.6), joined(), [ARMED, left], vehicle, controller)
    s = out.summary
    assert s["lockstep"] == {"held": False, "left_at_s": 0.6, "why": left.text, "times": 1}
    assert s["outcome"] == "completed"  # the controller flew it to the end; run_ok says it is no lockstep run
    assert [n.kind for n in out.notes] == ["ended", "lockstep"] and "left lockstep at t=0.600 s" in out.notes[1].text


def test_a_violation_is_in_the_policies_and_noted() -> None:
    vehicle, controller = ends()
    never_armed = session_summary(FLIGHT, facts(), joined(), [], vehicle, controller)  # thrust while disarmed
    bad = [p for p in never_armed.summary["policies"] if not p["ok"]]
    assert [p["name"] for p in bad] == ["no_actuation_disarmed"]
    assert never_armed.notes[-1].kind == "policy" and never_armed.notes[-1].text.startswith("no_actuation_disarmed")
    # an arm by a controller without authority
    rogue = RunEvent(0.0, "armed", "armed, offboard control", "vehicle", Sender(1, 1, "127.0.0.1", 9, "controller"))
    s = session_summary(FLIGHT, facts(), joined(), [rogue], vehicle, controller).summary
    assert [p["name"] for p in s["policies"] if not p["ok"]] == ["arm_authority"]


@pytest.mark.parametrize(("rc", "said", "seen", "vehicle", "expect"), [
    (0, "completed", {}, (), "completed"),
    (1, "completed", {}, (), "completed"),  # lockstep left: completed, exit 1
    (1, "failsafe", {}, (), "failsafe"),
    (1, "diverged", {}, ("diverged",), "diverged"),
    (1, "nonsense", {}, (), "aborted"),
    (None, None, {}, (), "aborted"),
    (0, "completed", {"aborted": True}, (), "aborted"),
    (0, "completed", {}, ("failsafe", "armed"), "completed"),  # resumed after its failsafe (armed again)
    # not resumed: a real-time controller whose link was lost over the end heard nothing of it (completed, exit 0
    # until the third wave's fortieth session)
    (0, "completed", {}, ("failsafe",), "failsafe"),
    (1, "aborted", {}, ("failsafe",), "failsafe"),
    (-9, None, {"died": "controller"}, (), "aborted"),
])
def test_the_outcome_from_what_the_session_saw(rc, said, seen, vehicle, expect) -> None:
    controller = ChildEnd("controller", rc, "", {}, said)
    events = [RunEvent(0.5, kind, kind, "vehicle") for kind in vehicle]  # (the vehicle's events of the mission)
    assert outcome_of(facts(**seen), controller, events) == expect
    assert controller_completed(controller) == (rc in (0, 1) and (rc == 0 or said == "completed"))


def test_a_failsafe_after_the_missions_end_leaves_a_completion() -> None:
    """A completed mission's vehicle that fails safe in its end landing (after the mission's end) completed it; one that
    failed safe before the end, never armed again, did not, whatever its controller heard (:func:`outcome_of`)."""
    controller = ChildEnd("controller", 0, "", {}, "completed")
    for t, expect in ((2.3, "completed"), (1.5, "failsafe")):
        assert outcome_of(facts(), controller, [RunEvent(t, "failsafe", "no target", "vehicle")], 2.0) == expect


def test_an_end_action_the_vehicle_never_took_is_not_flown_as_asked() -> None:
    """The controller sent the end action (its ``end`` event) and the vehicle never took it (no ``end`` event of its
    own: the NAV_LAND lost in a real-time blackout over the end); its failsafe after the end landed it. The mission
    stays completed (the failsafe came after its end), but ``end`` says ``taken`` false and what flew instead, a
    closing note says not flown as asked, and the exit status is 1 (until the third wave's fortieth session: no
    ``end``, no note, exit 0). A vehicle that took it (its ``end`` event) leaves none of that."""
    vehicle, controller = ends()
    lost = RunEvent(4.0, "end", "the vehicle did not take the mission's end action (LAND): no answer", "controller",
                    result="no answer")  # (its command's answer, typed: Event.result)
    after = [RunEvent(1.3, "failsafe", "no actuator target for 0.503 s: level and descend", "vehicle"),
             RunEvent(4.5, "landed", "landing detected", "vehicle"),
             RunEvent(6.5, "disarmed", "landed: disarmed", "vehicle", ITSELF)]
    out = session_summary(FLIGHT, facts(clock="realtime"), joined(), [ARMED, *after, lost], vehicle, controller)
    s = out.summary
    assert s["outcome"] == "completed" and s["ended_by"] == {"who": "mission", "how": "completed"}
    assert s["end"] == {"action": "land", "taken": False, "why": "no answer", "failsafe": after[0].text,
                        "failsafe_t": 1.3, "late_t": None, "disarmed": True, "disarmed_t": 6.5}
    note = ("not flown as asked: the vehicle never took the mission's end action (LAND; its command: no answer): "
            "its failsafe took over at t=1.300 s (no actuator target for 0.503 s: level and descend), disarmed at "
            "t=6.500 s")
    assert [(n.kind, n.text) for n in out.notes][-1] == ("end", note)
    assert not run_ok(s) and all(p["ok"] for p in s["policies"])
    took = [RunEvent(1.0, "end", "mission over: LAND at x=0 y=1 m from z=1 m, 0.7 m/s", "vehicle"),
            RunEvent(1.0, "end", "mission over: the vehicle lands where it is and disarms on the ground", "controller",
                     result="accepted")]
    out = session_summary(FLIGHT, facts(clock="realtime"), joined(), [ARMED, *took], vehicle, controller)
    assert "end" not in out.summary and [n.kind for n in out.notes] == ["ended"] and run_ok(out.summary)
    # the link back at 2.8 s, after the vehicle's failsafe: it takes the LAND as a mode the controller selected, late:
    # its failsafe flew the end first (until the third wave's forty-second session: taken, no ``end``, exit 0)
    late = [after[0], RunEvent(1.8, "mode", "LAND at x=0 y=1 m", "vehicle", CONTROLLER, mode="LAND", armed=True),
            took[1], *after[1:]]
    out = session_summary(FLIGHT, facts(clock="realtime"), joined(), [ARMED, *late], vehicle, controller)
    assert out.summary["end"] == {"action": "land", "taken": False, "why": "accepted", "failsafe": after[0].text,
                                  "failsafe_t": 1.3, "late_t": 1.8, "disarmed": True, "disarmed_t": 6.5}
    assert [(n.kind, n.text) for n in out.notes][-1] == ("end", (
        "not flown as asked: the vehicle did not take the mission's end action at its end (LAND; its command: "
        "accepted late): its failsafe took over at t=1.300 s (no actuator target for 0.503 s: level and descend), "
        "LAND only at t=1.800 s (0.500 s of its failsafe), disarmed at t=6.500 s"))
    assert not run_ok(out.summary)
    # a mode the controller selected with no failsafe before it is taken
    first = [late[1], took[1]]
    out = session_summary(FLIGHT, facts(clock="realtime"), joined(), [ARMED, *first], vehicle, controller)
    assert "end" not in out.summary and run_ok(out.summary)


def test_trace_rows_have_the_trace_columns_as_names() -> None:
    assert TraceRow._fields == TRACE_COLUMNS
    r = rows(2)[1]
    assert r.t == 1 / RATE and r.z == r.z_ref and math.isnan(r.state_age_s) is False and r.nees == 0.0
    assert ITSELF.is_vehicle


def test_the_part_files_rows_have_their_columns_as_names() -> None:
    assert VehicleRow._fields == VEHICLE_COLUMNS and ControllerRow._fields == CONTROLLER_COLUMNS


def test_a_perfect_links_counts_name_where_every_datagram_went() -> None:
    """Real time with no model between the sockets: what the receiver never read (sent before it listened, after it
    stopped) is in flight, the kernel's drops are the kernel's, what it refused is refused; lost is the rest."""
    vehicle = {"accepted": 97, "odometry_sent": 110, "odometry_steps": [[5, 60], [62, 115]], "kernel_drops": 1,
               "rejected": {}}
    controller = {"commands": 100, "states": 100, "states_refused": 2, "state_window": [10, 113], "kernel_drops": 1}
    link = link_block(joined(100), vehicle, controller, None)
    down = link["down"]
    assert (down["in_flight"], down["dropped_by_kernel"], down["refused"]) == (5 + 2, 1, 2)  # steps 5-9, 114-115
    assert down["lost"] == 110 - 100 - 2 - 7 - 1 == 0  # the one step the vehicle skipped (61) was never sent
    assert link["up"]["dropped_by_kernel"] == 1 and link["up"]["lost"] == 100 - 97 - 1


def test_a_real_time_run_the_machine_stalled_lists_each_stall_on_the_flights_clock_and_says_so() -> None:
    """The children's stalls (their own clocks) on the flight's clock (the vehicle's less step k0's time: k0 = 5,
    0.02 s), the mission's only (an arming stall before t = 0 and a landing one after its end are left out),
    earliest first; the note and the exit status say the run was not flown as asked."""
    vehicle_stalls = {"count": 3, "worst_ms": 120.0, "at": [[0.01, 120.0], [0.52, 97.0], [1.5, 30.0]]}
    controller_stalls = {"count": 1, "worst_ms": 41.0, "at": [[0.3, 41.0]]}
    block = stalls_block({"stalls": vehicle_stalls}, {"stalls": controller_stalls}, 5, RATE, 1.0)
    assert block == {"threshold_ms": 10.0, "count": 2, "worst_ms": 97.0,
                     "at": [{"t": 0.3, "ms": 41.0, "side": "controller"}, {"t": 0.5, "ms": 97.0, "side": "vehicle"}]}
    relayed = stalls_block({}, {}, 5, RATE, 1.0, {"stalls": {"count": 1, "worst_ms": 12.5, "at": [[0.7, 12.5]]}})
    assert relayed["at"] == [{"t": 0.7, "ms": 12.5, "side": "relay"}]  # the relay's are on the flight's clock
    # a side that listed only some of its stalls: the others count, their times unknown
    assert stalls_block({"stalls": {**controller_stalls, "count": 4}}, {}, 5, RATE, 1.0)["count"] == 4
    vehicle, controller = ends()
    vehicle = ChildEnd("vehicle", 0, "exited with status 0", {**VEHICLE_STATS, "stalls": vehicle_stalls})
    controller = ChildEnd("controller", 0, "exited with status 0", {**CONTROLLER_STATS, "stalls": controller_stalls},
                          "completed")
    out = session_summary(FLIGHT, facts(clock="realtime"), joined(), [ARMED], vehicle, controller)
    assert out.summary["timing"]["stalls"] == block and out.summary["outcome"] == "completed"
    assert [n.kind for n in out.notes] == ["ended", "stall"]
    assert out.notes[1].text.startswith("not flown as asked: the machine stalled the real-time loop 2 time(s), "
                                        "worst 97 ms (controller 41 ms at t=0.300 s, vehicle 97 ms at t=0.500 s)")
    calm = session_summary(FLIGHT, facts(clock="realtime"), joined(), [ARMED], *ends())
    assert calm.summary["timing"]["stalls"]["count"] == 0 and [n.kind for n in calm.notes] == ["ended"]
    lockstep = session_summary(FLIGHT, facts(), joined(), [ARMED], *ends())
    assert "stalls" not in lockstep.summary["timing"]  # lockstep waits for its answers: nothing to stall


def test_a_resend_after_the_receiver_stopped_reading_is_in_flight_not_lost() -> None:
    """Lockstep resends its newest state while it waits: the sends of a step the controller read that left after it
    stopped reading (its ``read_until``, one monotonic clock) never came, and are in flight; a send that was
    leaving just then was read or not, never lost; every send of a step outside its window is in flight, resends
    too. Once a step is counted per send, a perfect link loses nothing."""
    sends = StepSends()
    for k in range(10, 20):
        sends.add(k, float(k), k + 0.001)
    for j in range(1, 6):  # step 19 (the newest) sent again five times, at 19.05 .. 19.25 s
        sends.add(19, 19 + 0.05 * j, 19 + 0.05 * j + 0.001)
    sends.add(20, 20.0, 20.001)
    sends.add(20, 20.05, 20.051)  # step 20, never read, sent twice
    stats = sends.stats()
    assert stats["odometry_steps"] == [[10, 20]] and stats["odometry_again"] == [[19, 5], [20, 1]]
    assert sends.resends == 6 and [r[0] for r in stats["odometry_resent"]] == [19] * 5 + [20]
    vehicle = {"accepted": 10, "odometry_sent": 17, "rejected": {}, **stats}
    # it read steps 10-19 and the first two resends (12 states), and stopped reading at 19.12 s
    controller = {"commands": 10, "states": 12, "states_refused": 0, "state_window": [10, 19], "read_until": 19.12}
    down = link_block(joined(10), vehicle, controller, None)["down"]
    assert (down["delivered"], down["in_flight"], down["lost"]) == (12, 3 + 2, 0), down  # 19's last three; 20 x2
    # one resend was leaving as it stopped (19.1505 within 19.15 .. 19.151), and was read: nothing left for it
    at = {**controller, "states": 13, "read_until": 19.1505}
    down = link_block(joined(10), vehicle, at, None)["down"]
    assert (down["delivered"], down["in_flight"], down["lost"]) == (13, 2 + 2, 0), down
    # the same one not read: in flight
    down = link_block(joined(10), vehicle, {**at, "states": 12}, None)["down"]
    assert (down["delivered"], down["in_flight"], down["lost"]) == (12, 2 + 2 + 1, 0), down
    # counted per step, as before, the resends of step 19 after the stop were "lost"
    assert steps_outside(stats["odometry_steps"], [10, 19]) == 1


def test_a_killed_controllers_window_is_the_steps_its_rows_answer() -> None:
    """A controller killed leaves no stats: what it read is its rows (the states it answered), the steps they answer
    its window, and no time it stopped; what the vehicle sent after is in flight (it counted -300 lost before)."""
    sends = StepSends()
    for k in range(5, 105):
        sends.add(k, float(k), k + 0.001)
    sends.add(104, 104.05, 104.051)  # its last answered step, sent again: read or not, nobody can say; never lost
    vehicle = {"accepted": 50, "odometry_sent": 101, "rejected": {}, **sends.stats()}
    down = link_block(replace(joined(50), controller_steps=(5, 54)), vehicle, {}, None)["down"]
    assert (down["delivered"], down["in_flight"], down["lost"]) == (50, 50 + 1, 0), down  # steps 55-104, 104 again
    down = link_block(replace(joined(100), controller_steps=(5, 104)), vehicle, {}, None)["down"]
    assert (down["delivered"], down["in_flight"], down["lost"]) == (100, 1, 0), down  # killed after its last row


def test_the_sender_counts_every_send_and_keeps_only_a_bounded_record() -> None:
    """A step's first send is in its ranges; a send of a step already sent is a resend, counted for its step (at most
    MAX_AGAIN steps listed, the rest unlisted) and timed (the latest MAX_TIMED): a long flight's record stays small."""
    s = StepSends()
    s.add(3, 0.0, 0.0)
    s.add(5, 1.0, 1.0)
    s.add(3, 2.0, 2.0)  # an older step sent again
    s.add(4, 3.0, 3.0)  # an older step never sent: a first send (its range folded into the last)
    assert s.resends == 1 and s.again == {3: 1}
    big = StepSends()
    for k in range(StepSends.MAX_AGAIN + 10):
        big.add(k, 0.0, 0.0)
        big.add(k, 0.0, 0.0)
    assert len(big.again) == StepSends.MAX_AGAIN and big.again_unlisted == 10
    assert len(big.timed) == StepSends.MAX_TIMED and big.resends == StepSends.MAX_AGAIN + 10


def test_a_target_sent_after_the_vehicle_stopped_reading_is_in_flight_not_lost() -> None:
    """Real time stopped by Ctrl-C: both children get SIGTERM at once, and the controller's last targets may leave
    after the vehicle's last look at its socket (its ``read_until``); the controller times its latest targets'
    sends, so such a target is in flight, not lost (a real-time Ctrl-C counted ``lost 1`` up, 4 runs of 4)."""
    vehicle = {"accepted": 98, "odometry_sent": 0, "rejected": {}, "read_until": 10.0}
    timed = ([[9.0 + 0.004 * i, 9.0 + 0.004 * i + 1e-5] for i in range(98)]  # before it: read
             + [[10.0 - 1e-6, 10.0 + 1e-6], [10.001, 10.00101], [10.005, 10.00501]])  # leaving, then two after
    controller = {"commands": 101, "targets_left": timed, "states": 0, "state_window": None}
    up = link_block(joined(10), vehicle, controller, None)["up"]
    assert (up["delivered"], up["in_flight"], up["lost"]) == (98, 2 + 1, 0), up
    up = link_block(joined(10), {**vehicle, "accepted": 99}, controller, None)["up"]  # the one leaving was read
    assert (up["delivered"], up["in_flight"], up["lost"]) == (99, 2, 0), up
    # a vehicle that did not say when it stopped: nothing is taken from lost
    up = link_block(joined(10), {k: v for k, v in vehicle.items() if k != "read_until"}, controller, None)["up"]
    assert (up["in_flight"], up["lost"]) == (0, 3), up
    # 400 sent, the last 256 timed, all after the stop: the 144 older were read or not (100 were read)
    many = {"commands": 400, "targets_left": [[10.5 + i * 1e-3, 10.5 + i * 1e-3 + 1e-5] for i in range(256)]}
    up = link_block(joined(10), {**vehicle, "accepted": 100}, many, None)["up"]
    assert (up["delivered"], up["in_flight"], up["lost"]) == (100, 300, 0), up


def test_a_failsafe_or_a_breach_of_a_ground_stations_flight_before_the_mission_is_said_not_its_outcome() -> None:
    """A ground station's own flight before an awaited mission's start is at negative times: its failsafe (a geofence
    breach landing it) is recorded, said in a closing note, and not the mission's outcome, end or geofence verdict;
    the mission's own failsafe still is. (Until the third wave's thirty-seventh session the session's failsafe flag
    made a mission a ground station then paused ``failsafe``, and the hop's breach broke the mission's geofence.)"""
    vehicle, controller = ends(rc=1, outcome="aborted", reason="a ground station took over: HOLD")
    hop = [RunEvent(-9.0, "armed", "armed, TAKEOFF", "vehicle", GCS),
           RunEvent(-8.0, "geofence", "beyond GF_MAX_VER_DIST", "vehicle"),
           RunEvent(-8.0, "failsafe", "geofence: beyond GF_MAX_VER_DIST: land here", "vehicle"),
           RunEvent(-5.0, "disarmed", "landed: disarmed", "vehicle", ITSELF)]
    pause = RunEvent(0.5, "mode", "HOLD", "vehicle", GCS, mode="HOLD", armed=True)
    out = session_summary(FLIGHT, facts(), joined(int(0.5 * RATE)), [*hop, ARMED, pause], vehicle, controller)
    s = out.summary
    assert s["outcome"] == "aborted" and s["ended_by"]["how"] == "mode changed at t=0.500 s: HOLD", s["ended_by"]
    assert next(p for p in s["policies"] if p["name"] == "geofence")["ok"]
    assert [(n.kind, n.text) for n in out.notes if n.kind == "before_start"] == [
        ("before_start", "before the mission's start, not its outcome: geofence at t=-8.000 s: beyond GF_MAX_VER_DIST"),
        ("before_start", "before the mission's start, not its outcome: failsafe at t=-8.000 s: geofence: beyond "
                         "GF_MAX_VER_DIST: land here")]
    assert s["interventions"][0]["before_start"]  # exit 1: a ground station flew the vehicle
    own = RunEvent(0.8, "failsafe", "no actuator target for 0.504 s: land", "vehicle")
    vehicle, controller = ends(rc=1, outcome="failsafe", reason="the vehicle's failsafe took over")
    s = session_summary(FLIGHT, facts(), joined(int(0.8 * RATE)), [*hop, ARMED, own], vehicle, controller).summary
    assert s["outcome"] == "failsafe"
    assert s["ended_by"] == {"who": "vehicle", "how": f"failsafe at t=0.800 s: {own.text}"}, s["ended_by"]


def test_the_closing_notes_of_a_session_with_no_trace_row_come_after_its_events() -> None:
    """No trace row (no mission's time 0: a session stopped before the start, a ground station's own flight before
    it): the events are on the vehicle's clock, and the session's closing notes are at the latest of them, last.
    (Until the third wave's thirty-ninth session they were at t=0, before the flight they summed up.)"""
    vehicle, controller = ends(rc=1, outcome="aborted", reason="interrupted")
    hop = [RunEvent(0.0, "started", "vehicle pid 1", "session"),
           RunEvent(1.9, "armed", "armed, TAKEOFF", "vehicle", GCS, mode="TAKEOFF", armed=True),
           RunEvent(3.0, "disarmed", "landed: disarmed", "vehicle", ITSELF, armed=False)]
    out = session_summary(FLIGHT, facts(aborted=True), Joined(), hop, vehicle, controller)
    assert out.notes and {n.t for n in out.notes} == {3.0}, out.notes
    events = out.summary["events"]
    assert [e["t"] for e in events] == sorted(e["t"] for e in events), events
    assert events[len(hop):] == [n.as_dict() for n in out.notes] and events[len(hop)]["kind"] == "ended", events
    assert session_summary(FLIGHT, facts(aborted=True), Joined(), [], vehicle, controller).notes[0].t == 0.0


def test_a_failsafe_parameter_a_ground_station_set_after_its_hops_failsafe_is_named_in_the_missions_end() -> None:
    """A failsafe parameter a ground station sets after its own flight's failsafe, before the awaited mission's start,
    shapes the mission's failsafe: ``ended_by`` names it. (Until the third wave's thirty-eighth session the failsafe
    it weighed was the hop's, the first of the run: only a change before that one counted, and this was unnamed.)"""
    vehicle, controller = ends(rc=1, outcome="failsafe", reason="the vehicle's failsafe took over")
    hop = [RunEvent(-9.0, "armed", "armed, TAKEOFF", "vehicle", GCS),
           RunEvent(-8.0, "failsafe", "geofence: beyond GF_MAX_VER_DIST: land here", "vehicle"),
           RunEvent(-5.0, "disarmed", "landed: disarmed", "vehicle", ITSELF),
           RunEvent(-3.0, "param", "COM_OBL_ACT = 3", "vehicle", GCS, ParamChanged("COM_OBL_ACT", 1.0, 3.0))]
    own = RunEvent(0.8, "failsafe", "no actuator target for 0.504 s: disarm", "vehicle")
    s = session_summary(FLIGHT, facts(), joined(int(0.8 * RATE)), [*hop, ARMED, own], vehicle, controller).summary
    assert s["outcome"] == "failsafe" and s["ended_by"] == {
        "who": str(GCS), "how": f"failsafe at t=0.800 s: {own.text}, under COM_OBL_ACT = 3 (was 1) set by a ground "
                                "station at t=-3.000 s (step -750)"}, s["ended_by"]


def test_a_scheduled_change_confirmed_after_the_flights_end_is_not_made_and_never_before_the_vehicles_change() -> None:
    """``summary.json["param_at"]``: an echo stamped by the controller 1 ms before the vehicle's own event of the
    change is put at that event (the controller maps its clock onto the vehicle's only to within a few ms); one
    confirmed after the flight's end (its time flown: a crash in a real-time blackout the controller heard of only
    after it) is not made (``confirmed`` false, ``late_t``), said so, and the run is no clean one. (Until the third
    wave's thirty-ninth session both were copied as the controller said: confirmed, the first before its change.)"""
    sent = {"sends": 1, "confirmed": True}
    stats = {**CONTROLLER_STATS, "param_at": [
        {"t_s": 0.3, "name": "MPC_LAND_SPEED", "value": 0.8, "sent_t": 0.3, "confirmed_t": 0.301, **sent},
        {"t_s": 0.6, "name": "MIS_TAKEOFF_ALT", "value": 5, "sent_t": 0.6, "confirmed_t": 1.2, **sent}]}
    vehicle, _ = ends()
    controller = ChildEnd("controller", 0, "exited with status 0", stats, "completed", None)
    made = [RunEvent(0.302, "param", "MPC_LAND_SPEED = 0.8 (was 0.7)", "vehicle", CONTROLLER,
                     ParamChanged("MPC_LAND_SPEED", 0.7, 0.800000011920929)),
            RunEvent(1.19, "param", "MIS_TAKEOFF_ALT = 5 (was 2.5)", "vehicle", CONTROLLER,
                     ParamChanged("MIS_TAKEOFF_ALT", 2.5, 5.0))]
    out = session_summary(FLIGHT, facts(), joined(), [ARMED, *made], vehicle, controller)
    early, late = out.summary["param_at"]
    assert out.summary["duration_s"] == 1.0
    assert early["confirmed"] is True and early["confirmed_t"] == 0.302, early
    assert late["confirmed"] is False and late["confirmed_t"] is None and late["late_t"] == 1.2, late
    assert not run_ok(out.summary)
    [note] = [n.text for n in out.notes if n.kind == "param"]
    assert "MIS_TAKEOFF_ALT=5 was confirmed by the vehicle only at t=1.200 s, after" in note


def test_a_scheduled_change_made_in_flight_is_judged_by_the_vehicles_event_not_its_echos_arrival() -> None:
    """A change the vehicle made at 0.95 s whose echo reached the controller only after the 1 s flight's end (a
    real-time link's delay: the controller said it late) was made in flight: ``confirmed`` at the vehicle's event,
    a clean run. A set to the value in force has no event of the vehicle's (nothing changed): its echo's time is
    judged, and the summary is written. (Until the third wave's thirty-ninth session the first was said not made,
    exit 1, and the second raised a TypeError in the session's summary.)"""
    stats = {**CONTROLLER_STATS, "param_at": [
        {"t_s": 0.9, "name": "MPC_LAND_SPEED", "value": 0.8, "sent_t": 0.9, "sends": 1, "confirmed": False,
         "confirmed_t": None, "late_t": 1.05},
        {"t_s": 0.5, "name": "COM_OF_LOSS_T", "value": 1.0, "sent_t": 0.5, "sends": 1, "confirmed": True,
         "confirmed_t": 0.51}]}
    vehicle, _ = ends()
    controller = ChildEnd("controller", 0, "exited with status 0", stats, "completed", None)
    made = RunEvent(0.95, "param", "MPC_LAND_SPEED = 0.8 (was 0.7)", "vehicle", CONTROLLER,
                    ParamChanged("MPC_LAND_SPEED", 0.7, 0.800000011920929))
    out = session_summary(FLIGHT, facts(), joined(), [ARMED, made], vehicle, controller)
    late_echo, same = out.summary["param_at"]
    assert late_echo["confirmed"] is True and late_echo["confirmed_t"] == 0.95 and "late_t" not in late_echo
    assert same["confirmed"] is True and same["confirmed_t"] == 0.51
    assert not [n for n in out.notes if n.kind == "param"] and run_ok(out.summary)

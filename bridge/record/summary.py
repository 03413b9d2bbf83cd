"""A SITL session's ``summary.json``, as pure functions of what the session saw (no processes, no files).

In:  the :class:`~bridge.core.flight.Flight`; the joined trace and the per-packet times measured while
     joining (:class:`Joined`: rows of :class:`~bridge.record.columns.TraceRow`, times ms); each child's end
     (:class:`ChildEnd`: exit, its ``stats`` report's values, the controller's outcome and reason); what the
     session itself saw (:class:`SessionFacts`: clock, wall time s, interrupted, who died, the first step flown off
     the step clock s, the ``sitl`` block); the relay's statistics (``relay.json``'s dict, or None); the events
     (:class:`~bridge.record.events.RunEvent`: the vehicle's failsafe and divergence among them)
Out: :class:`SessionSummary`: the trace arrays, ``summary.json`` (the figures of
     :func:`bridge.record.metrics.summarise`, the ``link``, ``timing`` and ``sitl`` blocks, the downloads of a
     ground station's mission, fence and rally points (``mission_transfer``: :mod:`bridge.record.transfers`;
     ``--await-mission`` only), the lockstep record, ``ended_by``, the policies' verdicts, the events in time
     order; ``end`` of a vehicle that never took the end action: :func:`~bridge.record.ending.end_not_taken`) and
     the session's closing notes (its ``ended``, ``lockstep``, ``end`` and ``policy`` events, also in
     ``summary["events"]``, for events.log; at the trace's last row or an event in its period, with none at the
     latest event's: :func:`notes_time`)

See docs/design.md, "Files of a run", and docs/sitl.md, "Outcomes, exit statuses and safety policies".
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bridge.core.clock import STALL_S
from bridge.core.flight import Flight
from bridge.record.asked import stalls_text, waiting_stalls_text
from bridge.record.columns import TRACE_COLUMNS
from bridge.record.endedby import arming_denied_end, ended_by_command, ended_by_outcome, failsafe_not_resumed
from bridge.record.ending import end_not_taken, not_taken_text
from bridge.record.events import RunEvent, in_time_order, split_at_start
from bridge.record.interventions import (
    ended_by_change,
    intervention_text,
    interventions,
    made_in_flight,
    reproducibility,
    unconfirmed_text,
)
from bridge.record.joiner import Joined
from bridge.record.linkblock import Cut, link_block
from bridge.record.metrics import after_faults, not_reached, percentiles, plant_summary, summarise
from bridge.record.policies import (
    CONTROLLER_ID,
    judge,
    lockstep_record,
    rules_for,
    stalls_of,
    vehicle_events,
    violation_text,
)
from bridge.record.runlog import trace_arrays
from bridge.record.transfers import mission_transfer

FAILED_OUTCOMES = ("failsafe", "diverged", "aborted", "law_failed", "denied")
PLANT_OUTCOMES = ("diverged", "crashed", "collision")  # the plant ended it (SimVehicle.plant_verdict, a contact)


@dataclass(frozen=True)
class ChildEnd:
    """How a child ended: ``name``, its exit status (``returncode``; None: still running) and as said in
    ``summary.json`` (``exit_text``), its ``stats`` report's values, and for the controller its ``done``
    report's ``outcome`` and ``reason`` (None: it said none)."""

    name: str
    returncode: int | None
    exit_text: str
    stats: Mapping[str, Any] = field(default_factory=dict)
    outcome: str | None = None
    reason: str | None = None


@dataclass(frozen=True)
class SessionFacts:
    """What the session itself saw. ``clock``: ``lockstep`` or ``realtime``; ``wall_s``: the whole session
    (s); ``aborted``: interrupted by the user; ``died``: the name of a child that died (or None); ``off_clock_t``:
    lockstep, the mission's
    time (s) of the vehicle's first row of it flown off the step clock (or None); ``sitl``: ``summary.json["sitl"]``
    but for the children's exits (added here)."""

    clock: str
    wall_s: float
    aborted: bool = False
    died: str | None = None
    off_clock_t: float | None = None
    sitl: Mapping[str, Any] = field(default_factory=dict)
    mission_transfer: Mapping[str, Any] | None = None  # --await-mission: the downloads, as the controller said them
    cut: Cut | None = None  # a side that died without its stats: the link counted from both tlogs up to its cut


@dataclass(frozen=True)
class SessionSummary:
    arrays: dict[str, Any]
    summary: dict[str, Any]
    notes: list[RunEvent]  # the session's closing events, in order (also in summary["events"], in time order)


def controller_completed(controller: ChildEnd | None) -> bool:
    """Whether the controller flew its mission to the end: exit 0, or exit 1 with outcome completed
    (in lockstep, a vehicle that left lockstep)."""
    if controller is None or controller.returncode not in (0, 1):
        return False
    return controller.returncode == 0 or controller.outcome == "completed"


def outcome_of(facts: SessionFacts, controller: ChildEnd | None, events: Sequence[RunEvent] = (),
               end_s: float = math.inf) -> str:
    """The flight's outcome before who ended it is weighed (:func:`ended_by`), the vehicle's failsafe and divergence
    from ``events``, the mission's (from its time 0: :func:`~bridge.record.events.split_at_start`; ``end_s``: its
    end, s). A failsafe before it is a ground station's own flight's, before an awaited mission's start, recorded
    (its event, :func:`before_start_notes`), not the mission's; a divergence never comes before it (the plant halts
    for good: no mission's first row, no time 0, follows). A controller's completion after a failsafe in the mission
    is one only if an arm handed the vehicle back (:func:`~bridge.record.endedby.failsafe_not_resumed`)."""
    said = {e.kind for e in vehicle_events(events)}
    completed = controller_completed(controller) and not (facts.aborted or facts.died)
    if "diverged" in said:
        return "diverged"
    if controller is not None and controller.outcome == "law_failed" and not facts.died:
        return "law_failed"  # the failsafe that followed is the vehicle's answer to it, not the cause
    if "failsafe" in said and (not completed or failsafe_not_resumed(events, end_s)):
        return "failsafe"
    if facts.aborted or facts.died:
        return "aborted"
    if completed:
        return "completed"
    if controller is not None and controller.outcome is not None:
        return controller.outcome if controller.outcome in FAILED_OUTCOMES else "aborted"
    return "aborted"


def plant_outcome(outcome: str, facts: SessionFacts, events: Sequence[RunEvent]) -> str:
    """``crashed`` when the vehicle's events (the mission's) say it hit the ground armed (its ``crashed`` event: the
    flight's end, as offline), ``collision`` when another vehicle touched it, ``terminated`` when a ground station
    terminated the flight (motors off, whatever the fall came to), and nothing came before (diverged, interrupted, a
    child died); else ``outcome``."""
    if outcome == "diverged" or facts.aborted or facts.died:
        return outcome
    kinds = {e.kind for e in vehicle_events(events)}  # collision: a fleet's shared clock ended it
    return next((k for k in ("collision", "terminated", "crashed") if k in kinds), outcome)


def before_start_notes(hop: Sequence[RunEvent]) -> list[tuple[str, str]]:
    """The closing notes on what ended or breached nothing of the mission's because it came before its time 0
    (``hop``: those events, a ground station's own flight: a failsafe, a geofence breach, a plant's end), each said
    as what it was."""
    kinds = ("failsafe", "geofence", *PLANT_OUTCOMES, "terminated")
    return [("before_start", f"before the mission's start, not its outcome: {e.kind} at t={e.t:.3f} s: {e.shown}")
            for e in vehicle_events(hop) if e.kind in kinds]


def airborne(trace: Mapping[str, Any], t: float) -> bool:
    """Whether the trace's last row at or before ``t`` (s) is off the ground (z above it, or moving)."""
    ts = trace["t"]
    i = int(np.searchsorted(ts, t + 1e-9, side="right")) - 1
    return i >= 0 and (trace["z"][i] > 1e-6 or abs(trace["vz"][i]) > 1e-6)


def ended_by(outcome: str, trace: Mapping[str, Any], flight: Flight, facts: SessionFacts,
             events: Sequence[RunEvent], mission: Sequence[RunEvent], children: Sequence[ChildEnd],
             controller_id: tuple[int, int] = CONTROLLER_ID) -> tuple[str, dict[str, Any]]:
    """The outcome and ``summary.json["ended_by"]``: who ended the flight, and how. A disarm or takeover (an armed
    exit from OFFBOARD) from anyone but the configured controller, before the mission's end, ended it (named by the
    vehicle's event's sender), as does a controller that reports a completed mission whose trace stops short of the
    mission's end: both are ``aborted``, never ``completed``. A refused arm is ``denied``, as offline. ``events``:
    all of the run's; ``mission``: those from the mission's time 0, which alone can end it."""
    m = flight.mission
    ctl = next((c for c in children if c.name == "controller"), None)
    if facts.aborted:
        return "aborted", {"who": "user", "how": "interrupted (Ctrl-C or SIGTERM)"}
    if facts.died:
        child = next((c for c in children if c.name == facts.died), None)
        how = f"died ({child.exit_text if child else 'gone'})"
        if outcome == "failsafe":
            how += "; the vehicle's failsafe took over"
        return outcome, {"who": facts.died, "how": how}
    if outcome == "aborted" and arming_denied_end(events, controller_id) is not None:
        outcome = "denied"  # the controller's abort answers the vehicle's refusal to arm
    if outcome in (*PLANT_OUTCOMES, "terminated", "denied"):
        return outcome, ended_by_outcome(outcome, mission)
    if outcome == "law_failed" and ctl is not None:
        return outcome, {"who": "controller", "how": f"its law failed: {ctl.reason}"}
    hit = ended_by_command(mission, controller_id, before_s=m.duration_s)
    if hit is not None and not (controller_completed(ctl) and hit[1] is None):  # unattributed: the controller's own
        e, who = hit
        assert e.t is not None  # the policies' events have a time
        if e.kind == "mode":
            how = f"mode changed at t={e.t:.3f} s: {e.text}"
        else:
            how = f"disarmed {'in flight' if airborne(trace, e.t) else 'on the ground'} by command at t={e.t:.3f} s"
        named = str(who) if who is not None else "someone (the vehicle's event names no sender)"
        return ("aborted" if outcome == "completed" else outcome), {"who": named, "how": how}
    t = trace["t"]
    if outcome == "completed" and (not len(t) or t[-1] < m.duration_s - 1.5 / m.rate_hz):
        flown = float(t[-1]) + 1.0 / m.rate_hz if len(t) else 0.0
        return "aborted", {"who": "controller", "how": f"ended the mission after {flown:.3f} s of its "
                                                       f"{m.duration_s:g} s"}
    if outcome == "aborted" and ctl is not None and ctl.reason:
        return outcome, {"who": "controller", "how": ctl.reason}
    return outcome, ended_by_outcome(outcome, mission)


def timing_block(joined: Joined, rate_hz: float, wall_s: float, vehicle: Mapping[str, Any],
                 controller: Mapping[str, Any]) -> dict[str, Any]:
    """``summary.json["timing"]``: the session's wall time, the flight's pace and the per-step times (ms)."""
    n = len(joined.rows)
    first = joined.first_sent
    flight_s = joined.last_sent - first if first is not None and n > 1 else math.nan
    rate = (n - 1) / flight_s if flight_s > 0 else None
    return {
        "wall_s": wall_s,  # the whole session: start, fly, stop
        "sim_s": joined.rows[-1].t + 1.0 / rate_hz if n else 0.0,  # mission time flown (as duration_s), not n periods
        "flight_wall_s": flight_s if math.isfinite(flight_s) else None,
        "step_rate_hz": rate,  # control steps per wall second while flying
        "real_time_factor": rate / rate_hz if rate else None,
        "missing_rows": joined.missing,
        "state_to_command_ms": percentiles(joined.rtt_ms),
        "state_to_command_timesync_ms": percentiles(joined.s2c_ms),
        "period_error_ms": percentiles(joined.late_ms),
        "stale_ticks": int(controller.get("stale_ticks", 0)),
        # real time: the states' way down each age counts (TIMESYNC), and within how much it is right (ms; else None)
        "way_down": controller.get("way_down"),
        "overruns": int(controller.get("overruns", 0)),
        # lockstep: states resent after RESEND_S of wall time unanswered, and the second answers to them
        "lockstep_resends": int(vehicle.get("resends", 0)),
        "answered_again": int(vehicle.get("answered_again", 0)),
        # lockstep engaged again: answers to a state sent on the wall clock before it, come after (not flown)
        "answered_wall_clock": int(vehicle.get("answered_wall_clock", 0)),
        # lockstep waits that slept at once, without polling for the answer first, because the machine had more
        # runnable tasks than cores (bridge.mavlink.endpoint.Spinner), by side
        "spin_skipped": {"vehicle": int(vehicle.get("spin_skipped", 0)),
                         "controller": int(controller.get("spin_skipped", 0))},
    }


def stalls_block(vehicle: Mapping[str, Any], controller: Mapping[str, Any], k0: int | None,
                 rate_hz: float, duration_s: float, relay: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """``summary.json["timing"]["stalls"]`` (real time): the wake-ups of the vehicle's physics and of the controller's
    ticks, and the relay's packets handed on, more than :data:`~bridge.core.clock.STALL_S` late
    (:class:`~bridge.core.clock.Stalls`) during the mission (0 <= t < ``duration_s`` on the flight's clock: the
    vehicle's clock less its step k0's time), each ``{t, ms, side}``, earliest first. ``count`` adds a side's
    stalls past those it listed (its clock's times unknown)."""
    at, count, worst = [], 0, 0.0
    sides = (("vehicle", vehicle, (k0 or 0) / rate_hz), ("controller", controller, 0.0), ("relay", relay or {}, 0.0))
    for side, stats, shift in sides:
        got = stats.get("stalls") or {}
        listed = got.get("at", ())
        count += max(0, int(got.get("count", 0)) - len(listed))
        for t, ms in listed:
            if 0.0 <= t - shift < duration_s:
                at.append({"t": round(t - shift, 3), "ms": ms, "side": side})
                worst = max(worst, ms)
    return {"threshold_ms": 1e3 * STALL_S, "count": count + len(at), "worst_ms": worst,
            "at": sorted(at, key=lambda s: s["t"])}


def notes_time(joined: Joined, events: Sequence[RunEvent], rate_hz: float, reported: Sequence[float] = ()) -> float:
    """The time (s) of a session's closing notes: the trace's last row, or the latest event in its control period
    (``rate_hz``) if later, or the latest of ``reported`` (the times of the events the notes report) if later
    still; with no row (no mission's time 0: a session stopped, or a ground station's flight ended, before the
    start) the latest event's, on the clock the events are on then (the vehicle's:
    :mod:`bridge.record.missionclock`), so that the notes come after what they sum up. A row is stamped at its
    period's start, the vehicle's events at the physics step they happen in: in real time the disarm that ends the
    session's wait falls in the last row's period, and the notes were stamped up to a period before it. A vehicle
    leaving lockstep at the mission's end (its controller silent over it), the step after the last row's, was
    reported by a note stamped a period before it (``the vehicle left lockstep at t=30.000 s`` at 29.996) until the
    third wave's fortieth session's fix: the leaving is ``reported``. Nor before the session's own notes (a stop's,
    a death's: stamped when it came, :meth:`bridge.session.session.Session._note`): a run stopped in its end
    landing had its closing notes a period before the landing's first events, before its own stop too."""
    if not joined.rows:
        return max((*(e.t for e in events if e.t is not None), *reported), default=0.0)
    last = joined.rows[-1].t
    said = (e.t for e in events if e.t is not None and (e.t < last + 1.0 / rate_hz or e.source == "session"))
    return max((last, *said, *reported))


def session_summary(flight: Flight, facts: SessionFacts, joined: Joined, events: Sequence[RunEvent],
                    vehicle: ChildEnd | None, controller: ChildEnd | None, relay: ChildEnd | None = None,
                    relay_stats: Mapping[str, Any] | None = None,
                    controller_id: tuple[int, int] = CONTROLLER_ID) -> SessionSummary:
    """The trace arrays and ``summary.json`` of a session: the figures, the ``link``, ``timing`` and ``sitl``
    blocks, the lockstep record (lockstep), who ended the flight (``ended_by``, which may turn a completion
    into ``aborted``), the policies' verdicts, and the events with the session's closing notes. The events are on the
    trace's clock, the mission's (negative before its time 0: :mod:`bridge.record.missionclock`)."""
    m = flight.mission
    vs = vehicle.stats if vehicle is not None else {}
    cs = controller.stats if controller is not None else {}
    arrays = trace_arrays(joined.rows, TRACE_COLUMNS)
    link = link_block(joined, vs, cs, relay_stats if relay is not None else None, facts.cut)
    if caps := flight.link.jitter_capped():  # the delay capped a jitter: not flown as asked (docs/links.md)
        link["jitter_capped"] = caps
    mission, hop = split_at_start(events)  # (the hop: a ground station's own flight before an awaited mission's start)
    outcome = plant_outcome(outcome_of(facts, controller, mission, m.duration_s), facts, mission)
    summary = summarise(arrays, m, flight.gains, clock=facts.clock, outcome=outcome,
                        events=[], link=link, estimator=flight.estimator, sensors=flight.sensors.name)
    ev = vehicle_events(events)
    # the plant's own blocks as the vehicle reported them in its stats; the GPS outages from the trace and the
    # events' own texts (an injected fault's shown text names its sender)
    summary.update(plant_summary(vs.get("plant") or {}, arrays, [{**e.as_dict(), "text": e.text} for e in ev]))
    start = flight.wind.start if flight.wind is not None else None
    if start is not None and "steady_at_start" in summary.get("wind", {}):  # a t = 0 wind event: named where it was
        summary["wind"]["steady_at_start"]["by"] = start[2]  # given, as the session's other lines name it (the
        # vehicle read it from the run's copy of the mission, whose path it named)
    summary["timing"] = timing_block(joined, m.rate_hz, facts.wall_s, vs, cs)
    if facts.clock == "realtime":
        summary["timing"]["stalls"] = stalls_block(vs, cs, joined.k0, m.rate_hz, m.duration_s,
                                                   relay_stats if relay is not None else None)
        # the controller's before the mission's first state (after the vehicle's arm): not the mission's, listed apart
        summary["timing"]["stalls_waiting"] = cs.get("stalls_waiting") or {"count": 0, "worst_ms": 0.0, "at": []}
    summary["sitl"] = {**facts.sitl, "vehicle_exit": vehicle.exit_text if vehicle else None,
                       "controller_exit": controller.exit_text if controller else None}
    lockstep, off_clock = None, None
    if facts.clock == "lockstep":
        off_clock = facts.off_clock_t
        summary["lockstep"] = lockstep = lockstep_record(mission, off_clock)
    children = [c for c in (vehicle, controller, relay) if c is not None]
    summary["outcome"], summary["ended_by"] = ended_by(summary["outcome"], arrays, flight, facts, events, mission,
                                                       children, controller_id)
    summary["interventions"] = changes = interventions(events, m.rate_hz, controller_id)
    transfer = mission_transfer(cs.get("mission_transfer") or facts.mission_transfer, vs.get("mission_start"))
    if transfer is not None:
        summary["mission_transfer"] = transfer.as_dict()
    if cs.get("param_at"):  # the scheduled changes (--param-at) as sent, each confirmed by the vehicle's echo or not
        summary["param_at"] = [made_in_flight(p, summary["duration_s"], events, controller_id)
                              for p in cs["param_at"]]
    summary["ended_by"] = ended_by_change(summary["ended_by"], summary["outcome"], mission, changes)
    summary["ended_by"].update(after_faults(summary["outcome"], [e.as_dict() for e in ev]))
    summary["ended_by"].update(not_reached(summary["outcome"], flight.timeline, arrays["t"], flight.wind))
    # a completed mission whose end action the vehicle never took (lost on the wire): not flown as asked
    if (untaken := end_not_taken(summary["outcome"], m.end_action, mission, m.duration_s)) is not None:
        summary["end"] = untaken
    if lockstep is not None:
        summary["lockstep"] = reproducibility(lockstep, changes)
    rules = rules_for(flight, facts.clock, link, controller_id)
    violated = judge(summary, arrays, events, rules, lockstep, off_clock, mission, hop)
    end = summary["ended_by"]
    texts = [("ended", f"{summary['outcome']}: by {end['who']}: {end['how']}")]
    if lockstep is not None and not lockstep["held"]:
        texts.append(("lockstep", f"not a lockstep run: the vehicle left lockstep at t={lockstep['left_at_s']:.3f} s "
                                  f"({lockstep['why']}) and flew on the wall clock"))
    elif lockstep is not None and changes:
        texts.append(("lockstep", f"reproducible until step {changes[0]['step']}: {intervention_text(changes[0])}"))
    texts += [("intervention", f"not flown as asked: {intervention_text(i)}") for i in changes]
    texts += [("param", f"not flown as asked: {unconfirmed_text(p)}") for p in summary.get("param_at", ())
              if not p["confirmed"]]
    if untaken is not None:
        texts.append(("end", f"not flown as asked: {not_taken_text(untaken)}"))
    texts += before_start_notes(hop)
    texts += [("policy", violation_text(v)) for v in violated]
    if (stalls := stalls_of(summary)) is not None:
        texts.append(("stall", stalls_text(stalls)))
    if summary["outcome"] != "completed" and (waited := summary["timing"].get("stalls_waiting", {})).get("count"):
        texts.append(("stall", waiting_stalls_text(waited)))  # not the mission's, but what may have ended it
    left = [lockstep["left_at_s"]] if lockstep is not None and not lockstep["held"] else []  # (its note's)
    stop = [e.t for e in events if e.t is not None] if facts.aborted else []  # all came before it, its effects too
    t = notes_time(joined, events, m.rate_hz, left + stop)
    notes = [RunEvent.at(t, kind, text, "session") for kind, text in texts]
    summary["events"] = [e.as_dict() for e in in_time_order((*events, *notes))]  # the notes in their time too
    return SessionSummary(arrays, summary, notes)

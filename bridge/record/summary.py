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


def link_block(joined: Joined, vehicle: Mapping[str, Any], controller: Mapping[str, Any],
               relay: Mapping[str, Any] | None) -> dict[str, Any]:
    """``summary.json["link"]`` (docs/design.md, "Files of a run") from each side's ``stats`` (``vehicle``,
    ``controller``; empty when a side left none), the join's measures, and the relay's statistics, per direction:

    - lockstep: the link model's exact statistics, from the end that applies it (the
      vehicle: ``up``, the controller: ``down``), ``delay_ms`` in simulation time; plus
      ``socket_ms``, the wall-clock one-way time of the per-step messages over the socket;
    - real time through the relay: the relay's counts (every datagram), ``delay_ms``
      measured end to end on every per-step message delivered (ODOMETRY down, the targets up)
      from both ends' tlogs (one host: one clock, no offset to estimate), the
      model's schedule (``model_delay_ms``) and the delay the relay added (``relay_added_ms``);
    - otherwise (real time, perfect link; a side that left no statistics): counts from
      both sides, ``delay_ms`` from their stamps.
    """
    vs, cs = vehicle, controller
    # what each side's receive path refused (bridge.mavlink.receive), and all of it by reason
    by = {"vehicle": dict(vs.get("rejected", {})), "controller": dict(cs.get("rejected", {}))}
    rejected = {r: by["vehicle"].get(r, 0) + by["controller"].get(r, 0)
                for r in sorted(set(by["vehicle"]) | set(by["controller"]))}
    own = int(vs.get("rejected_from_controller", sum(by["vehicle"].values())))  # of the controller's datagrams
    measured = {"up": percentiles(joined.up_ms), "down": percentiles(joined.down_ms)}
    model = {"up": vs.get("up"), "down": cs.get("down")}
    sides = {"up": socket_counts(int(cs.get("commands", joined.commands)), int(vs.get("accepted", 0)), own,
                                 *targets_outside(vs, cs), kernel=vs.get("kernel_drops")),
             # a killed controller left no stats: its rows, the steps they answer, and no time it stopped reading
             "down": socket_counts(int(vs.get("odometry_sent", 0)), int(cs.get("states", joined.commands)),
                                   int(cs.get("states_refused", 0)),
                                   *sends_outside(vs, cs if "state_window" in cs
                                                  else {"state_window": joined.controller_steps}),
                                   kernel=cs.get("kernel_drops"))}
    sides["up"]["reordered"] = int(rejected.get("reordered", 0))
    out: dict[str, Any] = {}
    for d in ("up", "down"):
        if relay is not None:
            r = relay[d]
            out[d] = {**{k: r[k] for k in ("sent", "delivered", "lost", "duplicated", "reordered", "in_flight",
                                           "lost_by")},
                      # the relay's socket of this direction: what the kernel dropped before the relay read it
                      "dropped_by_kernel": (relay.get("kernel_drops") or {}).get(d),
                      "delay_ms": measured[d], "model_delay_ms": r["delay_ms"], "relay_added_ms": r["measured_ms"]}
            if "trace" in r:  # a replayed link trace: its own delays and losses, as offline
                out[d]["trace"] = r["trace"]
        elif model[d]:
            out[d] = {**model[d], "socket_ms": measured[d]}
        else:
            out[d] = {**sides[d], "delay_ms": measured[d]}
    out["rejected"] = rejected
    out["rejected_by"] = by
    # of those, how many came from the other side itself, and how many from anyone else on the link (a
    # ground station's, a stranger's): the vehicle counts its controller's apart from the GCS link's
    ctl_own = int(cs.get("rejected_from_vehicle", sum(by["controller"].values())))
    out["rejected_from_peer"] = {"vehicle": own, "controller": ctl_own}
    out["rejected_from_others"] = {"vehicle": max(0, sum(by["vehicle"].values()) - own),
                                   "controller": max(0, sum(by["controller"].values()) - ctl_own)}
    if relay is not None:  # datagrams the relay refused, from neither of its two ends, by reason
        out["relay_refused"] = relay.get("refused", {})
        if relay.get("radio"):  # a fleet's one radio in real time: this vehicle's part of it, by direction
            out["radio"] = relay["radio"]
    elif vs.get("radio") or cs.get("radio"):  # in lockstep: the vehicle's commands, the controller's states
        out["radio"] = {"up": vs.get("radio"), "down": cs.get("radio")}
    return out


def socket_counts(sent: int, delivered: int, refused: int, in_flight: int, maybe: int = 0, *,
                  kernel: int | None) -> dict[str, Any]:
    """One direction of a link with no model between the two sockets (real time, perfect link), every datagram
    sent accounted for under its own name: ``delivered``; ``refused`` by the receiver; ``in_flight``, sent
    where the receiver was not reading (outside the steps it read, after it stopped: :func:`sends_outside`),
    plus of the ``maybe`` sends it cannot tell (read, or sent after it stopped) as many as were not read;
    ``shed`` by the receive budgets (none: the peer is exempt, docs/hostile-input.md); ``dropped_by_kernel`` (the
    receiving socket's counter, :func:`bridge.mavlink.kerneldrops.socket_drops`; 0 where unknown); ``lost`` on the
    link, the rest (sent = delivered + refused + lost + in_flight + shed + dropped_by_kernel)."""
    dropped = int(kernel or 0)
    in_flight += min(maybe, max(0, sent - delivered - refused - in_flight - dropped))
    return {"sent": sent, "delivered": delivered, "lost": sent - delivered - refused - in_flight - dropped,
            "duplicated": 0, "reordered": 0, "refused": refused, "in_flight": in_flight, "shed": 0,
            "dropped_by_kernel": dropped, "kernel_counts": kernel is not None}


def sends_outside(vehicle: Mapping[str, Any], controller: Mapping[str, Any]) -> tuple[int, int]:
    """Of the vehicle's state sends (its ``stats``: :class:`bridge.mavlink.receive.StepSends`), how many the
    controller surely never read, and how many it may not have: (surely, maybe). Surely: every send of a step
    outside the controller's window of steps read (``state_window``; each resend of one too), and a resend of a
    step inside it that left after the controller stopped reading (``read_until``; the resend's time before it
    left later: one host, one monotonic clock). Maybe: a resend that was leaving just then, one of steps past
    the vehicle's list, and the resends older than those it timed when even its oldest timed one left after."""
    window = controller.get("state_window")
    again = [(int(k), int(n)) for k, n in vehicle.get("odometry_again") or []]
    unlisted = int(vehicle.get("odometry_again_unlisted", 0))
    surely = steps_outside(vehicle.get("odometry_steps") or [], window)
    if window is None:  # it read none: every send
        return surely + sum(n for _, n in again) + unlisted, 0
    lo, hi = window
    surely += sum(n for k, n in again if not lo <= k <= hi)
    inside = sum(n for k, n in again if lo <= k <= hi)  # resends of steps it read: before it stopped, or after
    until = controller.get("read_until")
    if until is None:  # it did not say when it stopped reading
        return surely, unlisted + inside
    resent = vehicle.get("odometry_resent") or []  # the latest resends, oldest first: [step, before, after]
    timed = [(a, b) for k, a, b in resent if lo <= k <= hi]
    after, leaving = left_after(timed, until)
    untimed = sum(n for _, n in again) + unlisted - len(resent)  # older than those timed
    unsure = max(0, min(untimed, inside - len(timed))) if untimed > 0 and resent and resent[0][1] > until else 0
    return surely + after, unlisted + leaving + unsure


def targets_outside(vehicle: Mapping[str, Any], controller: Mapping[str, Any]) -> tuple[int, int]:
    """Of the controller's targets, how many surely left after the vehicle stopped reading (its ``read_until``; the
    controller's latest targets timed, ``targets_left``), and how many may have (leaving just then; older than those
    timed when even the oldest timed left after): (surely, maybe). (0, 0) where either side did not say."""
    until = vehicle.get("read_until")
    timed = [(a, b) for a, b in controller.get("targets_left") or []]
    if until is None or not timed:
        return 0, 0
    after, leaving = left_after(timed, until)
    older = int(controller.get("commands", 0)) - len(timed)
    return after, leaving + (older if older > 0 and timed[0][0] > until else 0)


def left_after(timed: Sequence[tuple[float, float]], until: float) -> tuple[int, int]:
    """Of sends timed ``(before, after)`` (s, ``time.monotonic``), how many surely left after ``until`` (the
    receiver's last look found its socket empty then: queued before it, read; after it, never) and how many were
    leaving at that very time (read or not)."""
    return sum(a > until for a, _ in timed), sum(a <= until <= b for a, b in timed)


def steps_outside(sent: Sequence[Sequence[int]], window: Sequence[int] | None) -> int:
    """How many of the steps ``sent`` (inclusive ``[first, last]`` ranges,
    :class:`bridge.mavlink.receive.StepRanges`) lie outside the receiver's ``window`` ([first, last] step read;
    None: it read none, all of them)."""
    total = sum(b - a + 1 for a, b in sent)
    if window is None:
        return total
    lo, hi = window
    inside = sum(max(0, min(b, hi) - max(a, lo) + 1) for a, b in sent)
    return total - inside


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


def stalls_text(stalls: Mapping[str, Any]) -> str:
    """The note of a real-time run the machine stalled (its events and printed summary)."""
    first = ", ".join(f"{s['side']} {s['ms']:g} ms at t={s['t']:.3f} s" for s in stalls["at"][:3])
    more = f" and {stalls['count'] - 3} more" if stalls["count"] > 3 else ""
    return (f"not flown as asked: the machine stalled the real-time loop {stalls['count']} time(s), worst "
            f"{stalls['worst_ms']:g} ms ({first}{more}): outages no link model asked for")


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
    link = link_block(joined, vs, cs, relay_stats if relay is not None else None)
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
    summary["timing"] = timing_block(joined, m.rate_hz, facts.wall_s, vs, cs)
    if facts.clock == "realtime":
        summary["timing"]["stalls"] = stalls_block(vs, cs, joined.k0, m.rate_hz, m.duration_s,
                                                   relay_stats if relay is not None else None)
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
    left = [lockstep["left_at_s"]] if lockstep is not None and not lockstep["held"] else []  # (its note's)
    stop = [e.t for e in events if e.t is not None] if facts.aborted else []  # all came before it, its effects too
    t = notes_time(joined, events, m.rate_hz, left + stop)
    notes = [RunEvent.at(t, kind, text, "session") for kind, text in texts]
    summary["events"] = [e.as_dict() for e in in_time_order((*events, *notes))]  # the notes in their time too
    return SessionSummary(arrays, summary, notes)

"""Safety policies as executable properties (in the manner of PGFuzz), checked over every run.

In:  a run's trace arrays by column (:data:`~bridge.record.columns.TRACE_COLUMNS`: ``t`` s, ``u*_act`` N,
     ``state_age_s`` s), its events (:class:`~bridge.record.events.RunEvent`: ``t`` s, ``kind``, ``text``, in a
     session ``source``, and who caused it, ``by``), the :class:`Rules` it flew under (control rate Hz, ``[failsafe]
     timeout_s`` s, clock, link delays s, the controller's ids), and in a lockstep session its ``lockstep`` record and
     the first step its vehicle flew off the step clock; in a session, its events split at the mission's time 0 (the
     mission's and the hop's: :func:`~bridge.record.events.split_at_start`)
Out: one :class:`Verdict` per policy of :data:`POLICIES` (``ok``; when violated, the mission time of the first
     violation and a one-line why), for ``summary.json["policies"]``; and the lockstep record that goes with them
     (:func:`lockstep_record`; who ended a flight, by command or how: :mod:`bridge.record.endedby`)

The offline loop (:mod:`bridge.loop`) and the SITL session (:mod:`bridge.session`) both call :func:`check` on what
they recorded, so every run is judged by the same properties; a violated policy is named on stderr and in
``summary.json`` and makes ``bsst sim`` / ``bsst sitl`` exit 1.

What each policy reads, and why it cannot be fooled by a run's own claims:

- ``no_actuation_disarmed``: the disarmed intervals from the vehicle's ``armed`` / ``disarmed`` events; every trace
  row strictly inside one must realise zero wrench (``u1_act..u4_act``). With a motor lag (``Rules.spin_down``) the
  rotors spin down instead: the realised values may only shrink.
- ``failsafe_in_time``: armed under offboard control (from an ``armed`` event, or the start
  offline), the vehicle must leave offboard control (its ``failsafe`` event, a disarm, a
  divergence, or the mission's ``end``) within ``timeout_s`` plus one control period of the last valid target. The
  targets are read from the trace: a row that answers its step (offline, lockstep) with a
  command (finite ``state_age_s``) sent one at ``t``, which acts at most the up link's largest
  delay later (``Rules.command_slack_s``); a row that shows the command in force (real time,
  or lockstep after the vehicle left it) has it from the state stamped ``t - state_age_s``: a
  new stamp arrived by ``t``, and the controller repeats a stamp for at most its link guard's
  ``stop_ms`` plus the link's delays (``Rules.hold_slack_s``). These bounds are upper ones: a
  lost command counts as sent, so a lossy link never makes a violation, and a vehicle that
  flies on without targets always does.
- ``arm_authority``: every arm or disarm the vehicle reports names its sender (the event's ``by``:
  sysid, compid, address and link, or the vehicle itself): on the controller link only the
  configured controller's ids have authority; on the GCS link any ground station (with a key
  only signed frames get that far: the receive path refuses the rest). An event that names
  nobody is not judged.
- ``lockstep_recorded``: in a lockstep session, a vehicle that left lockstep (its ``lockstep`` event, or a vehicle
  row flown off the step clock) has a record saying so (``held`` false, the time of the first event); a row off the
  step clock with no ``lockstep`` event before it is a vehicle that left silently. The mission's steps only: what a
  ground station flew before an awaited mission's start (events before its time 0) is not the mission's.
- ``geofence``: every trace row's position is inside the mission's geofence (a ``.plan``'s ``geoFence`` or a
  mission's ``[geofence]``: inside an inclusion zone if there is one, outside every exclusion zone, as PX4's
  navigator judges it), and the vehicle never said it was outside a fence a ground station uploaded or beyond
  GF_MAX_HOR_DIST / GF_MAX_VER_DIST (its ``geofence`` event); the vehicle also acts on a breach (GF_ACTION). The
  mission's: a ground station's own flight before an awaited mission's start is its notes' (bridge.record.summary).
- ``time_steady``: the trace's ``t`` increases by exactly one control period from row to row (a missing row, a
  repeated step or a jump of the mission's clock breaks it), except over steps the vehicle flew disarmed: on the
  wall clock it writes no rows then (real time, landed by its failsafe until ``[failsafe] resume`` re-arms it).
- ``touchdown``: no ``touchdown`` event of the vehicle (armed in OFFBOARD, airborne, down with its reference up).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from bridge.autopilot.simvehicle import OFFBOARD
from bridge.record.events import RunEvent

POLICIES: dict[str, str] = {
    "no_actuation_disarmed": "the realised thrust and torques are zero whenever the vehicle is disarmed",
    "failsafe_in_time": "armed under offboard control, the vehicle fails safe within the timeout plus one step "
                        "of its last valid target",
    "arm_authority": "no arm or disarm from a sender without authority (controller link: the configured "
                     "controller only; GCS link: any ground station)",
    "lockstep_recorded": "lockstep is never left without a record",
    "time_steady": "the mission's time never jumps: trace t increases by one control period each row",
    "geofence": "the vehicle stays inside its mission's geofence (a plan's geoFence, or [geofence]), any fence a "
                "ground station uploaded, and GF_MAX_HOR_DIST / GF_MAX_VER_DIST (the vehicle acts on a breach by "
                "GF_ACTION, as PX4)",
    "touchdown": "armed and airborne, the vehicle touches the ground only in a landing it was asked to make",
}
EPS_S = 1e-5  # s: event times are rounded to 1 us; a physics step is at least 100 us
ZERO_N = 1e-9  # N: a realised wrench this small is zero
CONTROLLER_ID = (200, 191)  # the configured controller's sysid, compid (bridge.mavlink.endpoint's default)
_ENDS_OFFBOARD = ("failsafe", "disarmed", "diverged", "end")  # (``end``: the vehicle flies the mission's end action)


@dataclass(frozen=True)
class Rules:
    """What a run is judged against. ``clock``: ``offline``, ``lockstep`` or ``realtime``;
    ``armed_at_start``: the offline loop's vehicle is armed from t = 0, a session's is not;
    ``command_slack_s``: how long after its row a command sent may act (the up link's largest
    delay); ``hold_slack_s``: how long after its state's stamp a command in force may still be
    repeated (the guard's ``stop_ms`` plus both links' largest delays plus a period);
    ``spin_down``: a motor lag spins the rotors down after a disarm instead of stopping them."""

    rate_hz: float
    timeout_s: float
    clock: str = "offline"
    armed_at_start: bool = False
    command_slack_s: float = 0.0
    hold_slack_s: float = 0.0
    controller_id: tuple[int, int] = CONTROLLER_ID
    spin_down: bool = False
    geofence: Any = None  # the mission's missions.geofence.Geofence (None: none)
    fence_acted: bool = True  # GF_ACTION is not 0: the vehicle acts on a breach (with 0 it only says one, of a fence
    # the record does not hold: bridge.autopilot.vehiclechecks.check_limits)

    @property
    def period_s(self) -> float:
        return 1.0 / self.rate_hz


@dataclass(frozen=True)
class Verdict:
    """One policy over one run: ``ok``, or the mission time ``t`` (s) of its first violation and why."""

    name: str
    ok: bool
    t: float | None = None
    why: str | None = None
    note: str | None = None  # what a verdict that holds rests on, when it is not the whole run (geofence_kept)

    def as_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"name": self.name, "ok": self.ok}
        if not self.ok:
            out["t"] = None if self.t is None or not math.isfinite(self.t) else round(self.t, 6)
            out["why"] = self.why
        elif self.note is not None:
            out["note"] = self.note
        return out


def vehicle_events(events: Sequence[RunEvent]) -> list[RunEvent]:
    """The events the vehicle reported (offline: all of them; a session's carry ``source``), with a time."""
    return [e for e in events if (e.source or "vehicle") == "vehicle" and e.t is not None]


# -- the honest records ------------------------------------------------------------------------------
def lockstep_record(events: Sequence[RunEvent], off_clock_t: float | None = None) -> dict[str, Any]:
    """``summary.json["lockstep"]`` of a lockstep session: ``{"held": true}``, or ``held`` false with
    the time and text of the vehicle's first ``lockstep`` event (``left_at_s``, ``why``) and how many
    times it left (``times``); a vehicle row flown off the step clock (from ``off_clock_t`` s) with
    no such event is recorded too, as having left without saying so. ``events``: the mission's (a ground station's
    flight before an awaited mission's start, before its time 0, is its interventions')."""
    left = [e for e in vehicle_events(events) if e.kind == "lockstep"]
    if left:
        first = left[0]
        return {"held": False, "left_at_s": first.t, "why": first.text, "times": len(left)}
    if off_clock_t is not None:
        return {"held": False, "left_at_s": round(off_clock_t, 6),
                "why": "the vehicle flew off the step clock without saying so", "times": 1}
    return {"held": True}


# -- the policies ----------------------------------------------------------------------------------------
def check(trace: Mapping[str, Any], events: Sequence[RunEvent], rules: Rules,
          lockstep: Mapping[str, Any] | None = None, off_clock_t: float | None = None,
          mission: Sequence[RunEvent] | None = None, hop: Sequence[RunEvent] = ()) -> list[Verdict]:
    """Every policy of :data:`POLICIES` over one run, in that order (see the module docstring). ``events``: all of
    the run's; ``mission``, those from the mission's time 0 (None: all: offline), ``hop``, those before it
    (:func:`~bridge.record.events.split_at_start`)."""
    ev = vehicle_events(events)
    ours = ev if mission is None else vehicle_events(mission)  # the mission's
    t = np.asarray(trace["t"], dtype=float)
    return [
        no_actuation_disarmed(t, [np.asarray(trace[f"u{i}_act"], dtype=float) for i in range(1, 5)], ev, rules),
        failsafe_in_time(t, np.asarray(trace["state_age_s"], dtype=float), ev, rules, ours),
        arm_authority(ev, rules),
        lockstep_recorded(ours, rules, lockstep, off_clock_t),
        time_steady(t, rules, ev),
        geofence_kept(t, trace, rules, ev, ours, vehicle_events(hop)),
        touchdown_kept(ev),
    ]


def all_hold(verdicts: Sequence[Mapping[str, Any]] | None) -> bool:
    """Whether every policy of ``summary.json["policies"]`` holds (none checked: vacuously)."""
    return all(v.get("ok") for v in verdicts or ())


def disarmed_intervals(events: Sequence[RunEvent], armed_at_start: bool) -> list[tuple[float, float]]:
    """(disarm t, next arm t or inf) of each disarmed stretch the vehicle's events tell, in order."""
    out: list[tuple[float, float]] = []
    since: float | None = None if armed_at_start else -math.inf
    for e in events:
        if e.kind == "disarmed" and since is None:
            since = e.t
        elif e.kind == "armed" and since is not None:
            out.append((since, e.t))
            since = None
    if since is not None:
        out.append((since, math.inf))
    return out


def no_actuation_disarmed(t: np.ndarray, realised: Sequence[np.ndarray], events: Sequence[RunEvent],
                          rules: Rules) -> Verdict:
    """Rows strictly inside a disarmed stretch realise no wrench (``spin_down``: never more than the row before)."""
    name = "no_actuation_disarmed"
    u = np.abs(np.column_stack(realised)) if len(t) else np.zeros((0, 4))
    for start, end in disarmed_intervals(events, rules.armed_at_start):
        inside = np.nonzero((t > start + EPS_S) & (t < end - EPS_S))[0]
        if not len(inside):
            continue
        if rules.spin_down:
            grew = np.nonzero(np.any(u[inside[1:]] > u[inside[:-1]] + ZERO_N, axis=1))[0]
            if len(grew):
                i = inside[grew[0] + 1]
                return Verdict(name, False, float(t[i]), f"disarmed since t={start:.3f} s, the realised wrench "
                                                         f"grows at t={t[i]:.3f} s ({_wrench(u[i])})")
            continue
        bad = np.nonzero(np.any(u[inside] > ZERO_N, axis=1))[0]
        if len(bad):
            i = inside[bad[0]]
            return Verdict(name, False, float(t[i]), f"disarmed since t={start:.3f} s, yet at t={t[i]:.3f} s "
                                                     f"the plant realises {_wrench(u[i])}")
    return Verdict(name, True)


def _wrench(u: np.ndarray) -> str:
    return f"|u1..u4| = {u[0]:.3g} N, {u[1]:.3g}, {u[2]:.3g}, {u[3]:.3g}"


def offboard_intervals(events: Sequence[RunEvent], armed_at_start: bool
                       ) -> list[tuple[float, float, str | None]]:
    """(arm t, t it left offboard control or inf, the kind of event that ended it or None) of
    each stretch armed under offboard control."""
    out: list[tuple[float, float, str | None]] = []
    since: float | None = -math.inf if armed_at_start else None
    for e in events:
        if e.kind == "armed":
            if since is not None:  # armed again without leaving: the timeout restarts
                out.append((since, e.t, "armed"))
            since = e.t
        elif e.kind == "mode" and e.armed and e.mode == OFFBOARD:
            if since is not None:  # OFFBOARD again, armed: the timeout counts from the switch
                out.append((since, e.t, "mode"))
            since = e.t
        elif (e.kind in _ENDS_OFFBOARD or (e.kind == "mode" and e.armed)) \
                and since is not None:  # a failsafe, a disarm, or a ground station's HOLD, LAND, TAKEOFF
            out.append((since, e.t, e.kind))
            since = None
    if since is not None:
        out.append((since, math.inf, None))
    return out


def failsafe_in_time(t: np.ndarray, age: np.ndarray, events: Sequence[RunEvent], rules: Rules,
                     mission: Sequence[RunEvent] | None = None) -> Verdict:
    """Armed offboard, no stretch longer than ``timeout_s`` + one period since the last valid target
    without a failsafe (see the module docstring for how the targets are read from the trace). ``mission``: the
    events from the mission's time 0 (None: all), where a departure from lockstep is the mission's."""
    name = "failsafe_in_time"
    period = rules.period_s
    changes = timeout_changes(events)
    left = next((e.t for e in (events if mission is None else mission) if e.kind == "lockstep"), math.inf)
    answers_until = left if rules.clock in ("offline", "lockstep") else -math.inf  # rows answering their step
    for start, end, kind in offboard_intervals(events, rules.armed_at_start):
        last = start if math.isfinite(start) else (float(t[0]) if len(t) else 0.0)  # arming restarts the timeout
        stamp = math.nan
        inside = np.nonzero((t >= start - EPS_S) & (t < end - EPS_S))[0]
        for i in inside:
            ti, ai = float(t[i]), float(age[i])
            if math.isfinite(ai):
                if ti < answers_until - EPS_S:
                    last = max(last, ti + rules.command_slack_s)
                else:  # the command in force: from the state stamped ti - ai
                    s = ti - ai
                    if abs(s - stamp) > EPS_S or math.isnan(stamp):
                        last = max(last, ti + period)  # a new one, in by ti (repeats of it within a period)
                        stamp = s
                    last = max(last, s + rules.hold_slack_s)
            timeout = timeout_between(rules.timeout_s, changes, last, ti)
            if ti > last + timeout + period + EPS_S:
                return Verdict(name, False, ti, f"armed offboard with no actuator target since t={last:.3f} s, "
                                                f"still no failsafe at t={ti:.3f} s (timeout {timeout:g} s "
                                                f"+ one step {period:g} s)")
        timeout = timeout_between(rules.timeout_s, changes, last, end)
        if kind == "failsafe" and end > last + timeout + period + EPS_S:
            return Verdict(name, False, end, f"failsafe at t={end:.3f} s, {end - last:.3f} s after the last valid "
                                             f"target at t={last:.3f} s (timeout {timeout:g} s + one step "
                                             f"{period:g} s)")
    return Verdict(name, True)


def timeout_changes(events: Sequence[RunEvent]) -> list[tuple[float, float]]:
    """(t s, new timeout s) of each change of the offboard-loss timeout (COM_OF_LOSS_T) the events tell
    (a ``param`` event's typed change, ``param``: name, old and new value)."""
    return [(e.t, e.param.new) for e in events
            if e.kind == "param" and e.param is not None and e.param.name == "COM_OF_LOSS_T"]


def timeout_between(start: float, changes: Sequence[tuple[float, float]], a: float, b: float) -> float:
    """The longest timeout in force at any time in [a, b] (s): ``start`` changed by ``changes``; a
    failsafe is late only if it is late under each (a change of COM_OF_LOSS_T acts from its step on)."""
    now = start
    longest = -math.inf
    for t, v in changes:
        if t > b + EPS_S:
            break
        if t > a + EPS_S:
            longest = max(longest, now)
        now = v
    return max(longest, now)


def arm_authority(events: Sequence[RunEvent], rules: Rules) -> Verdict:
    """Every arm and disarm (and mode change) that names its sender names one with authority."""
    name = "arm_authority"
    for e in events:
        if e.kind not in ("armed", "disarmed", "mode"):
            continue
        who = e.by
        if who is None or who.is_vehicle or who.link == "gcs":
            continue
        if who.link != "controller":
            return Verdict(name, False, e.t, f"{e.kind} by {who}: not a link the vehicle has")
        if (who.sysid, who.compid) != rules.controller_id:
            ids = f"{rules.controller_id[0]}:{rules.controller_id[1]}"
            return Verdict(name, False, e.t, f"{e.kind} by {who}: on the controller link only {ids} has authority")
    return Verdict(name, True)


def lockstep_recorded(events: Sequence[RunEvent], rules: Rules, record: Mapping[str, Any] | None,
                      off_clock_t: float | None) -> Verdict:
    """A lockstep session that left lockstep says so: the vehicle's event (of ``events``, the mission's), and a record
    that agrees."""
    name = "lockstep_recorded"
    if rules.clock != "lockstep":
        return Verdict(name, True)
    left = next((e for e in events if e.kind == "lockstep"), None)
    if off_clock_t is not None and (left is None or left.t > off_clock_t + rules.period_s + EPS_S):
        return Verdict(name, False, off_clock_t, f"the vehicle flew off the step clock from t={off_clock_t:.3f} s "
                                                 "without a lockstep event")
    if left is None:
        if record is not None and not record.get("held", False):
            return Verdict(name, False, record.get("left_at_s"), "the record says lockstep was left, the vehicle "
                                                                  "never said so")
        return Verdict(name, True)
    if record is None or record.get("held", True):
        return Verdict(name, False, left.t, f"the vehicle left lockstep at t={left.t:.3f} s ({left.text}), "
                                            "the record says it held")
    at = record.get("left_at_s")
    if at is None or abs(at - left.t) > EPS_S:
        return Verdict(name, False, left.t, f"the vehicle left lockstep at t={left.t:.3f} s, the record says at {at}")
    return Verdict(name, True)


def geofence_kept(t: np.ndarray, trace: Mapping[str, Any], rules: Rules, events: Sequence[RunEvent] = (),
                  mission: Sequence[RunEvent] | None = None, hop: Sequence[RunEvent] = ()) -> Verdict:
    """Every row's position (``x``, ``y``) inside the mission's geofence (:mod:`missions.geofence`), and no
    ``geofence`` event of the vehicle (outside a fence a ground station uploaded: bridge.nodes.vehicle.zones); ok
    without either. The mission's fence is the one at the start: a fence a ground station uploads (or clears) in
    flight replaces it in the vehicle (its ``fence`` event), so rows from then on are the vehicle's watch's to
    judge (its ``geofence`` event, said with GF_ACTION 0 too), and the verdict says so (``note``); so are all rows
    when the flight started with a fence uploaded after the record's (the vehicle's ``fence`` event at its arm).
    ``mission``: the events from the mission's time 0 (None: all), whose breach is the mission's; ``hop``: those
    before it (a ground station's own flight)."""
    name = "geofence"
    left = next((e for e in (events if mission is None else mission) if e.kind == "geofence"), None)
    changed = _fence_changed_in_flight(events, hop)
    n = len(t) if changed is None else int(np.searchsorted(t, changed.t))  # the rows before it (in time order)
    breach = rules.geofence.first_breach(t[:n], np.asarray(trace["x"])[:n], np.asarray(trace["y"])[:n]) \
        if rules.geofence is not None and n else None
    if left is not None and (breach is None or (left.t is not None and left.t < breach[0])):
        return Verdict(name, False, left.t, left.text)
    if breach is not None:
        return Verdict(name, False, breach[0], f"{breach[1]} (the vehicle acts by GF_ACTION)")
    return Verdict(name, True, note=None if changed is None else _fence_note(changed, n, rules.fence_acted))


def _fence_note(changed: RunEvent, before: int, acted: bool) -> str:
    """The verdict's note on a fence the record does not hold: when it came, and what judged the trace."""
    watch = f"the vehicle's watch of {'the new one' if before else 'it'}" + (
        "" if acted else " (GF_ACTION = 0: it acts on no breach, but says the first, for this record)")
    if not before:  # (its arm's event: uploaded after the controller's download, or before a plain session's arm)
        return f"{changed.shown}: the trace is judged by {watch}, not against mission.toml's fence"
    return (f"the fence changed in flight at t={changed.t:.3f} s ({changed.shown}): the trace is judged against the "
            f"mission's fence (the one at the start) until then, by {watch} after")


def _fence_changed_in_flight(events: Sequence[RunEvent], hop: Sequence[RunEvent] = ()) -> RunEvent | None:
    """The vehicle's first event of a fence uploaded or cleared after its flight's arm (its first ``armed`` event
    that is not a ground station's arm awaiting a mission's start, nor of a ground station's own flight that a disarm
    of ``hop``, before the mission's time 0, ended), or the one it says at that arm when the fence it holds is not
    the record's (uploaded after the controller's download: bridge.nodes.vehicle.mission): the fence before it is
    the one the record holds (``--await-mission``: the one the controller downloaded, after any such flight)."""
    landed = {e for e in hop if e.kind == "disarmed"}
    flying, changed = False, None
    for e in events:
        if e.kind == "armed" and not e.pre_start:
            flying = True
        elif e in landed:  # (only its landing: the mission's own arm may come just before its 0, in real time)
            flying, changed = False, None
        elif flying and changed is None and e.kind == "fence":  # (uploaded or cleared: ...vehicle.mission.EVENT_OF)
            changed = e
    return changed


def touchdown_kept(events: Sequence[RunEvent]) -> Verdict:
    """No ``touchdown`` event of the vehicle (bridge.autopilot.touchdownwatch); its first breaks the policy."""
    down = next((e for e in events if e.kind == "touchdown"), None)
    return Verdict("touchdown", True) if down is None else Verdict("touchdown", False, down.t, down.text)


def time_steady(t: np.ndarray, rules: Rules, events: Sequence[RunEvent] = ()) -> Verdict:
    """``t`` finite and increasing by exactly one control period from row to row. The one gap allowed is over steps
    the vehicle's events say it flew disarmed (real time writes no rows then: landed by its failsafe until a re-arm)."""
    name = "time_steady"
    period = rules.period_s
    if len(t) and not np.all(np.isfinite(t)):
        i = int(np.nonzero(~np.isfinite(t))[0][0])
        return Verdict(name, False, float(t[i - 1]) if i else None, f"row {i} has t = {t[i]}")
    d = np.diff(t)
    bad = np.nonzero(np.abs(d - period) > 1e-6 * period)[0]
    off = disarmed_intervals(events, rules.armed_at_start)
    for i in map(int, bad):
        a, b = float(t[i]), float(t[i + 1])
        if b > a and any(s <= a + period + EPS_S and b - period - EPS_S <= e for s, e in off):
            continue  # every step in between flown disarmed, unrecorded
        return Verdict(name, False, a, f"t goes from {a:.6f} s to {b:.6f} s (one period is {period:g} s)")
    return Verdict(name, True)


def rules_for(flight: Any, clock: str, link: Mapping[str, Any] | None,
              controller_id: tuple[int, int] = CONTROLLER_ID) -> Rules:
    """The :class:`Rules` of a :class:`~bridge.core.flight.Flight` flown on ``clock``, with the
    largest delays of its ``summary.json["link"]`` block (ms; none: 0) and the configured
    controller's ids."""
    m = flight.mission

    def max_s(d: str) -> float:
        v = ((link or {}).get(d) or {}).get("delay_ms") or {}
        x = v.get("max")
        return 1e-3 * float(x) if x is not None and math.isfinite(float(x)) else 0.0

    up, down = max_s("up"), max_s("down")
    physics = 1.0 / m.physics_hz
    lag = flight.profile.actuation == "motors" and bool(getattr(flight.effects, "motor_lag", False))
    return Rules(rate_hz=m.rate_hz, timeout_s=flight.failsafe.timeout_s, clock=clock,
                 armed_at_start=clock == "offline", command_slack_s=up + physics,
                 hold_slack_s=flight.guard.stop_s + up + down + 1.0 / m.rate_hz, controller_id=controller_id,
                 spin_down=lag, geofence=m.geofence, fence_acted=flight.params.fence_action != 0)


def judge(summary: dict[str, Any], trace: Mapping[str, Any], events: Sequence[RunEvent], rules: Rules,
          lockstep: Mapping[str, Any] | None = None, off_clock_t: float | None = None,
          mission: Sequence[RunEvent] | None = None, hop: Sequence[RunEvent] = ()) -> list[Verdict]:
    """:func:`check` a run and put the verdicts into its ``summary["policies"]``; the violated ones."""
    verdicts = check(trace, events, rules, lockstep, off_clock_t, mission, hop)
    summary["policies"] = [v.as_dict() for v in verdicts]
    return [v for v in verdicts if not v.ok]


def violation_text(v: Verdict | Mapping[str, Any]) -> str:
    """One line naming a violated policy: ``NAME violated at t=... s: why``."""
    d = v.as_dict() if isinstance(v, Verdict) else v
    at = f" at t={d['t']:.3f} s" if d.get("t") is not None else ""
    return f"{d['name']} violated{at}: {d.get('why')}"


def stalls_of(summary: Mapping[str, Any]) -> Mapping[str, Any] | None:
    """A real-time run's ``timing.stalls`` when the machine stalled it (not flown as asked), else None."""
    stalls = (summary.get("timing") or {}).get("stalls")
    return stalls if stalls and stalls.get("count") else None


def run_ok(summary: Mapping[str, Any]) -> bool:
    """Whether a run is a clean completion (exit status 0): outcome ``completed``, every policy
    holds, a lockstep session held lockstep throughout, nobody but the flight's controller changed
    the flight (``interventions``, e.g. a ground station's parameter), the vehicle confirmed every
    scheduled change (``param_at``), took the mission's end action (``end.taken``) and (real time) the machine never
    stalled the loop (``timing.stalls``): else not flown as asked."""
    return (summary.get("outcome") == "completed" and all_hold(summary.get("policies"))
            and (summary.get("end") or {}).get("taken", True)
            and (summary.get("lockstep") or {"held": True}).get("held", False) and not summary.get("interventions")
            and all(p.get("confirmed") for p in summary.get("param_at") or ())
            and stalls_of(summary) is None)

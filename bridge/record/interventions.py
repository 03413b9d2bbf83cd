"""The changes made to a flight by someone other than its controller (a ground station), and what they mean for it.

In:  the run's events (:class:`~bridge.record.events.RunEvent`: the vehicle's, with their typed ``by`` and ``param``
     fields), the control rate (Hz), the flight's controller's (sysid, compid); the lockstep record and ``ended_by``
     of ``summary.json``; a scheduled change's entry (``summary.json["param_at"]``), the flight's end (s)
Out: ``summary.json["interventions"]`` (:func:`interventions`: t s, step, by, kind, what, a parameter's name, old,
     new), the lockstep record with whether the run can be flown again to the bit (:func:`reproducibility`),
     ``ended_by`` naming a ground station's failsafe parameter (:func:`ended_by_change`), and the lines a person
     reads (:func:`intervention_text`, :func:`unconfirmed_text`); a change confirmed after the flight's end as not
     made in flight (:func:`made_in_flight`)
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from bridge.autopilot.params import BY_NAME, float32, shown_value
from bridge.record.events import RunEvent
from bridge.record.policies import CONTROLLER_ID, vehicle_events

SENT_SLACK_S = 0.01  # s: a change's first PARAM_SET is stamped on the controller's clock, mapped to the vehicle's

# the vehicle's events that a sender other than the flight's controller may cause and that change the flight
INTERVENING = ("param", "mode", "armed", "disarmed", "fault")  # fault: a ground station's injected failure


def interventions(events: Sequence[RunEvent], rate_hz: float,
                  controller_id: tuple[int, int] = CONTROLLER_ID) -> list[dict[str, Any]]:
    """``summary.json["interventions"]``: every change to the flight made by a sender other than the flight's
    controller (a ground station), in order: each one's ``t`` (s, the mission's clock), ``step`` (the control
    step it acted from: round(t * rate_hz), the trace's row), ``by`` (the sender), ``kind`` and ``what``, and for a
    parameter its ``name``, ``old`` and ``new`` value; ``before_start`` (true) for one before the mission's time 0
    (negative t and step: a ground station's doings before an awaited mission's start, its own flight among
    them). Read from the vehicle's events' typed fields (``by``, ``param``): a parameter change (a set to the value
    in force makes no event), and while the vehicle is armed a mode, an arm or a disarm; a ground station's arm is
    one too, except its arm in HOLD on the ground awaiting a mission's start (``pre_start``: nothing flies until the
    start, which the flight's controller flies from its own arm; docs/missions.md)."""
    out: list[dict[str, Any]] = []
    armed = False
    for e in vehicle_events(events):
        by = e.by
        was_armed, armed = armed, (e.kind == "armed") or (armed and e.kind != "disarmed")
        if e.kind not in INTERVENING or by is None or by.is_vehicle or e.pre_start:
            continue
        if by.link == "controller" and (by.sysid, by.compid) == controller_id:
            continue
        if e.kind == "mode" and not was_armed:  # the mode a later arm of the controller's leaves: no change
            continue
        assert e.t is not None  # vehicle_events have a time
        d: dict[str, Any] = {"t": e.t, "step": round(e.t * rate_hz), "by": str(by), "kind": e.kind, "what": e.text}
        if e.before_start:
            d["before_start"] = True
        if e.param is not None:
            d.update(e.param.as_dict())
        out.append(d)
    return out


def intervention_text(i: Mapping[str, Any]) -> str:
    """One intervention as a person reads it: who, what, when (t and step)."""
    what = (f"changed {i['name']} from {shown_value(i['old'])} to {shown_value(i['new'])}" if "name" in i
            else f"{'set the mode' if i['kind'] == 'mode' else i['kind']}: {i['what']}")
    before = ", before the mission's start" if i.get("before_start") else ""
    return f"a ground station ({i['by']}) {what} at t={i['t']:.3f} s (step {i['step']}){before}"


def unconfirmed_text(p: Mapping[str, Any]) -> str:
    """A scheduled change (``summary.json["param_at"]``'s entry) the vehicle never confirmed in flight, for a
    person."""
    never = "never confirmed by the vehicle" if p.get("late_t") is None else \
        f"confirmed by the vehicle only at t={p['late_t']:.3f} s, after the flight's end"
    return f"--param-at {p['t_s']:g}:{p['name']}={p['value']:g} was {never} ({p['sends']} PARAM_SETs): not made"


def made_in_flight(p: Mapping[str, Any], end_s: float, events: Sequence[RunEvent],
                   controller_id: tuple[int, int] = CONTROLLER_ID) -> dict[str, Any]:
    """A scheduled change's entry (``summary.json["param_at"]``) judged against the flight's end (s, the time flown)
    by the vehicle's own event of the change where it has one, whenever its echo reached the controller: made by the
    end, it was made in flight (``confirmed``, at that event or the echo's arrival if later, when that came in
    flight: the controller maps it onto the vehicle's clock only to within the way down's few ms), even if the echo
    came after it (a real-time link's delay); made after the end (the vehicle crashed in a real-time blackout the
    controller heard of only after it), it was not (``confirmed`` false, its time as ``late_t``). A set to the value
    in force has no event of the vehicle's (no change): its echo's time is judged."""
    made = [e.t for e in vehicle_events(events) if e.kind == "param" and e.param is not None and e.by is not None
            and e.by.link == "controller" and (e.by.sysid, e.by.compid) == controller_id and e.param.name == p["name"]
            and float32(e.param.new) == float32(p["value"]) and e.t >= p["sent_t"] - SENT_SLACK_S]
    echoed = p.get("confirmed_t") if p.get("confirmed") else p.get("late_t")
    if not made and echoed is None:  # never echoed, never made
        return dict(p)
    t = made[0] if made else echoed
    if t > end_s + 1e-9:
        return {**p, "confirmed": False, "confirmed_t": None, "late_t": max(t, echoed or t)}
    in_flight = {k: v for k, v in p.items() if k != "late_t"}
    return {**in_flight, "confirmed": True, "confirmed_t": t if echoed is None or echoed > end_s else max(t, echoed)}


def reproducibility(lockstep: dict[str, Any], changes: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """The lockstep record with whether the run can be flown again to the bit: as it was without a change
    (``held`` says it), or ``reproducible`` false with ``reproducible_until_step`` (the first intervention's
    step: the steps before it are the mission's, the ones from it on depend on when the change arrived on
    the wall clock; 0 for a change before the mission's time 0) and ``because`` (that change)."""
    if not changes:  # held: reproducible (the record stays as it was); not held: its own why
        return lockstep
    first = changes[0]
    return {**lockstep, "reproducible": False, "reproducible_until_step": max(0, first["step"]),
            "because": intervention_text(first)}


def ended_by_change(end: dict[str, Any], outcome: str, events: Sequence[RunEvent],
                    changes: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """``ended_by`` naming the ground station whose parameter change made the vehicle's failsafe act as it
    did (its action, timeout, hold time or descent: a failsafe parameter set before the failsafe began),
    else ``end`` as it was. ``events``: the mission's (a ground station's own flight's failsafe, before an awaited
    mission's start, is not the one that ended it)."""
    if outcome != "failsafe" or end.get("who") != "vehicle":
        return end
    fs = next((e for e in vehicle_events(events) if e.kind == "failsafe"), None)
    cause = [c for c in changes if "name" in c and BY_NAME[c["name"]].failsafe_key is not None
             and (fs is None or c["t"] <= (fs.t or 0.0))]
    if not cause:
        return end
    c = cause[-1]
    return {"who": c["by"], "how": f"{end['how']}, under {c['name']} = {c['new']:g} (was {c['old']:g}) set by a "
                                   f"ground station at t={c['t']:.3f} s (step {c['step']})"}

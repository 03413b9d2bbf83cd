"""Who or what ended a flight, as its events tell it: ``summary.json["ended_by"]``.

In:  a run's events (:class:`~bridge.record.events.RunEvent`: ``t`` s, ``kind``, ``text``, in a session ``source``,
     and who caused it, ``by``; who ended it and how, from the mission's: from its time 0,
     :func:`~bridge.record.events.split_at_start`), its outcome (``completed``, ``failsafe``, ``diverged``, ...),
     the configured controller's ids (sysid, compid) and the mission's end (s)
Out: who ended it and how (:func:`ended_by_outcome`: ``{"who", "how"}``), the first disarm or takeover by command
     the controller did not send (:func:`ended_by_command`: the event and its sender), the end of a flight whose
     arm the vehicle's pre-arm check denied (:func:`arming_denied_end`), and the vehicle's failsafe in the mission
     that no arm after it ended (:func:`failsafe_not_resumed`)
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from bridge.autopilot.simvehicle import OFFBOARD
from bridge.autopilot.vehicleevents import Sender
from bridge.record.events import RunEvent, in_time_order
from bridge.record.policies import CONTROLLER_ID, EPS_S, vehicle_events


def ended_by_command(events: Sequence[RunEvent], controller_id: tuple[int, int] = CONTROLLER_ID,
                     before_s: float = math.inf) -> tuple[RunEvent, Sender | None] | None:
    """The vehicle's first disarm by command before ``before_s`` (or a takeover: a mode change of the
    armed vehicle out of OFFBOARD, not the vehicle's own) that the configured controller on its own link
    did not send: the event and its sender (None when the event names none), or None. A mode selected
    while disarmed, for the next arm, ends nothing: the controller's arm flies OFFBOARD; nor does a ground
    station's arm in HOLD on the ground awaiting a mission's start, or its timeout's disarm (``pre_start``).
    ``events``: the mission's (before its time 0, a ground station's own flight before an awaited mission's start,
    there is no flight of its to end)."""
    for e in vehicle_events(events):
        if e.t >= before_s - EPS_S:
            break
        if e.pre_start:
            continue
        # a disarm not of the vehicle's own (landed, stopped by its failsafe, diverged: ``by`` ITSELF)
        own = e.by is not None and e.by.is_vehicle
        commanded = ((e.kind == "disarmed" and not own)
                     or (e.kind == "mode" and bool(e.armed) and e.mode != OFFBOARD and not own))
        if not commanded:
            continue
        who = e.by
        if who is not None and who.link == "controller" and (who.sysid, who.compid) == controller_id:
            continue
        return e, who
    return None


def failsafe_not_resumed(events: Sequence[RunEvent], end_s: float = math.inf) -> RunEvent | None:
    """The vehicle's latest failsafe before ``end_s`` (the mission's end, s) if no arm came after it before then (an
    arm is what hands it back: ``[failsafe] resume``), else None. ``events``: the mission's. The controller's word
    cannot tell it in real time: a blackout over the mission's end lost the failsafe's every message on the wire,
    and the controller flew its ticks to the end and called it completed."""
    last = None
    for e in in_time_order(vehicle_events(events)):
        if e.t is None or e.t >= end_s:
            break
        if e.kind == "failsafe":
            last = e
        elif e.kind == "armed":
            last = None
    return last


def ended_by_outcome(outcome: str, events: Sequence[RunEvent]) -> dict[str, str]:
    """``summary.json["ended_by"]`` as the outcome and the vehicle's events tell it: the mission (completed), the
    vehicle (its failsafe, or its pre-arm check that denied the arm), the plant (diverged, crashed), the ground station
    that terminated it, or whoever interrupted it. A session knows more (a child that died, a command): it says so.
    ``events``: the mission's (what came before its time 0, a ground station's own flight before an awaited mission's
    start, is not its end; a denied arm flies no row: no time 0 is found, nothing comes before it)."""
    ev = vehicle_events(events)

    def first(kind: str) -> RunEvent | None:
        return next((e for e in ev if e.kind == kind), None)

    if outcome == "completed":
        return {"who": "mission", "how": "completed"}
    if outcome == "diverged":
        e = first("diverged")
        return {"who": "plant", "how": f"diverged at t={e.t:.3f} s: {e.text}" if e else "diverged"}
    if outcome == "crashed":
        e = first("crashed")
        return {"who": "plant", "how": f"crashed at t={e.t:.3f} s: {e.text}" if e else "crashed"}
    if outcome == "terminated" and (e := first("terminated")):  # a ground station's DO_FLIGHTTERMINATION: it fell
        hit = next((f"; {x.kind} at t={x.t:.3f} s: {x.text}" for x in ev if x.kind in ("impact", "crashed")), "")
        return {"who": str(e.by or "ground station"), "how": f"flight terminated at t={e.t:.3f} s: {e.text}{hit}"}
    if outcome == "collision":  # another vehicle touched this one (bridge.swarm)
        e = first("collision")
        return {"who": "plant", "how": f"collision at t={e.t:.3f} s: {e.text}" if e else "collision"}
    if outcome == "failsafe":  # the first one ended the mission; one that took over after it (a battery's
        fs = [e for e in ev if e.kind == "failsafe"]  # emergency after its critical) is what flew: both said
        then = "".join(f"; then at t={e.t:.3f} s: {e.text}" for e in fs[1:])
        return {"who": "vehicle", "how": f"failsafe at t={fs[0].t:.3f} s: {fs[0].text}{then}" if fs else "failsafe"}
    if outcome == "law_failed":  # a user's law raised, exited or gave no four finite inputs (controller.law)
        e = first("law_failed")
        return {"who": "controller", "how": f"its law failed at t={e.t:.3f} s: {e.text}" if e else "its law failed"}
    if outcome == "denied":  # PX4's pre-arm check denied the flight's arm: nothing flew
        return arming_denied_end(events) or {"who": "vehicle", "how": "arming denied"}
    return {"who": "user", "how": "interrupted (Ctrl-C or SIGTERM)"}


def arming_denied_end(events: Sequence[RunEvent], controller_id: tuple[int, int] | None = None
                      ) -> dict[str, str] | None:
    """``ended_by`` of a flight that never armed because the vehicle's pre-arm check denied it (outcome ``denied``:
    a ``preflight`` event, and no ``armed`` one): the vehicle, with why (its last denial); None for any other
    flight. With ``controller_id`` (a session), only if that last denial answered the configured controller's arm
    on its link (a ground station's denied arm does not explain why the controller gave up)."""
    ev = vehicle_events(events)
    denied = next((e for e in reversed(ev) if e.kind == "preflight"), None)
    if denied is None or any(e.kind == "armed" for e in ev):
        return None
    who = denied.by
    if controller_id is not None and who is not None and (who.link, (who.sysid, who.compid)) != (
            "controller", controller_id):
        return None
    return {"who": "vehicle", "how": f"{denied.text} (t={denied.t:.3f} s)"}

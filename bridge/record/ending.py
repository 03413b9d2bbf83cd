"""The mission's end action as flown (``[end] action``): what the vehicle did after the mission's time.

In:  the action (``land`` or ``hold``); the rows the vehicle flew under it, after the mission's last step (t s on
     the vehicle's clock, z m and vz m/s of the true state at the start of each control period); its events
     after the mission (t s, kind: ``end``, ``landed``, ``disarmed``, ``failsafe``; their text); the controller's
     ``end`` event's ``result``, its end-action command's answer
Out: :func:`end_block`, ``summary.json["end"]``: ``action``; ``rows``; ``disarmed`` (the landing ended in a
     disarm on the ground); ``landing_s`` (the ``end`` event to the disarm, s: the touchdown and COM_DISARM_LAND
     after it); ``disarm_z_m`` (the last row before the disarm) and ``touchdown_vz_mps`` (the last row before the
     ``landed`` event: the touchdown; without one, before the disarm); ``max_descent_mps``; ``failsafe`` (the
     text of the first failsafe that took the end action over, a position lost in the landing; None: none);
     ``max_drift_m`` (a hold: the largest height change from its first row); ``taken`` (true). A session's vehicle
     that never took it (:func:`end_not_taken`: no ``end`` event of its own, its command lost on a real-time link
     in a blackout over the end; or taken only after its failsafe had taken over, the command retried through a link
     back: ``late_t``): ``taken`` false and what flew instead, and :func:`not_taken_text`, the note; a
     controller alone whose end action went unanswered (:func:`end_unanswered`): ``taken`` and ``seen`` false

The mission's trace and figures stop at its end (``trace.csv`` holds the mission's rows only, so that every
figure is the mission's); the end action is summarised here, from the same rows in every clock (offline: the
loop's; a session: ``vehicle.bin``'s), so that a lockstep landing can be compared with offline's to the bit.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol

from bridge.record.events import RunEvent, in_time_order
from bridge.record.policies import EPS_S, vehicle_events


class _Event(Protocol):
    t: float | None
    kind: str
    text: str


def end_block(action: str, rows: Sequence[tuple[float, float, float]], events: Sequence[_Event]) -> dict[str, Any]:
    """``summary.json["end"]`` from the end action's ``rows`` ((t, z, vz) each) and the vehicle's ``events``."""
    start = next((e.t for e in events if e.kind == "end" and e.t is not None), None)
    disarm = None if start is None else next(
        (e.t for e in events if e.kind == "disarmed" and e.t is not None and e.t >= start), None)
    flown = [r for r in rows if disarm is None or r[0] <= disarm + 1e-9]
    last = flown[-1] if flown else None
    down = None if start is None else next(
        (e.t for e in events if e.kind == "landed" and e.t is not None and e.t >= start), None)
    touch = next((r for r in reversed(flown) if down is None or r[0] <= down + 1e-9), None)
    out: dict[str, Any] = {
        "action": action,
        "taken": True,
        "rows": len(flown),
        "disarmed": disarm is not None,
        "landing_s": None if disarm is None or start is None else round(disarm - start, 6),
        "disarm_z_m": last[1] if last is not None and disarm is not None else None,
        "touchdown_vz_mps": touch[2] if touch is not None and disarm is not None else None,
        "max_descent_mps": max((-r[2] for r in flown), default=None),
        "failsafe": None if start is None else next(
            (e.text for e in events if e.kind == "failsafe" and e.t is not None and e.t >= start), None),
    }
    if action == "hold":
        out["max_drift_m"] = max((abs(r[1] - flown[0][1]) for r in flown), default=None)
    return out


def end_not_taken(outcome: str, action: str, events: Sequence[RunEvent], end_s: float) -> dict[str, Any] | None:
    """``summary.json["end"]`` of a session whose mission was completed (``outcome``), whose controller sent the end
    action (its ``end`` event) but whose vehicle did not take it at the end (no ``end`` event of its own after the
    mission's end, ``end_s`` s, nor a mode the controller selected before a failsafe did): ``taken`` false, the answer
    its command had (``why``; ``accepted`` when it came late), the vehicle's first failsafe after the end (PX4's
    offboard loss: no target came after the mission's last), the controller's mode it took after that failsafe
    (``late_t``: the command retried through a link back; None: never) and whether it landed and disarmed. None when
    it took it, or when none was sent (a mission not completed). ``events``: the mission's (with ``source``)."""
    if outcome != "completed":
        return None
    ev = in_time_order([e for e in vehicle_events(events) if e.t >= end_s - EPS_S])
    # its command's answer, typed (RunEvent.result: "accepted", "no answer", "MAV_RESULT 4"), never cut out of its text
    why = next((e.result for e in events if e.kind == "end" and e.source == "controller" and e.result), None)
    fs = next((e for e in ev if e.kind == "failsafe"), None)
    mode = next((e for e in ev if e.kind == "mode" and e.by is not None and e.by.link == "controller"), None)
    # taken: its own end, or a mode by the controller before any failsafe; one after it is the failsafe's landing
    # finished by the command retried through a link back: the failsafe took over first (until the third wave's
    # forty-second session that read as taken: no ``end``, exit 0)
    if why is None or any(e.kind == "end" for e in ev) or (mode is not None and (fs is None or mode.t < fs.t)):
        return None
    down = next((e for e in ev if e.kind == "disarmed" and (fs is None or e.t >= fs.t)), None)
    return end_not_taken_block(action, why, None if fs is None else fs.text, None if fs is None else fs.t,
                               None if mode is None else mode.t, None if down is None else down.t)


def end_not_taken_block(action: str, why: str, failsafe: str | None, failsafe_t: float | None,
                        late_t: float | None, disarmed_t: float | None) -> dict[str, Any]:
    """``summary.json["end"]`` of an end action not taken at the mission's end (s, mission time): its command's answer
    (``why``), the failsafe that flew instead and when, when the action was taken late (None: never), when the
    vehicle disarmed (None: not seen to). The one shape :func:`end_not_taken` (a session) and a controller alone that
    saw it taken late give it."""
    return {"action": action, "taken": False, "why": why, "failsafe": failsafe, "failsafe_t": failsafe_t,
            "late_t": late_t, "disarmed": disarmed_t is not None, "disarmed_t": disarmed_t}


def end_unanswered(action: str, why: str, silent_s: float) -> dict[str, Any]:
    """The ``end`` a controller alone (``bsst controller``) knows of an end action its vehicle never answered as taken
    (``why``: its command's answer, "no answer", "MAV_RESULT 4"): ``taken`` false and ``seen`` false, as it stops
    there and never sees what flies instead; ``silent_s``: how long the vehicle had been silent then (s, wall time)."""
    return {"action": action, "taken": False, "why": why, "seen": False, "silent_s": round(silent_s, 3)}


def not_taken_text(end: dict[str, Any]) -> str:
    """The note of a vehicle that never took the mission's end action (:func:`end_not_taken`): what flew instead;
    a controller's alone (:func:`end_unanswered`): not seen to take it, what flew instead not seen."""
    what = "HOLD" if end["action"] == "hold" else "LAND"
    if not end.get("seen", True):
        quiet = f"; the vehicle silent for its last {end['silent_s']:.1f} s" if end["silent_s"] >= 1.0 else ""
        return (f"the vehicle was not seen to take the mission's end action ({what}; its command: {end['why']}): what "
                f"flew instead not seen (the controller stops there{quiet})")
    instead = (f"its failsafe took over at t={end['failsafe_t']:.3f} s ({end['failsafe']})" if end["failsafe"]
               else "nothing took over")
    down = f", disarmed at t={end['disarmed_t']:.3f} s" if end["disarmed"] else ", not seen to disarm"
    if end.get("late_t") is not None:  # the command retried through a link back, into the failsafe's flight
        late = end["late_t"] - (end["failsafe_t"] or end["late_t"])
        answer = f"{end['why']} late" if end["why"] == "accepted" else f"{end['why']}, taken late"
        return (f"the vehicle did not take the mission's end action at its end ({what}; its command: {answer}): "
                f"{instead}, {what} only at t={end['late_t']:.3f} s ({late:.3f} s of its failsafe){down}")
    why = f"; its command: {end['why']}" if end.get("why") else ""
    return f"the vehicle never took the mission's end action ({what}{why}): {instead}{down}"

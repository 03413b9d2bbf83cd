"""The mission's end action as flown (``[end] action``): what the vehicle did after the mission's time.

In:  the action (``land`` or ``hold``); the rows the vehicle flew under it, after the mission's last step (t s on
     the vehicle's clock, z m and vz m/s of the true state at the start of each control period); its events
     after the mission (t s, kind: ``end``, ``landed``, ``disarmed``, ``failsafe``; their text)
Out: :func:`end_block`, ``summary.json["end"]``: ``action``; ``rows``; ``disarmed`` (the landing ended in a
     disarm on the ground); ``landing_s`` (the ``end`` event to the disarm, s: the touchdown and COM_DISARM_LAND
     after it); ``disarm_z_m`` (the last row before the disarm) and ``touchdown_vz_mps`` (the last row before the
     ``landed`` event: the touchdown; without one, before the disarm); ``max_descent_mps``; ``failsafe`` (the
     text of the first failsafe that took the end action over, a position lost in the landing; None: none);
     ``max_drift_m`` (a hold: the largest height change from its first row)

The mission's trace and figures stop at its end (``trace.csv`` holds the mission's rows only, so that every
figure is the mission's); the end action is summarised here, from the same rows in every clock (offline: the
loop's; a session: ``vehicle.bin``'s), so that a lockstep landing can be compared with offline's to the bit.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol


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

"""A session's vehicle on its own, its controller ended: how long to wait for its failsafe to land it, and
whether a lockstep fleet's vehicle is frozen instead.

In:  the flight (its failsafe, rally and return settings, mission start), the trace's latest rows (m), the pace
     (x real time, None: 1); the controller's :class:`~bridge.nodes.report.Done`, whether the session is a lockstep
     fleet's (gated)
Out: :func:`landing_wait_s`: wall time (s) a session waits for the vehicle to land and disarm; :func:`is_frozen`:
     whether the vehicle is frozen (no landing of its own will come: the session kills it at once)

A lockstep fleet's vehicle sends its controller a HEARTBEAT every second, also while it waits at its gate for the
others (bridge.nodes.vehicle.gate), and a state unanswered again every 50 ms; so one its controller heard nothing
from for its vehicle timeout (2 s, ``Done.silent``) is not flying its failsafe: it is frozen (stopped, hung), and
the other vehicles wait for it at their gates. Waiting for its landing only held them up (until the third wave's
thirty-seventh session: the landing's wait and the 8 s SIGTERM deadline a stopped process never meets).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from bridge.autopilot.failsafe import return_time_s
from bridge.core.flight import Flight
from bridge.nodes.report import Done
from bridge.record.columns import TraceRow


def landing_wait_s(flight: Flight, rows: Sequence[TraceRow], speed: float | None) -> float:
    """Wall time allowed to a vehicle flying its failsafe alone: lockstep loss, timeout, descent from the highest
    point ``rows`` reached (``return``: the way home from the farthest, at half the on-board controller's speeds),
    with a margin."""
    z = max((r.z for r in rows), default=0.0)
    fs = flight.failsafe
    pace = speed or 1.0
    if fs.action == "return":
        x0, y0, z0 = flight.mission.flight_start[:3]
        away = max((math.hypot(r.x - x0, r.y - y0) for r in rows), default=0.0)
        flying = 2.0 * return_time_s(flight.params.rtl, away, z - z0, fs.descent_rate, slowdown=fs.slowdown)
    else:
        flying = fs.time_to_land_s(z)
    return 5.0 + (1.0 + fs.timeout_s + flying) / pace


def is_frozen(done: Done | None, gated: bool) -> bool:
    """Whether a lockstep fleet's vehicle (``gated``) is frozen: its controller ended hearing nothing from it."""
    return gated and done is not None and done.silent

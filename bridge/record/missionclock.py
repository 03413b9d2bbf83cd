"""Where the vehicle's clock and the mission's meet: the times a session records its children's events at.

In:  the vehicle's step of the mission's time 0 (``k0``: the first state the controller answered, the trace's first
     row, :class:`~bridge.record.joiner.TraceJoiner`'s) and the control rate (Hz), once known; each event's time as
     its child said it (s: the vehicle's on its own clock, the controller's and the session's on the mission's)
Out: the times the events of one read are recorded at (:meth:`MissionClock.stamps`); the vehicle's latest event of
     each kind recorded (:attr:`MissionClock.vehicle_said`, s: :mod:`bridge.session.eventorder` keeps it); once k0
     is known, the note saying where the mission's time 0 fell on the vehicle's clock (:meth:`MissionClock.learn`);
     the events with those recorded before then put on the mission's clock (:meth:`MissionClock.on_mission_clock`)

The record keeps the mission's clock (the trace's: t = 0 at its first row, step = round(t x rate) locates a row).
The vehicle's runs from its start: in lockstep it stands still until the flight (k0 is 0: one clock), unless a ground
station flew the vehicle before an awaited mission's start (``--await-mission``: its TAKEOFF flies on the wall
clock); in real time it always runs. Until k0 is known (before the mission's start) the vehicle's events are recorded
on the vehicle's clock, and the controller's and the session's at the vehicle's latest event at the earliest (they
have no time on that clock); events.log keeps them so and, if the two clocks differ, says where the mission's time 0
fell; summary.json has them on the mission's clock, before its 0 (negative). In real time with no mission awaited
they are at 0 instead, as they always were: only the controller's arm comes before its first state there.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

from bridge.record.events import RunEvent

EPS_S = 1e-6  # s: event times are rounded to 1 us


class MissionClock:
    """One session's mission clock against its vehicle's. ``vehicle_first``: before k0 is known, events are on the
    vehicle's clock (lockstep, or a mission awaited); else at 0 (real time, no mission awaited)."""

    def __init__(self, vehicle_first: bool) -> None:
        self.vehicle_first = vehicle_first
        self.origin_s: float | None = None  # the vehicle's time (s) of the mission's time 0, once known
        self.before = 0  # how many events the session recorded before it
        # the vehicle's latest event of each kind in earlier reads (s, as recorded: bridge.session.eventorder's)
        self.vehicle_said: dict[str, float] = {}

    def stamps(self, said: Sequence[tuple[bool, float]]) -> list[float]:
        """The times (s) to record the events of one read at: ``said`` is each one's (from the vehicle?, time as said;
        -inf: not a timed event, kept). The vehicle's first: the others' wait for its latest (of earlier reads, and of
        this one)."""
        out = [-math.inf] * len(said)
        latest = max((0.0, *self.vehicle_said.values()))  # the vehicle's latest of earlier reads, then of this one
        for pass_vehicle in (True, False):
            for i, (vehicle, t) in enumerate(said):
                if vehicle == pass_vehicle and math.isfinite(t):
                    out[i] = self._stamp(vehicle, t, latest)
                    if vehicle:
                        latest = max(latest, out[i])
        return out

    def _stamp(self, vehicle: bool, t: float, latest: float) -> float:
        if self.origin_s is not None:
            return t - self.origin_s if vehicle else t
        if not self.vehicle_first:
            return 0.0 if vehicle else t
        return t if vehicle else max(t, latest)

    def learn(self, k0: int, rate_hz: float, recorded: int) -> str | None:
        """The mission's time 0 is the vehicle's step ``k0``, with ``recorded`` events recorded before it; the latest
        times said (:attr:`vehicle_said`) are put on the mission's clock. The note for events.log and summary.json
        when the vehicle's clock had run before it (else None)."""
        self.origin_s = origin = k0 / rate_hz
        self.before = recorded
        if not self.vehicle_first:  # (recorded at 0: on the mission's clock already)
            return None
        for kind in self.vehicle_said:
            self.vehicle_said[kind] -= origin
        if origin <= EPS_S:
            return None
        return (f"the mission's time 0 (the trace's first row) is the vehicle's t={origin:.3f} s (its step {k0}): "
                "what came before it is on the vehicle's clock in events.log, at negative times in summary.json")

    def on_mission_clock(self, events: Sequence[RunEvent]) -> list[RunEvent]:
        """``events`` (as the session recorded them) on the mission's clock: those recorded before k0 was known moved
        by its time on the vehicle's clock (unchanged if it never was: nothing flew, the vehicle's clock is the only
        one)."""
        shift = self.origin_s or 0.0
        if not shift or not self.vehicle_first:
            return list(events)
        return [replace(e, t=round(e.t - shift, 6)) if i < self.before and e.t is not None else e
                for i, e in enumerate(events)]

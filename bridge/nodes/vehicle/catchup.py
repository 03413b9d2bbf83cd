"""A real-time vehicle after the machine stalled it: its stalls, and the messages it read late held for the
physics to catch up to when they were read (docs/sitl.md, "Stalls").

In:  wall times (s, ``time.monotonic``): when a physics step was due and when the vehicle woke for it; what a
     wait returned, and when
Out: :attr:`CatchUp.stalls` (:class:`~bridge.core.clock.Stalls`, on the vehicle's clock, s); the messages a wait
     returned more than :data:`~bridge.core.clock.STALL_S` after the step it waited for was due, given back
     (:meth:`CatchUp.release`) before the first physics step due at or after the wall time they were read

A stalled autopilot reads nothing: its rotors hold the target they had until it runs again. The physics, which
must not stall, then catches up the steps it missed in a burst; a target read at the stall's end must not be flown
over those steps, as if the frozen autopilot had had it all along (it was computed meanwhile, on a state that did
not come: flown over a 100 ms catch-up it turned a stall into a kick).
"""

from __future__ import annotations

import math
from typing import Any

from bridge.core.clock import STALL_S, Pace, Stalls


class CatchUp:
    """The stalls of a real-time vehicle's physics on ``pace``, and what it read late, held."""

    def __init__(self, pace: Pace) -> None:
        self.pace = pace
        self.stalls = Stalls()
        self._held: list[tuple[float, list[Any]]] = []  # (wall time read, what the wait returned), oldest first
        # wall time the last wait was to sleep to: one past the steps' dues (to a control period's end) flies the
        # steps due by its wake then, late by choice, not by a stall
        self.asleep_to = -math.inf

    def woke(self, due: float, now: float) -> None:
        """The physics step due at wall time ``due`` is taken at ``now``: a stall if more than STALL_S late (after
        its due, or after the wake the vehicle slept for if that is later)."""
        due = max(due, self.asleep_to)
        if now - due > STALL_S:  # (the clock's time only then: this is every physics step's path)
            self.stalls.note(self.pace.time_s(due), now - due)

    def overslept(self, due: float, now: float, got: list[Any], past_due: bool = False) -> bool:
        """A wait for the step due at ``due`` returned ``got`` at ``now``: held (True) if it overslept, the
        machine having stalled it, or (``past_due``: it slept past ``due`` by choice) if it returned after ``due``;
        else left to the caller (False)."""
        if now - max(due, self.asleep_to) <= STALL_S and not (past_due and now >= due):
            return False
        if got:
            self._held.append((now, got))
        return True

    def release(self, due: float) -> list[Any]:
        """What was read by wall time ``due`` and held: to take before flying the step due then."""
        if not self._held or self._held[0][0] > due:  # every physics step's path: nothing held, almost always
            return []
        out: list[Any] = []
        while self._held and self._held[0][0] <= due:
            out += self._held.pop(0)[1]
        return out

"""The wall-clock arithmetic of the two real-time clocks (docs/design.md, "Clocks"); no I/O.

In:  ``time.monotonic`` wall times (s), step or tick numbers, rates (Hz), a speed factor (x real time)
Out: the wall time (s) each step or tick is due, the paced clock's time (s), the tick to run after
     a late wake-up; counts of re-based schedules and skipped ticks

- :class:`Pace` — the vehicle's: physics step n of a counter running ``speed`` times real
  time is due at w0 + (n - n0) / (rate_hz * speed). Used by the real-time clock, by a
  lockstep vehicle paced with ``--speed``, and by a lockstep vehicle that lost its
  controller. A schedule fallen more than :data:`REBASE_S` behind (the machine stalled) is
  re-based on the present instead of caught up in a burst faster than ``speed``.
- :class:`FixedRate` — the controller's: tick j is due at t0 + j / rate_hz, drift-free; a
  tick woken more than a period late skips the ticks it missed, keeping the schedule (a
  fixed-rate law keeps its phase to the vehicle's states).

Lockstep itself needs no clock: the vehicle steps when the target of the step is in (PX4's
lockstep on HIL_ACTUATOR_CONTROLS), so simulation time is the step count.
"""

from __future__ import annotations

from dataclasses import dataclass

REBASE_S = 0.25  # a pace this far behind the wall clock is re-based, not caught up


@dataclass
class Pace:
    """Step n due at ``w0 + (n - n0) / (rate_hz * speed)`` on ``time.monotonic``'s clock (s)."""

    rate_hz: float
    speed: float = 1.0
    w0: float = 0.0  # wall time (s) of step n0
    n0: int = 0
    rebased: int = 0  # times the schedule was re-based after a stall

    def restart(self, now: float, n: int) -> None:
        """Step n is due now (the clock starts, or starts again after standing still)."""
        self.w0, self.n0 = now, n

    def due(self, n: int) -> float:
        """Wall time (s) of step n."""
        return self.w0 + (n - self.n0) / (self.rate_hz * self.speed)

    def time_s(self, now: float) -> float:
        """The paced clock's time (s) at wall time ``now``: it runs on between steps."""
        return self.n0 / self.rate_hz + (now - self.w0) * self.speed

    def rebase_if_stalled(self, now: float, due: float) -> bool:
        """If ``now`` is more than :data:`REBASE_S` past ``due``, shift the schedule so that
        ``due`` is now (counted in :attr:`rebased`) and say so."""
        if now - due <= REBASE_S:
            return False
        self.w0 += now - due
        self.rebased += 1
        return True


@dataclass
class FixedRate:
    """Tick j due at ``t0 + j / rate_hz`` (s, ``time.monotonic``), never re-based."""

    t0: float
    rate_hz: float
    skipped: int = 0  # ticks skipped because the process woke more than a period late

    def due(self, j: int) -> float:
        return self.t0 + j / self.rate_hz

    def catch_up(self, j: int, now: float) -> int:
        """The tick to run at ``now`` when tick j was due: j itself unless ``now`` is more
        than a period past it, else the last tick due by ``now`` (the others are skipped and
        counted)."""
        late = now - self.due(j)
        period = 1.0 / self.rate_hz
        if late <= period:
            return j
        skip = int(late / period)
        self.skipped += skip
        return j + skip

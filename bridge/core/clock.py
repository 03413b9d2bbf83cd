"""The wall-clock arithmetic of the two real-time clocks (docs/design.md, "Clocks"); no I/O.

In:  ``time.monotonic`` wall times (s), step or tick numbers, rates (Hz), a speed factor (x real time)
Out: the wall time (s) each step or tick is due, the paced clock's time (s), the tick to run after
     a late wake-up; counts of re-based schedules and skipped ticks; the machine's stalls (s of the
     clock, ms)

- :class:`Pace` — the vehicle's: physics step n of a counter running ``speed`` times real
  time is due at w0 + (n - n0) / (rate_hz * speed). Used by the real-time clock, by a
  lockstep vehicle paced with ``--speed``, and by a lockstep vehicle that lost its
  controller. A paced lockstep schedule fallen more than :data:`REBASE_S` behind (the machine stalled)
  is re-based on the present instead of caught up in a burst faster than ``speed``; the real-time clock
  never is (the controller's fixed-rate schedule keeps the wall's time, and a vehicle re-based 0.25 s
  behind it sent states the controller took for 0.25 s old ever after: its guard stopped commanding and the
  vehicle's failsafe landed it).
- :class:`Stalls` — the stretches a real-time process woke more than :data:`STALL_S` late: the
  machine, not the link model, held the loop (a virtual machine whose host takes its cores back
  stops every process in it, whatever its priority, for up to 100 ms).
- :func:`lockstep_pace` — the pace a lockstep vehicle keeps for the options given (``--speed``, a ground
  station's mission).
- :class:`FixedRate` — the controller's: tick j is due at t0 + j / rate_hz, drift-free; a
  tick woken more than a period late skips the ticks it missed, keeping the schedule (a
  fixed-rate law keeps its phase to the vehicle's states).

Lockstep itself needs no clock: the vehicle steps when the target of the step is in (PX4's
lockstep on HIL_ACTUATOR_CONTROLS), so simulation time is the step count.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

REBASE_S = 0.25  # a pace this far behind the wall clock is re-based, not caught up
# a wake-up this late is the machine's stall: Linux's own wake-up jitter stays under 9 ms with both cores busy
STALL_S = 0.010
STALLS_KEPT = 1000  # stalls listed one by one (an hour at one a second, 20 kB); the rest only counted


AWAIT_MISSION_SPEED = 1.0  # x real time: a ground station's mission, unless --speed says otherwise
# x real time, a paced lockstep's (0: as fast as it goes). Slower than 0.1x a control period of the slowest rate
# (50 Hz) lasts more than 0.2 s of wall time; at 0.001x the controller, 2 s without a new state, gave up
SPEED_RANGE = (0.1, 1000.0)


def realtime_speed_problem(speed: float | None) -> str | None:
    """Why ``--speed`` cannot go with ``--realtime``, or None: a real-time flight runs at the wall clock's pace (the
    controller keeps its rate on it; a plant paced faster would outrun it)."""
    if speed is None or speed == 1.0:
        return None
    return (f"--speed {speed:g} with --realtime: a real-time flight runs at the wall clock's pace (the controller "
            "keeps its rate on it, the plant would outrun it); --speed paces lockstep")


def speed_problem(speed: float) -> str | None:
    """Why ``speed`` (x real time) cannot pace a lockstep flight, or None: 0 (as fast as it goes) or within
    :data:`SPEED_RANGE`."""
    lo, hi = SPEED_RANGE
    if speed == 0.0 or lo <= speed <= hi:  # (NaN fails both)
        return None
    return f"must be 0 (as fast as it goes) or in [{lo:g}, {hi:g}] times real time, got {speed:g}"


def lockstep_pace(speed: float | None, *, realtime: bool, await_mission: bool) -> float | None:
    """The pace a lockstep vehicle keeps, x real time; None: as fast as the two sides go. ``speed`` as given (None:
    not given; 0: as fast as they go). Not given, a ground station's mission (``await_mission``) flies at
    :data:`AWAIT_MISSION_SPEED`, as PX4's and ArduPilot's SITL run at real time: its pilot watches it there (it flew
    as fast as it went until the third wave's thirty-third session: a 20 s mission was over in a second); a mission
    file flies as fast as it goes. Real time: ``speed`` unchanged (the wall clock is its pace)."""
    if speed == 0.0:
        return None
    return AWAIT_MISSION_SPEED if speed is None and await_mission and not realtime else speed


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
    behind: int = -1  # ticks up to this one were due before the schedule was set (in the past): skipped, not counted

    def due(self, j: int) -> float:
        return self.t0 + j / self.rate_hz

    def catch_up(self, j: int, now: float) -> int:
        """The tick to run at ``now`` when tick j was due: j itself unless ``now`` is more
        than a period past it, else the last tick due by ``now`` (the others are skipped and
        counted, but for those up to :attr:`behind`: no wake-up of the process was due for them)."""
        late = now - self.due(j)
        period = 1.0 / self.rate_hz
        if late <= period:
            return j
        skip = int(late / period)
        self.skipped += max(0, j + skip - max(j, self.behind + 1))
        return j + skip


@dataclass
class Stalls:
    """The stalls a real-time process met: each a stretch of wake-ups more than :data:`STALL_S`
    late, kept as ``[t, ms]`` (the clock's time, s, the wake-up was due at; how late the first
    of the stretch woke, ms). The wake-ups of the catch-up that follows a stall (each due
    before the stall's end) belong to it."""

    count: int = 0
    worst_s: float = 0.0
    kept: list[list[float]] = field(default_factory=list)
    _until: float = -math.inf  # the clock's time (s) the current stall reaches

    def note(self, t: float, late_s: float) -> None:
        """A wake-up due at ``t`` (s of the process's clock) came ``late_s`` (s) late."""
        if late_s <= STALL_S or t < self._until:
            return
        self.count += 1
        self.worst_s = max(self.worst_s, late_s)
        self._until = t + late_s
        if len(self.kept) < STALLS_KEPT:
            self.kept.append([round(t, 3), round(1e3 * late_s, 1)])

    def report(self) -> dict[str, object]:
        """What the process reports on exit (its ``stats``' ``stalls``)."""
        return {"count": self.count, "worst_ms": round(1e3 * self.worst_s, 1), "at": list(self.kept)}

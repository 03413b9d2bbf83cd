"""The offboard controller's real-time clock: phase-locked to the vehicle's states, a tick just after each arrives.

In:  the vehicle's states as :class:`~bridge.nodes.offboard.link.OffboardLink` reads them (their arrival, s of
     ``time.monotonic``; their stamps, us of the vehicle's clock), TIMESYNC's offset bounds (ns), the control rate (Hz)
Out: one control step per tick (:meth:`Offboard._decide <bridge.nodes.offboard.flight.Offboard._decide>`, mission
     time s on the vehicle's clock); the tick schedule (:class:`~bridge.core.clock.FixedRate`), its stalls
     (:class:`~bridge.core.clock.Stalls`: the mission's, and apart those met before its first state came), the stale
     ticks, and the states' way down (``way_down``: ms, within ms)

:class:`RealtimeFlying` is :class:`~bridge.nodes.offboard.flight.Offboard`'s base: the flight's steps (observe,
decide, end) are the flight's, named below as what this clock calls (docs/sitl.md, "Real time").
"""

from __future__ import annotations

import math
import time
from typing import Any

from bridge.core.clock import STALL_S, FixedRate, Stalls
from bridge.core.wire import step_of_usec
from bridge.mavlink.endpoint import wait
from bridge.nodes.offboard.config import (
    HOUSEKEEPING_S,
    PHASE_RELOCKS,
    PHASE_S,
    PHASE_STATES,
    STATE_WAIT_PERIODS,
    WAY_DOWN_MAX_S,
    WAY_DOWN_SLACK_S,
)
from bridge.nodes.offboard.link import OffboardLink
from bridge.nodes.process import tight_timer_slack


class RealtimeFlying(OffboardLink):
    """The real-time flight loop of an offboard controller (see the module docstring); the flight's own steps are
    :class:`~bridge.nodes.offboard.flight.Offboard`'s."""

    steps: int  # the mission's control steps
    stale_ticks: int  # ticks with no new state
    stalls: Stalls  # the mission's ticks the machine woke us too late for
    stalls_waiting: Stalls  # those of the ticks before the mission's first state (not the mission's)
    schedule: FixedRate | None  # the tick schedule, once phase-locked
    _held: Stalls | None = None  # the machine's stalls from the ARM to the mission's first tick (wall time)
    _woke: float = 0.0  # while they are watched: when the link's wait last woke, and how late (s)
    _late: float = 0.0
    _way_down: float | None  # the states' way down (s)
    way_down: dict[str, float] | None  # that in ms and how far off it may be (stats)
    _last_state: float  # wall time of the newest state flown
    _mission_zero: float | None  # the vehicle's clock (s) at mission time 0

    def _observe(self, odo: Any, t_state: float, recv: float) -> None:
        raise NotImplementedError  # the flight's: Offboard._observe

    def _decide(self, t: float, k: int, time_usec: int, recv: float, late: float) -> tuple[float, ...] | None:
        raise NotImplementedError  # the flight's: Offboard._decide

    def _end_of_mission(self, t_end: float, odo: Any, due: tuple[int, float] | None = None) -> str:
        raise NotImplementedError  # the flight's: Offboard._end_of_mission

    def _check_vehicle(self) -> str | None:
        raise NotImplementedError  # the flight's: Offboard._check_vehicle

    def _fly_realtime(self) -> str:
        tight_timer_slack()  # it sleeps to just before each tick (SPIN_BEFORE_TICK_S), then polls
        rate = self.rate
        period = 1.0 / rate
        steps = self.steps
        mono = time.monotonic
        if self._held is None:  # (watched from the ARM on: Offboard.run)
            self.watch_stalls()
        locked = self._phase_lock(period)
        if isinstance(locked, str):
            self._held_waiting(mono())  # the flight ended in the wait: t before its end
            return locked
        phase, k0 = locked
        self._mission_zero = k0 * period  # the vehicle's clock at mission time 0 (s): its events on the mission's
        # (its first tick's state may have come late, past where the phase puts it: the ticks due by now are skipped,
        # not overrun)
        t0 = phase + k0 * period + PHASE_S
        self.schedule = clock = FixedRate(t0, rate, behind=max(math.floor((mono() - t0) * rate), -1))
        self._held_waiting(clock.due(0))
        last_k = k0 - 1
        usec, recv = 0, math.nan  # the newest state's stamp and arrival
        flown: Any = None  # the newest state flown
        woke = max(mono(), clock.due(0) - period)  # when the last tick woke (s): the first tick's is judged too
        way_down: float | None = None  # the states' one-way trip (s), once TIMESYNC tells it
        j = 0
        while not self.stopping:
            self._sleep_until(clock.due(j))
            now = mono()
            # a stall: more than a period since the last tick woke (lateness against the schedule would count
            # a schedule re-phased into the past on the first state, below, which is arithmetic, not a stall);
            # while the mission's first state is awaited it is judged once this tick has read its state (below)
            stall = (j / rate, now - woke - period)
            if last_k >= k0:
                self.stalls.note(*stall)
            woke = now
            j = clock.catch_up(j, now)  # missed ticks are skipped, the schedule kept (no drift)
            due = clock.due(j)
            late = now - due
            for m, _addr in self.ep.poll():
                self._on(m)
            self._await_state(k0 + j, due + STATE_WAIT_PERIODS * period)  # at once if it is in
            if way_down is None:
                way_down = self._way_down = self._way_down_s(phase)
            outcome = self._check_vehicle()
            if outcome:
                return outcome
            odo = self._odo
            if odo is None or step_of_usec(odo.time_usec, rate) <= last_k:
                if j >= steps and last_k >= k0:
                    # the mission's time is over on the vehicle's clock and its state not come (a blackout over the
                    # end): nothing is left to fly. Waiting for it waited out the blackout, 30 s for --blackout 1:30
                    return self._end_of_mission(steps / rate, flown, (k0 + steps, clock.due(steps) - PHASE_S))
                self.stale_ticks += 1
                if last_k < k0:
                    self.stalls_waiting.note(*stall)  # the mission not begun: not its stall
                    j += 1
                    continue  # no state of the mission yet
            else:
                self._odo = None
                k = step_of_usec(odo.time_usec, rate)
                if last_k < k0 and (j or k != k0):
                    # the first state of the mission is not the first tick's (the earlier ones were lost, or
                    # a later one came with it, as states bunched on a busy machine do): the mission starts
                    # with it, as the trace and the vehicle's timeline do (their time 0 is the state the
                    # first target answers), its tick where its state was due (phase + k / rate)
                    # (moved back, the ticks due before this one's due are skipped, not overrun: none was the process's)
                    self.schedule = clock = FixedRate(due + (k - k0 - j) * period, rate, clock.skipped,
                                                      max(k0 + j - k, 0))
                    # the schedule moved, not the process: no stall at the next tick. Moved on (a later state came at
                    # once), the next tick is that much further off; moved back (an older state came late, as a
                    # radio's first one does), it is due at once: the process woke when it woke (counting the move
                    # made a stall of the state's lateness at t = 1 / rate, 26-98 ms for a SiK radio's on an idle
                    # machine: forty-fifth session's review)
                    woke += max(k - k0 - j, 0) * period
                    k0, j = k, 0
                    self._mission_zero = k0 * period
                    self.stalls_waiting.note(*stall)  # met before the mission's first state came: not its stall
                elif last_k < k0:
                    self.stalls.note(*stall)  # the mission's first tick, its state the first one's: judged
                if k - k0 >= steps:
                    return self._end_of_mission((k - k0) / rate, odo)
                usec, recv = odo.time_usec, self._odo_recv
                self._observe(odo, (k - k0) / rate, recv)
                last_k, flown = k, odo
            # mission time of this tick on the vehicle's clock: state k0 + j was measured at
            # j / rate, arrived the way down later, and the tick is PHASE_S after its arrival
            t = j / rate + (way_down + PHASE_S if way_down is not None else 0.0)
            j += 1
            self._t_wall = due  # the vehicle's clock reads t at the tick's due (OffboardLink.vehicle_t)
            self._decide(t, last_k, usec, recv, late)
        return "aborted"

    def watch_stalls(self) -> None:
        """From now on (the ARM sent) until the mission's first tick, the link's waits (:meth:`_serve`) note the
        machine's stalls: wake-ups more than STALL_S past the time they slept to (the link's next housekeeping, at
        most HOUSEKEEPING_S after the last wake-up: a longer wait, the ARM's 0.1 s, ends there and its caller waits
        on), at wall time (s of ``time.monotonic``)."""
        self._held, self._woke, self._late = Stalls(), time.monotonic(), 0.0

    def _serve(self, deadline: float) -> None:
        held = self._held
        if held is None:
            return super()._serve(deadline)
        # at most HOUSEKEEPING_S past the last wake (a stall before the sleep began: from it), whatever the caller's
        # deadline: it loops to its own. (An ARM's 0.1 s wait judged against 50 ms was a 50 ms stall each, on an idle
        # machine: forty-fifth session's review)
        slept_to = min(deadline, self._woke + HOUSEKEEPING_S)
        for _, m, _addr in wait((self.ep,), slept_to):
            self._on(m)
        now = time.monotonic()
        self._late, self._woke = now - slept_to, now
        held.note(slept_to, self._late)
        if now >= self._next_house:
            self._housekeeping()
        return None

    def _held_waiting(self, zero: float) -> None:
        """The stalls of the waits from the ARM to the mission's first tick (wall time) listed with the waiting ticks'
        (:attr:`stalls_waiting`), at s from wall time ``zero`` (that first tick, or where the flight ended before
        it): t < 0. The waits note no more."""
        held, self._held = self._held, None
        if held is None:
            return
        for at, ms in held.kept:
            self.stalls_waiting.note(at - zero, ms * 1e-3)
        self.stalls_waiting.count += held.count - len(held.kept)

    def _drop_queued(self) -> None:
        """After a stall of the machine, what queued meanwhile is read in bunches, late: a phase taken from it would be
        late by as much (a 0.3 s stall after the arm made every state look 0.25 s old, the guard sent no target and
        the vehicle's failsafe took over): read it all (its messages handled, its states not kept for the lock)."""
        self.ep.drain(lambda m, _addr: self._on(m))
        self._odo, self._late, self._woke = None, 0.0, time.monotonic()

    def _phase_lock(self, period: float) -> tuple[float, int] | str:
        """Real time: the phase of the vehicle's states (the ticks come just after they arrive): their earliest arrival
        (recv - k / rate) over the first PHASE_STATES states (states read together count each, the newest the read's
        sample), and the mission's first step: the next state's, or the newest's if it came after the five with the
        fifth (kept for the first tick, which answers it at once). Or the outcome if the vehicle is lost. After a
        stall of the machine (:meth:`watch_stalls`) the phase is found afresh, on the states that come after what
        queued meanwhile."""
        self._odo = None
        if self._late > STALL_S:  # the arm's answer read after a stall: what queued with it is as late
            self._drop_queued()
        self._last_state = time.monotonic()
        phase: float | None = None
        seen = relocks = 0  # states taken; locks begun afresh after a stall (a machine that stalls every wait: bounded)
        while not self.stopping:
            outcome = self._check_vehicle()
            if outcome:
                return outcome
            before = self.states
            self._serve(min(self._next_house, self._last_rx + self.cfg.vehicle_timeout_s))
            if self._late > STALL_S and relocks < PHASE_RELOCKS:  # the machine stalled this wait: lock afresh
                self._drop_queued()
                phase, seen, relocks = None, 0, relocks + 1
            if self._odo is None:
                continue
            k = step_of_usec(self._odo.time_usec, self.rate)
            seen += self.states - before
            if seen > PHASE_STATES and phase is not None:  # the newest came after the five: the mission's first
                return phase, k
            p = self._odo_recv - k * period
            phase = p if phase is None else min(phase, p)
            self._odo = None
            if seen >= PHASE_STATES:
                return phase, k + 1  # the mission starts with the next state
        return "aborted"

    def _way_down_s(self, phase: float) -> float | None:
        """Real time: the one-way trip of the earliest-arriving states (s, >= 0), from the phase of their arrivals
        and the vehicle's clock offset by TIMESYNC; None until a TIMESYNC answer is in. The offset is the middle of
        its bounds (config.offset_bounds), which takes the two ways' fastest trips as equal: an asymmetric link (a
        delay on the way down only) is credited with half of the difference, and the trip is right within half
        the bounds' width (:attr:`way_down`), plus how late the earliest arrival was read (never early)."""
        if self.offset_range_ns is None or self.offset_ns is None:
            return None
        trip = phase + self.offset_ns * 1e-9
        if not -WAY_DOWN_SLACK_S <= trip <= WAY_DOWN_MAX_S:
            # the stamps and TIMESYNC are not on one clock: count ages from the arrivals
            self.event("timesync", f"the states' way down comes out at {trip * 1e3:.1f} ms: "
                                   "not counted in their age (stamps and TIMESYNC on different clocks?)")
            return 0.0
        lo, hi = self.offset_range_ns
        self.way_down = {"ms": round(max(trip, 0.0) * 1e3, 3), "within_ms": round((hi - lo) * 0.5e-6, 3)}
        return max(trip, 0.0)

"""The vehicle's step clock: one state machine, every transition in :data:`TRANSITIONS`.

In:  :class:`Trigger` s from the vehicle's parts (an arm or OFFBOARD engages lockstep, the controller's
     answer to step k, the step flown, the controller lost, a ground station's mode, a disarm, divergence);
     wall times (s, ``time.monotonic``) and physics step counts for the pace
Out: :attr:`Clock.state` (a :class:`ClockState`), the held :class:`Answer` of step k, the :class:`Pace`
     of physics steps on the wall clock, the clock's time for TIMESYNC (s)

The clocks themselves are docs/design.md, "Clocks": in **lockstep** the vehicle is ``idle`` (no flight:
time stands still) until a flight engages it; then the state of step k goes out (``lockstep``), the
controller's answer is held (``answered``) and step k is flown (``lockstep`` again, step k + 1). A
controller silent too long, or a mode the vehicle flies itself (HOLD, LAND, TAKEOFF, RTL), leaves lockstep for
the wall clock (``free-running``), which the **realtime** clock is from the start. A diverged plant is
``halted`` for good. In a SITL fleet on one shared clock (:mod:`.gate`), the answer of step k held, the vehicle
is ``gated`` until every other vehicle has flown step k - 1 too; then step k is flown (``answered``), or,
touched by another vehicle, its flight ends there (``halted``). A trigger the table does not list for the state
is a bug: :class:`IllegalTransition`.
"""

from __future__ import annotations

from enum import Enum
from typing import NamedTuple

from bridge.core.clock import Pace


class ClockState(Enum):
    __hash__ = object.__hash__  # members are singletons: identity, in C (Enum's own hashes the name in Python)

    IDLE = "idle"  # lockstep clock, no flight on: time stands still, the state is still shown
    LOCKSTEP = "lockstep"  # a flight on: the state of step k is out, its answer awaited
    ANSWERED = "answered"  # the answer of step k is held: step k is flown next
    GATED = "gated"  # a fleet's shared clock: the answer of step k held, the others' step k - 1 awaited
    FREE_RUNNING = "free-running"  # physics on the wall clock (realtime; lockstep lost or a ground mode)
    HALTED = "halted"  # diverged: the plant is not stepped any more


class Trigger(Enum):
    __hash__ = object.__hash__  # (as ClockState's: the table is looked up at every lockstep step)

    ENGAGE = "engage"  # armed in offboard control, or OFFBOARD again while armed (lockstep clock)
    ANSWER = "answer"  # the controller's answer to step k: a target or the no-target acknowledgement
    STEP = "step"  # step k flown with its answer
    DROP = "drop"  # the held answer thrown away unflown (a test taking a step back)
    LOSE = "lose"  # the controller silent for ``lost_after_s`` of wall time
    GROUND = "ground"  # a ground station's mode, flown by the vehicle's own controller
    DISARM = "disarm"  # disarmed by command: a lockstep flight is over
    DIVERGE = "diverge"  # the plant diverged
    GATE = "gate"  # a fleet's shared clock: an answer held before every other vehicle has flown step k - 1
    RELEASE = "release"  # every other vehicle has flown step k - 1: step k is flown with the held answer
    COLLIDE = "collide"  # another vehicle touched this one at the shared clock's step: the flight is over


S, T = ClockState, Trigger
# (state, trigger) -> next state; any other pair is refused
TRANSITIONS: dict[tuple[ClockState, Trigger], ClockState] = {
    (S.IDLE, T.ENGAGE): S.LOCKSTEP,
    (S.LOCKSTEP, T.ENGAGE): S.LOCKSTEP,  # OFFBOARD again after a failsafe: step k's state out again
    (S.ANSWERED, T.ENGAGE): S.LOCKSTEP,  # (its held answer dropped)
    (S.FREE_RUNNING, T.ENGAGE): S.LOCKSTEP,  # armed again, or OFFBOARD again: back to lockstep
    (S.LOCKSTEP, T.ANSWER): S.ANSWERED,
    (S.ANSWERED, T.STEP): S.LOCKSTEP,
    (S.ANSWERED, T.DROP): S.LOCKSTEP,
    (S.LOCKSTEP, T.LOSE): S.FREE_RUNNING,
    (S.IDLE, T.GROUND): S.FREE_RUNNING,  # armed in HOLD, LAND or TAKEOFF
    (S.LOCKSTEP, T.GROUND): S.FREE_RUNNING,
    (S.ANSWERED, T.GROUND): S.FREE_RUNNING,
    (S.IDLE, T.DISARM): S.IDLE,
    (S.LOCKSTEP, T.DISARM): S.IDLE,
    (S.ANSWERED, T.DISARM): S.IDLE,
    (S.FREE_RUNNING, T.DISARM): S.FREE_RUNNING,  # the wall clock runs on, disarmed
    (S.HALTED, T.DISARM): S.HALTED,
    (S.IDLE, T.DIVERGE): S.HALTED,  # (disarmed by a command while its last step was paced)
    (S.LOCKSTEP, T.DIVERGE): S.HALTED,
    (S.ANSWERED, T.DIVERGE): S.HALTED,
    (S.FREE_RUNNING, T.DIVERGE): S.HALTED,
    (S.ANSWERED, T.GATE): S.GATED,  # (the answer still held)
    (S.GATED, T.RELEASE): S.ANSWERED,
    (S.GATED, T.ENGAGE): S.LOCKSTEP,  # (its held answer dropped, as from ANSWERED)
    (S.GATED, T.GROUND): S.FREE_RUNNING,
    (S.GATED, T.DISARM): S.IDLE,
    (S.ANSWERED, T.COLLIDE): S.HALTED,
    (S.GATED, T.COLLIDE): S.HALTED,
}
del S, T
_ENGAGED = frozenset({ClockState.LOCKSTEP, ClockState.ANSWERED, ClockState.GATED})


class IllegalTransition(RuntimeError):
    """A trigger the clock's table does not allow in its state (a bug, never a peer's doing)."""


class Answer(NamedTuple):
    """The controller's answer to step k: its actuator target on the wire (None: the no-target
    acknowledgement) and the wall time it came (s)."""

    wire: tuple[float, ...] | None
    recv: float


class Clock:
    """The step clock's state, the answer it holds, and the wall-clock pace of physics steps."""

    def __init__(self, realtime: bool, physics_hz: float, speed: float, now: float) -> None:
        self.state = ClockState.FREE_RUNNING if realtime else ClockState.IDLE
        self.answer: Answer | None = None  # held in ANSWERED and GATED only
        self.pace = Pace(physics_hz, speed, now)  # the wall clock of physics steps
        self._halted_on_wall = False  # halted from the wall clock: its time runs on (TIMESYNC)

    def fire(self, trigger: Trigger) -> ClockState:
        """Make the transition ``trigger`` from the current state; :class:`IllegalTransition` if the
        table has none. Leaving ANSWERED (for anywhere but GATED) drops the held answer."""
        state = self.state
        nxt = TRANSITIONS.get((state, trigger))
        if nxt is None:
            raise IllegalTransition(f"clock: {trigger.value} is not allowed while {state.value}")
        if nxt is ClockState.HALTED and state is not ClockState.HALTED:
            self._halted_on_wall = state is ClockState.FREE_RUNNING
        if nxt is not ClockState.ANSWERED and nxt is not ClockState.GATED:
            self.answer = None
        self.state = nxt
        return nxt

    # -- the transitions with what they carry -------------------------------------------------------
    def hold(self, answer: Answer) -> None:
        """Step k's answer is here (LOCKSTEP -> ANSWERED)."""
        self.fire(Trigger.ANSWER)
        self.answer = answer

    def take(self) -> Answer:
        """The held answer, to fly step k with (ANSWERED -> LOCKSTEP)."""
        answer = self.answer
        assert answer is not None
        self.fire(Trigger.STEP)
        return answer

    def engage(self, now: float, n: int) -> None:
        """Lockstep from wall time ``now``, physics step ``n`` due then."""
        self.fire(Trigger.ENGAGE)
        self.pace.restart(now, n)

    def run_free(self, trigger: Trigger, now: float, n: int) -> None:
        """On the wall clock from ``now`` (``trigger``: LOSE or GROUND), physics step ``n`` due then."""
        self.fire(trigger)
        self.pace.restart(now, n)

    # -- what the state means --------------------------------------------------------------------------
    @property
    def engaged(self) -> bool:
        """A lockstep flight is on: the step clock runs on the controller's answers."""
        return self.state in _ENGAGED

    @property
    def free_running(self) -> bool:
        return self.state is ClockState.FREE_RUNNING

    @property
    def halted(self) -> bool:
        return self.state is ClockState.HALTED

    @property
    def on_wall_clock(self) -> bool:
        """Time runs on the wall clock between physics steps (free-running, or halted from it)."""
        return self.state is ClockState.FREE_RUNNING or (self.state is ClockState.HALTED and self._halted_on_wall)

    def time_s(self, now: float, step_t: float) -> float:
        """The clock's time (s) at wall time ``now``: the paced time on the wall clock, else
        ``step_t``, the simulation time of the current step."""
        return self.pace.time_s(now) if self.on_wall_clock else step_t

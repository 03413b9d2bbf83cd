"""Covers bridge.nodes.vehicle.clock: the vehicle's step clock, its table of transitions walked whole.

Every listed transition leads where the table says (and keeps or drops the held answer as it should),
every pair the table does not list is refused with :class:`IllegalTransition` and leaves the clock as
it was, and every state is reachable from ``idle`` (the lockstep clock's start) by listed transitions.
"""

from __future__ import annotations

from collections import deque

import pytest

from bridge.nodes.vehicle.clock import TRANSITIONS, Answer, Clock, ClockState, IllegalTransition, Trigger

ANSWER = Answer((0.5, 0.5, 0.5, 0.5), 12.0)


def path_from_idle() -> dict[ClockState, list[Trigger]]:
    """The shortest trigger sequence from idle to each state reachable by the table."""
    paths = {ClockState.IDLE: []}
    todo = deque([ClockState.IDLE])
    while todo:
        state = todo.popleft()
        for (src, trigger), dst in TRANSITIONS.items():
            if src is state and dst not in paths:
                paths[dst] = [*paths[state], trigger]
                todo.append(dst)
    return paths


def clock_in(state: ClockState) -> Clock:
    """A lockstep clock brought to ``state`` by listed transitions only (an answer held when it is ANSWERED or
    GATED)."""
    clock = Clock(False, 1000.0, 1.0, 0.0)
    for trigger in path_from_idle()[state]:
        if trigger is Trigger.ANSWER:
            clock.hold(ANSWER)
        else:
            clock.fire(trigger)
    assert clock.state is state
    return clock


def test_every_state_is_reachable_from_idle() -> None:
    assert set(path_from_idle()) == set(ClockState)
    assert Clock(False, 1000.0, 1.0, 0.0).state is ClockState.IDLE  # the lockstep clock starts idle
    assert Clock(True, 1000.0, 1.0, 0.0).state is ClockState.FREE_RUNNING  # the realtime clock runs at once


@pytest.mark.parametrize(("state", "trigger"), sorted(TRANSITIONS, key=lambda p: (p[0].value, p[1].value)),
                         ids=lambda x: x.value)
def test_listed_transition_leads_where_the_table_says(state: ClockState, trigger: Trigger) -> None:
    clock = clock_in(state)
    if trigger is Trigger.ANSWER:
        clock.hold(ANSWER)
        assert clock.answer == ANSWER
    elif trigger is Trigger.STEP:
        assert clock.take() == ANSWER  # the answer the step is flown with
    else:
        assert clock.fire(trigger) is TRANSITIONS[state, trigger]
    assert clock.state is TRANSITIONS[state, trigger]
    if clock.state in (ClockState.ANSWERED, ClockState.GATED):
        assert clock.answer == ANSWER  # held from ANSWERED to GATED and back
    else:
        assert clock.answer is None  # no answer outlives ANSWERED (and GATED)
    assert clock.engaged == (clock.state in (ClockState.LOCKSTEP, ClockState.ANSWERED, ClockState.GATED))
    assert clock.halted == (clock.state is ClockState.HALTED)


UNLISTED = [(s, t) for s in ClockState for t in Trigger if (s, t) not in TRANSITIONS]


@pytest.mark.parametrize(("state", "trigger"), UNLISTED, ids=lambda x: x.value)
def test_unlisted_pair_is_refused(state: ClockState, trigger: Trigger) -> None:
    clock = clock_in(state)
    before = (clock.state, clock.answer, clock.pace.w0, clock.pace.n0)
    with pytest.raises(IllegalTransition, match=f"{trigger.value} is not allowed while {state.value}"):
        clock.fire(trigger)
    assert (clock.state, clock.answer, clock.pace.w0, clock.pace.n0) == before


def test_the_table_is_not_trivial() -> None:
    """Halted is final but for a disarm, and every trigger acts somewhere (none is dead)."""
    assert {t for (s, t) in TRANSITIONS if s is ClockState.HALTED} == {Trigger.DISARM}
    assert {t for (_, t) in TRANSITIONS} == set(Trigger)
    assert len(UNLISTED) + len(TRANSITIONS) == len(ClockState) * len(Trigger) and UNLISTED


def test_engage_and_run_free_restart_the_pace() -> None:
    """Lockstep and the wall clock each start their pace at the step they begin from."""
    clock = Clock(False, 1000.0, 2.0, 0.0)
    clock.engage(5.0, 40)
    assert (clock.state, clock.pace.w0, clock.pace.n0) == (ClockState.LOCKSTEP, 5.0, 40)
    assert clock.time_s(9.0, 0.04) == 0.04  # lockstep: the step's simulation time, whatever the wall says
    clock.run_free(Trigger.LOSE, 7.0, 60)
    assert (clock.state, clock.pace.w0, clock.pace.n0) == (ClockState.FREE_RUNNING, 7.0, 60)
    assert clock.time_s(8.0, 0.06) == pytest.approx(0.06 + 1.0 * 2.0)  # on the wall clock, at 2x
    clock.fire(Trigger.DIVERGE)
    assert clock.on_wall_clock and clock.time_s(8.0, 0.06) == pytest.approx(2.06)  # halted from the wall clock
    halted_in_lockstep = clock_in(ClockState.HALTED)
    assert not halted_in_lockstep.on_wall_clock and halted_in_lockstep.time_s(99.0, 1.5) == 1.5

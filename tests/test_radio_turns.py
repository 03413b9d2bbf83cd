"""Covers bridge.link.turns and bridge.link.radio: a fleet's one radio taken in turns, as the offline loop flies
its vehicles (pure: the order, who waits for whom, and the file that several processes map).

The offline loop (bridge.swarm) flies every vehicle's step in turn, the first one rotating, so on one radio the
packets sent at the same instant queue in that order. Under ``bsst sitl`` in lockstep each vehicle and each
controller admits its own packets into the file's queue, each when every user before it in the step's order has
taken its turn of the step and every user after it its turn of the step before.
"""

from __future__ import annotations

import random
from pathlib import Path

from bridge.link.radio import NEVER, NOT_YET, Radio, make_radio_file, radio_file_bytes
from bridge.link.turns import TurnRadio, blocking, turn_order

UP, DOWN = 0, 1


def test_the_order_rotates_its_first_user_over_those_still_flying() -> None:
    assert [turn_order([0, 1, 2, 3], k) for k in range(5)] == [
        [0, 1, 2, 3], [1, 2, 3, 0], [2, 3, 0, 1], [3, 0, 1, 2], [0, 1, 2, 3]]
    assert turn_order([0, 2, 3], 4) == [2, 3, 0]  # user 1 gone: the rotation is over the three left
    assert turn_order([5], 7) == [5]


def rows(*turns: tuple[int, int, int]) -> list[tuple[int, int, int]]:
    return list(turns)


def test_a_user_waits_for_those_before_it_at_this_step_and_those_after_it_at_the_step_before() -> None:
    # step 1: order 1, 2, 3, 0. User 3 waits for 1 and 2 to take step 1, and for 0 to have taken step 0
    fresh = rows(*[(NOT_YET, NOT_YET, NEVER)] * 4)
    assert blocking(3, 1, UP, fresh) == [0, 1, 2]
    assert blocking(3, 1, UP, rows((0, 0, NEVER), (1, 0, NEVER), (1, 0, NEVER), (0, 0, NEVER))) == []
    assert blocking(3, 1, DOWN, rows((0, 0, NEVER), (1, 0, NEVER), (1, 0, NEVER), (0, 0, NEVER))) == [1, 2]
    # the first of the step waits for everyone's step before only
    assert blocking(1, 1, UP, rows((0, 0, NEVER), (0, 0, NEVER), (0, 0, NEVER), (NOT_YET, 0, NEVER))) == [3]
    assert blocking(0, 0, UP, fresh) == []  # the very first turn of the flight


def test_a_user_that_left_is_waited_for_up_to_its_last_turn_and_then_never() -> None:
    # user 1 left from step 5 (it flew step 4 and took its turns of step 4): step 5's order still has its slot,
    # as the offline loop's (it ends in its turn), but nobody waits for it there; from step 6 it has none
    assert turn_order([0, 1, 2], 5) == [2, 0, 1]
    assert blocking(0, 5, UP, rows((4, 4, NEVER), (4, 4, 5), (4, 4, NEVER))) == [2]
    assert blocking(0, 5, UP, rows((4, 4, NEVER), (4, 4, 5), (5, 4, NEVER))) == []
    assert blocking(2, 5, UP, rows((4, 4, NEVER), (3, 3, 5), (4, 4, NEVER))) == [1]  # it owes its step 4
    assert blocking(1, 6, UP, rows((5, 5, NEVER), (4, 4, 5), (5, 5, NEVER))) == []  # (itself: no turns any more)
    # step 6 over the two left: 0 then 2
    assert turn_order([0, 2], 6) == [0, 2]
    assert blocking(0, 6, UP, rows((5, 5, NEVER), (4, 4, 5), (5, 5, NEVER))) == []
    assert blocking(2, 6, UP, rows((5, 5, NEVER), (4, 4, 5), (5, 5, NEVER))) == [0]


def test_turns_taken_in_the_order_give_each_packet_the_fate_one_radio_gives_it(tmp_path: Path) -> None:
    """Three users, each its own mapping of one file (as three processes), admit random packets of 200 steps in
    the turn order, each user skipping some steps and one leaving: every packet's end of transmission (or drop)
    is the in-memory radio's, flown as the offline loop does, and at no time is anyone's turn taken out of order."""
    f = tmp_path / "radio"
    make_radio_file(f, 3)
    assert f.stat().st_size == radio_file_bytes(3)
    users = [TurnRadio(f, "down", 3000.0, 0.05, u) for u in range(3)]
    one = Radio(3000.0, 0.05, users=3)
    rnd = random.Random(4)
    live = [0, 1, 2]
    for k in range(200):
        if k == 120:  # user 1 leaves from step 120 (it flew 119)
            users[1].leave(120)
            live.remove(1)
        order = turn_order(live, k)
        for pos, u in enumerate(order):
            for later in order[pos + 1:]:  # nobody after it may go yet
                assert users[later].blocking(k), (k, u, later)
            assert users[u].blocking(k) == []
            for _ in range(rnd.choice((0, 1, 1, 2))):
                t, size = k * 0.02, rnd.choice((242, 60))
                want = one.admit(t, size, u)
                got = users[u].admit(t, size, u)
                assert got == want  # the same arithmetic on the same state: bit for bit
            users[u].took(k)
    for u in range(3):
        part = users[u].part()
        assert part["bytes"] == one.bytes[u] and part["lost_queue"] == one.dropped[u] > 0
        assert part["first_s"] == 0.0
        users[u].close()


def test_a_radio_without_a_rate_takes_no_turns(tmp_path: Path) -> None:
    """Without a rate nothing queues, so the order is moot: nobody waits, and no turn is written in the file."""
    f = tmp_path / "radio"
    make_radio_file(f, 2)
    free, capped = TurnRadio(f, "up", 0.0, 0.05, 1), TurnRadio(f, "up", 1000.0, 0.05, 1)
    assert not free.ordered and capped.ordered
    assert free.blocking(3) == [] and capped.blocking(3) == [0]  # user 0 has taken no turn yet
    free.took(3)
    assert capped.rows()[1][UP] == NOT_YET
    capped.took(3)
    assert capped.rows()[1][UP] == 3
    free.close()
    capped.close()

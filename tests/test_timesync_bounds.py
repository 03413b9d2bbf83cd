"""Covers bridge.nodes.offboard.config: the vehicle's clock offset as TIMESYNC answers bound it (offset_bounds).

Each answer says the vehicle read its clock between our request's send and the answer's arrival, so the offset
lies within a range its round trip wide; the controller takes the middle of where its latest answers agree. The
exchanges here are written out in ns, each way's time chosen, so the truth is known.
"""

from __future__ import annotations

import numpy as np
import pytest

from bridge.nodes.offboard.config import offset_bounds

OFFSET = 123_456_789_000  # the vehicle's clock less ours (ns)


def answer(ts1: int, over: int, back: int, offset: int = OFFSET) -> tuple[int, int, int]:
    """The controller's record of one exchange (round trip, least and greatest offset) for a request sent at ts1
    (our clock, ns) that took ``over`` ns to be read and an answer that took ``back`` ns to be read."""
    tc1 = ts1 + over + offset  # the vehicle's clock when it read the request
    now = ts1 + over + back  # ours when its answer was read
    return now - ts1, tc1 - now, tc1 - ts1


def middle(bounds: tuple[int, int]) -> int:
    return sum(bounds) // 2


def test_one_answer_bounds_the_offset_by_its_round_trip() -> None:
    lo, hi = offset_bounds([answer(1_000, 40_000, 60_000)])
    assert (lo, hi) == (OFFSET - 60_000, OFFSET + 40_000)  # the round trip wide, the truth inside
    assert middle((lo, hi)) == OFFSET - 10_000  # both ways taken as equal: half their difference off


def test_answers_held_up_one_way_each_agree_where_neither_was() -> None:
    """A busy machine holds up one way of an exchange (the side that should read it waits for a core): here every
    other answer waits 2 ms and every other request 3 ms. The shortest round trip's own middle is 1 ms off; where
    all of them agree, the fastest way over and the fastest way back bound it to 30 us."""
    held = [answer(10_000_000 * i, 30_000, 2_000_000) if i % 2 else answer(10_000_000 * i, 3_000_000, 30_000)
            for i in range(8)]
    best = min(held)
    assert abs(middle((best[1], best[2])) - OFFSET) == pytest.approx(985_000, abs=1)  # one exchange's middle
    lo, hi = offset_bounds(held)
    assert (lo, hi) == (OFFSET - 30_000, OFFSET + 30_000)
    assert middle((lo, hi)) == OFFSET


def test_answers_that_cannot_all_hold_give_way_to_the_shortest_round_trip() -> None:
    """The vehicle's clock stepped between two answers: no offset fits both, and the one with the shortest round
    trip gives the bounds (as one answer alone would)."""
    answers = [answer(0, 50_000, 50_000), answer(10_000_000, 20_000, 30_000, OFFSET + 5_000_000)]
    assert offset_bounds(answers) == (OFFSET + 5_000_000 - 30_000, OFFSET + 5_000_000 + 20_000)


def test_the_truth_is_always_within_and_never_wider_than_the_best_answer() -> None:
    """Whatever each way took, the offset lies within the bounds, and they are no wider than the shortest round
    trip (the intersection is inside every answer's range)."""
    rng = np.random.default_rng(7)
    for _ in range(500):
        n = int(rng.integers(1, 9))
        ways = rng.exponential(200_000, size=(n, 2)).astype(int) + 10_000
        answers = [answer(10_000_000 * i, int(w[0]), int(w[1])) for i, w in enumerate(ways)]
        lo, hi = offset_bounds(answers)
        assert lo <= OFFSET <= hi
        assert hi - lo <= min(answers)[0]

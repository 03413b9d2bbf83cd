"""Covers bridge.mavlink.eventseq: following a vehicle's EVENT sequence, offline.

Gaps shown by an EVENT or CURRENT_EVENT_SEQUENCE, asked for at once and again after the timeout, a limited number of
times; the uint16 wrap; the RESET flag; RESPONSE_EVENT_ERROR giving a gap up; each sequence handled once. Against the
vehicle's own ring (bridge.mavlink.events.EventRing) a lossy exchange recovers every event the ring still keeps. A
real controller and vehicle: tests/test_events_sitl.py.
"""

from __future__ import annotations

import random

from bridge.mavlink import events as ev
from bridge.mavlink.eventseq import MAX_MISSING, REQUEST_TIMEOUT_S, REQUEST_TRIES, EventSequence, ahead


def test_ahead_wraps() -> None:
    assert ahead(5, 3) == 2 and ahead(3, 5) == -2 and ahead(0, 65535) == 1 and ahead(65535, 0) == -1
    assert ahead(7, 7) == 0


def test_in_order_events_ask_for_nothing_and_a_duplicate_is_dropped() -> None:
    s = EventSequence()
    assert [s.event(q, 0.0) for q in (0, 1, 2)] == [True, True, True]
    assert s.requests(0.0) == [] and not s.pending()
    assert s.event(1, 0.0) is False and s.counts.duplicates == 1
    s.current(2, 0, 0.0)
    assert s.requests(0.0) == []


def test_a_gap_an_event_shows_is_asked_for_at_once_then_again_after_the_timeout_then_given_up() -> None:
    s = EventSequence()
    s.event(0, 0.0)
    assert s.event(4, 0.0) is True  # handled at once, not held back for the missed ones
    assert s.pending() and s.requests(0.0) == [(1, 3)]
    assert s.requests(0.0) == []  # at most once within the timeout
    assert s.next_due() == REQUEST_TIMEOUT_S
    t = 0.0
    for _ in range(REQUEST_TRIES - 1):
        t += REQUEST_TIMEOUT_S
        assert s.requests(t) == [(1, 3)]
    t += REQUEST_TIMEOUT_S
    assert s.requests(t) == [] and not s.pending()
    assert (s.counts.requests, s.counts.lost) == (REQUEST_TRIES, 3)
    assert s.event(2, t) is False  # given up, and come late: not handled (once or never, never twice)


def test_a_missed_event_that_comes_when_asked_is_handled_once() -> None:
    s = EventSequence()
    s.event(0, 0.0)
    s.event(3, 0.0)
    assert s.requests(0.0) == [(1, 2)]
    assert s.event(2, 0.01) is True and s.event(2, 0.01) is False  # the request's answer, then a duplicate
    assert s.requests(REQUEST_TIMEOUT_S) == [(1, 1)]  # the one still missed, alone
    assert s.event(1, 0.2) is True and not s.pending()
    assert (s.counts.recovered, s.counts.duplicates, s.counts.lost) == (2, 1, 0)


def test_current_event_sequence_shows_a_gap_and_its_first_sets_where_to_start() -> None:
    s = EventSequence()
    s.current(41, 0, 0.0)  # joined late: the events before are not asked for (libevents)
    assert not s.pending()
    s.current(43, 0, 0.0)  # 42 and 43 missed
    assert s.requests(0.0) == [(42, 43)]
    assert s.event(43, 0.0) is True and s.event(44, 0.0) is True
    s.current(44, 0, 0.0)
    assert list(s.missing) == [42]


def test_the_sequence_wraps() -> None:
    s = EventSequence()
    s.event(65533, 0.0)
    assert s.event(1, 0.0) is True
    assert s.requests(0.0) == [(65534, 0)]  # one range across the wrap
    assert s.event(65535, 0.0) is True and s.event(0, 0.0) is True and s.event(65534, 0.0) is True
    assert not s.pending() and s.event(65535, 0.0) is False


def test_reset_starts_over() -> None:
    s = EventSequence()
    s.event(10, 0.0)
    s.event(12, 0.0)
    assert s.pending()
    s.current(65535, ev.SEQUENCE_RESET, 0.0)  # the vehicle restarted: nothing sent yet
    assert not s.pending() and s.next == 0
    assert s.event(0, 0.0) is True and s.requests(0.0) == []


def test_an_error_gives_up_up_to_the_oldest_kept_and_others_change_nothing() -> None:
    s = EventSequence()
    s.event(0, 0.0)
    s.event(10, 0.0)
    s.requests(0.0)
    s.error(50, 60)  # not awaited: nothing
    assert len(s.missing) == 9
    s.error(1, 5)  # 1..4 no longer kept; 5 is
    assert list(s.missing) == [5, 6, 7, 8, 9] and s.counts.lost == 4
    s.error(9, 9)  # nothing kept after it: that one alone
    assert list(s.missing) == [5, 6, 7, 8] and s.counts.lost == 5


def test_a_gap_longer_than_the_vehicle_keeps_awaits_its_newest_only() -> None:
    s = EventSequence()
    s.event(0, 0.0)
    s.event(100, 0.0)
    assert len(s.missing) == MAX_MISSING and min(s.missing) == 100 - MAX_MISSING
    assert s.counts.lost == 99 - MAX_MISSING
    assert s.requests(0.0) == [(100 - MAX_MISSING, 99)]


def test_against_the_vehicles_ring_a_lossy_exchange_recovers_every_kept_event() -> None:
    """The vehicle's EventRing sends 300 EVENTs (past the wrap) and a CURRENT_EVENT_SEQUENCE per 10; a fifth of
    every datagram both ways is lost; each REQUEST_EVENT is answered by the ring. Every event is handled once,
    and what is never handled is counted lost (given up, or too old for the ring)."""
    rng = random.Random(7)
    ring = ev.EventRing()
    ring.next = 65400  # near the wrap
    s = EventSequence()
    handled: list[int] = []
    t = 0.0

    def deliver(m) -> None:
        if rng.random() < 0.2:
            return
        if m.get_type() == "EVENT" and s.event(m.sequence, t):
            handled.append(m.sequence)
        elif m.get_type() == "RESPONSE_EVENT_ERROR":
            s.error(m.sequence, m.sequence_oldest_available)

    first = ring.next
    for i in range(300):
        deliver(ring.add("failsafe", t, 2))
        if i % 10 == 9 and rng.random() >= 0.2:
            s.current(ring.current().sequence, ring.current().flags, t)
        for _ in range(3):  # three turns of requests and answers per event
            t += REQUEST_TIMEOUT_S
            for a, b in s.requests(t):
                if rng.random() >= 0.2:
                    for m in ring.resend(a, b, 255, 190):
                        deliver(m)
    assert len(handled) == len(set(handled))  # once each
    sent = {(first + i) & 0xFFFF for i in range(300)}
    assert set(handled) <= sent
    assert len(handled) + s.counts.lost + len(s.missing) >= 299  # every one handled, counted lost, or awaited
    assert len(handled) >= 295, (len(handled), s.counts)
    assert s.counts.requests < 300  # small: a request per gap and turn, not per event

"""Covers bridge.cli.runreport: the events a run's printed summary lists.

`bsst sitl` listed only the first eight, five of them a session's start-up events, so a failsafe, its landing and
its disarm were never printed; a long list now keeps its head and its tail.
"""

from __future__ import annotations

from bridge.cli.runreport import EVENTS_SHOWN, event_lines


def _events(n: int) -> list[dict]:
    return [{"t": float(i), "kind": "k", "text": f"e{i}"} for i in range(n)]


def test_a_short_list_is_printed_whole() -> None:
    assert event_lines(_events(EVENTS_SHOWN)) == [f"event t={i:.3f} k: e{i}\n" for i in range(EVENTS_SHOWN)]


def test_a_long_list_keeps_its_first_six_and_last_ten_and_says_how_many_more() -> None:
    lines = event_lines(_events(40))
    assert lines[:6] == [f"event t={i:.3f} k: e{i}\n" for i in range(6)]
    assert lines[6] == f"event … {40 - EVENTS_SHOWN} more (summary.json)\n"
    assert lines[7:] == [f"event t={i:.3f} k: e{i}\n" for i in range(30, 40)]


def test_an_event_with_no_time_is_printed_without_one() -> None:
    """A controller's failsafe judgement with no EVENT's time is ``null`` in summary.json (a TypeError, before)."""
    said = {"t": None, "kind": "failsafe", "text": "the vehicle's failsafe took over (its HEARTBEAT)"}
    assert event_lines([said]) == ["event t=n/a failsafe: the vehicle's failsafe took over (its HEARTBEAT)\n"]

"""Covers bridge.autopilot.simvehicle: the ``landed`` event of the vehicle's own landing, and none at a crash.

A landing the vehicle flies itself says ``landed`` at its touchdown and disarms COM_DISARM_LAND (2 s) later; a
touchdown too hard to be a landing is the period's ``crashed`` verdict alone (it once said ``landed`` 17 ms before
``crashed``).
"""

from __future__ import annotations

from bridge.loop import simulate


def _kinds(summary: dict) -> list[tuple[float, str]]:
    return [(e["t"], e["kind"]) for e in summary["events"] if e["kind"] in ("landed", "crashed", "disarmed")]


def test_a_failsafe_descent_that_hits_hard_is_a_crash_not_a_landing() -> None:
    """One SiK radio at 50 Hz: the states barely come down, the failsafe descends from 0.8 s and the vehicle,
    tumbling, hits the ground at 7.9 m/s."""
    s = simulate("missions/sine.toml", link={"profile": "sik-57600"}, rate_hz=50.0).summary
    assert s["outcome"] == "crashed" and _kinds(s) == [(1.1, "crashed")], _kinds(s)


def test_the_end_landing_says_landed_then_disarms_two_seconds_later() -> None:
    s = simulate("missions/sine.toml").summary
    (t_landed, landed), (t_disarmed, disarmed) = _kinds(s)
    assert (landed, disarmed) == ("landed", "disarmed") and abs(t_disarmed - t_landed - 2.0) < 1e-6, _kinds(s)
    assert s["outcome"] == "completed"

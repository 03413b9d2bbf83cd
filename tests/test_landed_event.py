"""Covers bridge.autopilot.simvehicle and bridge.loop: the `landed` event of the vehicle's own landing; none at a crash.

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


def test_a_failsafe_landing_going_at_the_missions_end_lands_and_is_judged() -> None:
    """The link lost at 27.5 s of the 30 s sine: the failsafe's descent from 28.0 s is still going at the mission's
    end; offline flies it on to the ground as a session's vehicle does (which leaves lockstep for it): landed at
    32.571 s, disarmed at 34.571 s, the run ``failsafe``. It once ended armed in the air."""
    s = simulate("missions/sine.toml", link={"blackouts": [[27.5, 3.0]]}).summary
    assert s["outcome"] == "failsafe" and _kinds(s) == [(32.571, "landed"), (34.571, "disarmed")], _kinds(s)


def test_a_hard_failsafe_landing_after_the_missions_end_is_a_crash() -> None:
    """The link lost at 29 s, the failsafe's landing at MPC_LAND_SPEED 4 m/s from 29.5 s: its touchdown, after the
    mission's end, is judged: ``crashed`` at 30.488 s (it was ``failsafe``, armed in the air)."""
    s = simulate("missions/sine.toml", link={"blackouts": [[29.0, 3.0]]}, failsafe={"action": "land"},
                 params={"MPC_LAND_SPEED": 4.0}).summary
    assert s["outcome"] == "crashed" and s["impact"]["speed_mps"] > 2.0, s["events"]
    assert _kinds(s)[0] == (30.488, "crashed") and s["ended_by"]["who"] == "plant", (s["events"], s["ended_by"])

"""Covers bridge.autopilot.intention and bridge.loop: the failsafe cleared on disarm, offline, as PX4.

PX4 (failsafe/framework.cpp, ``FailsafeBase::update`` and ``getSelectedAction``) selects no failsafe action while
disarmed, so once its failsafe has landed the vehicle and disarmed it, the commander shows the user's mode again
(UserModeIntention), and HEARTBEAT says STANDBY. The vehicle core does the same, with a ``mode`` event of its own: the
offline loop as a session's vehicle (tests/test_failsafe_disarm.py flies both and a ground station).
"""

from __future__ import annotations

from bridge.autopilot.failsafe import PositionHold
from bridge.autopilot.intention import UserModeIntention
from bridge.autopilot.simvehicle import HOLD, LAND, OFFBOARD
from bridge.core.flight import prepare
from bridge.loop import simulate
from missions import Mission, Setpoint, Step

CLEARED = ("(disarmed after its failsafe: PX4 clears the failsafe on disarm and takes the last mode it arms in; "
           "armed in it next)")


def _ground_mission() -> Mission:
    return Mission(Step(setpoints=(Setpoint(0.0, 0.0, 0.0, 0.0, 0.0),)), duration_s=20.0, name="ground")


def _fly(sim, intention: UserModeIntention, seconds: float) -> None:
    """Control periods of ``sim`` for ``seconds`` of its time, each followed by the intention's turn (as the loop)."""
    period = sim.plant.dt * sim.substeps
    for _ in range(round(seconds / period)):
        sim.advance()
        intention.after_period()


def test_the_briefs_failsafe_landing_disarms_then_shows_offboard_again_offline() -> None:
    """``--blackout 27.5:3`` on the sine: the failsafe's descent from 28.0 s lands at 32.571 s, disarms at 34.571 s,
    and at the end of that control period the vehicle is back in OFFBOARD, disarmed, saying so; the run is still
    ``failsafe``, ended by it."""
    s = simulate("missions/sine.toml", link={"blackouts": [[27.5, 3.0]]}).summary
    assert s["outcome"] == "failsafe" and s["ended_by"]["who"] == "vehicle", (s["outcome"], s["ended_by"])
    tail = [(e["t"], e["kind"], e["text"], e.get("mode"), e.get("armed")) for e in s["events"][-3:]]
    assert tail == [(32.571, "landed", "landing detected at x=0.991 y=-2.156 m: disarms in COM_DISARM_LAND = 2 s",
                     None, None),
                    (34.571, "disarmed", "landed: disarmed", None, None),
                    (34.572, "mode", f"OFFBOARD {CLEARED}", OFFBOARD, False)], tail


def test_the_end_landing_disarm_takes_offboard_offline_as_a_session_does() -> None:
    """The mission's own end LAND: offline now says the mode its disarm leaves, as a session's vehicle always did
    (``mode: OFFBOARD (disarmed after LAND: ...)`` at the end of the disarm's control period)."""
    s = simulate("missions/sine.toml").summary
    tail = [(e["t"], e["kind"], e["text"]) for e in s["events"][-2:]]
    assert tail == [(36.301, "disarmed", "landed: disarmed"),
                    (36.304, "mode", "OFFBOARD (disarmed after LAND: PX4 takes the last mode it arms in; armed in "
                                     "it next)")], tail
    assert s["outcome"] == "completed"


def test_a_failsafe_on_the_ground_clears_at_once_and_the_controller_arms_it_again() -> None:
    """No target for COM_OF_LOSS_T on the ground: the failsafe disarms it in that control period (LANDED), and at its
    end the vehicle is in OFFBOARD, the mode it was armed in; an arm takes it as before (offboard control)."""
    sim = prepare(_ground_mission()).make_vehicle(armed=True)
    intention = UserModeIntention(sim)
    _fly(sim, intention, 0.6)
    kinds = [(e.kind, e.text) for e in sim.events]
    assert [k for k, _ in kinds] == ["failsafe", "disarmed", "mode"] and kinds[-1][1] == f"OFFBOARD {CLEARED}", kinds
    assert not sim.armed and sim.mode == OFFBOARD
    sim.arm()
    assert sim.armed and sim.mode == OFFBOARD and sim.events[-1].text == "armed, offboard control"


def test_a_geofence_land_failsafe_from_hold_disarms_into_hold_where_a_ground_stations_arm_arms() -> None:
    """Held at 2 m (HOLD, a ground station's), GF_MAX_VER_DIST set to 1 m with GF_ACTION 5: the fence's Land
    failsafe lands it (LAND shown, CRITICAL) and disarms it; then it is in HOLD, the last mode it was put in, and a
    ground station's arm arms in HOLD (PX4 arms in Hold); a disarm by command in the failsafe clears it likewise."""
    sim = prepare(_ground_mission(), params={"GF_ACTION": 5}).make_vehicle(armed=True)
    intention = UserModeIntention(sim)
    sim.plant.state = (0.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    sim.set_mode(HOLD)
    _fly(sim, intention, 0.5)
    assert intention.after == HOLD and sim.mode == HOLD and sim.armed
    sim.change_param("GF_MAX_VER_DIST", 1.0)
    _fly(sim, intention, 7.0)
    kinds = [e.kind for e in sim.events]
    assert kinds[-5:] == ["geofence", "failsafe", "landed", "disarmed", "mode"], kinds
    assert sim.events[-1].text == f"HOLD {CLEARED}" and (sim.events[-1].mode, sim.events[-1].armed) == (HOLD, False)
    assert sim.mode == HOLD and not sim.armed
    sim.arm_in_mode()
    assert sim.armed and sim.mode == HOLD and [e.text for e in sim.events[-2:]] == [
        "armed, HOLD", "HOLD at x=0.000 y=0.000 z=0.000 m: landed, idle until a takeoff"]


def test_a_disarm_by_command_in_the_failsafe_clears_it_too() -> None:
    """Any disarm clears PX4's failsafe: one by command while it flies (in FAILSAFE) leaves the user's mode."""
    sim = prepare(_ground_mission(), failsafe={"action": "hold"}).make_vehicle(armed=True)
    intention = UserModeIntention(sim)
    sim.plant.state = (0.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    _fly(sim, intention, 1.0)  # no target: its hold failsafe holds at 2 m
    assert sim.armed and sim.mode == "failsafe"
    sim.disarm("disarmed by command")
    assert intention.fall_back() and sim.mode == OFFBOARD and sim.events[-1].text == f"OFFBOARD {CLEARED}"


def test_land_and_rtl_disarms_keep_their_text() -> None:
    """The modes PX4 does not arm in (LAND here) still say so as before (tests/test_ground_stations.py reads it)."""
    sim = prepare(_ground_mission()).make_vehicle(armed=True)
    intention = UserModeIntention(sim)
    sim.set_mode(HOLD)
    intention.note()
    sim.set_mode(LAND)
    sim.disarm()
    assert intention.fall_back() and sim.mode == HOLD
    assert sim.events[-1].text == "HOLD (disarmed after LAND: PX4 takes the last mode it arms in; armed in it next)"
    assert not intention.fall_back()  # in a mode it arms in now: nothing more to take


def test_hold_asked_again_while_holding_changes_nothing_and_a_reposition_goes_on() -> None:
    """HOLD selected while in HOLD, armed, is no change, as PX4's navigation state stays Loiter: a reposition under
    way (DO_REPOSITION: HOLD flown to a point) goes on to its point; it stopped where the vehicle was, re-held
    there (a HOLD event, and MAVSDK's hold() during a goto_location stopped short)."""
    sim = prepare(_ground_mission()).make_vehicle(armed=True)
    intention = UserModeIntention(sim)
    sim.plant.state = (0.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    sim.set_mode(HOLD, hold_at=PositionHold(6.0, 0.0, 2.0))
    _fly(sim, intention, 1.0)
    n, target = len(sim.events), sim.onboard.target
    assert 0.5 < sim.published()[0] < 5.0  # on its way
    sim.set_mode(HOLD)
    assert len(sim.events) == n and sim.onboard.target is target  # no event, the same point
    _fly(sim, intention, 8.0)
    assert abs(sim.published()[0] - 6.0) < 0.1 and sim.mode == HOLD

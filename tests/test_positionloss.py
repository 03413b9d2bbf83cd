"""Covers bridge.autopilot.positionloss, bridge.autopilot.simvehicle and bridge.nodes.vehicle.streams: the timing.

PX4's loss of the horizontal position estimate (a GPS that stopped), its failsafe and its telemetry.

PX4's rules as pure functions (EKF2_NOAID_TOUT's invalidity, the commander's 1 s probation, what each mode falls back
to), then the real vehicle core (SimVehicle with its sensors and EKF, offline, no sockets): a GPS back before the
timeout is no failsafe; one that stays off is PX4's Descend at the timeout, the flight's outcome ``failsafe`` naming
it; a ground station's HOLD falls back to it and flies again once the position is valid; EKF2_NOAID_TOUT acts as a
parameter; ESTIMATOR_STATUS and GLOBAL_POSITION_INT say it, through MAVLink bytes. The same flights with a real
vehicle process, MAVSDK and a lockstep session: tests/test_gps_failsafe.py.
"""

from __future__ import annotations

import math
import re

import pytest
from pymavlink.dialects.v20 import common as M

from bridge import simulate
from bridge.autopilot.failsafe import Land, Level, PositionHold, ReturnHome, Takeoff
from bridge.autopilot.modes import FAILSAFE, HOLD, LAND, LANDED, OFFBOARD, RTL, TAKEOFF
from bridge.autopilot.params import ParamRefused, VehicleParams, change_param, read_param
from bridge.autopilot.positionloss import (
    NOAID_TIMEOUT_US,
    PROBATION_S,
    PositionWatch,
    Resume,
    ekf_valid,
    fallback,
    taken_without_position,
)
from bridge.core.flight import prepare
from bridge.mavlink.telemetry import Home
from bridge.nodes.vehicle.streams import VehicleView, estimator_streams, health_of, message
from missions.mission import Mission
from missions.references import Setpoint, Step

GNSS_EKF = {"sensors": {"set": "gnss"}, "estimator": "ekf"}


def test_ekf_calls_the_position_invalid_once_unaided_for_longer_than_the_timeout() -> None:
    """EKF2_NOAID_TOUT (us): valid while the last aiding is at most that old (PX4's isTimedOut: strictly longer)."""
    assert NOAID_TIMEOUT_US == 5_000_000
    assert ekf_valid(15.0, 10.0, 5_000_000) and ekf_valid(9.12, 4.12, 5_000_000)  # (9.12 - 4.12 > 5 in floats)
    assert not ekf_valid(15.001, 10.0, 5_000_000)
    assert ekf_valid(10.5, 10.0, 500_000) and not ekf_valid(10.6, 10.0, 500_000)
    assert ekf_valid(1e9, math.inf, 500_000)  # truth's: never unaided


def test_the_commander_loses_the_position_at_once_and_finds_it_after_its_probation() -> None:
    """Invalid the first time EKF2 says so (the event says for how long nothing was fused); valid again only once
    EKF2 has said valid for over 1 s, and a relapse restarts that second."""
    w = PositionWatch()
    assert w.update(14.9, 10.0, 5_000_000) is None and w.valid and w.ekf_valid
    said = w.update(15.1, 10.0, 5_000_000)
    assert not w.valid and not w.ekf_valid
    assert said == "horizontal position estimate invalid: no position fix fused for 5.100 s (EKF2_NOAID_TOUT = 5 s)"
    assert w.update(20.116, 10.0, 5_000_000) is None  # said once
    assert w.update(20.12, 20.12, 5_000_000) is None and w.ekf_valid and not w.valid  # fused again: probation
    assert w.update(20.5, 15.4, 5_000_000) is None and not w.ekf_valid  # a relapse (EKF2 invalid at 20.5 s) ...
    assert w.update(21.2, 21.2, 5_000_000) is None and not w.valid  # ... restarts the second
    assert w.update(21.504, 21.4, 5_000_000) == "horizontal position estimate valid again (fused again for 1 s)"
    assert w.valid and PROBATION_S == 1.0


def test_each_mode_falls_back_to_descend_and_says_what_flies_again() -> None:
    """PX4's fallback: OFFBOARD flies its offboard-loss action, Descend unless it disarms (the offboard loss never
    resumes here); a ground station's mode descends and flies again once valid; a failsafe flying a position
    (hold, land, return) descends and resumes its action; a descent, a vehicle landed or stopped: nothing."""
    X = (1.0, 0.0, 2.0, 0.0, 3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    assert fallback(OFFBOARD, None, "hold") == ("descend", None)
    assert fallback(OFFBOARD, None, "disarm") == ("disarm", None)
    for mode, target in ((HOLD, PositionHold.here(X)), (LAND, Land.here(X, 0.7)), (TAKEOFF, Takeoff.here(X, 5.0)),
                         (RTL, ReturnHome(0.0, 0.0, 60.0, 30.0, 0.7))):
        assert fallback(mode, target, "descend") == ("descend", Resume(mode))
    assert fallback(FAILSAFE, PositionHold.here(X), "hold") == ("descend", Resume(FAILSAFE, "hold"))
    assert fallback(FAILSAFE, Land.here(X, 0.7), "land") == ("descend", Resume(FAILSAFE, "land"))
    assert fallback(FAILSAFE, ReturnHome(0.0, 0.0, 60.0, 30.0, 0.7), "x") == ("descend", Resume(FAILSAFE, "return"))
    assert fallback(FAILSAFE, Level(0.7), "descend") is None
    assert fallback(FAILSAFE, None, "disarm") is None and fallback(LANDED, None, "descend") is None


def test_ekf2_noaid_tout_is_px4s_int32_in_microseconds() -> None:
    """PX4's name, type, unit, range (0.5 to 10 s) and default (5 s); out of range refused, naming it."""
    p = change_param(VehicleParams(), "EKF2_NOAID_TOUT", 2_000_000)
    assert p.noaid_timeout_us == 2_000_000 and read_param(p, "EKF2_NOAID_TOUT") == 2e6
    assert read_param(VehicleParams(), "EKF2_NOAID_TOUT") == 5e6
    for bad, why in ((400_000, "must be in [500000, 10000000] us, got 400000"), (2.5e6 + 0.5, "an INT32")):
        with pytest.raises(ParamRefused, match=f"^EKF2_NOAID_TOUT: {re.escape(why)}"):
            change_param(VehicleParams(), "EKF2_NOAID_TOUT", bad)


def _events(summary: dict, kinds: tuple[str, ...]) -> list[tuple[float, str, str]]:
    return [(e["t"], e["kind"], e["text"]) for e in summary["events"] if e["kind"] in kinds]


def test_a_gps_back_before_the_timeout_is_no_failsafe() -> None:
    """The sine, GPS off from 10 s to 14 s (under EKF2_NOAID_TOUT): the estimate drifts, the flight completes, no
    position event, no failsafe."""
    s = simulate("missions/sine.toml", at=("10:gps:off", "14:gps:on"), **GNSS_EKF).summary
    assert s["outcome"] == "completed" and not _events(s, ("position", "failsafe"))
    (o,) = s["gps_outages"]
    assert 0.05 < o["drift_max_m"] < 2.0


def test_a_gps_that_stays_off_is_px4s_descend_at_the_timeout() -> None:
    """GPS off at 10 s: the last fix (valid 10.0 s) fused on arrival at 10.12 s, the position invalid 5 s later, at
    the control step after 15.12 s; the vehicle levels and descends at MPC_LAND_SPEED, disarms 2 s (COM_DISARM_LAND)
    after its touchdown, and the flight ends ``failsafe``, ``ended_by`` naming the position loss and the fault before
    it. EKF2_NOAID_TOUT 2 s: the same 3 s earlier."""
    s = simulate("missions/sine.toml", at=("10:gps:off",), **GNSS_EKF).summary
    got = _events(s, ("position", "failsafe", "disarmed"))
    assert [(t, k) for t, k, _ in got] == [(15.124, "position"), (15.124, "failsafe"), (19.876, "disarmed")], got
    assert got[1][2] == "position lost: level and descend" and got[2][2] == "landed: disarmed"
    assert s["outcome"] == "failsafe" and s["ended_by"] == {
        "who": "vehicle", "how": "failsafe at t=15.124 s: position lost: level and descend",
        "after_faults": ["t=10.000 s: gps off"]}
    short = simulate("missions/sine.toml", at=("10:gps:off",), params={"EKF2_NOAID_TOUT": 2_000_000}, **GNSS_EKF)
    assert [(t, k) for t, k, _ in _events(short.summary, ("failsafe",))] == [(12.124, "failsafe")]


def test_the_offboard_loss_action_disarm_stops_the_motors_when_the_position_is_lost() -> None:
    """COM_OBL_RC_ACT 7 (Disarm): PX4's offboard-loss action needs no position, so it is what flies."""
    s = simulate("missions/sine.toml", at=("10:gps:off",), failsafe={"action": "disarm"}, **GNSS_EKF).summary
    assert _events(s, ("failsafe", "disarmed"))[:2] == [(15.124, "failsafe", "position lost: stop the motors"),
                                                        (15.124, "disarmed", "position lost: motors stopped")]


def _gcs_vehicle(*at: str):
    """A vehicle on the ground with the GNSS set and the EKF, its timeline ``at``, armed by a ground station in
    TAKEOFF to 3 m (then HOLD there, PX4's)."""
    m = Mission(Step((Setpoint(0.0, 0.0, 0.0, 0.0, 0.0),)), duration_s=60.0, name="g")
    sim = prepare(m, at=at, **GNSS_EKF).make_vehicle()
    sim.set_mode(TAKEOFF, 3.0)
    sim.arm_in_mode()
    return sim


def _fly(sim, seconds: float) -> None:
    for _ in range(int(round(seconds * 250))):
        sim.advance()


def test_a_ground_stations_hold_descends_while_lost_and_holds_again_once_valid() -> None:
    """Held at 3 m, GPS off at 4 s: at the timeout the vehicle descends (PX4's Descend: LAND shown), GPS on at 10 s:
    1 s after its first fix is fused the position is valid again and HOLD flies again, where the vehicle is then
    (PX4 clears its fallback with its cause); it stays armed and holds that height."""
    sim = _gcs_vehicle("4:gps:off", "10:gps:on")
    _fly(sim, 4.0)
    assert sim.mode == HOLD and abs(sim.plant.state[4] - 3.0) < 0.15
    _fly(sim, 6.0)
    assert sim.mode == FAILSAFE and isinstance(sim.onboard.target, Level) and sim.plant.state[5] < -0.5
    _fly(sim, 3.0)
    kinds = [(round(e.t, 3), e.kind, e.text.split(":")[0]) for e in sim.events if e.t > 3.9]
    assert [k for _, k, _ in kinds] == ["fault", "position", "failsafe", "fault", "position", "mode"], kinds
    lost, fs, back, mode = kinds[1][0], kinds[2][0], kinds[4][0], kinds[5]
    # the last fix (taken at 4.0 s, the step before the fault acts) fused at 4.12 s: lost after 9.12 s; the first
    # after 10 s (taken at 10.2 s) fused at 10.32 s, EKF2 unaided last at the step before: valid again at 11.32 s
    assert lost == fs == 9.124 and back == 11.32 == mode[0] and mode[2].startswith("HOLD at x=")
    assert sim.mode == HOLD and sim.armed
    z = sim.plant.state[4]
    _fly(sim, 3.0)
    assert 0.5 < z < 2.5 and abs(sim.plant.state[4] - z) < 0.3 and sim.armed


def test_a_land_asked_while_lost_is_taken_descends_on_and_lands_once_valid() -> None:
    """PX4's commander, armed without a position (UserModeIntention::change; LAND forced since PX4 pull request
    23580): HOLD, RTL, TAKEOFF and OFFBOARD need the position and are refused, nothing changed; LAND is taken, the
    Descend flies on, and once the position is valid again (11.32 s) LAND flies, not the HOLD from before the loss,
    lands where it is, and disarms. (It was refused like the others: the vehicle held again.)"""
    sim = _gcs_vehicle("4:gps:off", "10:gps:on")
    _fly(sim, 9.5)
    assert sim.mode == FAILSAFE and sim.position.resume == Resume(HOLD)  # lost at 9.124 s, descending
    for mode in (HOLD, RTL, TAKEOFF, OFFBOARD):
        assert not taken_without_position(mode, sim.position) and sim.position.resume == Resume(HOLD)
    assert taken_without_position(LAND, sim.position) and sim.position.resume == Resume(LAND)
    assert sim.mode == FAILSAFE and isinstance(sim.onboard.target, Level)  # the descent flies on
    _fly(sim, 2.0)
    (back,) = [e for e in sim.events if e.kind == "mode" and e.t > 9.5]
    assert round(back.t, 3) == 11.32 and back.mode == LAND and back.text.startswith("LAND at x=")
    assert sim.mode == LAND and isinstance(sim.onboard.target, Land) and sim.armed
    xy = (sim.plant.state[0], sim.plant.state[2])
    _fly(sim, 6.0)
    assert not sim.armed and [e.text for e in sim.events if e.kind == "disarmed"] == ["landed: disarmed"]
    assert math.dist(xy, (sim.plant.state[0], sim.plant.state[2])) < 0.3  # landed where LAND began


def _sent(mid: int, view: VehicleView) -> list:
    """Message ``mid`` of ``view`` through MAVLink 2 bytes (pymavlink's encoder and parser)."""
    mav = M.MAVLink(None, srcSystem=1, srcComponent=1)
    return [mav.parse_char(m.pack(mav)) for m in message(mid, view)]


def test_estimator_status_and_the_global_position_say_what_ekf2_says() -> None:
    """ESTIMATOR_STATUS (PX4 v1.15's solution flags) of the held vehicle above: before the fault every position flag
    set; GPS off, the predicted position flags clear a second after the last fix fused (aiding stopped), the
    position flags at the timeout, with GLOBAL_POSITION_INT (PX4 v1.14 publishes no global position then); the
    accuracy (m) grows meanwhile; once a fix is fused again, all back at once (EKF2's view), the failsafe's view a
    second later. Under truth: no ESTIMATOR_STATUS."""
    sim = _gcs_vehicle("4:gps:off", "10:gps:on")
    E = M.ESTIMATOR_ATTITUDE | M.ESTIMATOR_VELOCITY_VERT | M.ESTIMATOR_POS_VERT_ABS
    POS = M.ESTIMATOR_VELOCITY_HORIZ | M.ESTIMATOR_POS_HORIZ_REL | M.ESTIMATOR_POS_HORIZ_ABS
    PRED = M.ESTIMATOR_PRED_POS_HORIZ_REL | M.ESTIMATOR_PRED_POS_HORIZ_ABS
    seen = []
    for until in (4.0, 5.5, 9.5, 10.5, 11.5):
        _fly(sim, until - sim.t)
        view = VehicleView(sim.plant.state, sim.t, sim.mode, sim.onboard.target, sim.armed, False, False, (0.0,) * 4,
                           1000.0, 0, sim.sensors, Home(), 1, position_valid=sim.position.ekf_valid,
                           health=lambda: health_of(sim))
        (status,) = _sent(M.MAVLINK_MSG_ID_ESTIMATOR_STATUS, view)
        seen.append((status.flags, len(_sent(M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, view)), sim.position.valid,
                     status.pos_horiz_accuracy))
        assert status.time_usec == round(sim.t * 1e6) and math.isnan(status.pos_horiz_ratio)
    # EKF2's view at once, the commander's (the failsafe's) after its probation: valid again at 11.32 s
    assert [s[:3] for s in seen] == [(E | POS | PRED, 1, True), (E | POS, 1, True), (E, 0, False),
                                     (E | POS | PRED, 1, False), (E | POS | PRED, 1, True)]
    assert seen[0][3] < 1.0 < seen[2][3]  # the horizontal 1-sigma (m): metre-class fixes, then dead reckoning
    truth = VehicleView(sim.plant.state, 1.0, HOLD, None, True, False, False, (0.0,) * 4, 1000.0, 0, None, Home(), 1)
    assert _sent(M.MAVLINK_MSG_ID_ESTIMATOR_STATUS, truth) == [] and estimator_streams(None) == {}
    assert estimator_streams(sim.sensors) == {M.MAVLINK_MSG_ID_ESTIMATOR_STATUS: 2.0}  # PX4's 0.5 Hz

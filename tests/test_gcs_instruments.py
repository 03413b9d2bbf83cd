"""Covers bridge.mavlink.telemetry and bridge.nodes.vehicle.streams: what a ground station's instruments read.

Built from the vehicle's view and sent through real MAVLink 2 bytes. VFR_HUD: the ground speed is the horizontal
speed, the heading the compass heading of the paper frame's yaw (NWU, counter-clockwise) in NED, the climb rate up,
the altitude AMSL as GLOBAL_POSITION_INT's, the throttle the rotors' thrust as a percentage of their full thrust (0
disarmed), the airspeed 0 as PX4 sends it for a multicopter with no airspeed sensor. ALTITUDE: the heights, the home
the local origin. SYS_STATUS: the pre-arm bit healthy while PX4's pre-arm checks pass. The same numbers reach
MAVSDK's ``fixedwing_metrics``, ``altitude`` and ``health`` from real vehicles in tests/test_ground_stations.py
and tests/test_await_mission.py.
"""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as M

from bridge.autopilot.failsafe import Land, Level, PositionHold, ReturnHome, Takeoff
from bridge.autopilot.modes import TERMINATION
from bridge.core.flight import prepare
from bridge.mavlink import telemetry as tm
from bridge.nodes.vehicle.streams import (
    ALTITUDE_S,
    DEFAULT_STREAMS,
    HOME_POSITION_S,
    VFR_HUD_S,
    VehicleView,
    landed_state,
    message,
)
from missions import Mission, Sine
from missions.geofence import Geofence, Zone

HOME = tm.Home(47.0, 8.0, 500.0)


def _view(X: tuple[float, ...], armed: bool = True, omega: tuple[float, ...] = (500.0,) * 4,
          armable: bool = True, target: object = None, on_ground: bool = False, mode: str = "offboard") -> VehicleView:
    refusal = None if armable else "arming denied: outside its fence"
    return VehicleView(X, 1.0, mode, target, armed, False, on_ground, omega, 1000.0, 0, None, HOME, 1,
                       prearm_refusal=lambda: refusal)


def _sent(mid: int, view: VehicleView):
    (msg,) = message(mid, view)
    mav = M.MAVLink(None, srcSystem=1, srcComponent=1)
    return mav.parse_char(msg.pack(mav))


def _hud(view: VehicleView):
    return _sent(M.MAVLINK_MSG_ID_VFR_HUD, view)


@pytest.mark.parametrize(("psi", "heading"), [(0.0, 0), (math.pi / 2, 270), (-math.pi / 2, 90), (3.0, 188)])
def test_heading_is_the_compass_heading_of_the_papers_yaw(psi: float, heading: int) -> None:
    """ψ counter-clockwise from north (NWU): ψ = π/2 faces west, 270° on a compass."""
    X = (0.0,) * 10 + (psi, 0.0)
    assert _hud(_view(X)).heading == heading


def test_speeds_altitude_and_throttle() -> None:
    # x north 3 m/s, y (west) 4 m/s, z up 1.5 m/s, 12 m above home
    X = (1.0, 3.0, 2.0, 4.0, 12.0, 1.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    hud = _hud(_view(X, omega=(500.0, 600.0, 700.0, 800.0)))
    assert hud.groundspeed == pytest.approx(5.0) and hud.climb == pytest.approx(1.5)
    assert hud.alt == pytest.approx(512.0) and hud.airspeed == 0.0
    assert hud.throttle == round(100 * (500**2 + 600**2 + 700**2 + 800**2) / (4 * 1000.0**2))  # 44 %
    assert _hud(_view(X, armed=False)).throttle == 0
    assert _hud(_view(X, omega=(2000.0,) * 4)).throttle == 100  # never past full


def test_altitude_gives_the_heights_above_the_sea_and_the_home() -> None:
    X = (1.0, 0.0, 2.0, 0.0, 12.5, -0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    alt = _sent(M.MAVLINK_MSG_ID_ALTITUDE, _view(X))
    assert alt.altitude_amsl == alt.altitude_monotonic == pytest.approx(512.5) and alt.time_usec == 1_000_000
    assert alt.altitude_local == alt.altitude_relative == pytest.approx(12.5)
    assert math.isnan(alt.altitude_terrain) and math.isnan(alt.bottom_clearance)  # no distance sensor


def test_each_is_a_default_stream_at_px4s_rate_and_silent_for_a_state_not_finite() -> None:
    assert DEFAULT_STREAMS[M.MAVLINK_MSG_ID_VFR_HUD] == VFR_HUD_S == 0.25  # 4 Hz
    assert DEFAULT_STREAMS[M.MAVLINK_MSG_ID_ALTITUDE] == ALTITUDE_S == 1.0
    assert DEFAULT_STREAMS[M.MAVLINK_MSG_ID_HOME_POSITION] == HOME_POSITION_S == 2.0  # 0.5 Hz
    X = (math.nan,) + (0.0,) * 11
    assert message(M.MAVLINK_MSG_ID_VFR_HUD, _view(X)) == message(M.MAVLINK_MSG_ID_ALTITUDE, _view(X)) == []


def test_sys_status_says_whether_the_pre_arm_checks_pass() -> None:
    bit = M.MAV_SYS_STATUS_PREARM_CHECK
    ok, refused = (_sent(M.MAVLINK_MSG_ID_SYS_STATUS, _view((0.0,) * 12, armable=a)) for a in (True, False))
    assert ok.onboard_control_sensors_present & ok.onboard_control_sensors_enabled & bit
    assert ok.onboard_control_sensors_health & bit and not refused.onboard_control_sensors_health & bit
    assert refused.onboard_control_sensors_health & M.MAV_SYS_STATUS_SENSOR_3D_GYRO  # the rest stays healthy


def test_the_pre_arm_checks_can_be_asked_without_an_event() -> None:
    """``prearm_refusal`` (what SYS_STATUS's bit reads, ten times a second) says why and records nothing;
    ``arming_denied`` (an arm) records the ``preflight`` event."""
    square = Zone(True, points=((2.0, 2.0), (4.0, 2.0), (4.0, 4.0), (2.0, 4.0)))
    fenced = Mission(Sine(), duration_s=5.0, name="fenced", geofence=Geofence((square,)))
    sim = prepare(fenced, params={"GF_ACTION": 2}).make_vehicle()
    assert "outside its fence" in sim.prearm_refusal() and sim.events == []
    assert sim.arming_denied() and [e.kind for e in sim.events] == ["preflight"]
    assert prepare(fenced, params={"GF_ACTION": 0}).make_vehicle().prearm_refusal() is None


def test_the_landed_state_says_taking_off_and_landing_as_px4s() -> None:
    """EXTENDED_SYS_STATE: on the ground; TAKEOFF while the vehicle's own controller climbs to a takeoff's height;
    LANDING while it lands (LAND, the failsafe's land or descend, Return's last phase over home); IN_AIR under
    offboard control, in a hold, and on Return's way home (PX4 says LANDING only for a landing setpoint)."""
    X = (0.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)  # 2 m up over home
    home_return = ReturnHome(0.0, 0.0, 10.0, 5.0, 0.7)
    cases = [(None, False, M.MAV_LANDED_STATE_IN_AIR), (None, True, M.MAV_LANDED_STATE_ON_GROUND),
             (Land(0.0, 0.0, 0.7), False, M.MAV_LANDED_STATE_LANDING),
             (Level(0.5), False, M.MAV_LANDED_STATE_LANDING),
             (PositionHold(0.0, 0.0, 2.0), False, M.MAV_LANDED_STATE_IN_AIR),
             (home_return, False, M.MAV_LANDED_STATE_LANDING),  # over home, below its descent height: landing
             (ReturnHome(20.0, 0.0, 10.0, 5.0, 0.7), False, M.MAV_LANDED_STATE_IN_AIR),  # 20 m from home: climbing
             (Land(0.0, 0.0, 0.7), True, M.MAV_LANDED_STATE_ON_GROUND)]
    for target, ground, want in cases:
        view = _view(X, target=target, on_ground=ground, mode="failsafe" if target else "offboard")
        assert landed_state(view) == want, (target, ground)
        assert _sent(M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE, view).landed_state == want
    climbing, held = (_view(X, target=Takeoff(0.0, 0.0, 3.0), mode=m) for m in ("takeoff", "hold"))
    assert landed_state(climbing) == M.MAV_LANDED_STATE_TAKEOFF
    assert landed_state(held) == M.MAV_LANDED_STATE_IN_AIR  # at its height, holding there


def test_a_vehicle_disarmed_in_the_air_is_landed_as_px4s_land_detector_says_but_a_terminated_one() -> None:
    """PX4's multicopter land detector calls a vehicle not armed landed, wherever it is (``_get_landed_state``: "When
    not armed, consider to be landed"): EXTENDED_SYS_STATE ON_GROUND for a vehicle disarmed 2 m up (a forced disarm,
    the ``disarm`` failsafe, a flight its plant ended: found on a MAVSDK tour, an x500 whose motor 1 the Failure
    plugin turned off said IN_AIR, disarmed, until the vehicle was stopped). A terminated flight, which PX4 keeps
    armed with its outputs off (here shown disarmed), is in the air as it falls. Fails on the code before (IN_AIR)."""
    X = (0.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)  # 2 m up
    for target, mode in ((None, "offboard"), (Level(0.5), "failsafe"), (PositionHold(0.0, 0.0, 2.0), "hold")):
        view = _view(X, armed=False, omega=(0.0,) * 4, target=target, mode=mode)
        assert landed_state(view) == M.MAV_LANDED_STATE_ON_GROUND, mode
        assert _sent(M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE, view).landed_state == M.MAV_LANDED_STATE_ON_GROUND
    falling = _view(X, armed=False, omega=(0.0,) * 4, mode=TERMINATION)
    assert landed_state(falling) == M.MAV_LANDED_STATE_IN_AIR

"""Covers bridge.mavlink.telemetry and bridge.nodes.vehicle.streams: VFR_HUD, the ground station's HUD numbers.

Built from the vehicle's view and sent through real MAVLink 2 bytes: the ground speed is the horizontal speed, the
heading the compass heading of the paper frame's yaw (NWU, counter-clockwise) in NED, the climb rate up, the
altitude AMSL as GLOBAL_POSITION_INT's, the throttle the rotors' thrust as a percentage of their full thrust (0
disarmed), the airspeed 0 as PX4 sends it for a multicopter with no airspeed sensor. The same numbers reach
MAVSDK's ``fixedwing_metrics`` from a flying vehicle in tests/test_ground_stations.py.
"""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as M

from bridge.mavlink import telemetry as tm
from bridge.nodes.vehicle.streams import DEFAULT_STREAMS, VFR_HUD_S, VehicleView, message

HOME = tm.Home(47.0, 8.0, 500.0)


def _view(X: tuple[float, ...], armed: bool = True, omega: tuple[float, ...] = (500.0,) * 4) -> VehicleView:
    return VehicleView(X, 1.0, "offboard", None, armed, False, False, omega, 1000.0, 0, None, HOME, 1)


def _hud(view: VehicleView):
    (msg,) = message(M.MAVLINK_MSG_ID_VFR_HUD, view)
    mav = M.MAVLink(None, srcSystem=1, srcComponent=1)
    return mav.parse_char(msg.pack(mav))


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


def test_it_is_a_default_stream_at_px4s_rate_and_silent_for_a_state_not_finite() -> None:
    assert DEFAULT_STREAMS[M.MAVLINK_MSG_ID_VFR_HUD] == VFR_HUD_S == 0.25  # 4 Hz
    X = (math.nan,) + (0.0,) * 11
    assert message(M.MAVLINK_MSG_ID_VFR_HUD, _view(X)) == []

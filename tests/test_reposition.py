"""Covers bridge.nodes.vehicle.reposition: MAV_CMD_DO_REPOSITION (MAVSDK's ``goto_location``, QGroundControl's
"Go to location") as the point and heading HOLD flies to, or PX4's answer refusing it (docs/ground-station.md).
The commander's part and MAVSDK's own call fly in tests/test_ground_stations.py."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as M

from bridge.nodes.vehicle.reposition import FARTHEST_M, LOWEST_M, UNSET_INT, reposition
from missions.geodetic import Home

HOME = Home()  # PX4 SITL's (Zurich, 488 m AMSL)
X = (1.0, 0.0, -2.0, 0.0, 3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.4, 0.0)  # hovering 3 m up at x = 1, y = -2 m
CHANGE_MODE = M.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE


def _global(north: float, east: float) -> tuple[float, float]:
    """Latitude and longitude (deg) of the point ``north``, ``east`` m from home (the inverse of the vehicle's
    projection, found by Newton's method on it: the test does not trust a second formula)."""
    geo = HOME
    lat, lon = HOME.lat, HOME.lon
    for _ in range(6):
        n, e, _ = geo.ned(lat, lon, HOME.alt)
        lat += math.degrees((north - n) / 6_371_000.0)
        lon += math.degrees((east - e) / (6_371_000.0 * math.cos(math.radians(lat))))
    return lat, lon


def _int(frame: int, north: float, east: float, z: float, flags: float = CHANGE_MODE,
         yaw: float = math.nan) -> M.MAVLink_command_int_message:
    lat, lon = _global(north, east)
    return M.MAVLink_command_int_message(1, 1, frame, M.MAV_CMD_DO_REPOSITION, 0, 0, -1.0, flags, 0.0, yaw,
                                         round(lat * 1e7), round(lon * 1e7), z)


def _long(lat: float, lon: float, alt: float, flags: float = CHANGE_MODE,
          yaw: float = math.nan) -> M.MAVLink_command_long_message:
    return M.MAVLink_command_long_message(1, 1, M.MAV_CMD_DO_REPOSITION, 0, -1.0, flags, 0.0, yaw, lat, lon, alt)


@pytest.mark.parametrize("frame, z", [(M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 4.0),
                                      (M.MAV_FRAME_GLOBAL_RELATIVE_ALT, 4.0),
                                      (M.MAV_FRAME_GLOBAL_INT, HOME.alt + 4.0),
                                      (M.MAV_FRAME_GLOBAL, HOME.alt + 4.0)])
def test_a_global_point_is_the_paper_frames_point_about_home(frame: int, z: float) -> None:
    """10 m north and 5 m east, 4 m above home (AMSL, or above home by the frame): x = 10, y = -5 (west is
    +y), z = 4 m, to degE7's resolution (1.1 cm)."""
    got = reposition(_int(frame, 10.0, 5.0, z), HOME, X)
    assert got.result == M.MAV_RESULT_ACCEPTED and got.why is None and got.psi is None
    x, y, zz = got.to
    assert abs(x - 10.0) < 0.011 and abs(y + 5.0) < 0.011 and abs(zz - 4.0) < 1e-9, got


def test_command_long_takes_degrees_and_metres_amsl_in_float32() -> None:
    """COMMAND_LONG's param5/6 are float32 degrees (0.4 m here): the point within half a metre."""
    lat, lon = _global(-20.0, 7.0)
    m = M.MAVLink_command_long_message(1, 1, M.MAV_CMD_DO_REPOSITION, 0, -1.0, CHANGE_MODE, 0.0, math.nan,
                                       lat, lon, HOME.alt + 6.0)
    raw = m.pack(M.MAVLink(None, srcSystem=255, srcComponent=190))
    sent = M.MAVLink(None).decode(bytearray(raw))  # as the vehicle receives it: float32
    got = reposition(sent, HOME, X)
    x, y, z = got.to
    assert abs(x + 20.0) < 0.5 and abs(y + 7.0) < 0.5 and abs(z - 6.0) < 1e-3, got


def test_what_is_not_given_stays_as_it_is() -> None:
    """NaN latitude/longitude (COMMAND_LONG) or INT32_MAX x/y (COMMAND_INT) keep the position now, a NaN
    altitude the height now, a NaN heading the heading (None: HOLD only damps the yaw rate)."""
    keep = reposition(_long(math.nan, math.nan, math.nan), HOME, X)
    assert keep.to == (1.0, -2.0, 3.0) and keep.psi is None
    m = M.MAVLink_command_int_message(1, 1, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, M.MAV_CMD_DO_REPOSITION, 0, 0,
                                      -1.0, CHANGE_MODE, 0.0, math.nan, UNSET_INT, UNSET_INT, 7.0)
    up = reposition(m, HOME, X)
    assert up.to == (1.0, -2.0, 7.0)


def test_the_heading_is_px4s_radians_clockwise_from_north() -> None:
    """param4 = π/2 (east, as PX4 and MAVSDK send it) is ψ = −π/2 in the paper frame (counter-clockwise, y west)."""
    got = reposition(_int(M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 0.0, 0.0, 3.0, yaw=math.pi / 2), HOME, X)
    assert got.psi is not None and abs(got.psi + math.pi / 2) < 1e-6


@pytest.mark.parametrize("m, result, words", [
    (_long(math.nan, math.nan, math.nan, flags=0.0), M.MAV_RESULT_UNSUPPORTED, "param2 (flags) must be 1"),
    (_long(math.nan, math.nan, math.nan, flags=3.0), M.MAV_RESULT_UNSUPPORTED, "got 3"),
    (_long(math.nan, math.nan, math.nan, flags=math.nan), M.MAV_RESULT_UNSUPPORTED, "got nan"),
    (M.MAVLink_command_int_message(1, 1, M.MAV_FRAME_LOCAL_NED, M.MAV_CMD_DO_REPOSITION, 0, 0, -1.0, CHANGE_MODE,
                                   0, math.nan, 0, 0, 3.0), M.MAV_RESULT_UNSUPPORTED, "frame 1"),
    (_long(math.nan, math.nan, HOME.alt + 0.2), M.MAV_RESULT_DENIED, f"must be at least {LOWEST_M:g} m"),
    (_int(M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 80.0, 60.0, 5.0), M.MAV_RESULT_DENIED,
     f"must be within {FARTHEST_M:g} m"),
    (_long(95.0, 8.5, HOME.alt + 3.0), M.MAV_RESULT_DENIED, "not a place on earth"),
    (_long(math.inf, 8.5, HOME.alt + 3.0), M.MAV_RESULT_DENIED, "infinite"),
    (_long(math.nan, math.nan, math.nan, yaw=-math.inf), M.MAV_RESULT_DENIED, "infinite"),
], ids=["flags-0", "flags-3", "flags-nan", "frame-local", "too-low", "too-far", "latitude-95", "latitude-inf",
        "heading-inf"])
def test_a_point_not_flown_is_refused_saying_why(m, result: int, words: str) -> None:
    got = reposition(m, HOME, X)
    assert got.result == result and got.to is None, got
    assert got.why is not None and got.why.startswith("DO_REPOSITION: ") and words in got.why, got.why


@pytest.mark.parametrize("param1, speed", [(0.5, 0.5), (-1.0, None), (0.0, None), (math.nan, None)])
def test_a_ground_speed_above_zero_is_the_speed_across(param1: float, speed: float | None) -> None:
    """param1 > 0 is PX4's ground speed for the way there (the on-board controller holds it to 2 m/s); -1, 0
    and NaN leave the controller's own."""
    m = M.MAVLink_command_int_message(1, 1, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, M.MAV_CMD_DO_REPOSITION, 0, 0,
                                      param1, CHANGE_MODE, 0.0, math.nan, UNSET_INT, UNSET_INT, 4.0)
    assert reposition(m, HOME, X).speed == speed

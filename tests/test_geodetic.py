"""Covers missions.geodetic: PX4's azimuthal equidistant projection about a home, checked against an
independent formula (great-circle distance and initial bearing on the same sphere: the projection keeps
both exactly) to 1 mm at 1 km, the paper frame's signs (x north, y west, z up), and its inverse (the telemetry's)."""

from __future__ import annotations

import math

import pytest

from missions.geodetic import EARTH_RADIUS_M, Home, project, reproject

HOMES = [(47.397742, 8.545594), (-33.86, 151.21), (0.0, 0.0), (64.1, -21.9), (-77.8, 166.7), (35.0, 179.99)]


def haversine_ne(lat0: float, lon0: float, lat: float, lon: float) -> tuple[float, float]:
    """(north, east) m by the great-circle distance (haversine) and the initial bearing: independent of
    the projection's own formula."""
    p0, p1, dl = math.radians(lat0), math.radians(lat), math.radians(lon - lon0)
    h = math.sin((p1 - p0) / 2) ** 2 + math.cos(p0) * math.cos(p1) * math.sin(dl / 2) ** 2
    d = 2.0 * EARTH_RADIUS_M * math.asin(math.sqrt(h))
    bearing = math.atan2(math.sin(dl) * math.cos(p1), math.cos(p0) * math.sin(p1) - math.sin(p0) * math.cos(p1)
                         * math.cos(dl))
    return d * math.cos(bearing), d * math.sin(bearing)


def destination(lat0: float, lon0: float, dist: float, bearing: float) -> tuple[float, float]:
    """The point ``dist`` m from (lat0, lon0) along ``bearing`` (rad from north), on the sphere."""
    p0, l0, c = math.radians(lat0), math.radians(lon0), dist / EARTH_RADIUS_M
    p = math.asin(math.sin(p0) * math.cos(c) + math.cos(p0) * math.sin(c) * math.cos(bearing))
    lon = l0 + math.atan2(math.sin(bearing) * math.sin(c) * math.cos(p0), math.cos(c) - math.sin(p0) * math.sin(p))
    return math.degrees(p), (math.degrees(lon) + 540.0) % 360.0 - 180.0


@pytest.mark.parametrize("home", HOMES)
def test_agrees_with_distance_and_bearing_to_a_millimetre_at_a_kilometre(home: tuple[float, float]) -> None:
    worst = 0.0
    for k in range(16):
        bearing = 2 * math.pi * k / 16 + 0.1
        for dist in (1.0, 100.0, 1000.0):
            lat, lon = destination(*home, dist, bearing)
            n, e = project(*home, lat, lon)
            n2, e2 = haversine_ne(*home, lat, lon)
            worst = max(worst, math.hypot(n - n2, e - e2))
            assert math.hypot(n, e) == pytest.approx(dist, abs=1e-3)  # the distance from home is kept
            if dist == 1000.0:
                assert math.atan2(e, n) == pytest.approx(math.remainder(bearing, 2 * math.pi), abs=1e-6)
    assert worst <= 1e-3


def test_the_home_itself_and_the_frames() -> None:
    home = Home(47.397742, 8.545594, 488.0)
    assert home.ned(home.lat, home.lon, home.alt) == (0.0, 0.0, 0.0)
    lat, lon = destination(home.lat, home.lon, 100.0, math.pi / 2)  # 100 m east, 10 m up
    n, e, d = home.ned(lat, lon, 498.0)
    assert n == pytest.approx(0.0, abs=1e-6) and e == pytest.approx(100.0, abs=1e-6) and d == -10.0
    x, y, z = home.paper(lat, lon, 498.0)
    assert (x, y, z) == (n, -e, 10.0)  # NWU: west is -east, up is -down
    lat, lon = destination(home.lat, home.lon, 50.0, 0.0)  # 50 m north
    assert home.paper(lat, lon, 488.0)[0] == pytest.approx(50.0, abs=1e-6)


@pytest.mark.parametrize("home", HOMES)
def test_reproject_is_the_projections_inverse_and_the_vehicles_telemetry_uses_it(home: tuple[float, float]) -> None:
    """:func:`reproject` undoes :func:`project` (to a micrometre out to 10 km; PX4's own pair, one sphere), and
    agrees with the independent destination formula; the vehicle's GLOBAL_POSITION_INT reports a state the
    plan reader maps back onto it, to degE7's resolution (it once used a flat earth of the WGS-84 radius: 11 cm
    off at 100 m)."""
    for k in range(12):
        bearing = 2 * math.pi * k / 12 + 0.2
        for dist in (0.5, 100.0, 10_000.0):
            n, e = dist * math.cos(bearing), dist * math.sin(bearing)
            lat, lon = reproject(*home, n, e)
            n2, e2 = project(*home, lat, lon)
            assert math.hypot(n2 - n, e2 - e) < 1e-6, (home, dist, bearing)
            lat3, lon3 = destination(*home, dist, bearing)
            assert abs(lat3 - lat) < 1e-9 and abs(math.remainder(lon3 - lon, 360.0)) < 1e-9
    assert reproject(*home, 0.0, 0.0) == home
    from bridge.mavlink import telemetry as tm  # (the vehicle's side: its telemetry module)

    gcs_home = tm.Home(home[0], home[1], 488.0)
    m = tm.global_position((100.0, 0.0, -50.0, 0.0, 10.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0), 0, gcs_home)
    x, y, z = Home(*home, 488.0).paper(m.lat * 1e-7, m.lon * 1e-7, m.alt * 1e-3)
    assert abs(x - 100.0) < 0.012 and abs(y + 50.0) < 0.012 and abs(z - 10.0) < 1e-3, (x, y, z)

"""Latitude, longitude and altitude to the local frames about a home, as PX4 projects them.

In:  a home (latitude, longitude in degrees, altitude AMSL in m) and a point (the same units), or a local
     offset (north, east, down in m)
Out: the point in local NED about the home (north, east, down in m) and in the paper frame
     (x north, y west, z up in m: NWU, the ground z = 0 at the home's altitude); an offset back on earth
     (:meth:`Home.global_of`, PX4's ``MapProjection::reproject``: what the vehicle's telemetry reports)

PX4 projects a global position onto its local frame with the azimuthal equidistant projection on a
sphere of radius ``CONSTANTS_RADIUS_OF_EARTH`` = 6 371 000 m about the reference point
(``MapProjection::project`` in ``src/lib/geo/geo.cpp``; formulas after Weisstein, "Azimuthal
Equidistant Projection", MathWorld). Distances and bearings from the home are kept exactly on that
sphere. PX4 stores the result in float32; we keep float64 (1 km off, float32's step is 6e-5 m).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

EARTH_RADIUS_M = 6_371_000.0  # PX4's CONSTANTS_RADIUS_OF_EARTH (src/lib/geo/geo.h)
# m: one 1e-7 degree of latitude on that sphere, the wire's step (MISSION_ITEM_INT x, y in degE7): a point on a
# bound comes back from the wire up to half of it outside, on each axis, so bounds read from the wire allow one
WIRE_STEP_M = math.radians(1e-7) * EARTH_RADIUS_M


def onto_bound(x: float, y: float, over: float, bound: float) -> tuple[float, float] | None:
    """(x, y) m as read from the wire, whose size ``over`` (its distance, or its largest coordinate) may be at most
    ``bound`` m: itself within the bound, scaled back onto it when over by no more than :data:`WIRE_STEP_M` (the
    wire's rounding of a point on the bound), None when farther out."""
    if over <= bound:
        return x, y
    return (x * bound / over, y * bound / over) if over <= bound + WIRE_STEP_M else None


@dataclass(frozen=True)
class Home:
    """The local frames' origin: latitude, longitude (deg), altitude AMSL (m); by default PX4 SITL's (Zurich)."""

    lat: float = 47.397742
    lon: float = 8.545594
    alt: float = 488.0

    def amsl(self, up: float) -> float:
        """The altitude AMSL (m) of a point ``up`` m above the home (down = -up): one sum for every stream."""
        return self.alt + up

    def ned(self, lat: float, lon: float, alt: float) -> tuple[float, float, float]:
        """(north, east, down) in m of the point (deg, deg, m AMSL), PX4's projection about the home."""
        north, east = project(self.lat, self.lon, lat, lon)
        return north, east, self.alt - alt

    def global_of(self, north: float, east: float, down: float) -> tuple[float, float, float]:
        """(lat, lon deg, alt m AMSL) of the NED offset (m) about the home: the inverse of :meth:`ned`."""
        lat, lon = reproject(self.lat, self.lon, north, east)
        return lat, lon, self.amsl(-down)

    def paper(self, lat: float, lon: float, alt: float) -> tuple[float, float, float]:
        """(x, y, z) in m of the point in the paper frame (NWU about the home, z up from its altitude)."""
        north, east, down = self.ned(lat, lon, alt)
        return north, -east, -down


def project(lat0: float, lon0: float, lat: float, lon: float) -> tuple[float, float]:
    """(north, east) in m of (lat, lon) about (lat0, lon0), all in degrees: PX4's azimuthal
    equidistant projection (``MapProjection::project``), in float64."""
    ref_lat, ref_lon = math.radians(lat0), math.radians(lon0)
    sin_ref, cos_ref = math.sin(ref_lat), math.cos(ref_lat)
    lat_rad, lon_rad = math.radians(lat), math.radians(lon)
    sin_lat, cos_lat = math.sin(lat_rad), math.cos(lat_rad)
    cos_d_lon = math.cos(lon_rad - ref_lon)
    arg = min(max(sin_ref * sin_lat + cos_ref * cos_lat * cos_d_lon, -1.0), 1.0)
    c = math.acos(arg)
    k = c / math.sin(c) if c != 0.0 else 1.0
    north = k * (cos_ref * sin_lat - sin_ref * cos_lat * cos_d_lon) * EARTH_RADIUS_M
    east = k * cos_lat * math.sin(lon_rad - ref_lon) * EARTH_RADIUS_M
    return north, east


def reproject(lat0: float, lon0: float, north: float, east: float) -> tuple[float, float]:
    """(lat, lon) in degrees of the point ``north``, ``east`` m from (lat0, lon0): the inverse of :func:`project`
    on the same sphere (PX4's ``MapProjection::reproject``; the inverse azimuthal equidistant projection)."""
    ref_lat, ref_lon = math.radians(lat0), math.radians(lon0)
    x, y = north / EARTH_RADIUS_M, east / EARTH_RADIUS_M  # the point's angular offsets (rad)
    c = math.hypot(x, y)  # its angular distance from the reference
    if c == 0.0:
        return lat0, lon0
    sin_c, cos_c = math.sin(c), math.cos(c)
    sin_ref, cos_ref = math.sin(ref_lat), math.cos(ref_lat)
    lat = math.asin(min(1.0, max(-1.0, cos_c * sin_ref + x * sin_c * cos_ref / c)))
    lon = ref_lon + math.atan2(y * sin_c, c * cos_ref * cos_c - x * sin_ref * sin_c)
    return math.degrees(lat), math.degrees(lon)


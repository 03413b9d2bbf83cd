"""A mission's rally points: where Return may land instead of the home (PX4's RTL_TYPE 0, the closest safe point).

In:  a mission's ``[rally]`` table (``points`` [[x, y], ...]: m, the paper frame, x north, y west about the home),
     or a plan's ``rallyPoints`` (``points`` [[lat, lon, alt AMSL], ...]) and its home (deg, deg, m AMSL); the
     radius (m) the points must lie within (the plant's envelope)
Out: the points (x, y) in m, in order; :func:`rally_dict` for a mission as flown

A rally point's height is not used: the ground is flat at the home's altitude, and Return lands on it there
(bridge.autopilot.failsafe.return_point picks the closest of the home and the rally points).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from missions.geodetic import Home, onto_bound
from missions.geofence import plan_object_keys
from params import ConfigError, Table, finite_float, json_show, show

MAX_RALLY = 100  # points; QGroundControl plans hold a handful
Point = tuple[float, float]


def rally_from_table(t: Table, radius_m: float) -> tuple[Point, ...]:
    """A mission's ``[rally]`` (the module's docstring), validated: each error names the key."""
    raw = t.raw("points")
    if raw is None:
        t.done()  # a misspelled key is named as such ("did you mean 'points'?")
        raise t.error("points", "is required")
    if not isinstance(raw, list) or not 1 <= len(raw) <= MAX_RALLY:
        raise t.error("points", f"expected 1 to {MAX_RALLY} points [x, y] (m), got {str(raw)[:60]}")
    points = []
    for i, p in enumerate(raw):
        xy = [finite_float(v) for v in p] if isinstance(p, (list, tuple)) and len(p) == 2 else [None]
        if None in xy or math.hypot(*xy) > radius_m:  # type: ignore[arg-type]
            raise t.error("points", f"point {i}: expected [x, y], finite, within {radius_m:g} m of the home "
                                    f"(the plant's envelope), got {show(p)}")
        points.append((xy[0], xy[1]))
    t.done()
    return tuple(points)


def rally_from_plan(raw: Any, home: Home, source: str, radius_m: float) -> tuple[Point, ...]:
    """The rally points of a plan's ``rallyPoints`` object about ``home`` (() when none; a malformed one is a
    ConfigError naming the file and the key)."""
    if raw is None:
        return ()
    if not isinstance(raw, Mapping) or not isinstance(raw.get("points", []), list):
        raise ConfigError(f"{source}: rallyPoints: expected an object with points [[lat, lon, alt], ...]")
    plan_object_keys(raw, source, "rallyPoints", ("version", "points"), ("points",))
    local = []
    for i, p in enumerate(raw.get("points", [])):
        lat, lon, alt = (finite_float(v) for v in p) if isinstance(p, list) and len(p) == 3 else (None,) * 3
        if lat is None or lon is None or alt is None:
            raise ConfigError(f"{source}: rallyPoints.points[{i}]: expected [lat, lon, alt], finite numbers, "
                              f"got {json_show(p)}")
        if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
            raise ConfigError(f"{source}: rallyPoints.points[{i}]: latitude {lat:g}, longitude {lon:g}: "
                              "not a place on earth")
        x, y, _ = home.paper(lat, lon, home.alt)
        away = math.hypot(x, y)
        kept = onto_bound(x, y, away, radius_m)  # a point on the bound comes back from the wire a little over it
        if kept is None:  # said in the plan's own terms (it was the metres it became)
            raise ConfigError(f"{source}: rallyPoints.points[{i}]: latitude {lat:g}, longitude {lon:g}: "
                              f"{away:.0f} m from the plan's home; rally points lie within {radius_m:g} m of it")
        local.append(list(kept))
    if not local:
        return ()
    return rally_from_table(Table({"points": local}, source, "rallyPoints"), radius_m)


def rally_dict(points: tuple[Point, ...]) -> dict[str, Any]:
    """``[rally]`` of a mission as flown."""
    return {"points": [list(p) for p in points]}

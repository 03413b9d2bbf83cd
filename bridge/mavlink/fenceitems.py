"""Fence and rally items on the wire (MAV_MISSION_TYPE_FENCE, MAV_MISSION_TYPE_RALLY): checked as PX4's mission
manager takes them (mavlink_mission.cpp), and read as a plan file's ``geoFence`` and ``rallyPoints`` are.

In:  a MISSION_ITEM_INT (x, y: latitude, longitude in degE7) or MISSION_ITEM (deg, float32) of a fence's or rally
     points' upload; a held fence's or rally points' items
Out: a :class:`~bridge.mavlink.missionitems.MissionItem`, or :class:`~bridge.mavlink.missionitems.ItemRefused`
     with the MAV_MISSION_RESULT PX4 answers; the items as a plan's ``geoFence`` object (:func:`fence_plan`:
     polygons and circles, for :func:`missions.geofence.geofence_from_plan`) or ``rallyPoints`` object
     (:func:`rally_plan`, for :func:`missions.rally.rally_from_plan`); a mission's own fence and rally points (paper
     frame, m) as the items a ground station downloads (:func:`fence_items`, :func:`rally_items`)

As PX4 stores them: a polygon's vertices are consecutive items, each with the polygon's vertex count in param1
(fewer than 3: ``MAV_MISSION_ERROR``, PX4's "Fence: too few vertices"); a circle is one item with its radius (m)
in param1; a rally point is a NAV_RALLY_POINT. All in a global frame (GLOBAL, GLOBAL_RELATIVE_ALT, their _INT
forms in a MISSION_ITEM_INT). Heights are not part of a fence, and a rally point's is not used (missions.rally).

Ours on top (PX4 stores whatever comes and its navigator later ignores a fence it cannot read): a command other
than the four fence zones' and NAV_FENCE_RETURN_POINT (held, not used: PX4's multicopter breach actions do not use
it either) in a fence, or than NAV_RALLY_POINT in rally points, is ``MAV_MISSION_UNSUPPORTED``; another frame
``MAV_MISSION_UNSUPPORTED_FRAME``; a position as a mission's (missionitems); a circle's radius not finite or not
positive ``MAV_MISSION_INVALID_PARAM1``; a polygon whose vertices do not come as many in a row as each says, a
``ValueError`` naming the item, which the upload answers with ``MAV_MISSION_ERROR``.
"""

from __future__ import annotations

import math
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from bridge.mavlink.missionitems import GLOBAL_FRAMES, GLOBAL_INT_FRAMES, ItemRefused, MissionItem, item_position
from missions.geodetic import Home
from missions.geofence import Geofence

_C = mavlink
POLYGONS = {_C.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION: True, _C.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION: False}
CIRCLES = {_C.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION: True, _C.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION: False}
FENCE_COMMANDS = frozenset({*POLYGONS, *CIRCLES, _C.MAV_CMD_NAV_FENCE_RETURN_POINT})
RALLY_COMMANDS = frozenset({_C.MAV_CMD_NAV_RALLY_POINT})
FENCE, RALLY = _C.MAV_MISSION_TYPE_FENCE, _C.MAV_MISSION_TYPE_RALLY


def parse_zone_item(m: Any, int_mode: bool, mission_type: int) -> MissionItem:
    """The :class:`MissionItem` of one item of a fence's (``mission_type`` FENCE) or rally points' (RALLY) upload,
    or :class:`ItemRefused` (the module's docstring)."""
    frame, command = m.frame, m.command
    if not (frame in GLOBAL_FRAMES or (int_mode and frame in GLOBAL_INT_FRAMES)):
        raise ItemRefused(_C.MAV_MISSION_UNSUPPORTED_FRAME, f"frame {frame} unsupported (a global frame only)")
    allowed, what = (FENCE_COMMANDS, "a fence") if mission_type == FENCE else (RALLY_COMMANDS, "rally points")
    if command not in allowed:
        raise ItemRefused(_C.MAV_MISSION_UNSUPPORTED, f"command {command} is not one of {what}")
    if command in POLYGONS and not (math.isfinite(m.param1) and int(m.param1 + 0.5) >= 3):
        raise ItemRefused(_C.MAV_MISSION_ERROR, f"a polygon's vertex count (param1) {m.param1:g}: too few vertices")
    if command in CIRCLES and not (math.isfinite(m.param1) and m.param1 > 0.0):
        raise ItemRefused(_C.MAV_MISSION_INVALID_PARAM1, f"a circle's radius (param1) {m.param1:g} m: not positive")
    x, y = item_position(m, int_mode)
    return MissionItem(m.seq, frame, command, m.param1, m.param2, m.param3, m.param4, x, y, m.z, m.autocontinue)


def fence_plan(items: tuple[MissionItem, ...]) -> dict[str, Any]:
    """A held fence's items as a plan's ``geoFence`` object (polygons and circles, lat/lon in deg); a polygon
    whose vertices do not come as many in a row as each says is a ValueError naming the item."""
    polygons: list[dict[str, Any]] = []
    circles: list[dict[str, Any]] = []
    i = 0
    while i < len(items):
        it = items[i]
        if it.command in CIRCLES:
            circles.append({"inclusion": CIRCLES[it.command], "circle": {"center": [it.lat_deg, it.lon_deg],
                                                                         "radius": float(it.param1)}})
        elif it.command in POLYGONS:
            n = int(it.param1 + 0.5)
            group = items[i:i + n]
            if len(group) < n or any(g.command != it.command or int(g.param1 + 0.5) != n for g in group):
                raise ValueError(f"fence item {it.seq}: a polygon of {n} vertices, but not {n} such items in a row")
            polygons.append({"inclusion": POLYGONS[it.command], "polygon": [[g.lat_deg, g.lon_deg] for g in group]})
            i += n
            continue
        i += 1  # (a return point: held, not a zone)
    return {"version": 2, "polygons": polygons, "circles": circles}


def rally_plan(items: tuple[MissionItem, ...]) -> dict[str, Any]:
    """Held rally points as a plan's ``rallyPoints`` object ([lat, lon, alt] each: deg, deg, m as sent)."""
    return {"version": 2, "points": [[it.lat_deg, it.lon_deg, float(it.z)] for it in items]}


def _global_item(seq: int, frame: int, command: int, param1: float, home: Home, x_m: float, y_m: float) -> MissionItem:
    """An item at the paper-frame point (x north, y west, m about ``home``), latitude and longitude in degE7."""
    lat, lon, _ = home.global_of(x_m, -y_m, 0.0)
    return MissionItem(seq, frame, command, float(param1), 0.0, 0.0, 0.0, round(lat * 1e7), round(lon * 1e7), 0.0, 1)


def fence_items(fence: Geofence | None, home: Home) -> tuple[MissionItem, ...]:
    """A mission's fence (paper frame, m, about ``home``) as PX4 holds a fence's items: each polygon's vertices in a
    row with its vertex count in param1, each circle one item with its radius (m) in param1; MAV_FRAME_GLOBAL, no
    height (heights are not part of a fence). :func:`fence_plan` reads them back as the same zones."""
    items: list[MissionItem] = []
    for z in fence.zones if fence is not None else ():
        if z.center is not None:
            command = next(c for c, inc in CIRCLES.items() if inc == z.inclusion)
            items.append(_global_item(len(items), _C.MAV_FRAME_GLOBAL, command, z.radius_m, home, *z.center))
            continue
        command = next(c for c, inc in POLYGONS.items() if inc == z.inclusion)
        for x, y in z.points:
            items.append(_global_item(len(items), _C.MAV_FRAME_GLOBAL, command, len(z.points), home, x, y))
    return tuple(items)


def rally_items(points: tuple[tuple[float, float], ...], home: Home) -> tuple[MissionItem, ...]:
    """A mission's rally points (paper frame, m, about ``home``) as NAV_RALLY_POINT items (frame
    GLOBAL_RELATIVE_ALT, at the home's height: a rally point's height is not used)."""
    return tuple(_global_item(i, _C.MAV_FRAME_GLOBAL_RELATIVE_ALT, _C.MAV_CMD_NAV_RALLY_POINT, 0.0, home, x, y)
                 for i, (x, y) in enumerate(points))

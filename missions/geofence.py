"""A mission's geofence: the zones a QGroundControl plan's ``geoFence`` draws, and whether a path stays in them.

In:  a mission's ``[geofence]`` table (``zones``: each ``kind`` ``polygon`` with ``points`` [[x, y], ...] or
     ``circle`` with ``center`` [x, y] and ``radius_m``, and ``inclusion`` true or false; m, the paper frame:
     x north, y west about the home), or a plan's ``geoFence`` (``polygons`` [{``inclusion``, ``polygon``
     [[lat, lon], ...]}], ``circles`` [{``inclusion``, ``circle`` {``center`` [lat, lon], ``radius`` m}}]) and
     its home (deg, deg, m AMSL); positions x, y (m, paper frame)
Out: :class:`Geofence` (its zones in the paper frame, :meth:`Geofence.to_dict` for a mission as flown);
     :meth:`Geofence.first_breach`: the first of a path's positions outside it, and why

As PX4's navigator judges a position (``Geofence::checkPolygons``): inside at least one inclusion zone, when
there is one, and outside every exclusion zone; heights are not part of a plan's fence. The fence is checked
over every run (the ``geofence`` policy, bridge.record.policies), and the vehicle holds it as PX4 does, acting on
a breach by GF_ACTION (Hold by default: bridge.autopilot.fencewatch); the run says where it left the fence.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from missions.geodetic import Home, onto_bound
from params import ConfigError, Table, finite_float, json_show, show

MAX_ZONES = 100
MAX_POINTS = 1000  # a polygon's vertices (QGroundControl draws a handful)
COORD_M = 1e5  # m: the most a zone's point or radius may be from the home (a fence is a field's, not a country's)


@dataclass(frozen=True)
class Zone:
    """One polygon (``points``, m) or circle (``center`` m, ``radius_m`` m) of a fence, inclusion or exclusion."""

    inclusion: bool
    points: tuple[tuple[float, float], ...] = ()
    center: tuple[float, float] | None = None
    radius_m: float = 0.0

    @property
    def kind(self) -> str:
        return "circle" if self.center is not None else "polygon"

    def contains(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Whether each position (x, y m) is inside (on the edge counts as inside for a circle; for a
        polygon, by the even-odd rule of a horizontal ray)."""
        if self.center is not None:
            return np.hypot(x - self.center[0], y - self.center[1]) <= self.radius_m
        inside = np.zeros(np.shape(x), dtype=bool)
        pts = self.points
        for (x1, y1), (x2, y2) in zip(pts, pts[1:] + pts[:1]):
            crosses = (y1 > y) != (y2 > y)
            with np.errstate(divide="ignore", invalid="ignore"):
                at = x1 + (y - y1) * (x2 - x1) / (y2 - y1)
            inside ^= crosses & (x < at)
        return inside

    def to_dict(self) -> dict[str, Any]:
        if self.center is not None:
            return {"kind": "circle", "inclusion": self.inclusion, "center": list(self.center),
                    "radius_m": self.radius_m}
        return {"kind": "polygon", "inclusion": self.inclusion, "points": [list(p) for p in self.points]}


@dataclass(frozen=True)
class Geofence:
    """A mission's fence: its zones (the module's docstring)."""

    zones: tuple[Zone, ...]

    def first_breach(self, t: Sequence[float], x: Sequence[float], y: Sequence[float]) -> tuple[float, str] | None:
        """The time (s) of the first position (x[i], y[i] m at t[i]) outside the fence and why, or None."""
        xs, ys = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        bad = np.zeros(xs.shape, dtype=bool)
        why = np.full(xs.shape, -1)
        inclusions = [i for i, z in enumerate(self.zones) if z.inclusion]
        if inclusions:
            inside_any = np.zeros(xs.shape, dtype=bool)
            for i in inclusions:
                inside_any |= self.zones[i].contains(xs, ys)
            bad |= ~inside_any
        for i, z in enumerate(self.zones):
            if not z.inclusion:
                hit = z.contains(xs, ys) & ~bad
                why[hit] = i
                bad |= hit
        if not bad.any():
            return None
        k = int(np.argmax(bad))
        where = f"x={xs[k]:.3f} y={ys[k]:.3f} m"
        if why[k] >= 0:
            z = self.zones[int(why[k])]
            return float(t[k]), f"at {where}, inside exclusion {z.kind} {int(why[k])} of the geofence"
        return float(t[k]), f"at {where}, outside every inclusion zone of the geofence"

    def to_dict(self) -> dict[str, Any]:
        return {"zones": [z.to_dict() for z in self.zones]}


def geofence_from_table(t: Table) -> Geofence:
    """A mission's ``[geofence]`` table (the module's docstring), validated: each error names the key."""
    raw = t.raw("zones")
    if raw is None:
        t.done()  # a misspelled key is named as such ("did you mean 'zones'?")
        raise t.error("zones", "is required")
    if not isinstance(raw, list) or not all(isinstance(z, Mapping) for z in raw):
        raise t.error("zones", "expected an array of tables (kind polygon or circle, inclusion, points or center "
                               "and radius_m)")
    if not 1 <= len(raw) <= MAX_ZONES:
        raise t.error("zones", f"expected 1 to {MAX_ZONES} zones, got {len(raw)}")
    zones = tuple(_zone(Table(z, t._source, f"{t.key('zones')}[{i}]")) for i, z in enumerate(raw))
    t.done()
    return Geofence(zones)


def _zone(z: Table) -> Zone:
    kind = z.string("kind", choices=("polygon", "circle"))
    inclusion = z.boolean("inclusion")
    if kind == "circle":
        center = z.vector("center", 2, lo=-COORD_M, hi=COORD_M)
        zone = Zone(inclusion, center=(center[0], center[1]),
                    radius_m=z.number("radius_m", lo=0.0, lo_open=True, hi=COORD_M))
    else:
        pts = z.raw("points")
        if not isinstance(pts, list) or not 3 <= len(pts) <= MAX_POINTS:
            raise z.error("points", f"expected 3 to {MAX_POINTS} points [x, y] (m), got {str(pts)[:60]}")
        zone = Zone(inclusion, points=tuple(_point(z, "points", i, p) for i, p in enumerate(pts)))
    z.done()
    return zone


def _point(z: Table, key: str, i: int, p: Any) -> tuple[float, float]:
    xy = [finite_float(v) for v in p] if isinstance(p, (list, tuple)) and len(p) == 2 else [None]
    if not all(v is not None and abs(v) <= COORD_M for v in xy):
        raise z.error(key, f"point {i}: expected [x, y], finite, within {COORD_M:g} m of the home, got {str(p)[:60]}")
    return xy[0], xy[1]  # type: ignore[return-value]


# what QGroundControl's plan loader does with a plan's object given without a version (src/MissionManager:
# GeoFenceController::load ignores it, "old version 1 or prior data", and loads the plan with no fence;
# RallyPointController::load requires the key and refuses the plan), and what to do, for the refusal
CONTROLLER = {"geoFence": "GeoFenceController", "rallyPoints": "RallyPointController"}  # whose load reads each
NO_VERSION = {
    "geoFence": ("QGroundControl's plan loader (GeoFenceController::load) takes a geoFence without a version for old "
                 "data and ignores it: the plan it loads has no fence, where this one draws zones; give "
                 "\"version\": 2 (as QGroundControl writes it) to fly them, or remove them"),
    "rallyPoints": ("QGroundControl's plan loader (RallyPointController::load) requires it and refuses the plan; give "
                    "\"version\": 2 (as QGroundControl writes it)"),
}


def plan_object_keys(raw: Mapping[str, Any], source: str, name: str, keys: tuple[str, ...],
                     required: tuple[str, ...] = ()) -> None:
    """Refuse a plan's ``name`` object (``geoFence``, ``rallyPoints``) of a ``version`` other than QGroundControl's 2,
    with a key not in ``keys``, or, of version 2, without one of ``required``: each was read as no zones or no
    points, and flown without them, where QGroundControl's loader refuses the plan (``JsonHelper::validateKeys``: a
    version 2 ``geoFence`` requires ``circles`` and ``polygons``, ``rallyPoints`` ``points``). One without a
    ``version`` is QGroundControl's to say (its plan loader, :data:`NO_VERSION`): a ``geoFence`` it ignores, so one
    holding zones is refused (with none, it is read as QGroundControl reads it: no fence); ``rallyPoints`` it refuses.
    """
    if "version" not in raw and (name != "geoFence" or any(raw.get(k) for k in ("polygons", "circles"))):
        raise ConfigError(f"{source}: {name}.version: missing: {NO_VERSION[name]}")
    v = raw.get("version", 2)
    if isinstance(v, bool) or v != 2:
        raise ConfigError(f"{source}: {name}.version: version {json_show(v)} not supported (2 is, as QGroundControl "
                          "writes it)"[:300])
    unknown = sorted(str(k) for k in raw if k not in keys)
    if unknown:
        raise ConfigError(f"{source}: {name}.{unknown[0]}: unknown key; {name} has {', '.join(keys)}"[:300])
    missing = [k for k in required if k not in raw] if "version" in raw else []
    if missing:
        raise ConfigError(f"{source}: {name}.{missing[0]}: missing: QGroundControl's plan loader "
                          f"({CONTROLLER[name]}::load) requires {' and '.join(required)} in a version 2 {name} and "
                          f"refuses the plan; give \"{missing[0]}\": [] for none")


def geofence_from_plan(raw: Any, home: Home, source: str) -> Geofence | None:
    """The fence of a plan's ``geoFence`` object about ``home`` (None: no zones; a malformed one is a
    ConfigError naming the file and the key)."""
    if raw is None:
        return None
    if not isinstance(raw, Mapping):
        raise ConfigError(f"{source}: geoFence: expected an object")
    plan_object_keys(raw, source, "geoFence", ("version", "polygons", "circles", "breachReturn"),
                     ("circles", "polygons"))
    zones: list[Zone] = []
    for key in ("polygons", "circles"):
        items = raw.get(key, [])
        if not isinstance(items, list) or not all(isinstance(z, Mapping) for z in items):
            raise ConfigError(f"{source}: geoFence.{key}: expected an array of objects")
        for i, z in enumerate(items):
            where = f"geoFence.{key}[{i}]"
            try:
                if key == "polygons":
                    if not isinstance(z["polygon"], list) or not 3 <= len(z["polygon"]) <= MAX_POINTS:
                        raise ConfigError(f"polygon: expected 3 to {MAX_POINTS} points [lat, lon], "
                                          f"got {str(z['polygon'])[:60]}")
                    pts = [_local(home, lat, lon) for lat, lon in z["polygon"]]
                    zone = {"kind": "polygon", "inclusion": z["inclusion"], "points": pts}
                else:
                    (lat, lon), radius = z["circle"]["center"], z["circle"]["radius"]
                    zone = {"kind": "circle", "inclusion": z["inclusion"], "center": _local(home, lat, lon),
                            "radius_m": radius}
            except ConfigError as exc:  # a polygon or a point refused (_local): its reason alone
                raise ConfigError.at(source, where, str(exc)) from None
            except (KeyError, TypeError, ValueError):  # the zone's shape is not the plan's
                shape = "polygon [[lat, lon], ...]" if key == "polygons" else "circle {center [lat, lon], radius}"
                raise ConfigError.at(source, where, f"expected inclusion and {shape}") from None
            zones.append(_zone(Table(zone, source, where)))
    if len(zones) > MAX_ZONES:
        raise ConfigError(f"{source}: geoFence: at most {MAX_ZONES} zones, got {len(zones)}")
    return Geofence(tuple(zones)) if zones else None


def _local(home: Home, lat: Any, lon: Any) -> list[float]:
    """[x, y] m in the paper frame of a plan's latitude and longitude (deg), checked to be a place on earth and
    within reach of the plan's home (else a ConfigError of the reason alone, which its caller names)."""
    la, lo = finite_float(lat), finite_float(lon)
    if la is None or lo is None or not (-90.0 <= la <= 90.0 and -180.0 <= lo <= 180.0):
        raise ConfigError(f"latitude {show(lat) if la is None else f'{la:g}'}, "
                          f"longitude {show(lon) if lo is None else f'{lo:g}'}: not a place on earth")
    x, y, _ = home.paper(la, lo, home.alt)
    kept = onto_bound(x, y, max(abs(x), abs(y)), COORD_M)  # a point on the bound comes back from the wire over it
    if kept is None:  # said in the plan's own terms (it was the metres it became)
        raise ConfigError(f"latitude {la:g}, longitude {lo:g}: {abs(x) / 1000.0:.3f} km "
                          f"{'north' if x >= 0 else 'south'}, {abs(y) / 1000.0:.3f} km {'west' if y >= 0 else 'east'} "
                          f"of the plan's home; a fence's points lie within {COORD_M / 1000.0:g} km of it each way")
    return list(kept)

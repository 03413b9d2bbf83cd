"""Several vehicles in one mission: ``[[vehicles]]``, ``--vehicles N --formation``, and the separation policy.

In:  a mission's ``[[vehicles]]`` tables (``id`` 1..N; ``offset`` m [dx, dy, dz] of the mission's trajectory and
     start, or a ``trajectory`` table of its own; ``start`` {position m, psi rad}; ``profile``; ``controller``),
     its ``[separation]`` table (``min_m`` m, ``rotor_radius_m`` m), or a vehicle count and a formation
     (``line:SPACING``, ``grid:SPACING``, ``circle:RADIUS``, m)
Out: validated :class:`VehicleSpec` values (system ids 1..N) and a :class:`Separation`; a bad value as a
     :class:`params.ConfigError` naming the file (or the flag), the key and its range; :func:`shifted`
     a reference moved by an offset (m), of the same kind

Pure: no sockets, no files. A vehicle with an ``offset`` flies the mission's trajectory moved by it, from the
mission's start moved by it (unless it gives its own ``start``); a vehicle with a ``trajectory`` of its own flies
that, from its ``start`` (default: the mission's). What it does not name (profile, controller) is the mission's.
A formation lays N vehicles out around the mission's trajectory: ``line`` along the paper frame's y axis,
vehicle i at (i - 1) SPACING; ``grid`` in rows of ceil(sqrt N) along y, rows SPACING apart along x;
``circle`` on a circle of RADIUS about the trajectory, vehicle i at the angle 2 pi (i - 1) / N from the x axis.

The separation policy's distance between two vehicles is the distance between their centres less each one's
disc radius: its arm (centre to rotor axis) plus its rotor radius (``rotor_radius_m``; by default half its arm,
as the profiles give no propeller size). Below ``min_m`` the policy is broken; at zero or less they touch.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from numbers import Real
from typing import Any, TypeVar

from missions.minsnap import Knot, Smooth
from missions.references import Reference, Setpoint, Sine, Step, Waypoints
from missions.trajectories import psi_of
from params import ConfigError, Table

MAX_VEHICLES = 64  # system ids 1..N; a MAVLink system id is one byte, and N plants are flown in one loop
FORMATIONS = ("line", "grid", "circle")
DEFAULT_MIN_SEPARATION_M = 0.5  # m between rotor discs (issue 28)
SEEDS = 2**31  # a mission's seeds are 0..SEEDS - 1 (missions.mission.MISSION_RANGES["seed"])
# the allowed range [lo, hi] of each number of the fleet's tables and flags: one range per key
FLEET_RANGES: dict[str, tuple[float, float]] = {
    "vehicles": (1, MAX_VEHICLES),
    "offset": (-1e3, 1e3),  # m, each axis
    "spacing_m": (0.0, 1e3),  # m, lo excluded: a formation's spacing or radius
    "min_m": (0.0, 100.0),  # m
    "rotor_radius_m": (0.0, 10.0),  # m, lo excluded
}


@dataclass(frozen=True)
class Separation:
    """The separation policy: ``min_m`` (m) between rotor discs; ``rotor_radius_m`` (m, None: half the arm)."""

    min_m: float = DEFAULT_MIN_SEPARATION_M
    rotor_radius_m: float | None = None

    def disc_radius(self, arm_m: float) -> float:
        """A vehicle's disc radius (m): its arm plus its rotor's radius."""
        return arm_m + (self.rotor_radius_m if self.rotor_radius_m is not None else arm_m / 2.0)

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"min_m": self.min_m}
        return d | ({"rotor_radius_m": self.rotor_radius_m} if self.rotor_radius_m is not None else {})


def clearance(pa: Sequence[float], pb: Sequence[float], ra: float, rb: float) -> tuple[float, float]:
    """Two vehicles' centres ``pa``, ``pb`` (m, x y z) and disc radii (m): (the centres' distance, the clearance
    between their rotor discs), m. The one test of the shared world, offline and in a SITL fleet's shared clock."""
    d = math.sqrt((pa[0] - pb[0]) ** 2 + (pa[1] - pb[1]) ** 2 + (pa[2] - pb[2]) ** 2)
    return d, d - ra - rb


def four_of(v: Any) -> tuple[Any, ...] | None:
    """A start's four values in order (a tuple, a list, a numpy array: x, y, z, psi), their numbers for the file's
    reader to judge; None for text, a mapping, or other than four."""
    try:
        got = None if isinstance(v, (str, bytes, Mapping)) else tuple(v)
    except TypeError:  # not a sequence: a number, None, a 0-d array
        return None
    return got if got is not None and len(got) == 4 else None


@dataclass(frozen=True)
class VehicleSpec:
    """One vehicle of a mission: its system id, and what of the mission it flies differently."""

    id: int
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)  # m: the mission's trajectory and start, moved
    start: tuple[float, float, float, float] | None = None  # x, y, z m, psi rad; None: the mission's (moved)
    trajectory: Reference | None = None  # its own; None: the mission's (moved by ``offset``)
    profile: str | None = None  # None: the mission's
    controller: str | None = None  # None: the mission's

    def __post_init__(self) -> None:
        four = four_of(self.start)  # an array's, numpy's numbers: a file's floats (the rest refused by check_fields)
        if four is not None and all(isinstance(x, Real) and not isinstance(x, bool) for x in four):
            object.__setattr__(self, "start", tuple(map(float, four)))

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"id": self.id}
        if any(self.offset):
            d["offset"] = list(self.offset)
        if self.start is not None:
            d["start"] = {"position": list(self.start[:3]), "psi": self.start[3]}
        if self.trajectory is not None:
            d["trajectory"] = self.trajectory.to_dict()
        for k in ("profile", "controller"):
            if getattr(self, k) is not None:
                d[k] = getattr(self, k)
        return d


def fleet_from_table(t: Table, trajectory: Callable[[Table], Reference],
                     law: Callable[[Table, str], str | None]) -> tuple[tuple[VehicleSpec, ...], Separation | None]:
    """A mission's ``[[vehicles]]`` and ``[separation]`` (read from its top-level table ``t``): the vehicles,
    or () for a mission of one vehicle; the policy, or None when the table is absent. ``trajectory`` parses
    a vehicle's own ``trajectory`` table, ``law`` a ``controller`` key (the mission's parsers)."""
    sep = None
    if t.has("separation"):
        s = t.table("separation")
        r = FLEET_RANGES
        rr = s.number("rotor_radius_m", None, lo=r["rotor_radius_m"][0], lo_open=True, hi=r["rotor_radius_m"][1]) \
            if s.has("rotor_radius_m") else None
        sep = Separation(s.number("min_m", DEFAULT_MIN_SEPARATION_M, lo=r["min_m"][0], hi=r["min_m"][1]), rr)
        s.done()
    items = t.raw("vehicles", [])
    if not isinstance(items, list) or not all(isinstance(v, Mapping) for v in items):
        raise t.error("vehicles", "expected an array of tables [[vehicles]] (id, offset or trajectory, start, "
                                  "profile, controller)")
    if len(items) > MAX_VEHICLES:
        raise t.error("vehicles", f"at most {MAX_VEHICLES} vehicles, got {len(items)}")
    if t.has("vehicles") and not items:  # (it flew one vehicle, as if the key were not there)
        raise t.error("vehicles", "an empty array: give one [[vehicles]] table per vehicle, or leave the key out "
                                  "for one vehicle")
    specs = tuple(_vehicle(Table(v, t._source, f"{t.key('vehicles')}[{i}]"), i, trajectory, law)
                  for i, v in enumerate(items))
    ids = sorted(v.id for v in specs)
    if ids != list(range(1, len(specs) + 1)):
        raise t.error("vehicles", f"the ids must be 1..{len(specs)}, each once (they are the system ids); "
                                  f"got {', '.join(map(str, ids))}")
    return tuple(sorted(specs, key=lambda v: v.id)), sep


def _vehicle(v: Table, i: int, trajectory: Callable[[Table], Reference],
             law: Callable[[Table, str], str | None]) -> VehicleSpec:
    vid = v.integer("id", i + 1, lo=1, hi=MAX_VEHICLES)
    lo, hi = FLEET_RANGES["offset"]
    own = trajectory(v.table("trajectory")) if v.has("trajectory") else None
    if own is not None and v.has("offset"):
        raise v.error("offset", "give an offset of the mission's trajectory or a trajectory of its own, not both")
    offset = v.vector("offset", 3, (0.0, 0.0, 0.0), lo=lo, hi=hi)
    start = None
    if v.has("start"):
        st = v.table("start")
        start = st.vector("position", 3, (0.0, 0.0, 0.0), lo=-1e4, hi=1e4) + (psi_of(st),)
        st.done()
    profile = v.string("profile") if v.has("profile") else None
    controller = law(v, "controller")
    v.done()
    return VehicleSpec(vid, offset, start, own, profile, controller)  # type: ignore[arg-type]


def parse_formation(text: str, flag: str = "--formation") -> tuple[str, float]:
    """``line:SPACING``, ``grid:SPACING`` or ``circle:RADIUS`` (m) -> (kind, metres); ConfigError naming ``flag``."""
    kind, sep, value = str(text).partition(":")
    lo, hi = FLEET_RANGES["spacing_m"]
    if kind not in FORMATIONS or not sep:
        raise ConfigError(f"{flag} {text}: expected line:SPACING, grid:SPACING or circle:RADIUS (metres)"[:300])
    try:
        metres = float(value)
    except ValueError:
        raise ConfigError(f"{flag} {text}: {value!r} is not a number of metres"[:300]) from None
    if not (math.isfinite(metres) and lo < metres <= hi):
        raise ConfigError(f"{flag} {text}: the {'radius' if kind == 'circle' else 'spacing'} must be in "
                          f"({lo:g}, {hi:g}] m, got {metres:g}"[:300])
    return kind, metres


def formation(n: int, text: str, flag: str = "--formation") -> tuple[VehicleSpec, ...]:
    """``n`` vehicles (system ids 1..n) laid out by ``text`` (:func:`parse_formation`) about the trajectory."""
    lo, hi = FLEET_RANGES["vehicles"]
    if isinstance(n, bool) or not isinstance(n, int) or not lo <= n <= hi:
        raise ConfigError(f"--vehicles {n}: must be a whole number in [{lo:g}, {hi:g}]"[:200])
    kind, d = parse_formation(text, flag)
    if kind == "line":
        offsets = [(0.0, i * d, 0.0) for i in range(n)]
    elif kind == "grid":
        cols = math.ceil(math.sqrt(n))
        offsets = [((i // cols) * d, (i % cols) * d, 0.0) for i in range(n)]
    else:
        offsets = [(d * math.cos(2 * math.pi * i / n), d * math.sin(2 * math.pi * i / n), 0.0) for i in range(n)]
    lo, hi = FLEET_RANGES["offset"]
    far = next(((i, a, c) for i, o in enumerate(offsets) for a, c in zip("xy", o) if not lo <= c <= hi), None)
    if far is not None:  # (named as the flag: the mission's file has no vehicles[i] to name)
        i, axis, c = far
        size = "radius" if kind == "circle" else "spacing"
        raise ConfigError(f"{flag} {text}: vehicle {i + 1} would be moved {c:g} m along {axis}, past the "
                          f"[{lo:g}, {hi:g}] m an offset may be: give a smaller {size} or fewer vehicles"[:300])
    return tuple(VehicleSpec(i + 1, tuple(round(c, 12) + 0.0 for c in o)) for i, o in enumerate(offsets))  # type: ignore[misc]


def shifted(ref: Reference, offset: tuple[float, float, float], source: str = "<python>") -> Reference:
    """``ref`` moved by ``offset`` (m), a reference of the same kind (the mission's own when the offset is zero).
    A reference written in Python, which cannot be moved here, is ConfigError: give that vehicle a trajectory."""
    dx, dy, dz = offset
    if not (dx or dy or dz):
        return ref
    if isinstance(ref, Sine):
        return replace(ref, x0=ref.x0 + dx, y0=ref.y0 + dy, z0=ref.z0 + dz)
    if isinstance(ref, (Step, Waypoints)):
        pts = ref.setpoints if isinstance(ref, Step) else ref.points
        moved = tuple(Setpoint(p.t, p.x + dx, p.y + dy, p.z + dz, p.psi) for p in pts)
        return Step(moved) if isinstance(ref, Step) else Waypoints(moved)
    if isinstance(ref, Smooth):
        knots = tuple(Knot(k.t, k.x + dx, k.y + dy, k.z + dz, k.psi, k.stop) for k in ref.knots)
        return replace(ref, knots=knots)
    raise ConfigError(f"{source}: vehicles: a {type(ref).__name__} trajectory cannot be moved by an offset: "
                      "give each vehicle a trajectory of its own"[:300])


M = TypeVar("M")


def vehicle_mission(m: M, v: VehicleSpec) -> M:
    """The mission (a :class:`missions.Mission`) vehicle ``v`` of ``m`` flies alone: its trajectory (or ``m``'s
    moved by its offset), start, profile and law; its seed ``m``'s plus its id less one, so that every vehicle
    draws its own random streams (effects, sensors, and its link's fates unless ``[link]`` names a seed)."""
    mm: Any = m
    start = v.start or tuple(a + b for a, b in zip(mm.start, (*v.offset, 0.0)))
    trajectory = v.trajectory or shifted(mm.trajectory, v.offset, mm.source)
    seed = (mm.seed + v.id - 1) % SEEDS
    return replace(mm, trajectory=trajectory, start=start, profile=v.profile or mm.profile,
                   controller=v.controller or mm.controller, seed=seed, link=link_seeds_moved(mm.link, v.id - 1),
                   vehicles=(), separation=None)


def link_seeds_moved(link: Mapping[str, Any], by: int) -> Mapping[str, Any]:
    """A ``[link]`` table whose ``seed`` keys (its own, ``[link.up]``'s, ``[link.down]``'s) are moved by ``by``:
    a vehicle's link draws its own fates even where the mission names the seed. A seed that is no integer is
    left for the link's own check to name."""
    def moved(t: Mapping[str, Any]) -> dict[str, Any]:
        d = dict(t)
        if isinstance(d.get("seed"), int) and not isinstance(d["seed"], bool):
            d["seed"] = (d["seed"] + by) % SEEDS
        return d

    if not by or not link:
        return link
    out = moved(link)
    for k in ("up", "down"):
        if isinstance(out.get(k), Mapping):
            out[k] = moved(out[k])
    return out

"""From a ground station's mission to a smooth trajectory: local waypoints, stops, yaw and times.

In:  a :class:`~missions.planfiles.PlanFile` (home deg, deg, m AMSL; items) and the speed and
     acceleration limits (:class:`Limits`, PX4's parameter names: m/s, m/s²; yaw rate deg/s)
Out: a :class:`Route`: the knots (t s; x, y, z m and psi rad in the paper frame about the home; stop or
     pass through) and the waypoints the plan names there; :func:`smooth_from_plan` its
     :class:`~missions.minsnap.Smooth` trajectory; :func:`least_duration_s`, a lower bound of its length (s)
     before it is timed. What cannot be flown is a :class:`params.ConfigError`
     naming the file, the item and its command

The vehicle starts at rest on the ground at the home. NAV_TAKEOFF climbs over where it is and stops (then flies to
its point, if it gives one other than 0, 0 or NaN, NaN);
NAV_WAYPOINT passes through (stops when it holds: param1 s); NAV_LOITER_TIME stops and holds param1 s; the
first of either from the ground is climbed to straight up first, to at least MIS_TAKEOFF_ALT (PX4's default);
NAV_LAND flies over its point (here if its latitude and longitude are 0, or both NaN), stops, and descends to the
ground; NAV_RETURN_TO_LAUNCH flies over the home at its altitude, stops and lands; nothing may follow a
landing. As PX4's feasibility check, a takeoff after an item that flies and a landing as the first item that
flies are refused, and so is any leg along the ground (both ends at 0 m). DO_CHANGE_SPEED (param1 0/1
horizontal, 2 up, 3 down; param2 m/s, -1 or -2 no change) changes the limit of the legs after it.
Yaw (param4 deg, clockwise from north; NaN or none) is as given, else
along the path: the heading of the leg (the bisector of the two at a pass-through corner).

Guide points on every horizontal leg, near its ends, keep the curve close to the legs (:func:`with_guides`).
Times: each leg first gets 2 sqrt(T) of its constant-speed time T (:func:`_first_time`); then each piece
between two stops is scaled as one, so that the polynomial's own peak speed, acceleration and yaw rate
meet the limits exactly where they bind (time scaling is exact: speed goes as 1/k, acceleration 1/k²),
times rounded up to 1 ms. Per-leg factors were tried: the legs are coupled and that iteration diverges.
The yaw rate there is the minimum-snap yaw's, by which the legs were timed when it was flown (so every position
keeps its time, to the bit); the yaw flown is monotone between knots (:mod:`missions.minsnap`), kept within
MPC_YAWRAUTO_MAX by spreading a turn too quick for its corner along the legs beside it (:func:`spread_turns`:
guide knots' yaws moved); a turn between knots that cannot move (waypoints, stops) over it slows its piece.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from missions.geodetic import Home
from missions.minsnap import Knot, Smooth, knot_arrays, yaw_rate_peaks
from missions.planfiles import (
    DO_CHANGE_SPEED,
    MAX_HOLD_S,
    NAV_LAND,
    NAV_LOITER_TIME,
    NAV_RETURN_TO_LAUNCH,
    NAV_TAKEOFF,
    RELATIVE_FRAMES,
    Item,
    PlanFile,
)
from params import ConfigError

SAME_POINT_M = 0.01  # m: closer than this, two points are one (no leg between them)
MIS_TAKEOFF_ALT_M = 2.5  # m: PX4's default; a first waypoint from the ground is climbed to straight up to at least this
MAX_SPEED_M_S = 12.0  # PX4's MPC_XY_VEL_MAX default: a faster cruise or DO_CHANGE_SPEED is refused
SAMPLING_MARGIN = 1.002  # the peaks fall between samples: 48 a leg see them to about 1e-5; this keeps them under
SAMPLES_PER_LEG = 48  # samples of each leg's speed, acceleration and yaw rate against the limits
GUIDE_SHARE = 0.2  # guide points this share of a horizontal leg from its ends (with_guides)
MAX_SPREAD_SWEEPS = 200  # spread_turns: sweeps over the segments at most (the tests' plans need at most 9)


@dataclass(frozen=True)
class Limits:
    """Speed and acceleration limits of the trajectory, PX4's multicopter parameters (defaults: PX4's)."""

    MPC_XY_CRUISE: float = 5.0  # m/s, horizontal (a plan's hoverSpeed; DO_CHANGE_SPEED 0 or 1)
    MPC_ACC_HOR: float = 3.0  # m/s²
    MPC_Z_V_AUTO_UP: float = 3.0  # m/s (DO_CHANGE_SPEED 2)
    MPC_Z_V_AUTO_DN: float = 1.5  # m/s (DO_CHANGE_SPEED 3)
    MPC_ACC_UP_MAX: float = 4.0  # m/s²
    MPC_ACC_DOWN_MAX: float = 3.0  # m/s²
    MPC_YAWRAUTO_MAX: float = 45.0  # deg/s


LIMIT_RANGES = {"MPC_XY_CRUISE": (0.1, MAX_SPEED_M_S), "MPC_ACC_HOR": (0.1, 20.0), "MPC_Z_V_AUTO_UP": (0.1, 8.0),
                "MPC_Z_V_AUTO_DN": (0.1, 4.0), "MPC_ACC_UP_MAX": (0.1, 20.0), "MPC_ACC_DOWN_MAX": (0.1, 20.0),
                "MPC_YAWRAUTO_MAX": (5.0, 360.0)}


@dataclass(frozen=True)
class Stop:
    """A point of the route before times are given: position (m), yaw (rad, NaN: along the path),
    whether the vehicle stops, how long it holds (s), the speeds of the leg that ends here (m/s) and
    the plan items it comes from (their labels, in order; none for the start). Two items at one point share
    it: a waypoint and the "land here" after it both name the waypoint's point (the land named it alone until
    the third wave's thirty-third session, so the waypoint had no point and a ground station heard it reached at
    takeoff)."""

    x: float
    y: float
    z: float
    psi: float
    stop: bool
    hold_s: float
    xy: float
    up: float
    dn: float
    items: tuple[str, ...]


@dataclass(frozen=True)
class Route:
    """The knots of a plan's trajectory; ``waypoints``: (item label, knot index, stop) of each position
    the plan names; ``lands``: it ends on the ground."""

    knots: tuple[Knot, ...]
    waypoints: tuple[tuple[str, int, bool], ...]
    lands: bool


def _metres(v: float, decimals: int) -> str:
    """A distance in a message: ``decimals`` decimals, or a few significant digits when huge (1e+300, not 301
    digits)."""
    return f"{v:.{decimals}f}" if abs(v) < 1e9 else f"{v:.4g}"


def _finite(plan: PlanFile, item: Item, *vals: float) -> None:
    if not all(math.isfinite(v) for v in vals):
        raise plan.refuse(item, "coordinates must be numbers, got "
                                 f"lat {plan.shown(item.lat)}, lon {plan.shown(item.lon)}, alt {plan.shown(item.alt)}")


def _local(plan: PlanFile, home: Home, item: Item, envelope_m: float) -> tuple[float, float, float]:
    """The item's position in the paper frame (m), checked: finite, on the earth, above the ground, inside
    the plant's envelope (``envelope_m`` from the home)."""
    _finite(plan, item, item.lat, item.lon, item.alt)
    if not (-90.0 < item.lat < 90.0 and -180.0 <= item.lon <= 180.0):
        raise plan.refuse(item, f"latitude {item.lat:g}, longitude {item.lon:g}: not on the earth")
    x, y, _ = home.paper(item.lat, item.lon, home.alt)
    z = item.alt if item.frame in RELATIVE_FRAMES else item.alt - home.alt
    if z < 0.0:
        raise plan.refuse(item, f"altitude {_metres(z, 3)} m above the home: below the ground")
    r = math.hypot(x, y, z)
    if r > envelope_m:
        raise plan.refuse(item, f"{_metres(r, 1)} m from the home, outside the plant's envelope of {envelope_m:g} m "
                                f"(plant/quadrotor.py: a vehicle farther out has diverged)")
    return x, y, z


def _yaw(plan: PlanFile, item: Item) -> float:
    """param4 (deg clockwise from north) as the paper frame's psi (rad counter-clockwise), NaN if not given."""
    if not math.isfinite(item.p4):
        return math.nan
    if abs(item.p4) > 360.0:
        raise plan.refuse(item, f"yaw (param4) {item.p4:g} deg: must be in [-360, 360]")
    return -math.radians(item.p4)


def _hold(plan: PlanFile, item: Item) -> float:
    h = 0.0 if math.isnan(item.p1) else item.p1
    if not (math.isfinite(h) and 0.0 <= h <= MAX_HOLD_S):
        raise plan.refuse(item, f"hold time (param1) {item.p1:g} s: must be in [0, {MAX_HOLD_S:g}]")
    return h


def _here(plan: PlanFile, item: Item) -> bool:
    """Whether ``item`` is a NAV_LAND or NAV_TAKEOFF whose latitude and longitude are both not given (NaN: a plan's
    null, a waypoint file's nan, a legacy MISSION_ITEM's NaN): PX4 flies it where the vehicle is, as one at 0, 0 (its
    own land-here item is one: ``MissionBlock::set_land_item``, "descend at current position"; its flight task holds
    the position of a setpoint without latitude and longitude: ``FlightTaskAuto``, "No position provided in xy. Lock
    position"). A land's altitude is not used (it descends to the ground); a takeoff's is. One of the two not given
    is refused, naming both."""
    if item.command not in (NAV_LAND, NAV_TAKEOFF) or not (math.isnan(item.lat) or math.isnan(item.lon)):
        return False
    if not (math.isnan(item.lat) and math.isnan(item.lon)):
        point, here = ("landing point", "land") if item.command == NAV_LAND else ("takeoff point", "take off")
        raise plan.refuse(item, f"latitude {plan.shown(item.lat)}, longitude {plan.shown(item.lon)}: give both (the "
                                f"{point}) or neither (both {plan.nan_word}: {here} where it is)")
    return True


def _off_the_ground(plan: PlanFile, item: Item, last: Stop, x: float, y: float, z: float) -> None:
    """Refuse a leg from ``last`` to (x, y, z) (m) that moves along the ground: a vehicle standing there cannot fly
    it (until the forty-fifth session it was planned, the vehicle stood still at its start, and the run said
    ``completed``, exit 0, its 3-D RMS error the leg's length)."""
    d = math.hypot(x - last.x, y - last.y)
    if max(last.z, z) < SAME_POINT_M and d >= SAME_POINT_M:
        raise plan.refuse(item, f"flies {d:.2f} m along the ground (from x={last.x:.2f} y={last.y:.2f} m to "
                                f"x={x:.2f} y={y:.2f} m, both at its level): a vehicle on the ground cannot; climb "
                                "first (NAV_TAKEOFF, or a waypoint above the ground)")


def stops_of(plan: PlanFile, limits: Limits, envelope_m: float) -> tuple[list[Stop], bool]:
    """The plan's points in order (the start first), and whether it lands."""
    home = Home(*plan.home)
    xy, up, dn = limits.MPC_XY_CRUISE, limits.MPC_Z_V_AUTO_UP, limits.MPC_Z_V_AUTO_DN
    pts = [Stop(0.0, 0.0, 0.0, 0.0, True, 0.0, xy, up, dn, ())]
    landed_by: Item | None = None

    def add(x: float, y: float, z: float, psi: float, stop: bool, hold: float, item: Item) -> None:
        last, label = pts[-1], item.label
        _off_the_ground(plan, item, last, x, y, z)
        if math.dist((x, y, z), (last.x, last.y, last.z)) < SAME_POINT_M:  # the same point: one stop
            pts[-1] = replace(last, psi=last.psi if math.isnan(psi) else psi, stop=last.stop or stop,
                              hold_s=last.hold_s + hold,
                              items=last.items if label in last.items else (*last.items, label))
        else:
            pts.append(Stop(x, y, z, psi, stop, hold, xy, up, dn, (label,)))

    for item in plan.items:
        if landed_by is not None:
            raise plan.refuse(item, f"after {landed_by.name} ({landed_by.label}) the flight is over")
        cmd = item.command
        if cmd == DO_CHANGE_SPEED:
            xy, up, dn = _speed(plan, item, xy, up, dn)
            continue
        here = pts[-1]
        if cmd == NAV_RETURN_TO_LAUNCH:
            add(0.0, 0.0, here.z, math.nan, True, 0.0, item)
            add(0.0, 0.0, 0.0, math.nan, True, 0.0, item)
            landed_by = item
            continue
        if cmd in (NAV_LAND, NAV_TAKEOFF) and item.lat == 0.0 and item.lon == 0.0 or _here(plan, item):
            x, y = here.x, here.y  # no position given: where it is
            if cmd == NAV_TAKEOFF and not math.isfinite(item.alt):  # (the home's latitude, longitude stand in below)
                raise plan.refuse(item, f"takeoff altitude {plan.shown(item.alt)}: not a number (latitude "
                                        f"{plan.shown(item.lat)}, longitude {plan.shown(item.lon)}: it takes off "
                                        "where it is)")
            z = 0.0 if cmd == NAV_LAND else _local(plan, home, replace(item, lat=home.lat, lon=home.lon),
                                                   envelope_m)[2]
        else:
            x, y, z = _local(plan, home, item, envelope_m)
        psi = _yaw(plan, item)
        if cmd == NAV_TAKEOFF:
            if len(pts) > 1:  # PX4's FeasibilityChecker::checkTakeoff
                raise plan.refuse(item, f"a takeoff after {pts[-1].items[-1]}, an item that flies (PX4 rejects it: "
                                        "\"Mission rejected: takeoff not first waypoint item\"); make it the first "
                                        "item that flies")
            if z <= here.z + SAME_POINT_M:
                raise plan.refuse(item, f"takeoff altitude {z:.2f} m is not above the vehicle ({here.z:.2f} m)")
            add(here.x, here.y, z, psi, True, 0.0, item)  # straight up, then to its position
            add(x, y, z, psi, True, 0.0, item)
        elif cmd == NAV_LAND:
            if len(pts) == 1:  # on the ground at its start: PX4's feasibility check refuses it too
                raise plan.refuse(item, "a landing as the first item that flies, the vehicle still on the ground "
                                        "(PX4 rejects a mission whose item 0 is one: \"Mission rejected: starts "
                                        "with landing\"); take off first (NAV_TAKEOFF)")
            add(x, y, here.z, psi, True, 0.0, item)  # over the landing point, then down
            add(x, y, 0.0, psi, True, 0.0, item)
            landed_by = item
        else:
            hold = _hold(plan, item)
            if len(pts) == 1 and z >= SAME_POINT_M:  # from the ground: PX4's Mission::do_need_vertical_takeoff
                add(here.x, here.y, max(z, MIS_TAKEOFF_ALT_M), psi, True, 0.0, item)
            add(x, y, z, psi, cmd == NAV_LOITER_TIME or hold > 0.0, hold, item)
    if len(pts) < 2:
        raise ConfigError(f"{plan.source}: mission.items: no position to fly to (no item takes the vehicle up "
                          "from where it stands: NAV_TAKEOFF, NAV_WAYPOINT, NAV_LOITER_TIME)")
    last = pts[-1]
    pts[-1] = replace(last, stop=True)
    return pts, landed_by is not None


def least_duration_s(plan: PlanFile, limits: Limits, envelope_m: float) -> float:
    """A lower bound of the time (s) the plan's trajectory lasts, before any of it is timed (a few ms for thousands
    of items): each leg straight at its speed limits (horizontal and vertical), plus the holds. The timed
    trajectory keeps every leg's speeds within those limits (:func:`route_of`) along a path no shorter than the
    leg, and fitting it to the airframe only slows it."""
    pts, _ = stops_of(plan, limits, envelope_m)
    t = sum(p.hold_s for p in pts)
    for a, b in zip(pts, pts[1:]):
        dz = b.z - a.z
        t += max(math.hypot(b.x - a.x, b.y - a.y) / b.xy, abs(dz) / (b.up if dz > 0 else b.dn))
    return t


def _speed(plan: PlanFile, item: Item, xy: float, up: float, dn: float) -> tuple[float, float, float]:
    """The speeds after DO_CHANGE_SPEED (param1 type: 0 air, 1 ground, 2 climb, 3 descent; param2 m/s)."""
    kind, v = item.p1, item.p2
    if kind not in (0.0, 1.0, 2.0, 3.0):
        raise plan.refuse(item, f"speed type (param1) {kind:g}: must be 0 airspeed, 1 ground speed, 2 climb or "
                                f"3 descent")
    if v == -1.0 or v == -2.0:  # no change; -2: back to the default (PX4: the cruise it had)
        return xy, up, dn
    sets = "MPC_XY_CRUISE" if kind < 2 else "MPC_Z_V_AUTO_UP" if kind == 2 else "MPC_Z_V_AUTO_DN"
    lo, hi = LIMIT_RANGES[sets]
    if not (math.isfinite(v) and lo <= v <= hi):  # (the ranges: docs/missions.md, "Supported and refused")
        raise plan.refuse(item, f"speed (param2) {v:g} m/s: must be in [{lo:g}, {hi:g}] (the range of {sets}, "
                                f"which param1 {kind:g} sets), or -1 or -2 (no change)")
    return (v, up, dn) if kind < 2 else ((xy, v, dn) if kind == 2 else (xy, up, v))


def _heading(a: Stop, b: Stop) -> float | None:
    """psi (rad) of the horizontal leg from a to b, None if it is vertical."""
    dx, dy = b.x - a.x, b.y - a.y
    return math.atan2(dy, dx) if math.hypot(dx, dy) >= SAME_POINT_M else None


def _near(angle: float, ref: float) -> float:
    """``angle`` plus a whole number of turns, within half a turn of ``ref``."""
    return ref + math.remainder(angle - ref, 2.0 * math.pi)


def yaws(pts: list[Stop]) -> list[float]:
    """The yaw at each point (rad, unwrapped along the route): as given, else along the path."""
    out = [pts[0].psi]
    for i in range(1, len(pts)):
        p, prev = pts[i], out[-1]
        h_in = _heading(pts[i - 1], p)
        h_out = _heading(p, pts[i + 1]) if i + 1 < len(pts) else None
        if not math.isnan(p.psi):
            target = p.psi
        elif h_in is not None and h_out is not None and not p.stop:
            a = _near(h_in, prev)
            target = 0.5 * (a + _near(h_out, a))  # the corner's bisector
        elif h_in is not None:
            target = h_in
        elif h_out is not None:
            target = h_out  # straight up or down, then away: turn to the next leg on the way
        else:
            target = prev
        out.append(_near(target, prev))
    return out


def with_guides(pts: list[Stop], psi: list[float], lim: Limits) -> tuple[list[Stop], list[float]]:
    """The points with two guide points on every horizontal leg, :data:`GUIDE_SHARE` of its length (at most
    the braking distance v²/a) from each end: without them the C⁶ curve through sharp corners swings metres
    wide of the legs; with them it turns near each corner and runs straight between (yaw: the leg's heading
    when it is along the path)."""
    out, yaw = [pts[0]], [psi[0]]
    for i in range(1, len(pts)):
        a, b = pts[i - 1], pts[i]
        length = math.hypot(b.x - a.x, b.y - a.y)
        if length >= 4.0 * SAME_POINT_M:
            g = min(GUIDE_SHARE * length, b.xy * b.xy / lim.MPC_ACC_HOR)
            h = math.atan2(b.y - a.y, b.x - a.x)
            for d in (g, length - g):
                s = d / length
                out.append(replace(b, x=a.x + s * (b.x - a.x), y=a.y + s * (b.y - a.y), z=a.z + s * (b.z - a.z),
                                   psi=math.nan, stop=False, hold_s=0.0, items=()))
                yaw.append(_near(h, yaw[-1]) if math.isnan(b.psi) else _near(b.psi, yaw[-1]))
        out.append(b)
        yaw.append(_near(psi[i], yaw[-1]))
    return out, yaw


def _first_time(a: Stop, b: Stop, lim: Limits) -> float:
    """A leg's time before scaling: 2 sqrt(T) of its time T at constant speed (plus v/a at each end it
    stops at) on its slower axis. The square root gives short legs (corners) relatively more time, which
    keeps the curve near the legs."""
    dxy, dz = math.hypot(b.x - a.x, b.y - a.y), b.z - a.z
    vz, az = (b.up, lim.MPC_ACC_UP_MAX) if dz > 0 else (b.dn, lim.MPC_ACC_DOWN_MAX)
    ramp = max(b.xy / lim.MPC_ACC_HOR if dxy > 0 else 0.0, vz / az if dz != 0 else 0.0)
    t = max(dxy / b.xy, abs(dz) / vz) + ramp * (int(a.stop) + int(b.stop))
    return 2.0 * math.sqrt(max(t, 0.01))


def _knots(pts: list[Stop], psi: list[float], legs: list[float]) -> tuple[tuple[Knot, ...], list[int]]:
    """Knots at the times the legs give (a hold adds a knot where it ends); the knot of each point."""
    knots: list[Knot] = []
    at: list[int] = []
    t = 0.0
    for i, p in enumerate(pts):
        if i:
            t += legs[i - 1]
        at.append(len(knots))
        knots.append(Knot(t, p.x, p.y, p.z, psi[i], p.stop))
        if p.hold_s > 0.0:
            t += p.hold_s
            knots.append(Knot(t, p.x, p.y, p.z, psi[i], True))
    return tuple(knots), at


def _leg_ratio(ref: Smooth, j: int, b: Stop, lim: Limits) -> float:
    """How far the trajectory's peaks on the leg from knot j to j + 1 exceed the limits: > 1 too fast, < 1 slow;
    speed ratios count as they are, accelerations as their square root (time scales both so). The yaw's: the
    minimum-snap yaw's rate, by which the legs were timed when it was flown (so the positions keep their times;
    the yaw flown is kept within the limit by :func:`spread_turns`)."""
    k0, k1 = ref.knots[j], ref.knots[j + 1]
    worst = 0.0
    yaw_max = math.radians(lim.MPC_YAWRAUTO_MAX)
    for i in range(1, SAMPLES_PER_LEG):
        t = k0.t + (k1.t - k0.t) * i / SAMPLES_PER_LEG
        x, y, z, _ = ref.sample(t)
        vz, az = z[1], z[2]
        worst = max(worst, math.hypot(x[1], y[1]) / b.xy, (vz / b.up) if vz > 0 else (-vz / b.dn),
                    abs(ref.snap_yaw_rate(t)) / yaw_max, math.sqrt(math.hypot(x[2], y[2]) / lim.MPC_ACC_HOR),
                    math.sqrt(az / lim.MPC_ACC_UP_MAX if az > 0 else -az / lim.MPC_ACC_DOWN_MAX))
    return worst


def spread_turns(knots: tuple[Knot, ...], free: list[bool], yaw_max: float) -> np.ndarray:
    """The knots' yaws (rad), those of the ``free`` ones (guide knots) moved so that the yaw flown
    (:func:`missions.minsnap.yaw_pieces`) keeps within ``yaw_max`` (rad/s) where it can: each segment over it has
    its free ends moved towards each other, by half the share of its turn its peak is over (aiming 0.2 % under;
    the whole share moves them too far, as the rates at its ends fall with it, and the turn leaves the heading
    earlier than it needs), until none is over, nothing can move, or :data:`MAX_SPREAD_SWEEPS` sweeps. A turn too
    quick for its corner so spreads along the straight legs beside it, monotone: a moved knot stays between its
    neighbours. A turn that fits leaves every knot as it is (the box's)."""
    t, psi, stop = knot_arrays(knots)
    psi = psi.copy()
    for _ in range(MAX_SPREAD_SWEEPS):
        peaks = yaw_rate_peaks(t, psi, stop)
        moved = False
        for j in np.flatnonzero(peaks > yaw_max):
            ends = [i for i in (j, j + 1) if free[i]]
            if ends:
                x = (psi[j + 1] - psi[j]) * (1.0 - yaw_max / (peaks[j] * SAMPLING_MARGIN)) / (2 * len(ends))
                if free[j]:
                    psi[j] += x
                if free[j + 1]:
                    psi[j + 1] -= x
                moved = True
        if not moved:
            break
    return psi


def _scale(legs: list[float], ratios: list[float], pts: list[Stop], over_only: bool = False) -> None:
    """Scale each piece between two stops as one, in place, so that its peak meets the limits (``ratios``: each
    leg's peak over its limit); ``over_only``: only the pieces over them."""
    first = 0
    for i in range(len(legs)):
        if pts[i + 1].stop:
            factor = max(ratios[first:i + 1]) * SAMPLING_MARGIN
            if not over_only or max(ratios[first:i + 1]) > 1.0:
                for j in range(first, i + 1):
                    legs[j] = math.ceil(legs[j] * factor * 1000.0) / 1000.0  # whole ms, up: never over the limits
            first = i + 1


def route_of(plan: PlanFile, limits: Limits, envelope_m: float) -> Route:
    """The plan's knots with their times (see the module's docstring)."""
    pts, lands = stops_of(plan, limits, envelope_m)
    pts, psi = with_guides(pts, yaws(pts), limits)
    legs = [_first_time(pts[i], pts[i + 1], limits) for i in range(len(pts) - 1)]
    knots, at = _knots(pts, psi, legs)
    ref = Smooth(knots)
    seg = [at[i] + (1 if pts[i].hold_s > 0 else 0) for i in range(len(legs))]  # each leg's segment
    _scale(legs, [_leg_ratio(ref, seg[i], pts[i + 1], limits) for i in range(len(legs))], pts)
    knots, at = _knots(pts, psi, legs)
    yaw_max = math.radians(limits.MPC_YAWRAUTO_MAX)
    free = [False] * len(knots)  # the guide knots (no item, not the start)
    for i in range(1, len(pts)):
        free[at[i]] = pts[i].items == ()
    spread = spread_turns(knots, free, yaw_max)
    psi = [float(spread[k]) for k in at]
    knots, at = _knots(pts, psi, legs)
    peaks = yaw_rate_peaks(*knot_arrays(knots))
    if peaks.max() > yaw_max:  # a turn between knots that cannot move (stops, waypoints): slowed
        _scale(legs, [float(peaks[j]) / yaw_max for j in seg], pts, over_only=True)
        knots, at = _knots(pts, psi, legs)
    waypoints = tuple((label, at[i], p.stop) for i, p in enumerate(pts) for label in p.items)
    return Route(knots, waypoints, lands)


def smooth_from_plan(plan: PlanFile, limits: Limits, envelope_m: float) -> tuple[Smooth, Route]:
    """The minimum-snap trajectory of a plan, and its route."""
    route = route_of(plan, limits, envelope_m)
    return Smooth(route.knots, route.lands), route

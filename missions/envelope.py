"""The plant's envelope: how far from the origin a mission's start and reference may go, and the ground under them.

In:  a mission's reference (:mod:`missions.references`, :class:`missions.minsnap.Smooth`), its start (x, y, z m)
     and duration (s)
Out: the key and the reason when either leaves :data:`ENVELOPE_RADIUS_M` (m from the origin)
     (:func:`envelope_problem`), or goes below the ground, the plane z = 0 the plant rests on
     (:func:`ground_problem`), or None
"""

from __future__ import annotations

import functools
import math
from typing import Any

from missions.minsnap import Smooth
from missions.references import Reference, Sine, Step, Waypoints

# The plant's envelope: plant/quadrotor.py Quadrotor.diverged() calls a vehicle farther than this from the
# origin lost, so no start or reference may leave it (envelope_problem; the loader's wider ranges catch typos).
# Missions do not import the plant: tests/test_mission.py checks that the two agree.
ENVELOPE_RADIUS_M = 100.0


def _beyond(what: str, r: float) -> str:
    return (f"{what} is {r:.4g} m from the origin, outside the plant's envelope of {ENVELOPE_RADIUS_M:g} m "
            f"(plant/quadrotor.py: a vehicle farther out has diverged)")


@functools.lru_cache(maxsize=4)
def smooth_beyond(trajectory: Smooth) -> tuple[str, str] | None:
    """:func:`envelope_problem` of a minimum-snap trajectory, which may swing past its knots: sampled, 64 a
    segment. Kept for the last few: a mission is validated again each time a field of
    it is replaced (its overrides), and its trajectory is the same one."""
    ks = trajectory.knots
    for j in range(len(ks) - 1):
        for i in range(65):
            x, y, z, _ = trajectory.sample(ks[j].t + (ks[j + 1].t - ks[j].t) * i / 64)
            r = math.sqrt(x[0] * x[0] + y[0] * y[0] + z[0] * z[0])
            if r > ENVELOPE_RADIUS_M:
                return f"trajectory.points[{j}]", _beyond(f"after this knot, at ({x[0]:.4g}, {y[0]:.4g}, "
                                                          f"{z[0]:.4g}), the trajectory", r)
    return None


def envelope_problem(trajectory: Reference, start: tuple[float, ...], duration_s: float,
                     scatter_m: float = 0.0) -> tuple[str, str] | None:
    """The key and the reason when the start (anywhere within ``scatter_m`` of it: missions.scatter) or the
    reference leaves the plant's envelope (:data:`ENVELOPE_RADIUS_M` from the origin) at some time of the
    mission, or None.

    Step set-points and waypoints are checked point by point: a minimum-jerk segment runs on the
    straight line between its two points (a convex blend), and the envelope is a ball. A sine's
    horizontal radius is its amplitude and its height is linear in t, so its farthest points are
    at t = 0 and t = ``duration_s``. Other references (written in Python) are not checked here:
    the plant's own divergence check still stops them."""
    r = math.hypot(math.hypot(*start[:2]) + scatter_m, start[2])  # the farthest point of the start's disc
    if r > ENVELOPE_RADIUS_M:
        return "start.position", _beyond("the start" + (" with its scatter" if scatter_m else ""), r)
    if isinstance(trajectory, (Step, Waypoints)):
        key, points = _given_points(trajectory)
        for i, s in enumerate(points):
            r = math.sqrt(s.x * s.x + s.y * s.y + s.z * s.z)
            if r > ENVELOPE_RADIUS_M:
                return f"{key}[{i}]", _beyond(f"({s.x:g}, {s.y:g}, {s.z:g})", r)
    elif isinstance(trajectory, Smooth):
        return smooth_beyond(trajectory)
    elif isinstance(trajectory, Sine):  # its horizontal reach: the circle's centre's distance plus its radius
        a, z0 = math.hypot(trajectory.x0, trajectory.y0) + abs(trajectory.amplitude), trajectory.z0
        z_end = z0 + trajectory.climb * duration_s
        if a > ENVELOPE_RADIUS_M:
            return "trajectory.amplitude", _beyond(f"amplitude {a:g} m: the circle", a)
        if math.hypot(a, z0) > ENVELOPE_RADIUS_M:
            return "trajectory.z0", _beyond(f"at t = 0 (amplitude {a:g} m, z0 {z0:g} m) the reference",
                                           math.hypot(a, z0))
        if math.hypot(a, z_end) > ENVELOPE_RADIUS_M:
            return "trajectory.climb", _beyond(
                f"climbing {trajectory.climb:g} m/s from z0 {z0:g} m, at t = {duration_s:g} s (z = {z_end:g} m) "
                f"the reference", math.hypot(a, z_end))
    return None


def _given_points(trajectory: Step | Waypoints | Smooth) -> tuple[str, tuple[Any, ...]]:
    """The mission key and the points the user gave a reference (set-points, waypoints, a smooth one's knots)."""
    if isinstance(trajectory, Step):
        return "trajectory.setpoints", trajectory.setpoints
    return "trajectory.points", trajectory.points if isinstance(trajectory, Waypoints) else trajectory.knots


def _below(what: str, z: float) -> str:
    return (f"{what} is at z = {z:.4g} m, below the ground (the plane z = 0 the vehicle starts on and rests on: "
            f"plant/quadrotor.py), where no vehicle can follow it")


def ground_problem(trajectory: Reference, start: tuple[float, ...], duration_s: float) -> tuple[str, str] | None:
    """The key and the reason when the start or a point the user gave the reference (a set-point, a waypoint, a
    knot; a sine's height at t = 0 and at ``duration_s``, linear in t between) is below the ground, or None.
    A minimum-snap trajectory's swing between its knots and references written in Python are not checked."""
    if start[2] < 0.0:
        return "start.position", _below("the start", start[2])
    if isinstance(trajectory, (Step, Waypoints, Smooth)):
        key, points = _given_points(trajectory)
        for i, s in enumerate(points):
            if s.z < 0.0:
                return f"{key}[{i}]", _below(f"({s.x:g}, {s.y:g}, {s.z:g})", s.z)
    elif isinstance(trajectory, Sine):
        if trajectory.z0 < 0.0:
            return "trajectory.z0", _below("the reference at t = 0", trajectory.z0)
        z_end = trajectory.z0 + trajectory.climb * duration_s
        if z_end < 0.0:
            return "trajectory.climb", _below(f"climbing {trajectory.climb:g} m/s from z0 {trajectory.z0:g} m, at "
                                              f"t = {duration_s:g} s the reference", z_end)
    return None

"""A plan's trajectory fitted to the airframe that flies it: slowed where it asks more than the airframe gives.

In:  a :class:`~missions.mission.Mission`, the airframe's mass (kg), gravity (m/s²), the thrust its law may ask
     (u1 N) and its tilt limit (rad)
Out: the mission, its :class:`~missions.minsnap.Smooth` trajectory slowed (times stretched, the mission as much
     longer) by the least factor that fits, or a ConfigError saying what it needs against what the airframe gives
"""

from __future__ import annotations

import math
from dataclasses import replace

from missions.minsnap import Smooth, accelerations, demands, stretched
from missions.mission import Mission
from missions.trajectories import MAX_STRETCH
from params import ConfigError

# the share of the airframe's thrust (the profile's u1 limit) and tilt (the law's tilt_max) a trajectory may
# need in feed-forward: the rest is the law's room to correct (fitted_to_airframe)
THRUST_SHARE = 0.8
TILT_SHARE = 0.8


def fitted_to_airframe(m: Mission, mass: float, gravity: float, u1_max: float, tilt_max: float) -> Mission:
    """``m`` as it may fly on an airframe of ``mass`` (kg) whose law may ask ``u1_max`` (N) of thrust and
    ``tilt_max`` (rad) of tilt: a :class:`Smooth` trajectory that needs more than :data:`THRUST_SHARE` of the
    one or :data:`TILT_SHARE` of the other is slowed (its times stretched, the mission as much longer) by the
    least factor that fits (to 1 %), or refused when even :data:`MAX_STRETCH` does not. Other trajectories,
    and smooth ones that fit, come back unchanged."""
    ref = m.trajectory
    if not isinstance(ref, Smooth):
        return m
    f_max, a_max = THRUST_SHARE * u1_max, TILT_SHARE * tilt_max
    samples = accelerations(ref)  # taken once: stretching only divides them by k²

    def fits(k: float) -> bool:
        d = demands(ref, mass, gravity, k, samples)
        return d.thrust_n <= f_max and d.tilt_rad <= a_max

    if fits(1.0):
        return m
    d = demands(ref, mass, gravity, 1.0, samples)
    if mass * gravity > f_max or not fits(MAX_STRETCH):
        raise ConfigError(
            f"{m.source}: trajectory: refused: it needs {d.thrust_n:.3g} N of thrust (t = {d.thrust_t:.2f} s) and "
            f"{math.degrees(d.tilt_rad):.1f} deg of tilt (t = {d.tilt_t:.2f} s); the airframe allows "
            f"{THRUST_SHARE:.0%} of u1 = {u1_max:.3g} N and {TILT_SHARE:.0%} of tilt_max = "
            f"{math.degrees(tilt_max):.1f} deg, and slowed {MAX_STRETCH:g} times it still needs more")
    k = 1.0
    while not fits(k):
        k = round(k * 1.01, 6)
    slow = stretched(ref, k)
    return replace(m, trajectory=slow, duration_s=m.duration_s + (slow.end_s - ref.end_s))

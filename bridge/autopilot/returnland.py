"""Return mode's altitude near home (PX4's cone) and the auto landing's descent speed by height, as PX4 1.14 has them.

In:  Return's parameters (:class:`ReturnConfig`: RTL_RETURN_ALT, RTL_DESCEND_ALT m, RTL_CONE_ANG deg, RTL_MIN_DIST,
     NAV_ACC_RAD m), the horizontal distance (m) from where Return begins to where it lands and the height (m above
     that point) it begins at; the landing's parameters (:class:`LandSlowdown`: MPC_Z_V_AUTO_DN m/s, MPC_LAND_ALT1,
     MPC_LAND_ALT2 m; MPC_LAND_SPEED m/s beside them) and a height above home (m)
Out: the height Return flies home at (:func:`return_height`, m above where it lands); the landing's descent speed
     at a height (:func:`land_speed`, m/s, down) and the time a landing takes from a height (:func:`land_time_s`, s)

**Return's altitude.** PX4 1.14 computes it once, when Return begins
(``RTL::calculate_return_alt_from_cone_half_angle``, src/modules/navigator/rtl.cpp; a multicopter with RTL_CONE_ANG
above 0; 0 is no cone: RTL_RETURN_ALT, or the height it has if higher). With d the horizontal distance to where
it lands and h the height above it, in metres:

- d <= NAV_ACC_RAD: 2 d (it is all but there: no higher than twice the way left);
- else RTL_RETURN_ALT, or within RTL_MIN_DIST the cone's height there if lower, d / tan(RTL_CONE_ANG) (the
  half-angle held to 1..89 deg), and at least 2 NAV_ACC_RAD (not to touch the ground on the way);
- then at least h: Return never comes down to return, it climbs only if below.

The floor 2 NAV_ACC_RAD may lie above RTL_RETURN_ALT (RTL_RETURN_ALT 3 m with NAV_ACC_RAD 2 m returns at 4 m): PX4
1.14 does that; PX4 1.15 holds the result to RTL_RETURN_ALT (PX4-Autopilot#23558, ``RTL::computeReturnAltitude``).
NAV_ACC_RAD's default here is 2 m, RTL_RETURN_ALT's 30 m and RTL_DESCEND_ALT's 10 m, the multicopter's (ROMFS
rc.mc_defaults sets them for every multicopter airframe, PX4's SITL x500 included; the parameters' own defaults, 10 m,
60 m and 30 m, are a fixed wing's); RTL_CONE_ANG 45 deg and RTL_MIN_DIST 10 m are PX4's defaults.

**The landing's speed.** PX4's auto landing (Land mode, Return's last phase, a failsafe's landing) comes down at
``math::gradual(height, MPC_LAND_ALT2, MPC_LAND_ALT1, MPC_LAND_SPEED, MPC_Z_V_AUTO_DN)``
(``FlightTaskAuto::_prepareLandSetpoints``, src/modules/flight_mode_manager/tasks/Auto): MPC_LAND_SPEED at or below
MPC_LAND_ALT2, MPC_Z_V_AUTO_DN (PX4's descent speed in the auto modes) above MPC_LAND_ALT1, a straight line between;
MPC_LAND_ALT1 is taken as at least MPC_LAND_ALT2 (``FlightTaskAuto::updateParams``). The height is above home (PX4's
``_dist_to_ground`` without a distance sensor: the local z above the home's). Defaults: 1.5 m/s, 10 m, 5 m (PX4's).
"""

from __future__ import annotations

from dataclasses import dataclass
from math import log, radians, tan

# m: PX4's ranges, held inside the plant's 100 m envelope (RTL_RETURN_ALT to 150 m in PX4, NAV_ACC_RAD to 200 m,
# RTL_MIN_DIST without a top); RTL_CONE_ANG in degrees, PX4's 0..90
RETURN_RANGES = {"return_alt_m": (0.0, 100.0), "descend_alt_m": (2.0, 100.0), "cone_deg": (0, 90),
                 "min_dist_m": (0.5, 100.0), "acc_rad_m": (0.05, 100.0)}
LAND_RANGES = {"auto_down_mps": (0.5, 4.0), "alt1_m": (0.0, 122.0), "alt2_m": (0.0, 122.0)}  # PX4's, m/s and m


@dataclass(frozen=True)
class ReturnConfig:
    """Return mode's parameters (their ranges: :data:`RETURN_RANGES`): heights above where it lands (m), PX4's
    RTL_RETURN_ALT (climb to it, if lower, before flying home) and RTL_DESCEND_ALT (over it, come down to it, then
    land); the cone near home: RTL_CONE_ANG (deg, 0: none), RTL_MIN_DIST (m) and NAV_ACC_RAD (m)."""

    return_alt_m: float = 30.0  # PX4's multicopter default (ROMFS rc.mc_defaults; rtl_params.c's own 60 m)
    descend_alt_m: float = 10.0  # likewise (rtl_params.c's own 30 m)
    cone_deg: int = 45
    min_dist_m: float = 10.0
    acc_rad_m: float = 2.0


@dataclass(frozen=True)
class LandSlowdown:
    """The auto landing's speed above the ground (its ranges: :data:`LAND_RANGES`): MPC_Z_V_AUTO_DN (m/s) above
    MPC_LAND_ALT1 (m), MPC_LAND_SPEED (given: the failsafe's ``descent_rate``) at or below MPC_LAND_ALT2 (m)."""

    auto_down_mps: float = 1.5
    alt1_m: float = 10.0
    alt2_m: float = 5.0

    def speed(self, height_m: float, land_mps: float) -> float:
        """The descent speed (m/s, down) at ``height_m`` above home: :func:`land_speed`."""
        return land_speed(height_m, land_mps, self.auto_down_mps, self.alt1_m, self.alt2_m)

    def time_s(self, height_m: float, land_mps: float) -> float:
        """The time (s) of the descent from ``height_m`` to the ground: :func:`land_time_s`."""
        return land_time_s(height_m, land_mps, self.auto_down_mps, self.alt1_m, self.alt2_m)


def return_height(dist_m: float, height_m: float, return_alt_m: float, cone_deg: float, min_dist_m: float,
                  acc_rad_m: float) -> float:
    """The height (m above where Return lands) it flies home at, begun ``dist_m`` away horizontally at ``height_m``
    above it, PX4 1.14's formula (module docstring): no cone (``cone_deg`` <= 0), max(h, RTL_RETURN_ALT); else within
    NAV_ACC_RAD 2 d, beyond it RTL_RETURN_ALT or within RTL_MIN_DIST the lower d / tan(cone) (the angle held to 1..89
    deg), at least 2 NAV_ACC_RAD; at least h in every case."""
    if cone_deg <= 0:
        return max(height_m, return_alt_m)
    if dist_m <= acc_rad_m:
        h = 2.0 * dist_m
    else:
        h = return_alt_m
        if dist_m <= min_dist_m:
            h = min(dist_m / tan(radians(min(max(cone_deg, 1.0), 89.0))), h)
        h = max(h, 2.0 * acc_rad_m)
    return max(h, height_m)


def land_speed(height_m: float, land_mps: float, auto_down_mps: float, alt1_m: float, alt2_m: float) -> float:
    """The auto landing's descent speed (m/s, down) at ``height_m`` above home: PX4's ``math::gradual`` from
    (MPC_LAND_ALT2, MPC_LAND_SPEED) to (MPC_LAND_ALT1, MPC_Z_V_AUTO_DN), constant outside; MPC_LAND_ALT1 at least
    MPC_LAND_ALT2. At or below MPC_LAND_ALT2 it is ``land_mps`` itself."""
    top = max(alt1_m, alt2_m)
    if height_m <= alt2_m:
        return land_mps
    if height_m > top:
        return auto_down_mps
    return land_mps + (auto_down_mps - land_mps) * (height_m - alt2_m) / (top - alt2_m)


def land_time_s(height_m: float, land_mps: float, auto_down_mps: float, alt1_m: float, alt2_m: float) -> float:
    """The time (s) of a descent at :func:`land_speed` from ``height_m`` above home to the ground: the integral of
    dh / v(h); on the blend, where v = v2 + k (h - ALT2), that is ln(v(h) / v2) / k (k = 0: the length / v2)."""
    h = max(height_m, 0.0)
    top = max(alt1_m, alt2_m)
    low = min(h, alt2_m)
    t = low / land_mps
    if h <= alt2_m:
        return t
    mid = min(h, top) - alt2_m
    if mid > 0.0:
        k = (auto_down_mps - land_mps) / (top - alt2_m)
        t += mid / land_mps if k == 0.0 else log((land_mps + k * mid) / land_mps) / k
    return t + max(h - top, 0.0) / auto_down_mps

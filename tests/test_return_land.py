"""Covers bridge.autopilot.returnland, bridge.autopilot.failsafe and bridge.autopilot.params: Return mode's height
near home (PX4 1.14's cone: RTL_CONE_ANG, RTL_MIN_DIST, NAV_ACC_RAD) and the auto landing's speed by height
(MPC_Z_V_AUTO_DN above MPC_LAND_ALT1, MPC_LAND_SPEED below MPC_LAND_ALT2), against PX4's formulas written out here
at chosen points, their parameters, and the vehicle flying them offline (docs/ground-station.md, "Return's height
and the landing's speed"). In lockstep, from a battery failsafe: tests/test_battery_return.py."""

from __future__ import annotations

from math import hypot, radians, tan

import pytest

from bridge.autopilot.failsafe import (
    DEFAULT_GAINS,
    FailsafeConfig,
    Land,
    ReturnHome,
    failsafe_target,
    landing_target,
    return_time_s,
)
from bridge.autopilot.modes import LAND, RTL
from bridge.autopilot.params import BY_NAME, VehicleParams, change_param, read_param
from bridge.autopilot.returnland import LandSlowdown, ReturnConfig, land_speed, land_time_s, return_height
from bridge.core.flight import prepare
from missions import Mission, Setpoint, Step

# RTL_RETURN_ALT .. NAV_ACC_RAD: PX4's multicopter defaults (rc.mc_defaults: 30 m, 2 m; RTL_CONE_ANG, RTL_MIN_DIST)
PX4 = {"return_alt_m": 30.0, "cone_deg": 45, "min_dist_m": 10.0, "acc_rad_m": 2.0}


def _height(d: float, h: float, **over: float) -> float:
    p = {**PX4, **over}
    return return_height(d, h, p["return_alt_m"], p["cone_deg"], p["min_dist_m"], p["acc_rad_m"])


def test_return_height_is_px4_1_14s_cone_at_chosen_points() -> None:
    """``RTL::calculate_return_alt_from_cone_half_angle`` (PX4 1.14), heights above where it lands: within
    NAV_ACC_RAD 2 d; within RTL_MIN_DIST the cone d / tan(angle) if below RTL_RETURN_ALT, at least 2 NAV_ACC_RAD;
    beyond it RTL_RETURN_ALT; never below the height it has; no cone (0): RTL_RETURN_ALT."""
    assert _height(9.0, 4.0) == pytest.approx(9.0 / tan(radians(45)))  # the audit's case, inside: 9 m, not 30
    assert _height(10.0, 4.0) == pytest.approx(10.0)  # RTL_MIN_DIST itself is inside
    assert _height(10.05, 4.0) == 30.0  # just beyond it: RTL_RETURN_ALT
    assert _height(9.0, 4.0, cone_deg=25) == pytest.approx(9.0 / tan(radians(25)))  # 19.3 m: a narrower cone
    assert _height(9.0, 4.0, cone_deg=25, return_alt_m=15.0) == 15.0  # the cone never above RTL_RETURN_ALT
    assert _height(6.0, 1.0, cone_deg=80) == 4.0  # 6 / tan 80 = 1.06 m: the floor 2 NAV_ACC_RAD
    assert _height(6.0, 1.0, cone_deg=90) == 4.0  # 90 is held to 89: 0.10 m, the floor again
    assert _height(2.2, 2.0, return_alt_m=3.0) == 4.0  # PX4 1.14's floor lies above RTL_RETURN_ALT here
    assert _height(1.5, 1.0) == 3.0 and _height(0.0, 0.0) == 0.0  # within NAV_ACC_RAD: 2 d
    assert _height(1.5, 5.0) == 5.0 and _height(9.0, 25.0) == 25.0  # it never comes down to return
    assert _height(9.0, 4.0, cone_deg=0) == 30.0 and _height(9.0, 70.0, cone_deg=0) == 70.0  # no cone
    assert _height(10.05, 4.0, return_alt_m=60.0) == 60.0  # RTL_RETURN_ALT's own default (a fixed wing's)
    assert _height(1.5, 1.0, cone_deg=0, return_alt_m=3.0) == 3.0  # no cone: not the 2 d either
    assert _height(30.0, 4.0, acc_rad_m=10.0, min_dist_m=50.0) == pytest.approx(30.0)  # NAV_ACC_RAD 10 m (PX4's own)
    assert _height(8.0, 4.0, acc_rad_m=10.0) == 16.0


def _gradual(h: float, x_low: float, x_high: float, y_low: float, y_high: float) -> float:
    """PX4's ``math::gradual`` (src/lib/mathlib/math/Functions.hpp), as it is written there."""
    if h <= x_low:
        return y_low
    if h > x_high:
        return y_high
    a = (y_high - y_low) / (x_high - x_low)
    b = y_low - a * x_low
    return a * h + b


@pytest.mark.parametrize("h", [-1.0, 0.0, 2.0, 5.0, 5.5, 7.5, 9.99, 10.0, 10.01, 30.0])
def test_the_landing_speed_is_px4s_gradual_between_the_two_heights(h: float) -> None:
    """``FlightTaskAuto::_prepareLandSetpoints``: gradual(height, MPC_LAND_ALT2, MPC_LAND_ALT1, MPC_LAND_SPEED,
    MPC_Z_V_AUTO_DN), PX4's defaults 5 m, 10 m, 0.7 m/s, 1.5 m/s; a slower landing speed and other heights too."""
    assert land_speed(h, 0.7, 1.5, 10.0, 5.0) == pytest.approx(_gradual(h, 5.0, 10.0, 0.7, 1.5), abs=1e-12)
    assert land_speed(h, 0.5, 3.0, 20.0, 2.0) == pytest.approx(_gradual(h, 2.0, 20.0, 0.5, 3.0), abs=1e-12)
    if h <= 5.0:
        assert land_speed(h, 0.7, 1.5, 10.0, 5.0) == 0.7  # MPC_LAND_SPEED itself: the landings below 5 m unchanged


def test_landing_speed_edges_alt1_below_alt2_and_equal() -> None:
    """MPC_LAND_ALT1 below MPC_LAND_ALT2 is taken as MPC_LAND_ALT2 (``FlightTaskAuto::updateParams``): a step at it,
    no blend, no division by zero; equal heights alike."""
    for alt1 in (3.0, 5.0):
        assert land_speed(5.0, 0.7, 1.5, alt1, 5.0) == 0.7 and land_speed(5.001, 0.7, 1.5, alt1, 5.0) == 1.5
    assert land_time_s(8.0, 0.7, 1.5, 3.0, 5.0) == pytest.approx(5.0 / 0.7 + 3.0 / 1.5)


@pytest.mark.parametrize("h", [0.0, 3.0, 5.0, 7.0, 10.0, 26.75, 60.0])
def test_the_landing_time_is_the_integral_of_the_speed(h: float) -> None:
    """:func:`land_time_s` against a fine midpoint sum of dh / v(h); below MPC_LAND_ALT2 it is h / MPC_LAND_SPEED."""
    n = 20000
    step = h / n
    numeric = sum(step / land_speed((i + 0.5) * step, 0.7, 1.5, 10.0, 5.0) for i in range(n))
    assert land_time_s(h, 0.7, 1.5, 10.0, 5.0) == pytest.approx(numeric, rel=1e-6, abs=1e-9)
    if h <= 5.0:
        assert land_time_s(h, 0.7, 1.5, 10.0, 5.0) == pytest.approx(h / 0.7)
    flat = land_time_s(h, 1.0, 1.0, 10.0, 5.0)  # the two speeds equal: no blend (k = 0)
    assert flat == pytest.approx(h)


def test_the_parameters_are_px4s_with_their_defaults_and_ranges() -> None:
    p = VehicleParams()
    want = {"RTL_RETURN_ALT": (30.0, "REAL32", 0.0, 100.0), "RTL_DESCEND_ALT": (10.0, "REAL32", 2.0, 100.0),
            "COM_DISARM_LAND": (2.0, "REAL32", -1.0, 20.0),
            "RTL_CONE_ANG": (45, "INT32", 0, 90), "RTL_MIN_DIST": (10.0, "REAL32", 0.5, 100.0),
            "NAV_ACC_RAD": (2.0, "REAL32", 0.05, 100.0), "MPC_Z_V_AUTO_DN": (1.5, "REAL32", 0.5, 4.0),
            "MPC_LAND_ALT1": (10.0, "REAL32", 0.0, 122.0), "MPC_LAND_ALT2": (5.0, "REAL32", 0.0, 122.0)}
    for name, (default, kind, lo, hi) in want.items():
        spec = BY_NAME[name]
        assert (read_param(p, name), spec.kind, spec.lo, spec.hi) == (default, kind, lo, hi), name
    q = change_param(change_param(p, "RTL_CONE_ANG", 25), "MPC_LAND_ALT1", 12.0)
    assert q.rtl == ReturnConfig(cone_deg=25) and isinstance(q.rtl.cone_deg, int)
    assert q.failsafe.slowdown == LandSlowdown(alt1_m=12.0) and q.failsafe.descent_rate == 0.7


def test_return_and_land_targets_carry_the_cone_and_the_slowdown() -> None:
    """From 9 m north at 4 m: Return's target climbs to 9 m (the cone), lands as PX4 (1.5 m/s above 10 m, 0.7 m/s
    below 5 m, by the height above home); LAND's target likewise; ``descend`` keeps its constant rate."""
    X = (9.0, 0.0, 0.0, 0.0, 4.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    home = (0.0, 0.0, 0.0)
    t = failsafe_target(FailsafeConfig(action="return"), X, home, ReturnConfig())
    assert isinstance(t, ReturnHome) and t.z_return == pytest.approx(9.0) and t.z_descend == pytest.approx(9.0)
    assert ReturnHome.toward(X, home, ReturnConfig(cone_deg=0), 0.7).z_return == 30.0  # no cone: the multicopter's
    high = ReturnHome.toward((0.0,) * 4 + (25.0,) + (0.0,) * 7, home, ReturnConfig(), 0.7, LandSlowdown())
    assert high.phase((0.0,) * 4 + (25.0,) + (0.0,) * 7) == "descend" and high.z_descend == 10.0
    assert high.setpoint((0.0,) * 4 + (25.0,) + (0.0,) * 7, DEFAULT_GAINS).v_z == -1.5  # MPC_Z_V_AUTO_DN, not 1 m/s
    over_home = (0.0, 0.0, 0.0, 0.0, 20.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    land = landing_target(FailsafeConfig(), over_home, (0.0, 0.0, 2.0))
    assert isinstance(land, Land) and land.ground_z == 2.0
    for z, v in ((20.0, 1.5), (9.5, 1.1), (6.0, 0.7), (3.0, 0.7)):  # (heights above home at 2 m)
        assert land.setpoint(over_home[:4] + (z,) + over_home[5:], DEFAULT_GAINS).v_z == pytest.approx(-v)
    assert failsafe_target(FailsafeConfig(), over_home, home, ReturnConfig()).setpoint(
        over_home, DEFAULT_GAINS).v_z == -0.7  # descend (the default): 0.7 m/s at any height
    cone = return_time_s(ReturnConfig(), 9.0, 4.0, 0.7, slowdown=LandSlowdown())
    assert cone == pytest.approx(5.0 / 1.5 + 9.0 / 2.0 + land_time_s(9.0, 0.7, 1.5, 10.0, 5.0))
    far = return_time_s(ReturnConfig(), 20.0, 4.0, 0.7, slowdown=LandSlowdown())  # up to 30 m, down to 10 at 1.5
    assert far == pytest.approx(26.0 / 1.5 + 20.0 / 2.0 + 20.0 / 1.5 + land_time_s(10.0, 0.7, 1.5, 10.0, 5.0))


def _hover(north: float, z: float, **params: float):
    m = Mission(Step((Setpoint(0.0, 0.0, 0.0, 0.0, 0.0),)), duration_s=120.0, name="g")
    sim = prepare(m, params=params).make_vehicle(armed=True)
    sim.plant.state = (north, 0.0, 0.0, 0.0, z, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    return sim


def _fly_until_disarmed(sim, limit_s: float) -> list[tuple[float, ...]]:
    states = []
    for _ in range(int(limit_s * 250)):
        sim.advance()
        states.append(sim.plant.state)
        if not sim.armed:
            break
    return states


def test_rtl_from_9_m_away_at_4_m_climbs_to_the_cone_and_lands_home() -> None:
    """The vehicle (the paper profile, its estimate the truth) in RTL 9 m north at 4 m: its event says 9 m, it
    climbs no higher than 9.1 m, lands within 0.2 m of home and disarms there; from 30 m over home LAND comes down
    at 1.5 m/s above 10 m and 0.7 m/s below 5 m, in the time the speed's integral gives, and disarms COM_DISARM_LAND
    (2 s) after its ``landed`` event."""
    sim = _hover(9.0, 4.0)
    sim.set_mode(RTL)
    assert "at z=9.000 m, down to 9.000 m, land" in sim.events[-1].text, sim.events[-1].text
    states = _fly_until_disarmed(sim, 60.0)
    assert not sim.armed and 8.9 < max(s[4] for s in states) < 9.1
    end = states[-1]
    assert hypot(end[0], end[2]) < 0.2 and end[4] < 0.01
    sim = _hover(0.0, 30.0)
    sim.set_mode(LAND)
    assert "LAND at x=0.000 y=0.000 m, 0.7 m/s below 5 m, 1.5 m/s above 10 m" in sim.events[-1].text
    states = _fly_until_disarmed(sim, 60.0)
    assert not sim.armed
    high = [-s[5] for s in states if 12.0 < s[4] < 22.0]  # (from rest at 30 m its velocity loop overshoots 3 %)
    low = [-s[5] for s in states if 0.5 < s[4] < 2.5]  # (below 5 m the velocity loop takes 3 m to settle)
    assert min(high) == pytest.approx(1.5, abs=0.02) and max(high) == pytest.approx(1.5, abs=0.02)
    assert min(low) == pytest.approx(0.7, abs=0.01) and max(low) == pytest.approx(0.7, abs=0.01)
    took = len(states) / 250
    landed = next(e.t for e in sim.events if e.kind == "landed")
    assert sim.events[-1].kind == "disarmed" and sim.events[-1].t == pytest.approx(landed + 2.0, abs=1e-9)
    # 25.2 s to the ground, 27.2 s to the disarm; at 0.7 m/s all the way: 42.9 s to the ground
    assert took - 2.0 == pytest.approx(land_time_s(30.0, 0.7, 1.5, 10.0, 5.0), abs=1.0), took

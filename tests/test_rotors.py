"""Covers plant.rotors and controller.actuation.

Eq. (4)-(5): rotor speeds <-> wrench, and the controller's rotor allocation.

- plant/rotors.py: eq. (4) forward and inverse are a round trip; eq. (5) is signed.
- controller/actuation.py, MotorActuation: inside the rotor envelope the allocation
  realises the demanded wrench exactly; when the envelope binds it keeps thrust, then
  roll/pitch (scaled along their direction), and gives up yaw first; c_i in [0, 1].
"""

from __future__ import annotations

import math

import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from controller.actuation import MotorActuation, WrenchActuation
from controller.nominal import Nominal
from plant import load_profile
from plant.rotors import (
    motor_lag_step,
    motor_speeds_from_wrench,
    signed_speed_sum,
    wrench_from_motor_speeds,
)

X500 = load_profile("x500")
PAPER = load_profile("paper")
B, D, W_MAX = X500.thrust_coeff, X500.drag_coeff, X500.omega_max

speed = st.floats(0.0, W_MAX, allow_nan=False)
speeds = st.tuples(speed, speed, speed, speed)
unit = st.floats(-1.0, 1.0, allow_nan=False)


def _close(a: tuple[float, ...], b: tuple[float, ...], rel: float = 1e-9, abs_: float = 1e-9) -> bool:
    return all(math.isclose(x, y, rel_tol=rel, abs_tol=abs_) for x, y in zip(a, b, strict=True))


def test_eq4_by_hand() -> None:
    """One rotor at a time gives the signs of eq. (4): 1 front, 2 right, 3 back, 4 left."""
    b, d = 2.0, 0.5
    assert wrench_from_motor_speeds((1.0, 0.0, 0.0, 0.0), b, d) == (2.0, 0.0, -2.0, -0.5)
    assert wrench_from_motor_speeds((0.0, 1.0, 0.0, 0.0), b, d) == (2.0, -2.0, 0.0, 0.5)
    assert wrench_from_motor_speeds((0.0, 0.0, 1.0, 0.0), b, d) == (2.0, 0.0, 2.0, -0.5)
    assert wrench_from_motor_speeds((0.0, 0.0, 0.0, 1.0), b, d) == (2.0, 2.0, 0.0, 0.5)
    assert signed_speed_sum((1.0, 2.0, 3.0, 5.0)) == 2.0 + 5.0 - 1.0 - 3.0


@given(speeds)
def test_eq4_round_trip_speeds(omega: tuple[float, float, float, float]) -> None:
    """speeds -> wrench (eq. 4) -> speeds (eq. 4 inverted) is the identity."""
    u = wrench_from_motor_speeds(omega, B, D)
    back = motor_speeds_from_wrench(u, B, D)
    # squared speeds are recovered to rounding; speeds near 0 lose digits through the sqrt
    assert _close(tuple(w * w for w in back), tuple(w * w for w in omega), rel=1e-9, abs_=1e-6 * W_MAX**2)


@given(speeds)
def test_eq4_round_trip_wrench(omega: tuple[float, float, float, float]) -> None:
    """wrench -> speeds -> wrench is the identity for any wrench the rotors can give."""
    u = wrench_from_motor_speeds(omega, B, D)
    again = wrench_from_motor_speeds(motor_speeds_from_wrench(u, B, D), B, D)
    scale = (4 * B * W_MAX**2, B * W_MAX**2, B * W_MAX**2, 2 * D * W_MAX**2)
    assert all(abs(a - b) <= 1e-9 * s for a, b, s in zip(u, again, scale, strict=True))


def test_inverse_clips_negative_squares() -> None:
    """A wrench no pushing rotor gives (negative thrust) gets zero speeds, not NaN."""
    assert motor_speeds_from_wrench((-1.0, 0.0, 0.0, 0.0), B, D) == (0.0, 0.0, 0.0, 0.0)


def test_motor_lag_is_the_exact_first_order_step() -> None:
    tau, dt = 0.0125, 0.001
    out = motor_lag_step((0.0, 100.0, 200.0, 300.0), (500.0,) * 4, dt, tau)
    k = 1.0 - math.exp(-dt / tau)
    assert _close(out, tuple(w + (500.0 - w) * k for w in (0.0, 100.0, 200.0, 300.0)))
    # many small steps = one big step (exactness of the discretisation)
    w = (0.0,) * 4
    for _ in range(10):
        w = motor_lag_step(w, (500.0,) * 4, dt, tau)
    assert _close(w, motor_lag_step((0.0,) * 4, (500.0,) * 4, 10 * dt, tau))


# -- the controller's allocation (inverse of eq. 4 inside the envelope) ------------------
def _alloc() -> MotorActuation:
    return MotorActuation(Nominal.from_profile(X500))


def _check_outputs(c: tuple[float, ...]) -> None:
    assert all(0.0 <= ci <= 1.0 for ci in c), c


@settings(max_examples=300)
@given(speeds)
@example((0.0, 0.0, 0.0, 1.0))  # one rotor alone: roll/pitch fit only with the yaw it brings
@example((0.0, 0.0, 0.0, W_MAX))
def test_allocation_exact_inside_envelope(omega: tuple[float, float, float, float]) -> None:
    """Any wrench some rotor speeds in [0, omega_max] give is realised exactly."""
    u = wrench_from_motor_speeds(omega, B, D)
    act = _alloc()
    real, c, sat = act.allocate(u)
    _check_outputs(c)
    scale = (4 * B * W_MAX**2, B * W_MAX**2, B * W_MAX**2, 2 * D * W_MAX**2)
    assert all(abs(a - b) <= 1e-9 * s for a, b, s in zip(real, u, scale, strict=True)), (u, real)
    if all(1e-3 * W_MAX < w < (1 - 1e-3) * W_MAX for w in omega):
        assert not any(sat)  # on the envelope's edge the flags are a matter of rounding
    # the command on the wire gives that wrench through eq. (4) and the right omega_d
    assert _close(wrench_from_motor_speeds(tuple(ci * W_MAX for ci in c), B, D), real, rel=1e-9, abs_=1e-9)
    assert math.isclose(act.omega_d, signed_speed_sum(tuple(ci * W_MAX for ci in c)), abs_tol=1e-6)


@settings(max_examples=300)
@given(st.floats(0.05, 0.95), unit, unit, st.floats(-20.0, 20.0))
def test_allocation_priorities_when_the_envelope_binds(thrust: float, r: float, p: float, yaw: float) -> None:
    """Thrust is always kept; roll/pitch are kept or scaled together along their direction;
    yaw is given up before roll/pitch and never reversed."""
    u1 = thrust * 4 * B * W_MAX**2
    u = (u1, 2.0 * r * B * W_MAX**2, 2.0 * p * B * W_MAX**2, yaw * D * W_MAX**2)
    act = _alloc()
    real, c, sat = act.allocate(u)
    _check_outputs(c)
    assert math.isclose(real[0], u1, rel_tol=1e-9)
    # roll/pitch: the same fraction k of each, k in [0, 1]
    big = 1 if abs(u[1]) >= abs(u[2]) else 2
    if abs(u[big]) > 1e-6 * B * W_MAX**2:
        k = real[big] / u[big]
        assert -1e-9 <= k <= 1.0 + 1e-9
        assert math.isclose(real[1], k * u[1], rel_tol=1e-7, abs_tol=1e-9 * B * W_MAX**2)
        assert math.isclose(real[2], k * u[2], rel_tol=1e-7, abs_tol=1e-9 * B * W_MAX**2)
        if k < 1.0 - 1e-9:
            # roll/pitch were cut: then no yaw at all would have helped less, so yaw is
            # what it can be, and the command rides the envelope
            assert sat[1] and sat[2]
            assert min(c) ** 2 <= 1e-12 or max(c) ** 2 >= 1.0 - 1e-12
    # yaw: same sign as demanded, never more
    assert real[3] * u[3] >= -1e-12
    assert abs(real[3]) <= abs(u[3]) * (1 + 1e-9) + 1e-12


def test_yaw_goes_first() -> None:
    """At hover with full roll authority left, an impossible yaw is cut, not roll."""
    act = _alloc()
    u1 = X500.mass * X500.gravity
    u = (u1, 0.5, 0.0, 10.0)  # 10 N of u4 is far beyond 2 d w_max^2 = 1.09 N
    real, c, sat = act.allocate(u)
    assert math.isclose(real[0], u1, rel_tol=1e-12)
    assert math.isclose(real[1], 0.5, rel_tol=1e-9)
    assert real[2] == pytest.approx(0.0, abs=1e-12)
    assert 0.0 < real[3] < 10.0
    assert sat == (False, False, False, True)
    _check_outputs(c)


def test_thrust_clipped_to_the_envelope() -> None:
    act = _alloc()
    real, c, sat = act.allocate((1e3, 0.0, 0.0, 0.0))
    assert math.isclose(real[0], 4 * B * W_MAX**2, rel_tol=1e-12)
    assert c == pytest.approx((1.0, 1.0, 1.0, 1.0))
    assert sat[0]
    real, c, sat = act.allocate((-5.0, 0.0, 0.0, 0.0))
    assert real[0] == 0.0 and c == (0.0, 0.0, 0.0, 0.0) and sat[0]


@given(st.floats(-2.0, 2.0), unit, unit, unit)
def test_wrench_actuation_clamps_and_normalises(u1: float, u2: float, u3: float, u4: float) -> None:
    act = WrenchActuation(Nominal.from_profile(PAPER))
    m = PAPER.u_max
    u = (u1 * m[0], 2.0 * u2 * m[1], 2.0 * u3 * m[2], 2.0 * u4 * m[3])
    real, c, sat = act.allocate(u)
    assert 0.0 <= c[0] <= 1.0 and all(-1.0 <= ci <= 1.0 for ci in c[1:])
    assert _close(real, tuple(ci * mi for ci, mi in zip(c, m, strict=True)))
    for i in range(4):
        lo = 0.0 if i == 0 else -m[i]
        assert real[i] == min(max(u[i], lo), m[i])
        assert sat[i] == (real[i] != u[i])

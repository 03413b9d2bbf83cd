"""Covers plant.integrate: the fixed-step RK4, alone and as the plant flies it.

The plant's 1 kHz RK4 with commands held between control steps (zero-order hold) is
checked against scipy's solve_ivp at rtol = atol = 1e-12 over a 10 s flight with varying
commands, drag and a time-varying disturbance: position error <= 1e-6 m.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from plant import Disturbance, Effects, Quadrotor, load_profile
from plant.integrate import rk4_step
from plant.model import rigid_body, rk4_step_held, state_derivative


def test_exact_for_cubic_quadrature() -> None:
    """RK4 is Simpson's rule on x' = f(t): exact for polynomials of degree 3."""
    f = lambda t, x: (4 * t**3 - 3 * t**2 + 1.0,)  # noqa: E731
    x = rk4_step(f, 0.5, (2.0,), 0.3)
    F = lambda t: t**4 - t**3 + t  # noqa: E731
    assert x[0] == pytest.approx(2.0 + F(0.8) - F(0.5), rel=1e-14)


def test_fourth_order_convergence() -> None:
    """Global error on a rotation x'' = -x falls 16x when the step halves."""

    def f(_t: float, x: tuple[float, ...]) -> tuple[float, ...]:
        return (x[1], -x[0])

    def error(n: int) -> float:
        h = 2.0 / n
        x: tuple[float, ...] = (1.0, 0.0)
        for k in range(n):
            x = rk4_step(f, k * h, x, h)
        return math.hypot(x[0] - math.cos(2.0), x[1] + math.sin(2.0))

    e1, e2 = error(20), error(40)
    assert 15.0 < e1 / e2 < 17.0


small = st.floats(-3.0, 3.0, allow_nan=False)


@given(st.tuples(*[small] * 12), st.tuples(st.floats(0.0, 40.0), small, small, small), small,
       st.none() | st.tuples(*[small] * 6), st.sampled_from([1e-4, 1e-3, 4e-3]))
def test_specialised_step_is_bit_for_bit_rk4(X: tuple, u: tuple, omega_d: float, ext: tuple | None, h: float) -> None:
    """plant.model.rk4_step_held (the plant's fast step) == rk4_step over eq. (6), exactly."""
    body = rigid_body(1.1, 1.22, 0.9, 2.2, 0.21, 0.2, drag=(0.1, 0.2, 0.3, 0.12, 0.13, 0.14))
    generic = rk4_step(lambda _t, x: state_derivative(x, *u, omega_d, body, ext), 0.0, X, h)
    held = rk4_step_held(X, *u, omega_d, body, h, None if ext is None else (ext, ext, ext))
    assert held == generic


def test_plant_step_is_rk4_of_its_derivative() -> None:
    """Quadrotor.step (time-varying disturbance, motor commands) == rk4_step(Quadrotor.derivative)."""
    p = load_profile("x500")
    effects = Effects(drag=True, disturbance=Disturbance(force_amp=(0.3, 0.2, 0.1), torque_amp=(0.01, 0.02, 0.01),
                                                         freq_hz=2.0, random_phase=True))
    q = Quadrotor(p, effects, seed=1, ground=False, state=(0.0,) * 4 + (3.0,) + (0.0,) * 7)
    q.command((0.76, 0.75, 0.77, 0.755))
    X = q.state
    for _ in range(300):
        X = rk4_step(q.derivative, q.t, X, q.dt)
        q.step()
        assert q.state == X


def commands(t: float, hover: float) -> tuple[float, float, float, float]:
    """Normalised wrench commands that keep the paper's vehicle airborne and turning."""
    return (
        hover * (1.0 + 0.08 * math.sin(0.7 * t)),
        0.002 * math.sin(1.3 * t),
        0.0015 * math.cos(0.9 * t + 0.2),
        0.020 * math.sin(0.5 * t),
    )


def test_rk4_matches_solve_ivp_on_a_10s_flight() -> None:
    from scipy.integrate import solve_ivp  # lazy: ~1 s of every worker's collection otherwise

    p = load_profile("paper")
    effects = Effects(drag=True, disturbance=Disturbance(force_amp=(0.3, 0.2, 0.1), torque_amp=(0.05, 0.05, 0.02),
                                                         freq_hz=0.4, random_phase=True))
    start = (0.0, 0.2, 0.0, -0.1, 5.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    plant = Quadrotor(p, effects, seed=3, physics_hz=1000.0, state=start, ground=False)
    model = Quadrotor(p, effects, seed=3, physics_hz=1000.0, state=start, ground=False)  # derivative only
    hover = p.mass * p.gravity / p.u_max[0]
    hold_s, substeps = 0.02, 20  # commands at 50 Hz, physics at 1 kHz
    x_ref = np.array(start)
    worst = 0.0
    for k in range(500):
        t0 = k * hold_s
        c = commands(t0, hover)
        plant.command(c)
        model.command(c)
        for _ in range(substeps):
            plant.step()
        sol = solve_ivp(lambda t, x: model.derivative(t, tuple(x)), (t0, t0 + hold_s), x_ref,
                        method="DOP853", rtol=1e-12, atol=1e-12)
        x_ref = sol.y[:, -1]
        pos_err = math.dist((plant.state[0], plant.state[2], plant.state[4]), (x_ref[0], x_ref[2], x_ref[4]))
        worst = max(worst, pos_err)
    assert plant.t == pytest.approx(10.0)
    # the flight went somewhere: it climbed, drifted and turned
    assert abs(x_ref[4] - 5.0) > 0.1 and math.hypot(x_ref[0], x_ref[2]) > 0.1 and abs(x_ref[10]) > 0.01
    assert worst <= 1e-6
    assert np.allclose(plant.state, x_ref, atol=1e-6)

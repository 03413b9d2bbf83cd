"""Covers controller.power: the regularised sig_beta and the finite-time bound of eq. (11)/(19).

sig_beta(e) = |e|^beta sign(e), replaced inside |e| < eps by an odd polynomial with a C^3
join. Checked: the join, oddness, strict monotonicity for every beta in (0, 1), exactness
outside the band, and that the outer backstepping step e' = -c 2^-alpha sig_beta(e),
beta = 2 alpha - 1 (i.e. V' = -c V^alpha, V = e^2/2) reaches the band within the
eq. (11)/(19) bound V0^(1-alpha) / (c (1-alpha)).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bridge.record.metrics import finite_time_bound
from controller.power import SignedPower

BETA = st.floats(0.001, 0.999)
EPS = st.floats(1e-3, 1.0)


def exact(beta: float, e: float) -> tuple[float, float, float, float]:
    """|e|^beta sign(e) and its first three derivatives, e != 0."""
    m = abs(e)
    s = 1.0 if e > 0 else -1.0
    return (
        s * m**beta,
        beta * m ** (beta - 1),
        s * beta * (beta - 1) * m ** (beta - 2),
        beta * (beta - 1) * (beta - 2) * m ** (beta - 3),
    )


def _close(a: tuple[float, ...], b: tuple[float, ...], rel: float) -> bool:
    return all(math.isclose(x, y, rel_tol=rel, abs_tol=1e-12) for x, y in zip(a, b, strict=True))


@given(BETA, EPS)
def test_c3_join_at_the_band_edge(beta: float, eps: float) -> None:
    """Value and three derivatives of the polynomial meet |e|^beta sign(e) at +-eps."""
    f = SignedPower(beta, eps)
    for side in (1.0, -1.0):
        inside = f.derivs(side * eps * (1.0 - 1e-12))  # the polynomial branch
        assert _close(inside, exact(beta, side * eps), rel=1e-6)
        assert f.derivs(side * eps) == pytest.approx(exact(beta, side * eps), rel=1e-12)


@given(BETA, EPS, st.floats(0.0, 3.0))
def test_odd_with_even_slope(beta: float, eps: float, r: float) -> None:
    f = SignedPower(beta, eps)
    e = r * eps
    p, m = f.derivs(e), f.derivs(-e)
    assert m[0] == -p[0] and m[1] == p[1] and m[2] == -p[2] and m[3] == p[3]


@settings(max_examples=200)
@given(BETA)
def test_strictly_increasing_in_the_band(beta: float) -> None:
    """The join polynomial has a positive slope on the whole band, for any beta in (0, 1)."""
    eps = 0.05
    f = SignedPower(beta, eps)
    e = np.linspace(-eps, eps, 2001)
    slopes = np.array([f.derivs(float(x))[1] for x in e])
    assert slopes.min() > 0.0
    values = np.array([f(float(x)) for x in e])
    assert np.all(np.diff(values) > 0.0)


@given(BETA, EPS, st.floats(1.0, 1e3))
def test_exact_outside_the_band(beta: float, eps: float, r: float) -> None:
    f = SignedPower(beta, eps)
    for e in (r * eps, -r * eps):
        assert f.derivs(e) == pytest.approx(exact(beta, e), rel=1e-12)


def test_rejects_bad_parameters() -> None:
    for beta in (0.0, 1.0, -0.5, 1.5):
        with pytest.raises(ValueError, match="beta"):
            SignedPower(beta, 0.05)
    with pytest.raises(ValueError, match="eps"):
        SignedPower(0.6, 0.0)


def test_jet_is_the_chain_rule() -> None:
    """sig applied to the jet of e(t) = 0.3 + t (unit slope) gives sig and its derivatives."""
    f = SignedPower(0.6, 0.05)
    assert f.jet((0.3, 1.0, 0.0, 0.0)) == pytest.approx(exact(0.6, 0.3), rel=1e-12)
    # e(t) = 2 t at t = 0.01 (inside the band): derivatives scale by 2^k
    d = f.derivs(0.02)
    assert f.jet((0.02, 2.0, 0.0, 0.0)) == pytest.approx((d[0], 2 * d[1], 4 * d[2], 8 * d[3]), rel=1e-12)


def time_to_band(e0: float, c: float, alpha: float, eps: float) -> float:
    """Integrate the outer step e' = -c 2^-alpha sig_beta(e) (eq. 17/29) until |e| = eps."""
    sig = SignedPower(2.0 * alpha - 1.0, eps)
    gain = c * 2.0 ** (-alpha)

    def rhs(_t: float, y: np.ndarray) -> list[float]:
        return [-gain * sig(float(y[0]))]

    def reached(_t: float, y: np.ndarray) -> float:
        return abs(float(y[0])) - eps

    reached.terminal = True  # type: ignore[attr-defined]
    from scipy.integrate import solve_ivp  # lazy: ~0.45 s of every worker's collection otherwise

    horizon = 10.0 * finite_time_bound(e0, c, alpha) + 1.0
    sol = solve_ivp(rhs, (0.0, horizon), [e0], events=reached, rtol=1e-10, atol=1e-13, method="DOP853")
    assert sol.status == 1, "the band was never reached"
    return float(sol.t_events[0][0])


@pytest.mark.parametrize("e0", [2.0, -1.0, 0.3, 5.0])
@pytest.mark.parametrize("c, alpha", [(1.5, 0.8), (2.0, 0.6), (3.0, 0.9), (8.0, 0.75)])
def test_finite_time_bound_holds_outside_the_band(e0: float, c: float, alpha: float) -> None:
    """Time to reach |e| = eps <= V0^(1-alpha)/(c(1-alpha)) (eq. 11/19), and it is the bound
    exactly less the bound from eps: outside the band V' = -c V^alpha holds exactly."""
    eps = 0.05
    t_band = time_to_band(e0, c, alpha, eps)
    bound = finite_time_bound(e0, c, alpha)
    assert t_band <= bound
    assert t_band == pytest.approx(bound - finite_time_bound(eps, c, alpha), rel=1e-6)


def test_inside_the_band_the_error_still_goes_to_zero() -> None:
    """The regularised law keeps driving e to 0 inside the band (exponentially)."""
    from scipy.integrate import solve_ivp  # lazy: as in time_to_band

    sig = SignedPower(0.6, 0.05)
    gain = 1.5 * 2.0**-0.8
    sol = solve_ivp(lambda _t, y: [-gain * sig(float(y[0]))], (0.0, 20.0), [0.05], rtol=1e-10, atol=1e-14)
    e = sol.y[0]
    assert e.min() > -1e-12  # no overshoot through zero (beyond the solver's noise)
    assert abs(e[-1]) < 1e-6
    big = e > 1e-9
    assert np.all(np.diff(e[big]) < 0.0)  # decreasing while above the solver's noise

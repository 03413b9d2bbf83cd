"""Covers controller.jets: the chain rule on (value, 1st, 2nd, 3rd derivative) jets.

Each operation is checked against the closed-form derivatives of a known function of t
(derived by hand, not by the rules under test), at many t (hypothesis).
"""

from __future__ import annotations

import math

from hypothesis import given
from hypothesis import strategies as st

from controller import jets as J

T = st.floats(-1.2, 1.2, allow_nan=False)


def close(a: tuple[float, ...], b: tuple[float, ...], tol: float = 1e-9) -> bool:
    return all(math.isclose(x, y, rel_tol=tol, abs_tol=tol) for x, y in zip(a, b, strict=True))


def sin_t(t: float) -> J.Jet:
    return (math.sin(t), math.cos(t), -math.sin(t), -math.cos(t))


def cos_t(t: float) -> J.Jet:
    return (math.cos(t), -math.sin(t), -math.cos(t), math.sin(t))


def square_t(t: float) -> J.Jet:
    """t^2."""
    return (t * t, 2.0 * t, 2.0, 0.0)


def test_linear_operations() -> None:
    a = (1.0, 2.0, 3.0, 4.0)
    b = (0.5, -1.0, 2.0, -3.0)
    assert J.add(a, b) == (1.5, 1.0, 5.0, 1.0)
    assert J.sub(a, b) == (0.5, 3.0, 1.0, 7.0)
    assert J.scale(a, 2.0) == (2.0, 4.0, 6.0, 8.0)
    assert J.axpy(2.0, a, b) == (2.5, 3.0, 8.0, 5.0)
    assert J.shift(a) == (2.0, 3.0, 4.0, 0.0)
    assert J.const(3.0) == (3.0, 0.0, 0.0, 0.0)


@given(T)
def test_mul_sin_cos_is_half_sin_2t(t: float) -> None:
    """sin t cos t = sin(2t)/2: derivatives cos 2t, -2 sin 2t, -4 cos 2t."""
    got = J.mul(sin_t(t), cos_t(t))
    s, c = math.sin(2 * t), math.cos(2 * t)
    assert close(got, (0.5 * s, c, -2.0 * s, -4.0 * c))


@given(T)
def test_mul_polynomials(t: float) -> None:
    """(t^2)(t^2 + t) = t^4 + t^3."""
    got = J.mul(square_t(t), (t * t + t, 2 * t + 1, 2.0, 0.0))
    assert close(got, (t**4 + t**3, 4 * t**3 + 3 * t**2, 12 * t**2 + 6 * t, 24 * t + 6))


@given(T)
def test_div_is_tan(t: float) -> None:
    """sin t / cos t = tan t: sec^2, 2 sec^2 tan, 2 sec^4 + 4 sec^2 tan^2."""
    got = J.div(sin_t(t), cos_t(t))
    tn = math.tan(t)
    s2 = 1.0 / math.cos(t) ** 2
    assert close(got, (tn, s2, 2 * s2 * tn, 2 * s2 * s2 + 4 * s2 * tn * tn))


@given(T)
def test_chain_exp_of_t_squared(t: float) -> None:
    """exp(t^2): 2t e, (2 + 4t^2) e, (12 t + 8 t^3) e."""
    e = math.exp(t * t)
    got = J.chain(e, e, e, e, square_t(t))
    assert close(got, (e, 2 * t * e, (2 + 4 * t * t) * e, (12 * t + 8 * t**3) * e))


@given(T)
def test_sin_cos_of_t_squared(t: float) -> None:
    """sin(t^2)' = 2t cos, '' = 2 cos - 4t^2 sin, ''' = -12 t sin - 8 t^3 cos (and cos likewise)."""
    s, c = math.sin(t * t), math.cos(t * t)
    js, jc = J.sin_cos(square_t(t))
    assert close(js, (s, 2 * t * c, 2 * c - 4 * t * t * s, -12 * t * s - 8 * t**3 * c))
    assert close(jc, (c, -2 * t * s, -2 * s - 4 * t * t * c, -12 * t * c + 8 * t**3 * s))


@given(T)
def test_sqrt_of_one_plus_t_squared(t: float) -> None:
    """r = sqrt(1 + t^2): r' = t/r, r'' = 1/r^3, r''' = -3t/r^5."""
    r = math.sqrt(1 + t * t)
    got = J.sqrt_((1 + t * t, 2 * t, 2.0, 0.0))
    assert close(got, (r, t / r, 1 / r**3, -3 * t / r**5))


@given(T)
def test_atan2_is_atan(t: float) -> None:
    """atan2(t, 1) = atan t: 1/(1+t^2), -2t/(1+t^2)^2, (6t^2 - 2)/(1+t^2)^3."""
    q = 1 + t * t
    got = J.atan2((t, 1.0, 0.0, 0.0), J.const(1.0))
    assert close(got, (math.atan(t), 1 / q, -2 * t / q**2, (6 * t * t - 2) / q**3))


@given(T, st.floats(0.1, 5.0))
def test_atan2_recovers_the_angle(t: float, k: float) -> None:
    """atan2(k(t) sin t^2, k(t) cos t^2) = t^2 for any positive k(t) = k + t^2: 2t, 2, 0."""
    kt = (k + t * t, 2 * t, 2.0, 0.0)
    s, c = J.sin_cos(square_t(t))
    got = J.atan2(J.mul(kt, s), J.mul(kt, c))
    assert close(got, (math.atan2(math.sin(t * t), math.cos(t * t)), 2 * t, 2.0, 0.0), tol=1e-8)


def test_top_derivative_unknown_stays_downstream() -> None:
    """A jet whose 3rd derivative is unknown (0) still gives exact lower derivatives."""
    t = 0.7
    exact = J.mul(sin_t(t), cos_t(t))
    truncated = J.mul((*sin_t(t)[:3], 0.0), (*cos_t(t)[:3], 0.0))
    assert close(exact[:3], truncated[:3])
    assert not math.isclose(exact[3], truncated[3])


jet = st.tuples(*[st.floats(-10.0, 10.0, allow_nan=False)] * 4)


@given(jet, jet)
def test_atan2_is_its_definition_to_the_last_bit(y: J.Jet, x: J.Jet) -> None:
    """The written-out atan2 is exactly div(x y' - y x', x^2 + y^2) on the primitive jets."""
    if x[0] * x[0] + y[0] * y[0] < 1e-6:
        return  # at the origin the angle has no derivative
    r = J.add(J.mul(x, x), J.mul(y, y))
    q = J.div(J.sub(J.mul(x, J.shift(y)), J.mul(y, J.shift(x))), r)
    assert J.atan2(y, x) == (math.atan2(y[0], x[0]), q[0], q[1], q[2])

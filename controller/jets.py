"""Truncated derivative jets: a quantity and its first three time derivatives.

A jet is a tuple (v, v', v'', v''') of plain floats. Arithmetic on jets is the chain rule
done numerically (Leibniz for products, Faa di Bruno for compositions), which is how the
BS-ST law gets the exact time derivatives of its virtual controls (docs/law.md, "Exact
derivatives by jets") instead of differencing samples.

Derivative k of a result depends only on derivatives <= k of its inputs, so a jet whose
top derivative is unknown (set to 0) still gives exact lower derivatives downstream.

In:  jets (v, v', v'', v''') of any quantity, in its own units and per second
Out: the jets of sums, products, quotients, compositions (sin, cos, sqrt, atan2)
"""

from __future__ import annotations

from math import atan2 as _atan2
from math import cos, sin, sqrt

Jet = tuple[float, float, float, float]


def const(v: float) -> Jet:
    return (v, 0.0, 0.0, 0.0)


def add(a: Jet, b: Jet) -> Jet:
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2], a[3] + b[3])


def sub(a: Jet, b: Jet) -> Jet:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2], a[3] - b[3])


def scale(a: Jet, k: float) -> Jet:
    return (a[0] * k, a[1] * k, a[2] * k, a[3] * k)


def axpy(k: float, a: Jet, b: Jet) -> Jet:
    """k*a + b."""
    return (k * a[0] + b[0], k * a[1] + b[1], k * a[2] + b[2], k * a[3] + b[3])


def shift(a: Jet) -> Jet:
    """The jet of the derivative: (a', a'', a''', unknown = 0)."""
    return (a[1], a[2], a[3], 0.0)


def mul(a: Jet, b: Jet) -> Jet:
    """Leibniz rule."""
    a0, a1, a2, a3 = a
    b0, b1, b2, b3 = b
    return (
        a0 * b0,
        a1 * b0 + a0 * b1,
        a2 * b0 + 2.0 * a1 * b1 + a0 * b2,
        a3 * b0 + 3.0 * (a2 * b1 + a1 * b2) + a0 * b3,
    )


def div(n: Jet, r: Jet) -> Jet:
    """n / r by recurrence on q * r = n."""
    r0, r1, r2, r3 = r
    q0 = n[0] / r0
    q1 = (n[1] - q0 * r1) / r0
    q2 = (n[2] - 2.0 * q1 * r1 - q0 * r2) / r0
    q3 = (n[3] - 3.0 * (q2 * r1 + q1 * r2) - q0 * r3) / r0
    return (q0, q1, q2, q3)


def chain(f0: float, f1: float, f2: float, f3: float, a: Jet) -> Jet:
    """f(a) given f and its first three derivatives at a[0] (Faa di Bruno)."""
    _, a1, a2, a3 = a
    return (f0, f1 * a1, f2 * a1 * a1 + f1 * a2, f3 * a1 * a1 * a1 + 3.0 * f2 * a1 * a2 + f1 * a3)


def sin_cos(a: Jet) -> tuple[Jet, Jet]:
    s = sin(a[0])
    c = cos(a[0])
    return chain(s, c, -s, -c, a), chain(c, -s, -c, s, a)


def sqrt_(a: Jet) -> Jet:
    r = sqrt(a[0])
    return chain(r, 0.5 / r, -0.25 / (r * a[0]), 0.375 / (r * a[0] * a[0]), a)


def atan2(y: Jet, x: Jet) -> Jet:
    """atan2 with derivatives: theta' = (x y' - y x') / (x^2 + y^2). Exact to order 3.

    That is ``q = div(sub(mul(x, shift(y)), mul(y, shift(x))), add(mul(x, x), mul(y, y)))``
    and theta = (atan2, q0, q1, q2), written out: the same operations in the same order
    (the same result to the last bit, tested), keeping only the terms to order 2 that the
    result needs. The law calls it twice per control step.
    """
    x0, x1, x2, x3 = x
    y0, y1, y2, y3 = y
    r0 = x0 * x0 + y0 * y0  # r = x^2 + y^2 (Leibniz)
    r1 = (x1 * x0 + x0 * x1) + (y1 * y0 + y0 * y1)
    r2 = (x2 * x0 + 2.0 * x1 * x1 + x0 * x2) + (y2 * y0 + 2.0 * y1 * y1 + y0 * y2)
    n0 = x0 * y1 - y0 * x1  # n = x y' - y x'
    n1 = (x1 * y1 + x0 * y2) - (y1 * x1 + y0 * x2)
    n2 = (x2 * y1 + 2.0 * x1 * y2 + x0 * y3) - (y2 * x1 + 2.0 * y1 * x2 + y0 * x3)
    q0 = n0 / r0  # q = n / r by recurrence (div)
    q1 = (n1 - q0 * r1) / r0
    q2 = (n2 - 2.0 * q1 * r1 - q0 * r2) / r0
    return (_atan2(y0, x0), q0, q1, q2)

"""Fixed-step classical Runge-Kutta (RK4) on plain tuples.

The plant's state is 12 floats: tuples and a hand-unrolled combination are several times
faster than numpy arrays of that size. This is the generic step (any f); the plant's own
1 kHz step is :func:`plant.model.rk4_step_held`, the same arithmetic specialised for
eq. (6) with held inputs (bit for bit equal, about twice as fast).

In:  dx/dt = f(t, x), the state x, the time t and step h (s)
Out: the state after one RK4 step
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

Derivative = Callable[[float, tuple], tuple]


def rk4_step(f: Derivative, t: float, x: Sequence[float], h: float) -> tuple[float, ...]:
    """One RK4 step of dx/dt = f(t, x) from t to t + h (local error O(h^5))."""
    h2 = 0.5 * h
    k1 = f(t, x)
    k2 = f(t + h2, tuple([xi + h2 * ki for xi, ki in zip(x, k1)]))
    k3 = f(t + h2, tuple([xi + h2 * ki for xi, ki in zip(x, k2)]))
    k4 = f(t + h, tuple([xi + h * ki for xi, ki in zip(x, k3)]))
    h6 = h / 6.0
    return tuple([xi + h6 * (a + 2.0 * (b + c) + d) for xi, a, b, c, d in zip(x, k1, k2, k3, k4)])

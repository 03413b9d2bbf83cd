"""Angles: one wrap for the whole project (the law, the sensors, the estimator, the wire).

In:  an angle (rad), any real value
Out: the same angle in (-pi, pi] (rad)
"""

from __future__ import annotations

from math import pi

TWO_PI = 2.0 * pi


def wrap_angle(a: float) -> float:
    """a wrapped to (-pi, pi] (rad). A plain-float kernel: the law's batch cells and the estimator compile it."""
    b = a + pi
    # b % TWO_PI is b itself where 0 <= b < TWO_PI (the angles already wrapped, nearly all): the modulo, a library
    # call once compiled (~3 % of a batch cell-step), is skipped there; the same float either way
    a = (b if 0.0 <= b < TWO_PI else b % TWO_PI) - pi
    return pi if a == -pi else a

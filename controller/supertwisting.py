"""The last backstepping step: super-twisting (eq. 22) or first-order sliding mode.

Both return the "reaching" part of the command in acceleration units; the law adds the
model terms and the feed-forward phi-dot around it.
"""

from __future__ import annotations

from math import sqrt


def super_twisting_bound(k2: float, L: float) -> float:
    """Eq. (23): the smallest k1 for a disturbance whose derivative is bounded by L (k2 > L)."""
    return sqrt(4.0 * L * (k2 + L) / (k2 - L))


class SuperTwisting:
    """u = -k1 |s|^1/2 sign(s) + xi,  xi' = -k2 sign(s)   (eq. 22, rho = 1/2).

    The integrator is advanced by explicit Euler over the control period, clamped to
    |xi| <= xi_max (anti-windup) and frozen while ``hold`` is set (saturated actuators or
    stale state).
    """

    __slots__ = ("k1", "k2", "xi_max", "xi")

    def __init__(self, k1: float, k2: float, xi_max: float) -> None:
        self.k1 = k1
        self.k2 = k2
        self.xi_max = xi_max
        self.xi = 0.0

    def __call__(self, s: float) -> float:
        r = sqrt(abs(s))
        return (-self.k1 * r if s >= 0.0 else self.k1 * r) + self.xi

    def advance(self, s: float, dt: float, hold: bool = False) -> None:
        if hold or s == 0.0:
            return
        xi = self.xi - self.k2 * dt if s > 0.0 else self.xi + self.k2 * dt
        m = self.xi_max
        self.xi = m if xi > m else -m if xi < -m else xi

    def reset(self) -> None:
        self.xi = 0.0


class SignReaching:
    """First-order sliding mode: u = -k sign(s). The baseline the paper improves on."""

    __slots__ = ("k",)

    def __init__(self, k: float) -> None:
        self.k = k

    def __call__(self, s: float) -> float:
        return -self.k if s > 0.0 else self.k if s < 0.0 else 0.0

    def advance(self, s: float, dt: float, hold: bool = False) -> None:
        pass

    def reset(self) -> None:
        pass

"""The last backstepping step: super-twisting (eq. 22) or first-order sliding mode.

Both return the "reaching" part of the command in acceleration units; the law adds the
model terms and the feed-forward phi-dot around it.

In:  the sliding variable s of a loop's last step (m/s or rad/s), the gains k1 (units of s^1/2 per s),
     k2 (acceleration per s), the integrator xi and its clamp xi_max (acceleration), the control period (s)
Out: the reaching term (m/s^2 or rad/s^2) and the integrator after one period. :func:`reaching`,
     :func:`advance_xi` are the plain-float kernels the law and the batch engine share.
"""

from __future__ import annotations

from math import sqrt


def super_twisting_bound(k2: float, L: float) -> float:
    """Eq. (23): the smallest k1 for a disturbance whose derivative is bounded by L (k2 > L)."""
    return sqrt(4.0 * L * (k2 + L) / (k2 - L))


def reaching(s: float, k1: float, xi: float, k_sign: float, sign: bool) -> float:
    """The last step's reaching term: super-twisting -k1 |s|^1/2 sign(s) + xi (eq. 22, rho = 1/2), or with
    ``sign`` the first-order sliding mode -k_sign sign(s)."""
    if sign:
        return -k_sign if s > 0.0 else k_sign if s < 0.0 else 0.0
    r = sqrt(abs(s))
    return (-k1 * r if s >= 0.0 else k1 * r) + xi


def advance_xi(xi: float, s: float, k2: float, dt: float, xi_max: float, hold: bool) -> float:
    """xi' = -k2 sign(s) (eq. 22) by explicit Euler over dt (s), clamped to |xi| <= xi_max (anti-windup),
    unchanged while ``hold`` (saturated actuators, stale state) or s = 0."""
    if hold or s == 0.0:
        return xi
    xi = xi - k2 * dt if s > 0.0 else xi + k2 * dt
    return xi_max if xi > xi_max else -xi_max if xi < -xi_max else xi


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
        return reaching(s, self.k1, self.xi, 0.0, False)

    def advance(self, s: float, dt: float, hold: bool = False) -> None:
        self.xi = advance_xi(self.xi, s, self.k2, dt, self.xi_max, hold)

    def reset(self) -> None:
        self.xi = 0.0


class SignReaching:
    """First-order sliding mode: u = -k sign(s). The baseline the paper improves on."""

    __slots__ = ("k",)

    def __init__(self, k: float) -> None:
        self.k = k

    def __call__(self, s: float) -> float:
        return reaching(s, 0.0, 0.0, self.k, True)

    def advance(self, s: float, dt: float, hold: bool = False) -> None:
        pass

    def reset(self) -> None:
        pass

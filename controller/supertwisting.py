"""The last backstepping step: super-twisting (eq. 22) or first-order sliding mode.

Both return the "reaching" part of the command in acceleration units; the law adds the
model terms and the feed-forward phi-dot around it.

Two discretizations of eq. (22) over the control period h (docs/law.md, "Discretization"):

- ``explicit`` (the paper as printed, forward Euler): the term uses s_k and xi_k, and
  xi_{k+1} = xi_k - h k2 sign(s_k). Once |s| is small, xi jumps by +-k2 h every step and the
  sqrt term overshoots: a period-2 cycle in the command (issue 24).
- ``implicit`` (backward Euler, Brogliato, Polyakov and Efimov, IEEE Trans. Automatic Control, 2020: "The implicit
  discretization of the super-twisting sliding-mode control algorithm"; the set-valued sign treated as in
  Acary and Brogliato, Systems & Control Letters 59, 2010): the command is the one that brings the nominal
  sliding dynamics s' = u to s~_{k+1} in one step, with the sign and the root taken at s~_{k+1}, not s_k
  (:func:`implicit_twisting`).

In:  the sliding variable s of a loop's last step (m/s or rad/s), the gains k1 (units of s^1/2 per s),
     k2 (acceleration per s), the integrator xi and its clamp xi_max (acceleration), the control period (s)
Out: the reaching term (m/s^2 or rad/s^2) and the integrator after one period. :func:`reaching`,
     :func:`advance_xi`, :func:`implicit_twisting` and :func:`advance_xi_implicit` are the plain-float
     kernels the law and the batch engine share.
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


def implicit_twisting(s: float, xi: float, k1: float, k2: float, h: float) -> tuple[float, float]:
    """One backward-Euler step of the super-twisting law (Brogliato, Polyakov, Efimov 2020):
    (the reaching term u_k, xi_{k+1}) for s_k = ``s``, xi_k = ``xi`` and the period h (s).

    The implicit step of s' = -k1 |s|^1/2 sign(s) + xi, xi' = -k2 Sign(s) over h is
        s~ = s_k + h u_k,   u_k = -k1 |s~|^1/2 Sign(s~) + xi_{k+1},   xi_{k+1} = xi_k - h k2 Sign(s~)    (1)
    with Sign the set-valued sign (Sign(0) = [-1, 1]). Eliminating xi_{k+1}, with w = s_k + h xi_k:
        s~ + h k1 |s~|^1/2 Sign(s~) + h^2 k2 Sign(s~)  contains  w.                                        (2)
    Its unique solution in closed form:
    - |w| <= h^2 k2 (the dead zone): s~ = 0, Sign(s~) = w / (h^2 k2), so xi_{k+1} = xi_k - w/h = -s_k/h
      and u_k = xi_{k+1};
    - otherwise sign(s~) = sign(w) and r = |s~|^1/2 >= 0 solves r^2 + h k1 r + h^2 k2 - |w| = 0:
      r = 2 c / (b + sqrt(b^2 + 4 c)), b = h k1, c = |w| - h^2 k2 > 0 (the positive root, written
      without the cancellation of (-b + sqrt(b^2 + 4c)) / 2); xi_{k+1} = xi_k - h k2 sign(w),
      u_k = -k1 r sign(w) + xi_{k+1}.
    Either way u_k = (s~ - s_k) / h (tests/test_implicit.py). The command is a continuous function of
    (s_k, xi_k): no sign of s_k itself is taken, so nothing alternates once s is near zero."""
    w = s + h * xi
    dz = h * h * k2
    if -dz <= w <= dz:
        xi1 = -s / h
        return xi1, xi1
    b = h * k1
    c = (w if w > 0.0 else -w) - dz
    r = 2.0 * c / (b + sqrt(b * b + 4.0 * c))
    if w > 0.0:
        xi1 = xi - h * k2
        return xi1 - k1 * r, xi1
    xi1 = xi + h * k2
    return xi1 + k1 * r, xi1


def advance_xi_implicit(xi: float, s: float, k1: float, k2: float, h: float, xi_max: float, hold: bool) -> float:
    """xi_{k+1} of :func:`implicit_twisting` (eq. (1) there), clamped to |xi| <= xi_max (anti-windup),
    unchanged while ``hold`` (saturated actuators, stale state), as :func:`advance_xi`."""
    if hold:
        return xi
    xi = implicit_twisting(s, xi, k1, k2, h)[1]
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

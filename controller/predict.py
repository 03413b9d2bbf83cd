"""Latency compensation: carry a delayed state forward to "now" through the law's nominal model.

The controller receives the vehicle's state some time after it was measured (its age).
:class:`Predictor` integrates the nominal model of eq. (6) (corrected: docs/law.md, "Plant model") from that
state over its age, applying the wrenches the controller itself sent in the meantime, each
from the time it was sent plus an assumed command latency ``lag_s``, and returns the
predicted state, on which the law then computes its command.

Why this is not ``plant/``'s integrator: the controller must not import the plant
(docs/design.md, "Parts and layers"). A real offboard computer has a model of the vehicle, not the
simulator; this is that model: the law's :class:`~controller.nominal.Nominal` constants,
no drag, no disturbance, no motor lag, no ground, and the realisable wrench taken as
exactly applied. Everything else the plant does is prediction error that the next state
corrects. It is a few lines of RK4 at the control period, which is all it needs (the
horizon is a few periods).
"""

from __future__ import annotations

from collections import deque
from math import cos, sin

from controller.nominal import Coefficients, Nominal

State = tuple[float, ...]
Quad = tuple[float, float, float, float]


class NominalModel:
    """Eq. (6), corrected, with the nominal constants: ``derivative`` and one RK4 step."""

    def __init__(self, n: Nominal) -> None:
        self.m = n.mass
        self.g = n.gravity
        self.c = Coefficients.of(n)

    def derivative(self, X: State, u: Quad, omega_d: float) -> State:
        """dX/dt for state X (eq. 7 order, SI) under wrench u = (u1 N, u2..u4 as in eq. 6)."""
        _, vx, _, vy, _, vz, phi, dphi, th, dth, psi, dpsi = X
        cphi, sphi, cth, sth, cpsi, spsi = cos(phi), sin(phi), cos(th), sin(th), cos(psi), sin(psi)
        a = u[0] / self.m
        c = self.c
        return (
            vx, (cphi * sth * cpsi + sphi * spsi) * a,
            vy, (cphi * sth * spsi - sphi * cpsi) * a,
            vz, cphi * cth * a - self.g,
            dphi, c.i1 * dth * dpsi - c.jr_x * dth * omega_d + c.l_x * u[1],
            dth, c.i2 * dphi * dpsi + c.jr_y * dphi * omega_d + c.l_y * u[2],
            dpsi, c.i3 * dphi * dth + c.l_z * u[3],
        )

    def rk4(self, X: State, u: Quad, omega_d: float, h: float) -> State:
        """One classical Runge–Kutta step of h seconds with the wrench held.

        Bit for bit RK4 of :meth:`derivative` (stages X + h/2 k1, X + h/2 k2, X + h k3; X + h/6 (k1 +
        2 k2 + 2 k3 + k4); tested), written out: positions never enter the derivative, so each stage
        carries the 9 velocities, angles and rates in local floats (a horizon of 57 ms is 15 steps a
        control period: this is most of a predicting controller's time).
        """
        a = u[0] / self.m
        g = self.g
        c = self.c
        i1, i2, i3, jr_x, jr_y = c.i1, c.i2, c.i3, c.jr_x, c.jr_y
        tx, ty, tz = c.l_x * u[1], c.l_y * u[2], c.l_z * u[3]
        x, vx, y, vy, z, vz, phi, dphi, th, dth, psi, dpsi = X
        v1, v2, v3, f, df, t, dt, p, dp = vx, vy, vz, phi, dphi, th, dth, psi, dpsi  # the stage's values
        hh = 0.5 * h
        k = []
        for step in (hh, hh, h, 0.0):
            cf, sf, ct, st, cp, sp = cos(f), sin(f), cos(t), sin(t), cos(p), sin(p)
            ax = (cf * st * cp + sf * sp) * a
            ay = (cf * st * sp - sf * cp) * a
            az = cf * ct * a - g
            ddf = i1 * dt * dp - jr_x * dt * omega_d + tx
            ddt = i2 * df * dp + jr_y * df * omega_d + ty
            ddp = i3 * df * dt + tz
            k.append((v1, ax, v2, ay, v3, az, df, ddf, dt, ddt, dp, ddp))
            v1, v2, v3 = vx + step * ax, vy + step * ay, vz + step * az
            f, df, t, dt, p, dp = phi + step * df, dphi + step * ddf, th + step * dt, dth + step * ddt, \
                psi + step * dp, dpsi + step * ddp
        s = h / 6.0
        (a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11), (b0, b1, b2, b3, b4, b5, b6, b7, b8, b9, b10, b11), \
            (c0, c1, c2, c3, c4, c5, c6, c7, c8, c9, c10, c11), (d0, d1, d2, d3, d4, d5, d6, d7, d8, d9, d10, d11) = k
        return (x + s * (a0 + 2.0 * b0 + 2.0 * c0 + d0), vx + s * (a1 + 2.0 * b1 + 2.0 * c1 + d1),
                y + s * (a2 + 2.0 * b2 + 2.0 * c2 + d2), vy + s * (a3 + 2.0 * b3 + 2.0 * c3 + d3),
                z + s * (a4 + 2.0 * b4 + 2.0 * c4 + d4), vz + s * (a5 + 2.0 * b5 + 2.0 * c5 + d5),
                phi + s * (a6 + 2.0 * b6 + 2.0 * c6 + d6), dphi + s * (a7 + 2.0 * b7 + 2.0 * c7 + d7),
                th + s * (a8 + 2.0 * b8 + 2.0 * c8 + d8), dth + s * (a9 + 2.0 * b9 + 2.0 * c9 + d9),
                psi + s * (a10 + 2.0 * b10 + 2.0 * c10 + d10), dpsi + s * (a11 + 2.0 * b11 + 2.0 * c11 + d11))


class Predictor:
    """The state "now" from the newest (delayed) state and the commands sent since.

    ``sent(t, u, omega_d)`` records each command the controller sends (time in s, the
    realisable wrench, the signed rotor-speed sum of eq. 5); ``predict(t_state, X, t)``
    returns X carried from ``t_state`` to ``t``. Steps are at most ``dt_max`` seconds.
    Predictions from the same state are continued incrementally, so holding a stale state
    costs one step per call.
    """

    def __init__(self, nominal: Nominal, dt_max: float, lag_s: float = 0.0) -> None:
        self.model = NominalModel(nominal)
        self.dt_max = dt_max
        self.lag_s = lag_s
        self._cmds: deque[tuple[float, Quad, float]] = deque()
        self._from: float | None = None  # time stamp of the state the cache starts from
        self._t = 0.0
        self._X: State = ()

    def sent(self, t: float, u: Quad, omega_d: float) -> None:
        self._cmds.append((t + self.lag_s, u, omega_d))

    def reset(self) -> None:
        self._cmds.clear()
        self._from = None

    def predict(self, t_state: float, X: State, t: float) -> State:
        """X (measured at t_state) carried forward to t >= t_state through the nominal model.

        Calls with the same state must come with non-decreasing t and commands recorded
        in time order (the cached prediction is continued, not recomputed).
        """
        if t <= t_state:
            return X
        if self._from == t_state and self._t <= t:
            start_t, start_X = self._t, self._X
        else:
            start_t, start_X = t_state, tuple(X)
        cmds = self._cmds
        while len(cmds) > 1 and cmds[1][0] <= t_state:  # keep the one in effect at t_state
            cmds.popleft()
        Xp = self._propagate(start_X, start_t, t)
        self._from, self._t, self._X = t_state, t, Xp
        return Xp

    def _propagate(self, X: State, tau: float, t: float) -> State:
        cmds = self._cmds
        n = len(cmds)
        i = -1  # index of the command in effect at tau (-1: none yet, zero wrench)
        while i + 1 < n and cmds[i + 1][0] <= tau:
            i += 1
        rk4 = self.model.rk4
        while tau < t:
            nxt = cmds[i + 1][0] if i + 1 < n else t
            end = nxt if nxt < t else t
            if i >= 0:
                _, u, od = cmds[i]
            else:
                u, od = (0.0, 0.0, 0.0, 0.0), 0.0
            span = end - tau
            if span > 0.0:
                k = max(1, int(span / self.dt_max + 0.999999))
                h = span / k
                for _ in range(k):
                    X = rk4(X, u, od, h)
            tau = end
            if end == nxt and i + 1 < n:
                i += 1
        return X

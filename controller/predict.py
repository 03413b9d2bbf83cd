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

In:  the nominal model, the newest state (eq. 7: m, m/s, rad, rad/s) and its stamp (s), the commands sent
     (time s, realisable wrench N, omega_d rad/s), the time to predict to (s)
Out: the state carried to that time through the nominal model (RK4 steps of at most ``dt_max`` s)
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
        """One classical Runge–Kutta step of h seconds with the wrench held (:func:`nominal_rk4`)."""
        c = self.c
        return nominal_rk4(X, u[0] / self.m, self.g, c.i1, c.i2, c.i3, c.jr_x, c.jr_y, c.l_x * u[1], c.l_y * u[2],
                           c.l_z * u[3], omega_d, h)


def nominal_rk4(X: State, a: float, g: float, i1: float, i2: float, i3: float, jr_x: float, jr_y: float,
                tx: float, ty: float, tz: float, omega_d: float, h: float) -> State:
    """One RK4 step of h s of eq. (6), corrected, with the wrench held: ``a`` = u1/m (m/s²), ``g`` (m/s²),
    the :class:`~controller.nominal.Coefficients` i1..i3, jr_x, jr_y, the torque terms tx, ty, tz =
    l_x u2, l_y u3, l_z u4 (rad/s²) and omega_d (rad/s, eq. 5).

    Bit for bit RK4 of :meth:`NominalModel.derivative` (stages X + h/2 k1, X + h/2 k2, X + h k3;
    X + h/6 (k1 + 2 k2 + 2 k3 + k4), the sum in that order; tested), written out: positions never enter
    the derivative, so each stage carries the 9 velocities, angles and rates in local floats (a horizon of
    57 ms is 15 steps a control period: this is most of a predicting controller's time). Plain floats and
    a tuple: the batch engine compiles this same function (numba) for its cells.
    """
    x, vx, y, vy, z, vz, phi, dphi, th, dth, psi, dpsi = X
    hh = 0.5 * h
    v1, v2, v3, f, df, t, dt, p, dp = vx, vy, vz, phi, dphi, th, dth, psi, dpsi  # the stage's values
    sx = sy = sz = svx = svy = svz = sf = sdf = st = sdt = sp = sdp = 0.0  # k1 + 2 k2 + 2 k3 + k4, so far
    for stage in range(4):
        step = hh if stage < 2 else (h if stage == 2 else 0.0)  # where the next stage is taken
        w = 1.0 if stage == 0 or stage == 3 else 2.0
        cf, snf, ct, snt, cp, snp = cos(f), sin(f), cos(t), sin(t), cos(p), sin(p)
        ax = (cf * snt * cp + snf * snp) * a
        ay = (cf * snt * snp - snf * cp) * a
        az = cf * ct * a - g
        ddf = i1 * dt * dp - jr_x * dt * omega_d + tx
        ddt = i2 * df * dp + jr_y * df * omega_d + ty
        ddp = i3 * df * dt + tz
        if stage == 0:
            sx, svx, sy, svy, sz, svz, sf, sdf, st, sdt, sp, sdp = v1, ax, v2, ay, v3, az, df, ddf, dt, ddt, dp, ddp
        else:
            sx, svx, sy, svy, sz, svz = sx + w * v1, svx + w * ax, sy + w * v2, svy + w * ay, sz + w * v3, \
                svz + w * az
            sf, sdf, st, sdt, sp, sdp = sf + w * df, sdf + w * ddf, st + w * dt, sdt + w * ddt, sp + w * dp, \
                sdp + w * ddp
        v1, v2, v3 = vx + step * ax, vy + step * ay, vz + step * az
        f, df, t, dt, p, dp = phi + step * df, dphi + step * ddf, th + step * dt, dth + step * ddt, \
            psi + step * dp, dpsi + step * ddp
    s = h / 6.0
    return (x + s * sx, vx + s * svx, y + s * sy, vy + s * svy, z + s * sz, vz + s * svz,
            phi + s * sf, dphi + s * sdf, th + s * st, dth + s * sdt, psi + s * sp, dpsi + s * sdp)


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

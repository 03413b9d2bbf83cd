"""The plant of :class:`plant.quadrotor.Quadrotor` for N cells at once: a compiled loop over the cell axis.

In:  one profile and one set of effects for every cell, a seed per cell (the disturbance's phases), the
     physics rate (Hz) and the start state (eq. 7: m, m/s, rad, rad/s); then per step what each cell's
     command holds (see :meth:`BatchPlant.held`)
Out: the states [12, N] (eq. 7 order, NWU), the realised wrench [4, N] (N), ground contact and divergence
     per cell

The same model as the scalar plant: eq. (6) corrected, RK4 with the inputs held over a physics step,
drag, motor lag, the external disturbance, mass and inertia mismatch, and the ground plane. The step is
:func:`plant.model.rk4_step_held`'s arithmetic in its order, compiled with numba (``_rk4_step``: one pass
over the cells, a cell's stages in registers). One thing is arranged for speed, not for a different
result: the sines and cosines of a stage are the step's start ones turned by the stage's small angle
increment (angle addition, with a Taylor series accurate to 1e-15 for the increments a physics step
gives; a true evaluation whenever an increment is larger, and at the start of every control period).
The results agree with the scalar plant to about 1e-14, not to the bit.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numba import njit

from plant.effects import Effects
from plant.model import rigid_body
from plant.profiles import Profile

_SMALL = 0.02  # rad: the largest angle increment turned by the series (its error there is < 1e-15)


class BatchPlant:
    """N quadrotors of one profile and effects, each with its own command and disturbance phases."""

    def __init__(self, profile: Profile, effects: Effects | None, seeds: Sequence[int], *, physics_hz: float,
                 state: Sequence[float], ground: bool = True) -> None:
        e = effects or Effects()
        self.profile = profile
        self.effects = e
        n = len(seeds)
        self.n = n
        self.body = b = rigid_body(
            mass=profile.mass * e.mass_scale, ixx=profile.ixx * e.inertia_scale, iyy=profile.iyy * e.inertia_scale,
            izz=profile.izz * e.inertia_scale, arm=profile.arm, rotor_inertia=profile.rotor_inertia,
            gravity=profile.gravity, drag=profile.drag if e.drag else (0.0,) * 6)
        self.dt = 1.0 / physics_hz
        self.ground = ground
        self.t = 0.0
        self.X = np.repeat(np.asarray(state, float)[:, None], n, axis=1)
        self.motors = profile.actuation == "motors"
        self.lagged = self.motors and e.motor_lag
        self._lag_k = 1.0 - math.exp(-self.dt / profile.motor_time_constant)
        d = e.disturbance
        self.disturbed = d.active
        if self.disturbed:
            self._phases = np.array([d.phases(s) for s in seeds]).T  # [6, N]
            self._const = np.array(d.force_const + d.torque_const)[:, None]
            self._amp = np.array(d.force_amp + d.torque_amp)[:, None]
            self._ext_t = math.nan  # the time of the disturbance in _ext[2]
        # the disturbance at a step's start, middle and end ([3, 6, N]; a stand-in [3, 6, 1] when there is none)
        self._ext = np.zeros((3, 6, n if self.disturbed else 1))
        self._consts = np.array([b.mass, b.gravity, b.l_x, b.l_y, b.l_z, b.jr_x, b.jr_y, b.i1, b.i2, b.i3, *b.kv,
                                 *b.kw, self.dt, b.ixx, b.iyy, b.izz])  # in the order of _MASS ... _IZZ
        hover = profile.hover_omega
        self.omega = np.full((4, n), hover if self.motors else 0.0)
        self.target = self.omega.copy()
        self._u = np.zeros((5, n))  # what the step integrates with: the realised u1..u4 (N) and omega_d (rad/s)
        self.realised = self._u[:4]
        self.omega_d = self._u[4]
        # what a command holds (see held): the target speeds with motor lag, else the rows of _u
        self.holding = self.target if self.lagged else self._u
        self._c_lo = np.array([0.0, -1.0, -1.0, -1.0])  # the wrench command's range, [c_lo, 1]
        self._u_max = np.array(profile.u_max, float)
        # the sines and cosines of each cell's angles at its next step's start (rows cos phi, sin phi,
        # cos theta, sin theta, cos psi, sin psi), and whether they must be evaluated anew rather than read
        self._T0 = np.zeros((6, n))
        self._fresh = np.ones(n, bool)
        self.hold(self.held(np.zeros((4, n))))

    # -- actuation -------------------------------------------------------------------------------------
    def held(self, c: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """What :meth:`Quadrotor.command` holds for normalised commands c [4, k]: ``wrench`` and ``motors``
        without lag the realised u1..u4 (N) and omega_d (rad/s), [5, k]; ``motors`` with lag the four
        target speeds (rad/s), [4, k]. Into ``out`` if given (and returned)."""
        p = self.profile
        if not self.motors:
            if out is None:
                out = np.empty((5, c.shape[1]))
            _held_wrench(np.ascontiguousarray(c), self._c_lo, self._u_max, p.thrust_coeff, p.drag_coeff, out)
            return out
        target = np.minimum(np.maximum(c, 0.0), 1.0) * p.omega_max
        v = target if self.lagged else np.vstack(self._from_speeds(target))
        if out is None:
            return v
        out[...] = v
        return out

    def _from_speeds(self, omega: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Eq. (4) and (5): rotor speeds [4, k] -> (realised u [4, k], omega_d [1, k])."""
        p = self.profile
        b, d = p.thrust_coeff, p.drag_coeff
        w = omega * omega
        u = np.stack((b * (w[0] + w[1] + w[2] + w[3]), b * (w[3] - w[1]), b * (w[2] - w[0]),
                      d * (w[1] + w[3] - w[0] - w[2])))
        return u, (omega[1] + omega[3] - omega[0] - omega[2])[None, :]

    def hold(self, values: np.ndarray, cols: np.ndarray | slice | None = None) -> None:
        """Hold what :meth:`held` gave for the cells ``cols`` (all by default) until their next command."""
        self.holding[:, slice(None) if cols is None else cols] = values

    # -- dynamics ----------------------------------------------------------------------------------------
    def _disturbance(self, t: float, out: np.ndarray) -> None:
        """The external force (N) and torque (N m) at t into out [6, N] (plant.effects.disturbance_at)."""
        d = self.effects.disturbance
        w = 2.0 * math.pi * d.freq_hz * t
        np.sin(w + self._phases, out=out)
        out *= self._amp
        out += self._const

    def resync(self) -> None:
        """Evaluate the next step's sines and cosines anew (the engine calls it once per control period,
        so that the angle additions never accumulate over more than a few steps)."""
        self._fresh[:] = True

    def step(self) -> None:
        """Advance every cell one physics step (RK4 of eq. 6, commands and rotor speeds held)."""
        t, h = self.t, self.dt
        if self.lagged:
            self.omega += (self.target - self.omega) * self._lag_k
            u, od = self._from_speeds(self.omega)
            self.realised[...] = u
            self.omega_d[...] = od[0]
        ext = self._ext
        if self.disturbed:
            if self._ext_t == t:  # the last step's end is this one's start
                ext[0] = ext[2]
            else:
                self._disturbance(t, ext[0])
            self._disturbance(t + 0.5 * h, ext[1])
            self._disturbance(t + h, ext[2])
            self._ext_t = t + h
        _rk4_step(self.X, self._T0, self._fresh, self.realised, self.omega_d, ext, self.disturbed, self._consts,
                  self.ground)
        self.t = t + h

    @property
    def on_ground(self) -> np.ndarray:
        """[N] bool: resting on the ground plane (z <= 0 and not rising)."""
        X = self.X
        return (X[4] <= 0.0) & (X[5] <= 0.0) & self.ground

    def diverged(self) -> np.ndarray:
        """[N] bool: :meth:`Quadrotor.diverged` — not finite, |position| > 100 m, or tilt beyond 90 degrees."""
        bad = np.empty(self.n, bool)
        _diverged(self.X, bad)
        return bad


# -- the compiled step ----------------------------------------------------------------------------------
# consts of _rk4_step, in this order (BatchPlant._consts)
_MASS, _G, _LX, _LY, _LZ, _JRX, _JRY, _I1, _I2, _I3, _KV, _KW, _DT, _IXX, _IYY, _IZZ = (
    0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 13, 16, 17, 18, 19)


@njit(cache=True)
def net_rotor_speed(u0: float, u1: float, u2: float, u3: float, b: float, d: float) -> float:
    """The rotors' net speed w2 + w4 - w1 - w3 (rad/s, the gyroscopic term of eq. 6) of the wrench
    (u1..u4, N and N m) through the inverse of eq. 5 (thrust factor b, drag factor d), squares clipped at 0."""
    s24 = 0.5 * (u0 / b + u3 / d)
    s13 = 0.5 * (u0 / b - u3 / d)
    w0 = math.sqrt(max(0.5 * (s13 - u2 / b), 0.0))
    w1 = math.sqrt(max(0.5 * (s24 - u1 / b), 0.0))
    w2 = math.sqrt(max(0.5 * (s13 + u2 / b), 0.0))
    w3 = math.sqrt(max(0.5 * (s24 + u1 / b), 0.0))
    return w1 + w3 - w0 - w2


@njit(cache=True, inline="always")
def _turned(c0: float, s0: float, angle0: float, d: float) -> tuple[float, float]:
    """(cos, sin) of angle0 + d from those of angle0 (c0, s0): angle addition with the Taylor series of d
    while |d| <= _SMALL (its error there < 1e-15), else evaluated."""
    if abs(d) > _SMALL:
        return math.cos(angle0 + d), math.sin(angle0 + d)
    d2 = d * d
    sd = d * (1.0 + d2 * (-1.0 / 6.0 + d2 * (1.0 / 120.0)))
    cd = 1.0 + d2 * (-0.5 + d2 * (1.0 / 24.0 - d2 * (1.0 / 720.0)))
    return c0 * cd - s0 * sd, s0 * cd + c0 * sd


@njit(cache=True)
def _rk4_step(X: np.ndarray, T0: np.ndarray, fresh: np.ndarray, realised: np.ndarray, omega_d: np.ndarray,
              ext: np.ndarray, disturbed: bool, k: np.ndarray, ground: bool) -> None:  # pragma: no cover
    """One RK4 step of every cell in place: :func:`plant.model.rk4_step_held`'s operations in its order, but
    for the sines and cosines (see :func:`_turned`): a cell's start ones are read from T0 [6, N] unless
    ``fresh``, and the next step's are left there. ext [3, 6, N]: the force (N) and torque (N m) at the
    step's start, middle and end (read only when ``disturbed``); then the ground plane."""
    m, g, h = k[_MASS], k[_G], k[_DT]
    i1, i2, i3, jr_x, jr_y = k[_I1], k[_I2], k[_I3], k[_JRX], k[_JRY]
    kv0, kv1, kv2 = k[_KV], k[_KV + 1], k[_KV + 2]
    kw0, kw1, kw2 = k[_KW], k[_KW + 1], k[_KW + 2]
    ixx, iyy, izz = k[_IXX], k[_IYY], k[_IZZ]
    h2 = 0.5 * h
    h6 = h / 6.0
    kk = np.empty((4, 12))  # the four stages' derivatives (eq. 7 order)
    for j in range(X.shape[1]):
        vx, vy, vz = X[1, j], X[3, j], X[5, j]
        phi, dphi, th, dth, psi, dpsi = X[6, j], X[7, j], X[8, j], X[9, j], X[10, j], X[11, j]
        if fresh[j]:
            c_f0, s_f0, c_t0, s_t0 = math.cos(phi), math.sin(phi), math.cos(th), math.sin(th)
            c_p0, s_p0 = math.cos(psi), math.sin(psi)
        else:
            c_f0, s_f0, c_t0, s_t0, c_p0, s_p0 = T0[0, j], T0[1, j], T0[2, j], T0[3, j], T0[4, j], T0[5, j]
        a = realised[0, j] / m
        od = omega_d[j]
        tx = k[_LX] * realised[1, j]
        ty = k[_LY] * realised[2, j]
        tz = k[_LZ] * realised[3, j]
        v1, v2, v3, df, dt, dp = vx, vy, vz, dphi, dth, dpsi  # the stage's velocities and rates
        cf, sf, ct, st, cp, sp = c_f0, s_f0, c_t0, s_t0, c_p0, s_p0  # and its sines and cosines
        for s in range(4):
            cf_st = cf * st
            ax = (cf_st * cp + sf * sp) * a - kv0 * v1
            ay = (cf_st * sp - sf * cp) * a - kv1 * v2
            az = cf * ct * a - g - kv2 * v3
            ddf = i1 * dt * dp - jr_x * dt * od + tx - kw0 * df
            ddt = i2 * df * dp + jr_y * df * od + ty - kw1 * dt
            ddp = i3 * df * dt + tz - kw2 * dp
            if disturbed:
                e = 0 if s == 0 else 1 if s < 3 else 2  # the ext at t, t + h/2, t + h
                ax += ext[e, 0, j] / m
                ay += ext[e, 1, j] / m
                az += ext[e, 2, j] / m
                ddf += ext[e, 3, j] / ixx
                ddt += ext[e, 4, j] / iyy
                ddp += ext[e, 5, j] / izz
            r = kk[s]
            r[0], r[1], r[2], r[3], r[4], r[5] = v1, ax, v2, ay, v3, az
            r[6], r[7], r[8], r[9], r[10], r[11] = df, ddf, dt, ddt, dp, ddp
            if s < 3:  # the next stage: the start plus c times this stage's derivative
                c = h2 if s < 2 else h
                cf, sf = _turned(c_f0, s_f0, phi, c * df)
                ct, st = _turned(c_t0, s_t0, th, c * dt)
                cp, sp = _turned(c_p0, s_p0, psi, c * dp)
                v1, v2, v3 = vx + c * ax, vy + c * ay, vz + c * az
                df, dt, dp = dphi + c * ddf, dth + c * ddt, dpsi + c * ddp
        for i in range(12):  # rk4_step's x + h/6 (k1 + 2 (k2 + k3) + k4), term by term: the same rounding
            X[i, j] += h6 * (kk[0, i] + 2.0 * (kk[1, i] + kk[2, i]) + kk[3, i])
        if ground and X[4, j] < 0.0:  # plant.quadrotor._on_ground: resting, level, heading kept
            X[1, j] = X[3, j] = X[4, j] = X[6, j] = X[7, j] = X[8, j] = X[9, j] = X[11, j] = 0.0
            X[5, j] = max(X[5, j], 0.0)
            fresh[j] = True
            continue
        # the next step's start: these angles turned by the step's increments (evaluated if any is large)
        d_f, d_t, d_p = X[6, j] - phi, X[8, j] - th, X[10, j] - psi
        if abs(d_f) > _SMALL or abs(d_t) > _SMALL or abs(d_p) > _SMALL:
            fresh[j] = True
            continue
        T0[0, j], T0[1, j] = _turned(c_f0, s_f0, phi, d_f)
        T0[2, j], T0[3, j] = _turned(c_t0, s_t0, th, d_t)
        T0[4, j], T0[5, j] = _turned(c_p0, s_p0, psi, d_p)
        fresh[j] = False


@njit(cache=True)
def _diverged(X: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover
    """:meth:`Quadrotor.diverged` of every cell into out [N] bool."""
    for j in range(X.shape[1]):
        bad = False
        for i in range(12):
            if not math.isfinite(X[i, j]):
                bad = True
        out[j] = (bad or X[0, j] * X[0, j] + X[2, j] * X[2, j] + X[4, j] * X[4, j] > 1e4
                  or math.cos(X[6, j]) * math.cos(X[8, j]) < 0.0)


@njit(cache=True)
def _held_wrench(c: np.ndarray, c_lo: np.ndarray, u_max: np.ndarray, b: float, d: float,
                 out: np.ndarray) -> None:  # pragma: no cover
    """The ``wrench`` profile's :meth:`BatchPlant.held`: the clamped wrench and the omega_d its rotor speeds
    give, per cell (c [4, k] -> out [5, k])."""
    for j in range(c.shape[1]):
        u0 = min(max(c[0, j], c_lo[0]), 1.0) * u_max[0]
        u1 = min(max(c[1, j], c_lo[1]), 1.0) * u_max[1]
        u2 = min(max(c[2, j], c_lo[2]), 1.0) * u_max[2]
        u3 = min(max(c[3, j], c_lo[3]), 1.0) * u_max[3]
        out[0, j], out[1, j], out[2, j], out[3, j] = u0, u1, u2, u3
        out[4, j] = net_rotor_speed(u0, u1, u2, u3, b, d)

"""The plant of :class:`plant.quadrotor.Quadrotor` for N cells at once: numpy over the cell axis.

In:  one profile and one set of effects for every cell, a seed per cell (the disturbance's phases), the
     physics rate (Hz) and the start state (eq. 7: m, m/s, rad, rad/s); then per step what each cell's
     command holds (see :meth:`BatchPlant.held`)
Out: the states [12, N] (eq. 7 order, NWU), the realised wrench [4, N] (N), ground contact and divergence
     per cell

The same model as the scalar plant: eq. (6) corrected, RK4 with the inputs held over a physics step,
drag, motor lag, the external disturbance, mass and inertia mismatch, and the ground plane. Two things
are arranged for speed, not for a different result: the four stages are evaluated on [3, N] and
[12, N] blocks (a few dozen array operations per step whatever N is), and the sines and cosines of a
stage are the step's start ones turned by the stage's small angle increment (angle addition, with a
Taylor series accurate to 1e-14 for the increments a physics step gives; a true evaluation whenever an
increment is larger, and at the start of every control period). The results agree with the scalar
plant to 1e-14, not to the bit.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from plant.effects import Effects
from plant.model import rigid_body
from plant.profiles import Profile

_SMALL = 0.02  # rad: the largest stage increment turned by the series (its error there is < 1e-15)
_SHORT = 0.004  # rad: below it the series' 3rd and 4th terms (< 1e-14) are left out


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
            self._ext_scale = np.array([1.0 / b.mass] * 3 + [1.0 / b.ixx, 1.0 / b.iyy, 1.0 / b.izz])[:, None]
            self._ext_next: tuple[float, np.ndarray] | None = None
        self.drag = any(b.kv) or any(b.kw)
        self._kv = np.array(b.kv)[:, None]
        self._kw = np.array(b.kw)[:, None]
        hover = profile.hover_omega
        self.omega = np.full((4, n), hover if self.motors else 0.0)
        self.target = self.omega.copy()
        self.realised = np.zeros((4, n))
        self.omega_d = np.zeros(n)
        self._c_lo = np.array([0.0, -1.0, -1.0, -1.0])[:, None]  # the wrench command's range, [c_lo, 1]
        self._u_max = np.array(profile.u_max)[:, None]
        self._K = np.zeros((4, 12, n))
        self._tmp = np.zeros((12, n))
        self._delta = np.zeros((3, n))
        # a stage's trig, rows (cos phi, sin phi, cos theta, sin theta, cos psi, sin psi, -cos psi): the
        # cosines and the sines are each a strided view, and (c_psi, s_psi), (s_psi, -c_psi) are pairs
        self._T = np.zeros((7, n))
        self._T0 = np.zeros((7, n))  # the step's start angles'
        self._trig_valid = False
        self._turn_short = False
        self._lxy = np.array([b.l_x, b.l_y])[:, None]
        self._jr12 = np.array([-b.jr_x, b.jr_y])[:, None]
        self._i12 = np.array([b.i1, b.i2])[:, None]
        self.hold(self.held(np.zeros((4, n))))

    # -- actuation -------------------------------------------------------------------------------------
    def held(self, c: np.ndarray) -> np.ndarray:
        """What :meth:`Quadrotor.command` holds for normalised commands c [4, k]: ``wrench`` and ``motors``
        without lag the realised u1..u4 (N) and omega_d (rad/s), [5, k]; ``motors`` with lag the four
        target speeds (rad/s), [4, k]."""
        p = self.profile
        if not self.motors:
            u = np.minimum(np.maximum(c, self._c_lo), 1.0) * self._u_max
            b, d = p.thrust_coeff, p.drag_coeff
            s24 = 0.5 * (u[0] / b + u[3] / d)
            s13 = 0.5 * (u[0] / b - u[3] / d)
            w = np.sqrt(np.maximum(0.5 * np.stack((s13 - u[2] / b, s24 - u[1] / b, s13 + u[2] / b,
                                                   s24 + u[1] / b)), 0.0))
            return np.vstack((u, (w[1] + w[3] - w[0] - w[2])[None, :]))
        target = np.minimum(np.maximum(c, 0.0), 1.0) * p.omega_max
        if self.lagged:
            return target
        return np.vstack(self._from_speeds(target))

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
        cols = slice(None) if cols is None else cols
        if self.lagged:
            self.target[:, cols] = values
            return
        self.realised[:, cols] = values[:4]
        self.omega_d[cols] = values[4]

    # -- dynamics ----------------------------------------------------------------------------------------
    def _disturbance(self, t: float) -> np.ndarray:
        """The external force and torque at t, as accelerations (m/s^2, rad/s^2) [6, N]."""
        d = self.effects.disturbance
        w = 2.0 * math.pi * d.freq_hz * t
        return (self._const + self._amp * np.sin(w + self._phases)) * self._ext_scale

    def _turn(self, delta: np.ndarray, T: np.ndarray) -> None:
        """The trig rows (see ``_T``) of the step's start angles plus ``delta`` [3, N] into T, by angle
        addition (the caller has checked that every increment is small: ``_turn_short`` or below _SMALL)."""
        T0 = self._T0
        d2 = delta * delta
        if self._turn_short:  # |delta| <= _SHORT: the series' next terms are below 1e-14
            sd = delta * (1.0 - d2 * (1.0 / 6.0))
            cd = 1.0 - d2 * (0.5 - d2 * (1.0 / 24.0))
        else:
            sd = delta * (1.0 + d2 * (-1.0 / 6.0 + d2 * (1.0 / 120.0)))
            cd = 1.0 + d2 * (-0.5 + d2 * (1.0 / 24.0 - d2 * (1.0 / 720.0)))
        S0, C0 = T0[1:6:2], T0[0:5:2]
        s_new = S0 * cd
        s_new += C0 * sd
        C = T[0:5:2]
        np.multiply(C0, cd, out=C)
        C -= S0 * sd
        T[1:6:2] = s_new
        np.negative(T[4], out=T[6])

    def _trig(self, A: np.ndarray, T: np.ndarray) -> None:
        """The trig rows of the angles A [3, N] (phi, theta, psi) into T, evaluated."""
        np.cos(A, out=T[0:5:2])
        np.sin(A, out=T[1:6:2])
        np.negative(T[4], out=T[6])

    def resync(self) -> None:
        """Evaluate the next step's sines and cosines anew (the engine calls it once per control period,
        so that the angle additions never accumulate over more than a few steps)."""
        self._trig_valid = False

    def step(self) -> None:
        """Advance every cell one physics step (RK4 of eq. 6, commands and rotor speeds held)."""
        b = self.body
        t, h = self.t, self.dt
        if self.lagged:
            self.omega += (self.target - self.omega) * self._lag_k
            u, od = self._from_speeds(self.omega)
            self.realised[...] = u
            self.omega_d[...] = od[0]
        ext = None
        if self.disturbed:
            e0 = self._ext_next[1] if self._ext_next is not None and self._ext_next[0] == t else self._disturbance(t)
            e2 = self._disturbance(t + h)
            ext = (e0, self._disturbance(t + 0.5 * h), e2)
            self._ext_next = (t + h, e2)
        r = self.realised
        a = r[0] / b.mass
        txy = self._lxy * r[1:3]  # (l/I_x u2, l/I_y u3)
        tz = b.l_z * r[3]
        q12 = self._jr12 * self.omega_d  # (-J_r/I_x, J_r/I_y) omega_d
        X0 = self.X
        K, tmp, delta = self._K, self._tmp, self._delta
        biggest = float(np.abs(X0[7::2]).max()) * h  # the largest angle increment of a stage, about
        turn = self.n >= 400 and biggest <= _SMALL
        self._turn_short = biggest <= _SHORT
        if not (self._trig_valid and turn):
            self._trig(X0[6::2], self._T0)
        self._trig_valid = turn
        T = self._T0
        K[0][0::2] = X0[1::2]  # stage 1's velocities and rates: the step's start
        for s, (c, ei) in enumerate(((0.5 * h, 0), (0.5 * h, 1), (h, 1), (0.0, 2))):
            k = K[s]  # even rows: the stage's velocities and rates; odd rows: its accelerations
            # translation: [ax, ay] = (c_phi s_theta [c_psi, s_psi] + s_phi [s_psi, -c_psi]) a; az
            cf_st = T[0] * T[3]
            np.multiply(np.add(cf_st * T[4:6], T[1] * T[5:7]), a, out=k[1:4:2])
            np.multiply(T[0] * T[2], a, out=k[5])
            k[5] -= b.gravity
            # rotation: [phi'', theta''] = [theta', phi'] ([i1, i2] psi' + q12) + txy; psi'' = i3 phi' theta' + tz
            np.add(np.multiply(np.add(self._i12 * k[10], q12), k[8:5:-2]), txy, out=k[7:10:2])
            if b.i3 == 0.0:
                k[11] = tz
            else:
                np.add(b.i3 * k[6] * k[8], tz, out=k[11])
            if self.drag:
                k[1:6:2] -= self._kv * k[0:6:2]
                k[7::2] -= self._kw * k[6::2]
            if ext is not None:
                k[1::2] += ext[ei]
            if c:  # the next stage: the start plus c times this stage's derivative
                nxt = K[s + 1]
                np.multiply(k[1::2], c, out=tmp[1::2])
                np.add(X0[1::2], tmp[1::2], out=nxt[0::2])
                np.multiply(k[6::2], c, out=delta)  # its angles' increment
                T = self._T
                if turn:
                    self._turn(delta, T)
                else:
                    self._trig(X0[6::2] + delta, T)
        np.add(K[1], K[2], out=tmp)
        tmp *= 2.0
        tmp += K[0]
        tmp += K[3]
        tmp *= h / 6.0
        if turn:  # the next step's start angles are these plus the step's increment
            self._turn(tmp[6::2], self._T)
            self._T0[...] = self._T
        X0 += tmp
        if self.ground:
            below = X0[4] < 0.0
            if below.any():
                self._on_ground(below)
        self.t = t + h

    def _on_ground(self, below: np.ndarray) -> None:
        """:func:`plant.quadrotor._on_ground` for the cells below z = 0: resting, level, heading kept."""
        X = self.X
        for row in (1, 3, 4, 6, 7, 8, 9, 11):
            X[row, below] = 0.0
        X[5, below] = np.maximum(X[5, below], 0.0)
        self._trig_valid = False

    @property
    def on_ground(self) -> np.ndarray:
        """[N] bool: resting on the ground plane (z <= 0 and not rising)."""
        X = self.X
        return (X[4] <= 0.0) & (X[5] <= 0.0) & self.ground

    def diverged(self) -> np.ndarray:
        """[N] bool: :meth:`Quadrotor.diverged` — not finite, |position| > 100 m, or tilt beyond 90 degrees."""
        X = self.X
        with np.errstate(invalid="ignore", over="ignore"):
            bad = ~np.isfinite(X).all(axis=0)
            bad |= X[0] * X[0] + X[2] * X[2] + X[4] * X[4] > 1e4
            bad |= np.cos(X[6]) * np.cos(X[8]) < 0.0
        return bad

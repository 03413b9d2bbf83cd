"""The BS-ST, SMC and PID laws and the actuation for N cells at once: numpy over the cell axis.

In:  per cell a built-in law name (``bsst``, ``smc``, ``pid``), the nominal model, the gains and the control
     rate (Hz) they all share; each step the states [12, N] (eq. 7: m, m/s, rad, rad/s), the reference
     sample (x, y, z, psi, each value and 4 derivatives: [5] shared or [5, N]), which cells command and
     which hold their integrators
Out: the wrench demanded and realisable [4, N] (N), the normalised command [4, N], the saturation flags,
     the signed rotor-speed sum omega_d [N] (rad/s) the actuation allocated

The same arithmetic as :class:`controller.bsst.BacksteppingSuperTwisting`, :class:`controller.pid.CascadedPid`
and :mod:`controller.actuation`. The backstepping law, its integrators and the ``wrench`` actuation are
compiled loops over the cells (numba: ``_backstepping``, ``_advance``, ``_wrench``; a cell's jets — a value
and its three derivatives — in registers), the PID law and the rotor allocation numpy over the cell axis.
``smc`` cells fly the BS-ST arithmetic with the sign reaching law in the last step, as ``make_law("smc")``
does.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from math import pi

import numpy as np
from numba import njit

from controller.gains import Gains
from controller.nominal import Coefficients, Nominal
from controller.power import SignedPower
from plant.batch import net_rotor_speed

BACKSTEPPING = ("bsst", "smc")  # the laws of controller.bsst (super-twisting or sign reaching)
BATCH_LAWS = (*BACKSTEPPING, "pid")
TWO_PI = 2.0 * pi


def wrap_angle(a: np.ndarray) -> np.ndarray:
    """:func:`controller.bsst.wrap_angle` elementwise: to (-pi, pi]."""
    a = np.remainder(a + pi, TWO_PI) - pi
    return np.where(a == -pi, pi, a)


class BatchBacksteppingLaw:
    """:class:`~controller.bsst.BacksteppingSuperTwisting` for n cells; per cell super-twisting (``bsst``)
    or sign (``smc``) reaching in the last step."""

    def __init__(self, nominal: Nominal, gains: Gains, rate_hz: float, sign: np.ndarray) -> None:
        n = len(sign)
        self.n = n
        self.dt = 1.0 / rate_hz
        self.gains = gains
        co = Coefficients.of(nominal)
        g = gains
        loops = {"yaw": g.yaw, "z": g.z, "p": g.position, "v": g.velocity, "a": g.attitude}
        self._sp = np.array([_sp_row(SignedPower(2.0 * loops[r].alpha - 1.0, loops[r].eps)) for r in _SP_ROWS])
        c = {r: loops[r].c * 2.0 ** (-loops[r].alpha) for r in _SP_ROWS}
        st = (g.z_st, g.attitude_st, g.attitude_st, g.yaw_st)  # the channels: z, phi (u2), theta (u3), yaw
        k = {"c_yaw": c["yaw"], "c_z": c["z"], "c_p": c["p"], "c_v": c["v"], "c_a": c["a"],
             "k1_z": st[0].k1, "k1_phi": st[1].k1, "k1_th": st[2].k1, "k1_yaw": st[3].k1,
             "ks_z": g.smc_scale * st[0].k1, "ks_phi": g.smc_scale * st[1].k1, "ks_th": g.smc_scale * st[2].k1,
             "ks_yaw": g.smc_scale * st[3].k1,
             "kx": nominal.ixx / nominal.arm, "ky": nominal.iyy / nominal.arm, "kz": nominal.izz / nominal.arm,
             "u1_max": nominal.u_max[0], "m": nominal.mass, "g": nominal.gravity, "i1": co.i1, "i2": co.i2,
             "i3": co.i3, "jr_x": co.jr_x, "jr_y": co.jr_y, "l_z": co.l_z, "tilt_max": g.tilt_max,
             "rate_max": g.tilt_rate_max, "ff_max": g.feedforward_max}
        self._k = np.array([k[name] for name in _K], float)
        self.k2dt = np.array([s.k2 * self.dt for s in st])[:, None]
        self.xi_max = np.array([s.xi_max for s in st])[:, None]
        self.sign = np.asarray(sign, bool)
        self.xi = np.zeros((4, n))
        self.s = np.zeros((4, n))
        self.desired = np.zeros((2, n))

    def advance(self, saturated: np.ndarray, hold: np.ndarray) -> None:
        """Step the integrators (eq. 22) of the cells not holding, per channel not saturated and s != 0."""
        _advance(self.xi, self.s, self.k2dt[:, 0], self.xi_max[:, 0], np.ascontiguousarray(saturated),
                 np.ascontiguousarray(hold), self.sign)

    def update(self, X: np.ndarray, ref: np.ndarray, omega_d: np.ndarray) -> np.ndarray:
        """The wrench (u1..u4) [4, n] for the states X [12, n]; ref [4, 5, 1] or [4, 5, n] (x, y, z, psi)."""
        u = np.empty((4, X.shape[1]))
        _backstepping(np.ascontiguousarray(X), np.ascontiguousarray(ref), np.ascontiguousarray(omega_d), self._sp,
                      self._k, self.sign, self.xi, self.s, self.desired, u)
        return u


class BatchPid:
    """:class:`~controller.pid.CascadedPid` for n cells."""

    def __init__(self, nominal: Nominal, gains: Gains, rate_hz: float, n: int) -> None:
        self.n_ = nominal
        self.gains = gains
        self.k = dict(gains.pid)
        self.dt = 1.0 / rate_hz
        self.integral = np.zeros((3, n))
        self._err = np.zeros((3, n))
        self.desired = np.zeros((2, n))

    def advance(self, saturated: np.ndarray, hold: np.ndarray) -> None:
        m = self.k["i_max"]
        new = np.clip(self.integral + self._err * self.dt, -m, m)
        np.copyto(self.integral, new, where=~(hold | saturated[0])[None, :])

    def update(self, X: np.ndarray, ref: np.ndarray, omega_d: np.ndarray) -> np.ndarray:
        k = self.k
        n = self.n_
        x, vx, y, vy, z, vz, phi, dphi, th, dth, psi, dpsi = X
        rx, ry, rz, rpsi = ref[0], ref[1], ref[2], ref[3]
        ex, ey, ez = rx[0] - x, ry[0] - y, rz[0] - z
        self._err = np.stack((ex, ey, ez))
        ix, iy, iz = self.integral
        ax = rx[2] + k["kp_pos"] * ex + k["kd_pos"] * (rx[1] - vx) + k["ki_pos"] * ix
        ay = ry[2] + k["kp_pos"] * ey + k["kd_pos"] * (ry[1] - vy) + k["ki_pos"] * iy
        az = rz[2] + k["kp_z"] * ez + k["kd_z"] * (rz[1] - vz) + k["ki_z"] * iz
        gz = np.maximum(n.gravity + az, 0.2 * n.gravity)
        c, s = np.cos(psi), np.sin(psi)
        hx = ax * c + ay * s
        hy = ax * s - ay * c
        tm = self.gains.tilt_max
        phi_d = np.clip(np.arctan2(hy, np.sqrt(hx * hx + gz * gz)), -tm, tm)
        th_d = np.clip(np.arctan2(hx, gz), -tm, tm)
        self.desired = np.stack((phi_d, th_d))
        tilt = np.maximum(np.cos(phi) * np.cos(th), 0.2)
        u1 = n.mass * gz / tilt
        u2 = n.ixx / n.arm * (k["kp_att"] * (phi_d - phi) - k["kd_att"] * dphi)
        u3 = n.iyy / n.arm * (k["kp_att"] * (th_d - th) - k["kd_att"] * dth)
        u4 = n.izz / n.arm * (k["kp_yaw"] * wrap_angle(rpsi[0] - psi) + k["kd_yaw"] * (rpsi[1] - dpsi))
        return np.stack((u1, u2, u3, u4))


class BatchActuation:
    """:func:`controller.actuation.make_actuation` for n cells: clamp (``wrench``) or rotor allocation
    (``motors``), with the realisable wrench, the normalised command, the saturation flags and omega_d."""

    def __init__(self, nominal: Nominal, n: int) -> None:
        self.motors = nominal.actuation == "motors"
        self.u_max = np.array(nominal.u_max)[:, None]
        self.lo = np.array([0.0, -nominal.u_max[1], -nominal.u_max[2], -nominal.u_max[3]])[:, None]
        self.b = nominal.thrust_coeff
        self.d = nominal.drag_coeff
        self.omega_max = nominal.omega_max
        self.w2_max = nominal.omega_max**2
        self.omega_d = np.zeros(n)

    def allocate(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(realisable [4, k], normalised [4, k], saturated [4, k] bool, omega_d [k]) for the wrench u [4, k]."""
        return self._motors(u) if self.motors else self._wrench(u)

    def _wrench(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        k = u.shape[1]
        r, c, sat, od = np.empty((4, k)), np.empty((4, k)), np.empty((4, k), bool), np.empty(k)
        _wrench(np.ascontiguousarray(u), self.lo[:, 0], self.u_max[:, 0], self.b, self.d, r, c, sat, od)
        return r, c, sat, od

    def _motors(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        b, d, top = self.b, self.d, self.w2_max
        u1 = np.clip(u[0], 0.0, 4.0 * b * top)
        t = u1 / (4.0 * b)
        a2 = 0.5 * u[1] / b
        a3 = 0.5 * u[2] / b
        q = 0.25 * u[3] / d
        r2 = np.abs(a2)
        r3 = np.abs(a3)
        neg = q < 0.0
        q_lo = np.where(neg, q, 0.0)
        q_hi = np.where(neg, 0.0, q)
        zero = np.zeros_like(t)
        k = np.ones_like(t)
        with np.errstate(divide="ignore", invalid="ignore"):
            for ls, li in ((r3, t - top), (r2, -t), (zero, q_lo)):
                for us, ui in ((-r3, t), (-r2, top - t), (zero, q_hi)):
                    slope = ls - us
                    cut = (slope > 0.0) & ((ui - li) < k * slope)
                    k = np.where(cut, (ui - li) / slope, k)
        k = np.maximum(k, 0.0)
        lo = np.maximum(np.maximum(k * r3 + t - top, k * r2 - t), q_lo)
        hi = np.minimum(np.minimum(t - k * r3, top - t - k * r2), q_hi)
        Q = np.where((lo <= q) & (q <= hi), q, np.where(q < lo, lo, hi))
        ka2 = k * a2
        ka3 = k * a3
        w2 = np.clip(np.stack((t - ka3 - Q, t - ka2 + Q, t + ka3 - Q, t + ka2 + Q)), 0.0, top)
        omega = np.sqrt(w2)
        od = omega[1] + omega[3] - omega[0] - omega[2]
        real = np.stack((b * (w2[0] + w2[1] + w2[2] + w2[3]), b * (w2[3] - w2[1]), b * (w2[2] - w2[0]),
                         d * (w2[1] + w2[3] - w2[0] - w2[2])))
        sat = np.stack((u1 != u[0], k < 1.0, k < 1.0, Q != q))
        return real, omega / self.omega_max, sat, od


class BatchController:
    """The laws of n cells and their actuation, stepped at the control rate (:class:`controller.Controller`
    over the cell axis). ``laws`` must list the backstepping cells (``bsst``, ``smc``) before the ``pid``
    ones: each group is a contiguous block, so every array is a view, never a copy."""

    def __init__(self, laws: Sequence[str], nominal: Nominal, gains: Gains, rate_hz: float) -> None:
        unknown = sorted(set(laws) - set(BATCH_LAWS))
        if unknown:
            raise ValueError(f"the batch flies only {', '.join(BATCH_LAWS)}; got {unknown[0]!r}")
        n_bs = sum(1 for name in laws if name in BACKSTEPPING)
        if any(name == "pid" for name in laws[:n_bs]):
            raise ValueError("BatchController: the bsst and smc cells must come before the pid ones")
        self.n = len(laws)
        self.bs = slice(0, n_bs)
        self.pid = slice(n_bs, self.n)
        sign = np.array([name == "smc" for name in laws[:n_bs]], bool)
        self.backstepping = BatchBacksteppingLaw(nominal, gains, rate_hz, sign) if n_bs else None
        self.pid_law = BatchPid(nominal, gains, rate_hz, self.n - n_bs) if self.n > n_bs else None
        self.actuation = BatchActuation(nominal, self.n)

    @staticmethod
    def order(laws: Sequence[str]) -> list[int]:
        """A permutation of the cells that puts the backstepping ones first (stable)."""
        return sorted(range(len(laws)), key=lambda i: laws[i] == "pid")

    def step(self, X: np.ndarray, ref: np.ndarray, hold: np.ndarray,
             active: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One control step for every cell on the states X [12, n]; only the ``active`` cells (those that
        command this step) advance their integrators and keep their omega_d, ``hold`` ones do not
        integrate. Returns (demanded, realisable, normalised), each [4, n]."""
        u = np.empty((4, self.n))
        omega_d = self.actuation.omega_d
        if ref.ndim == 2:
            ref = ref[:, :, None]  # one sample for every cell
        shared = ref.shape[2] == 1
        if self.backstepping is not None:
            refb = ref if shared else ref[:, :, self.bs]
            u[:, self.bs] = self.backstepping.update(X[:, self.bs], refb, omega_d[self.bs])
        if self.pid_law is not None:
            refp = ref if shared else ref[:, :, self.pid]
            u[:, self.pid] = self.pid_law.update(X[:, self.pid], refp, omega_d[self.pid])
        real, c, sat, od = self.actuation.allocate(u)
        np.copyto(omega_d, od, where=active)
        idle = ~active | hold
        if self.backstepping is not None:
            self.backstepping.advance(sat[:, self.bs], idle[self.bs])
        if self.pid_law is not None:
            self.pid_law.advance(sat[:, self.pid], idle[self.pid])
        return u, real, c


# -- the compiled backstepping law -------------------------------------------------------------------------
# rows of the sig_beta table (BatchBacksteppingLaw._sp) and its columns: beta, eps, the C^3 join's a1..a7,
# the scales s0..s3, and the products of the a's the derivatives take (SignedPowers' c3a3 ... c210a7)
_SP_YAW, _SP_Z, _SP_P, _SP_V, _SP_A = range(5)
_SP_ROWS = ("yaw", "z", "p", "v", "a")
# the kernel's scalars (BatchBacksteppingLaw._k), in this order
_K = ("c_yaw", "c_z", "c_p", "c_v", "c_a", "k1_z", "k1_phi", "k1_th", "k1_yaw", "ks_z", "ks_phi", "ks_th", "ks_yaw",
      "kx", "ky", "kz", "u1_max", "m", "g", "i1", "i2", "i3", "jr_x", "jr_y", "l_z", "tilt_max", "rate_max", "ff_max")
(_C_YAW, _C_Z, _C_P, _C_V, _C_A, _K1_Z, _K1_PHI, _K1_TH, _K1_YAW, _KS_Z, _KS_PHI, _KS_TH, _KS_YAW, _KX, _KY, _KZ,
 _U1_MAX, _M, _G, _I1, _I2, _I3, _JR_X, _JR_Y, _L_Z, _TILT_MAX, _RATE_MAX, _FF_MAX) = range(len(_K))


def _sp_row(p: SignedPower) -> list[float]:
    a1, a3, a5, a7 = p._a
    return [p.beta, p.eps, a1, a3, a5, a7, *p._scale, 3.0 * a3, 5.0 * a5, 7.0 * a7, 6.0 * a3, 20.0 * a5, 42.0 * a7,
            60.0 * a5, 210.0 * a7]


@njit(cache=True, inline="always")
def _sgn(v: float) -> float:
    """np.sign of a float (nan stays nan)."""
    return 1.0 if v > 0.0 else -1.0 if v < 0.0 else v


@njit(cache=True, inline="always")
def _sig(e: float, P: np.ndarray) -> tuple[float, float, float, float]:
    """SignedPowers.derivs of one error e with the row P of the sig_beta table."""
    u = e / P[1]
    u2 = u * u
    f0 = P[6] * u * (P[2] + u2 * (P[3] + u2 * (P[4] + u2 * P[5])))
    f1 = P[7] * (P[2] + u2 * (P[10] + u2 * (P[11] + u2 * P[12])))
    f2 = P[8] * u * (P[13] + u2 * (P[14] + u2 * P[15]))
    f3 = P[9] * (P[13] + u2 * (P[16] + u2 * P[17]))
    m = abs(e)
    if m >= P[1]:
        b = P[0]
        p = m**b
        f0 = math.copysign(p, e)
        f1 = b * p / m
        g2 = (b - 1.0) * f1 / m
        f2 = g2 * _sgn(e)
        f3 = (b - 2.0) * g2 / m
    return f0, f1, f2, f3


@njit(cache=True, inline="always")
def _reach1(s: float, k1: float, xi: float, k_sign: float, sign: bool) -> float:
    """BatchBacksteppingLaw._reach of one channel of one cell."""
    if sign:
        return -k_sign * _sgn(s)
    return math.copysign(math.sqrt(abs(s)), s) * -k1 + xi


@njit(cache=True, inline="always")
def _wrap1(a: float) -> float:
    a = (a + pi) % TWO_PI - pi
    return pi if a == -pi else a


@njit(cache=True, inline="always")
def _atan2_1(y0: float, y1: float, y2: float, y3: float, x0: float, x1: float, x2: float,
             x3: float) -> tuple[float, float, float, float]:
    """:func:`_atan2` of one pair of jets."""
    r0 = x0 * x0 + y0 * y0
    r1 = 2.0 * (x1 * x0 + y1 * y0)
    r2 = (2.0 * x2 * x0 + 2.0 * x1 * x1) + (2.0 * y2 * y0 + 2.0 * y1 * y1)
    n0 = x0 * y1 - y0 * x1
    n1 = x0 * y2 - y0 * x2
    n2 = (x1 * y2 + x0 * y3) - (y1 * x2 + y0 * x3)
    q0 = n0 / r0
    q1 = (n1 - q0 * r1) / r0
    q2 = (n2 - 2.0 * q1 * r1 - q0 * r2) / r0
    return math.atan2(y0, x0), q0, q1, q2


@njit(cache=True, inline="always")
def _limit1(a0: float, a1: float, a2: float, a3: float, tm: float, rm: float) -> tuple[float, float, float, float]:
    """BatchBacksteppingLaw._limit_tilt of one jet."""
    if abs(a0) > tm:
        return min(max(a0, -tm), tm), 0.0, 0.0, 0.0
    if a1 > rm or a1 < -rm:
        return a0, min(max(a1, -rm), rm), 0.0, 0.0
    return a0, a1, a2, a3


@njit(cache=True)
def _backstepping(X: np.ndarray, ref: np.ndarray, omega_d: np.ndarray, sp: np.ndarray, k: np.ndarray,
                  sign: np.ndarray, xi: np.ndarray, s_out: np.ndarray, desired: np.ndarray,
                  u_out: np.ndarray) -> None:  # pragma: no cover
    """BatchBacksteppingLaw.update's arithmetic, cell by cell: the wrench into u_out [4, n], the sliding
    variables into s_out [4, n], (phi_d, theta_d) into desired [2, n]; ref [4, 5, 1] or [4, 5, n]."""
    shared = ref.shape[2] == 1
    g, m = k[_G], k[_M]
    i1, i2, i3, l_z = k[_I1], k[_I2], k[_I3], k[_L_Z]
    tm, rm, ffm = k[_TILT_MAX], k[_RATE_MAX], k[_FF_MAX]
    cp, cv, cz, ca = k[_C_P], k[_C_V], k[_C_Z], k[_C_A]
    P_yaw, P_z, P_p, P_v, P_a = sp[_SP_YAW], sp[_SP_Z], sp[_SP_P], sp[_SP_V], sp[_SP_A]
    aj = np.empty((2, 4))  # the jets of a_x and a_y
    for j in range(X.shape[1]):
        r = 0 if shared else j
        x, vx, y, vy, z, vz = X[0, j], X[1, j], X[2, j], X[3, j], X[4, j], X[5, j]
        phi, dphi, th, dth, psi, dpsi = X[6, j], X[7, j], X[8, j], X[9, j], X[10, j], X[11, j]
        sgn = sign[j]
        sphi, sth, spsi = math.sin(phi), math.sin(th), math.sin(psi)
        cphi, cth, cpsi = math.cos(phi), math.cos(th), math.cos(psi)

        # yaw and z: position steps, then the velocity steps' sliding variables
        f0y, f1y, _, _ = _sig(_wrap1(psi - ref[3, 0, r]), P_yaw)
        f0z, f1z, f2z, f3z = _sig(z - ref[2, 0, r], P_z)
        phi4 = ref[3, 1, r] - k[_C_YAW] * f0y
        dphi4 = ref[3, 2, r] - k[_C_YAW] * f1y * (dpsi - ref[3, 1, r])
        phi1 = ref[2, 1, r] - cz * f0z
        dphi1 = ref[2, 2, r] - cz * f1z * (vz - ref[2, 1, r])
        s_z = vz - phi1
        s_yaw = dpsi - phi4
        st_z = _reach1(s_z, k[_K1_Z], xi[0, j], k[_KS_Z], sgn)
        st_yaw = _reach1(s_yaw, k[_K1_YAW], xi[3, j], k[_KS_YAW], sgn)
        u4 = k[_KZ] * ((dphi4 + st_yaw) if i3 == 0.0 else (-i3 * dphi * dth + dphi4 + st_yaw))
        tilt = cphi * cth
        u1 = m * (g + dphi1 + st_z) / max(tilt, 0.2)
        a = min(max(u1, 0.0), k[_U1_MAX]) / m

        # the state's 2nd and 3rd derivatives along the nominal model, inputs held (x and y)
        cs = cphi * sth
        ss = sphi * sth
        A = cs * cpsi + sphi * spsi
        B = cs * spsi - sphi * cpsi
        tdth = tilt * dth
        dA = (cphi * spsi - ss * cpsi) * dphi + tdth * cpsi + -B * dpsi
        dB = -(ss * spsi + cphi * cpsi) * dphi + tdth * spsi + A * dpsi
        dC = -(sphi * cth * dphi + cs * dth)
        ddpsi = l_z * u4 if i3 == 0.0 else i3 * dphi * dth + l_z * u4

        # x (q = 0) and y (q = 1): position then velocity step, as jets; the a_x, a_y jets
        for q in range(2):
            rq = 0 if q == 0 else 1
            p1 = vx if q == 0 else vy
            p2 = (A if q == 0 else B) * a
            p3 = (dA if q == 0 else dB) * a
            fp0, fp1, fp2, fp3 = _sig(x - ref[0, 0, r] if q == 0 else y - ref[1, 0, r], P_p)
            e1 = p1 - ref[rq, 1, r]
            e2 = p2 - ref[rq, 2, r]
            e3 = p3 - ref[rq, 3, r]
            e11 = e1 * e1
            q0 = ref[rq, 1, r] - fp0 * cp
            q1 = ref[rq, 2, r] - fp1 * e1 * cp
            q2 = ref[rq, 3, r] - (fp2 * e11 + fp1 * e2) * cp
            q3 = ref[rq, 4, r] - (fp3 * e11 * e1 + 3.0 * fp2 * e1 * e2 + fp1 * e3) * cp
            z0 = p1 - q0
            z1 = p2 - q1
            z2 = p3 - q2
            z3 = -q3
            fv0, fv1, fv2, fv3 = _sig(z0, P_v)
            z11 = z1 * z1
            aj[q, 0] = q1 - fv0 * cv
            aj[q, 1] = q2 - fv1 * z1 * cv
            aj[q, 2] = q3 - (fv2 * z11 + fv1 * z2) * cv
            aj[q, 3] = -((fv3 * z11 * z1 + 3.0 * fv2 * z1 * z2 + fv1 * z3) * cv)
        # a_z = phi1' as a jet: G = g + a_z, floored
        ez1 = vz - ref[2, 1, r]
        ez2 = tilt * a - g - ref[2, 2, r]
        ez3 = dC * a - ref[2, 3, r]
        G0 = ref[2, 2, r] - f1z * ez1 * cz + g
        G1 = ref[2, 3, r] - (f2z * ez1 * ez1 + f1z * ez2) * cz
        G2 = ref[2, 4, r] - (f3z * ez1 * ez1 * ez1 + 3.0 * f2z * ez1 * ez2 + f1z * ez3) * cz
        if G0 < 0.2 * g:
            G0, G1, G2 = 0.2 * g, 0.0, 0.0
        # [hx, hy] = a_x [cos psi, sin psi] + a_y [sin psi, -cos psi], as jets (Leibniz)
        d1, d2 = dpsi, ddpsi
        d11 = d1 * d1
        sd12 = 3.0 * d1 * d2
        c0x, c0y = cpsi, spsi
        cAx, cAy = -spsi * d1, cpsi * d1
        cBx, cBy = -cpsi * d11 - spsi * d2, -spsi * d11 + cpsi * d2
        cCx, cCy = spsi * d11 * d1 - cpsi * sd12, -cpsi * d11 * d1 - spsi * sd12
        n0x, n0y, nAx, nAy, nBx, nBy, nCx, nCy = c0y, -c0x, cAy, -cAx, cBy, -cBx, cCy, -cCx
        ax0, ax1, ax2, ax3 = aj[0, 0], aj[0, 1], aj[0, 2], aj[0, 3]
        ay0, ay1, ay2, ay3 = aj[1, 0], aj[1, 1], aj[1, 2], aj[1, 3]
        hx0 = ax0 * c0x + ay0 * n0x
        hy0 = ax0 * c0y + ay0 * n0y
        hx1 = ax1 * c0x + ax0 * cAx + ay1 * n0x + ay0 * nAx
        hy1 = ax1 * c0y + ax0 * cAy + ay1 * n0y + ay0 * nAy
        hx2 = ax2 * c0x + 2.0 * ax1 * cAx + ax0 * cBx + ay2 * n0x + 2.0 * ay1 * nAx + ay0 * nBx
        hy2 = ax2 * c0y + 2.0 * ax1 * cAy + ax0 * cBy + ay2 * n0y + 2.0 * ay1 * nAy + ay0 * nBy
        hx3 = (ax3 * c0x + 3.0 * (ax2 * cAx + ax1 * cBx) + ax0 * cCx
               + ay3 * n0x + 3.0 * (ay2 * nAx + ay1 * nBx) + ay0 * nCx)
        hy3 = (ax3 * c0y + 3.0 * (ax2 * cAy + ax1 * cBy) + ax0 * cCy
               + ay3 * n0y + 3.0 * (ay2 * nAy + ay1 * nBy) + ay0 * nCy)
        # theta_d = atan2(hx, G), phi_d = atan2(hy, sqrt(hx^2 + G^2))
        r0 = hx0 * hx0 + G0 * G0
        r1 = 2.0 * (hx0 * hx1 + G0 * G1)
        r2 = 2.0 * (hx0 * hx2 + hx1 * hx1 + G0 * G2 + G1 * G1)
        r3 = 2.0 * (hx0 * hx3 + G0 * 0.0) + 6.0 * (hx1 * hx2 + G1 * G2)
        sq = math.sqrt(r0)
        k1_ = 0.5 / sq
        k2_ = -0.25 / (sq * r0)
        k3_ = 0.375 / (sq * r0 * r0)
        t0, t1, t2, t3 = _atan2_1(hx0, hx1, hx2, hx3, G0, G1, G2, 0.0)
        p0, p1_, p2_, p3_ = _atan2_1(hy0, hy1, hy2, hy3, sq, k1_ * r1, k2_ * r1 * r1 + k1_ * r2,
                                     k3_ * r1 * r1 * r1 + 3.0 * k2_ * r1 * r2 + k1_ * r3)
        t0, t1, t2, t3 = _limit1(t0, t1, t2, t3, tm, rm)
        p0, p1_, p2_, p3_ = _limit1(p0, p1_, p2_, p3_, tm, rm)
        desired[0, j] = p0
        desired[1, j] = t0

        # attitude steps: theta for x (u3), phi for y (u2)
        fa0t, fa1t, _, _ = _sig(th - t0, P_a)
        fa0p, fa1p, _, _ = _sig(phi - p0, P_a)
        ff_t = min(max(t2 - ca * fa1t * (dth - t1), -ffm), ffm)
        ff_p = min(max(p2_ - ca * fa1p * (dphi - p1_), -ffm), ffm)
        s_th = dth - (t1 - ca * fa0t)
        s_phi = dphi - (p1_ - ca * fa0p)
        st_th = _reach1(s_th, k[_K1_TH], xi[2, j], k[_KS_TH], sgn)
        st_phi = _reach1(s_phi, k[_K1_PHI], xi[1, j], k[_KS_PHI], sgn)
        u_out[0, j] = u1
        u_out[1, j] = k[_KX] * (-i1 * dth * dpsi + k[_JR_X] * dth * omega_d[j] + ff_p + st_phi)
        u_out[2, j] = k[_KY] * (-i2 * dphi * dpsi - k[_JR_Y] * dphi * omega_d[j] + ff_t + st_th)
        u_out[3, j] = u4
        s_out[0, j] = s_z
        s_out[1, j] = s_phi
        s_out[2, j] = s_th
        s_out[3, j] = s_yaw


@njit(cache=True)
def _advance(xi: np.ndarray, s: np.ndarray, k2dt: np.ndarray, xi_max: np.ndarray, saturated: np.ndarray,
             hold: np.ndarray, sign: np.ndarray) -> None:  # pragma: no cover
    """BatchBacksteppingLaw.advance in place on xi [4, n]."""
    for j in range(xi.shape[1]):
        if hold[j] or sign[j]:
            continue
        for r in range(4):
            if saturated[r, j] or s[r, j] == 0.0:
                continue
            xi[r, j] = min(max(xi[r, j] - _sgn(s[r, j]) * k2dt[r], -xi_max[r]), xi_max[r])


@njit(cache=True)
def _wrench(u: np.ndarray, lo: np.ndarray, u_max: np.ndarray, b: float, d: float, real: np.ndarray, c: np.ndarray,
            sat: np.ndarray, omega_d: np.ndarray) -> None:  # pragma: no cover
    """BatchActuation._wrench per cell: the clamped wrench, the normalised command, the saturation flags and
    the omega_d of the rotor speeds the clamped wrench gives."""
    for j in range(u.shape[1]):
        for i in range(4):
            r = min(max(u[i, j], lo[i]), u_max[i])
            real[i, j] = r
            c[i, j] = r / u_max[i]
            sat[i, j] = r != u[i, j]
        r0, r1, r2, r3 = real[0, j], real[1, j], real[2, j], real[3, j]
        omega_d[j] = net_rotor_speed(r0, r1, r2, r3, b, d)

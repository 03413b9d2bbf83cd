"""The BS-ST, SMC and PID laws and the actuation for N cells at once: numpy over the cell axis.

In:  per cell a built-in law name (``bsst``, ``smc``, ``pid``), the nominal model, the gains and the control
     rate (Hz) they all share; each step the states [12, N] (eq. 7: m, m/s, rad, rad/s), the reference
     sample (x, y, z, psi, each value and 4 derivatives: [5] shared or [5, N]), which cells command and
     which hold their integrators
Out: the wrench demanded and realisable [4, N] (N), the normalised command [4, N], the saturation flags,
     the signed rotor-speed sum omega_d [N] (rad/s) the actuation allocated

The same arithmetic as :class:`controller.bsst.BacksteppingSuperTwisting`, :class:`controller.pid.CascadedPid`
and :mod:`controller.actuation`, written on arrays (a jet is a [4, ...] array of a value and its three
derivatives); the x and y loops, and the sig_beta of loops that run side by side, share one array so
that a step costs the same few hundred array operations whatever N is. ``smc`` cells fly the BS-ST
arithmetic with the sign reaching law in the last step, as ``make_law("smc")`` does.
"""

from __future__ import annotations

from collections.abc import Sequence
from math import pi

import numpy as np

from controller.gains import Gains
from controller.nominal import Coefficients, Nominal
from controller.power import SignedPower

BACKSTEPPING = ("bsst", "smc")  # the laws of controller.bsst (super-twisting or sign reaching)
BATCH_LAWS = (*BACKSTEPPING, "pid")
TWO_PI = 2.0 * pi


def wrap_angle(a: np.ndarray) -> np.ndarray:
    """:func:`controller.bsst.wrap_angle` elementwise: to (-pi, pi]."""
    a = np.remainder(a + pi, TWO_PI) - pi
    return np.where(a == -pi, pi, a)


class SignedPowers:
    """Several :class:`~controller.power.SignedPower` side by side, one per row of a [rows, N] array."""

    def __init__(self, powers: Sequence[SignedPower]) -> None:
        col = lambda v: np.array(v, float)[:, None]  # noqa: E731
        self.beta = col([p.beta for p in powers])
        self.eps = col([p.eps for p in powers])
        a = np.array([p._a for p in powers])  # the C^3 join's coefficients, solved once by SignedPower
        self.a1, self.a3, self.a5, self.a7 = (col(a[:, i]) for i in range(4))
        s = np.array([p._scale for p in powers])
        self.s0, self.s1, self.s2, self.s3 = (col(s[:, i]) for i in range(4))
        self.c3a3, self.c5a5, self.c7a7 = 3.0 * self.a3, 5.0 * self.a5, 7.0 * self.a7
        self.c6a3, self.c20a5, self.c42a7 = 6.0 * self.a3, 20.0 * self.a5, 42.0 * self.a7
        self.c60a5, self.c210a7 = 60.0 * self.a5, 210.0 * self.a7

    def derivs(self, e: np.ndarray, order: int = 3) -> list[np.ndarray]:
        """sig_beta of each row of e [rows, N] and its derivatives up to ``order`` (SignedPower.derivs)."""
        u = e / self.eps
        u2 = u * u
        f = [self.s0 * u * (self.a1 + u2 * (self.a3 + u2 * (self.a5 + u2 * self.a7))),
             self.s1 * (self.a1 + u2 * (self.c3a3 + u2 * (self.c5a5 + u2 * self.c7a7)))]
        if order >= 2:
            f.append(self.s2 * u * (self.c6a3 + u2 * (self.c20a5 + u2 * self.c42a7)))
        if order >= 3:
            f.append(self.s3 * (self.c6a3 + u2 * (self.c60a5 + u2 * self.c210a7)))
        m = np.abs(e)
        out = m >= self.eps
        if not out.any():  # every error inside its band: the polynomial alone (the usual case in flight)
            return f
        b = self.beta
        with np.errstate(divide="ignore", invalid="ignore"):
            p = m**b
            g = [np.copysign(p, e), b * p / m]
            if order >= 2:
                g2 = (b - 1.0) * g[1] / m  # odd function: f0 and f2 take e's sign, f1 and f3 do not
                g.append(g2 * np.sign(e))
            if order >= 3:
                g.append((b - 2.0) * g2 / m)
        for fi, gi in zip(f, g, strict=True):
            np.copyto(fi, gi, where=out)
        return f


def _step_jet(fs: list[np.ndarray], c: np.ndarray, e: np.ndarray, lead: np.ndarray) -> np.ndarray:
    """``bsst._Step.jet``: lead - c' sig_beta(e) as a jet, from sig_beta's derivatives fs at e[0]."""
    f0, f1, f2, f3 = fs
    e1, e2, e3 = e[1], e[2], e[3]
    e11 = e1 * e1
    return np.stack((
        lead[0] - f0 * c,
        lead[1] - f1 * e1 * c,
        lead[2] - (f2 * e11 + f1 * e2) * c,
        lead[3] - (f3 * e11 * e1 + 3.0 * f2 * e1 * e2 + f1 * e3) * c,
    ))


def _mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """:func:`controller.jets.mul` (Leibniz) on [4, ...] jets."""
    a0, a1, a2, a3 = a
    b0, b1, b2, b3 = b
    return np.stack((a0 * b0, a1 * b0 + a0 * b1, a2 * b0 + 2.0 * a1 * b1 + a0 * b2,
                     a3 * b0 + 3.0 * (a2 * b1 + a1 * b2) + a0 * b3))


def _atan2(y: np.ndarray, x: np.ndarray) -> np.ndarray:
    """:func:`controller.jets.atan2` on [4, ...] jets (exact to order 2; the 3rd is not needed)."""
    x0, x1, x2, x3 = x[0], x[1], x[2], x[3]
    y0, y1, y2, y3 = y[0], y[1], y[2], y[3]
    r0 = x0 * x0 + y0 * y0
    r1 = 2.0 * (x1 * x0 + y1 * y0)
    r2 = (2.0 * x2 * x0 + 2.0 * x1 * x1) + (2.0 * y2 * y0 + 2.0 * y1 * y1)
    n0 = x0 * y1 - y0 * x1
    n1 = x0 * y2 - y0 * x2
    n2 = (x1 * y2 + x0 * y3) - (y1 * x2 + y0 * x3)
    q0 = n0 / r0
    q1 = (n1 - q0 * r1) / r0
    q2 = (n2 - 2.0 * q1 * r1 - q0 * r2) / r0
    return np.stack((np.arctan2(y0, x0), q0, q1, q2))


def _sqrt(a: np.ndarray) -> np.ndarray:
    """:func:`controller.jets.sqrt_` on a [4, ...] jet (chain rule)."""
    a0, a1, a2, a3 = a
    r = np.sqrt(a0)
    f1 = 0.5 / r
    f2 = -0.25 / (r * a0)
    f3 = 0.375 / (r * a0 * a0)
    return np.stack((r, f1 * a1, f2 * a1 * a1 + f1 * a2, f3 * a1 * a1 * a1 + 3.0 * f2 * a1 * a2 + f1 * a3))


class BatchBacksteppingLaw:
    """:class:`~controller.bsst.BacksteppingSuperTwisting` for n cells; per cell super-twisting (``bsst``)
    or sign (``smc``) reaching in the last step."""

    def __init__(self, nominal: Nominal, gains: Gains, rate_hz: float, sign: np.ndarray) -> None:
        n = len(sign)
        self.n = n
        self.dt = 1.0 / rate_hz
        self.gains = gains
        self.m = nominal.mass
        self.g = nominal.gravity
        co = Coefficients.of(nominal)
        self.co = co
        self.kx, self.ky, self.kz = nominal.ixx / nominal.arm, nominal.iyy / nominal.arm, nominal.izz / nominal.arm
        self.u1_max = nominal.u_max[0]
        g = gains
        steps = {name: SignedPower(2.0 * b.alpha - 1.0, b.eps) for name, b in
                 (("yaw", g.yaw), ("z", g.z), ("p", g.position), ("v", g.velocity), ("a", g.attitude))}
        cc = {name: b.c * 2.0 ** (-b.alpha) for name, b in
              (("yaw", g.yaw), ("z", g.z), ("p", g.position), ("v", g.velocity), ("a", g.attitude))}
        # the loops whose sig_beta runs side by side: (yaw, z, x, y); (x, y) velocity; (theta, phi) attitude
        self.sig1 = SignedPowers([steps["yaw"], steps["z"], steps["p"], steps["p"]])
        self.c1 = np.array([cc["yaw"], cc["z"], cc["p"], cc["p"]])[:, None]
        self.sig2 = SignedPowers([steps["v"], steps["v"]])
        self.cv = cc["v"]
        self.sigz = cc["z"]
        self.sig3 = SignedPowers([steps["a"], steps["a"]])
        self.ca = cc["a"]
        st = (g.z_st, g.attitude_st, g.attitude_st, g.yaw_st)
        self.k1 = np.array([s.k1 for s in st])[:, None]
        self.k2dt = np.array([s.k2 * self.dt for s in st])[:, None]
        self.xi_max = np.array([s.xi_max for s in st])[:, None]
        self.k_sign = np.array([g.smc_scale * s.k1 for s in st])[:, None]
        self.sign = np.asarray(sign, bool)
        self._any_sign = bool(self.sign.any())
        self._flip = np.array([1.0, -1.0])[:, None]
        self.xi = np.zeros((4, n))
        self.s = np.zeros((4, n))
        self.desired = np.zeros((2, n))

    def _reach(self, s: np.ndarray, k1: np.ndarray, xi: np.ndarray, k_sign: np.ndarray) -> np.ndarray:
        """ST(s) of some channels (rows): -k1 sqrt|s| sign s + xi, or -k sign s for the ``smc`` cells."""
        st = np.copysign(np.sqrt(np.abs(s)), s)
        st *= -k1
        st += xi
        if self._any_sign:
            np.copyto(st, -k_sign * np.sign(s), where=self.sign[None, :])
        return st

    def advance(self, saturated: np.ndarray, hold: np.ndarray) -> None:
        """Step the integrators (eq. 22) of the cells not holding, per channel not saturated and s != 0."""
        s = self.s
        xi = np.minimum(np.maximum(self.xi - np.sign(s) * self.k2dt, -self.xi_max), self.xi_max)
        frozen = saturated | hold[None, :] | (s == 0.0) | self.sign[None, :]
        np.copyto(self.xi, xi, where=~frozen)

    def update(self, X: np.ndarray, ref: np.ndarray, omega_d: np.ndarray) -> np.ndarray:
        """The wrench (u1..u4) [4, n] for the states X [12, n]; ref [4, 5, 1] or [4, 5, n] (x, y, z, psi)."""
        x, vx, y, vy, z, vz, phi, dphi, th, dth, psi, dpsi = X
        co = self.co
        g, m = self.g, self.m
        rz, rpsi = ref[2], ref[3]
        rxy = ref[0:2]  # [2, 5, n|1]: x and y side by side
        Sn = np.sin(X[6::2])
        Cs = np.cos(X[6::2])
        sphi, sth, spsi = Sn
        cphi, cth, cpsi = Cs

        # sig_beta of psi, z, x and y side by side
        e = np.empty((4, X.shape[1]))
        e[0] = wrap_angle(psi - rpsi[0])
        np.subtract(z, rz[0], out=e[1])
        np.subtract(X[0:4:2], rxy[:, 0], out=e[2:4])
        f0, f1, f2, f3 = self.sig1.derivs(e)
        c1 = self.c1
        phi4 = rpsi[1] - c1[0] * f0[0]
        dphi4 = rpsi[2] - c1[0] * f1[0] * (dpsi - rpsi[1])
        phi1 = rz[1] - c1[1] * f0[1]
        dphi1 = rz[2] - c1[1] * f1[1] * (vz - rz[1])
        s14 = np.empty((2, X.shape[1]))
        np.subtract(vz, phi1, out=s14[0])
        np.subtract(dpsi, phi4, out=s14[1])
        st14 = self._reach(s14, self.k1[0::3], self.xi[0::3], self.k_sign[0::3])
        u4 = self.kz * ((dphi4 + st14[1]) if co.i3 == 0.0 else (-co.i3 * dphi * dth + dphi4 + st14[1]))
        tilt = cphi * cth
        u1 = m * (g + dphi1 + st14[0]) / np.maximum(tilt, 0.2)
        a = np.minimum(np.maximum(u1, 0.0), self.u1_max) / m

        # the state's 2nd and 3rd derivatives along the nominal model, inputs held ([2, n]: x and y)
        cs = cphi * sth
        ss = sphi * sth
        AB = np.empty((2, X.shape[1]))
        np.add(cs * cpsi, sphi * spsi, out=AB[0])
        np.subtract(cs * spsi, sphi * cpsi, out=AB[1])
        dAB = np.empty_like(AB)
        tdth = tilt * dth
        np.add((cphi * spsi - ss * cpsi) * dphi + tdth * cpsi, -AB[1] * dpsi, out=dAB[0])
        np.add(-(ss * spsi + cphi * cpsi) * dphi + tdth * spsi, AB[0] * dpsi, out=dAB[1])
        dC = -(sphi * cth * dphi + cs * dth)
        ddpsi = co.l_z * u4 if co.i3 == 0.0 else co.i3 * dphi * dth + co.l_z * u4

        # x and y: position then velocity step, as jets of [2, n] rows
        p1 = X[1:4:2]
        p2 = AB * a
        p3 = dAB * a
        e1 = p1 - rxy[:, 1]
        e2 = p2 - rxy[:, 2]
        e3 = p3 - rxy[:, 3]
        cp = c1[2:4]
        fp0, fp1, fp2, fp3 = f0[2:4], f1[2:4], f2[2:4], f3[2:4]
        e11 = e1 * e1
        q0 = rxy[:, 1] - fp0 * cp
        q1 = rxy[:, 2] - fp1 * e1 * cp
        q2 = rxy[:, 3] - (fp2 * e11 + fp1 * e2) * cp
        q3 = rxy[:, 4] - (fp3 * e11 * e1 + 3.0 * fp2 * e1 * e2 + fp1 * e3) * cp
        z0 = p1 - q0
        z1 = p2 - q1
        z2 = p3 - q2
        z3 = -q3
        fv0, fv1, fv2, fv3 = self.sig2.derivs(z0)
        cv = self.cv
        z11 = z1 * z1
        a0 = q1 - fv0 * cv
        a1 = q2 - fv1 * z1 * cv
        a2 = q3 - (fv2 * z11 + fv1 * z2) * cv
        a3 = -((fv3 * z11 * z1 + 3.0 * fv2 * z1 * z2 + fv1 * z3) * cv)
        # a_z = phi1' as a jet (the z step again, from the state's derivatives): G = g + a_z, floored
        ez1 = vz - rz[1]
        ez2 = tilt * a - g - rz[2]
        ez3 = dC * a - rz[3]
        cz = self.sigz
        fz1, fz2, fz3 = f1[1], f2[1], f3[1]
        G0 = rz[2] - fz1 * ez1 * cz + g
        G1 = rz[3] - (fz2 * ez1 * ez1 + fz1 * ez2) * cz
        G2 = rz[4] - (fz3 * ez1 * ez1 * ez1 + 3.0 * fz2 * ez1 * ez2 + fz1 * ez3) * cz
        low = G0 < 0.2 * g
        if low.any():
            G0 = np.where(low, 0.2 * g, G0)
            G1 = np.where(low, 0.0, G1)
            G2 = np.where(low, 0.0, G2)
        # [hx, hy] = a_x [cos psi, sin psi] + a_y [sin psi, -cos psi], as jets (Leibniz)
        d1, d2 = dpsi, ddpsi
        d11 = d1 * d1
        sd12 = 3.0 * d1 * d2
        c0 = np.empty((2, X.shape[1]))  # the jet of (cos psi, sin psi)
        c0[0], c0[1] = cpsi, spsi
        cA = np.empty_like(c0)
        cA[0], cA[1] = -spsi * d1, cpsi * d1
        cB = np.empty_like(c0)
        cB[0], cB[1] = -cpsi * d11 - spsi * d2, -spsi * d11 + cpsi * d2
        cC = np.empty_like(c0)
        cC[0], cC[1] = spsi * d11 * d1 - cpsi * sd12, -cpsi * d11 * d1 - spsi * sd12
        # (sin psi, -cos psi) is the same jet turned: rows swapped, the second negated
        n0 = c0[::-1] * self._flip
        nA = cA[::-1] * self._flip
        nB = cB[::-1] * self._flip
        nC = cC[::-1] * self._flip
        ax0, ax1, ax2, ax3 = a0[0], a1[0], a2[0], a3[0]
        ay0, ay1, ay2, ay3 = a0[1], a1[1], a2[1], a3[1]
        h0 = ax0 * c0 + ay0 * n0
        h1 = ax1 * c0 + ax0 * cA + ay1 * n0 + ay0 * nA
        h2 = ax2 * c0 + 2.0 * ax1 * cA + ax0 * cB + ay2 * n0 + 2.0 * ay1 * nA + ay0 * nB
        h3 = (ax3 * c0 + 3.0 * (ax2 * cA + ax1 * cB) + ax0 * cC
              + ay3 * n0 + 3.0 * (ay2 * nA + ay1 * nB) + ay0 * nC)
        hx0, hx1, hx2, hx3 = h0[0], h1[0], h2[0], h3[0]
        # theta_d = atan2(hx, G), phi_d = atan2(hy, sqrt(hx^2 + G^2)): one atan2 of [2, n] jets
        r0 = hx0 * hx0 + G0 * G0
        r1 = 2.0 * (hx0 * hx1 + G0 * G1)
        r2 = 2.0 * (hx0 * hx2 + hx1 * hx1 + G0 * G2 + G1 * G1)
        r3 = 2.0 * (hx0 * hx3 + G0 * 0.0) + 6.0 * (hx1 * hx2 + G1 * G2)
        q = np.sqrt(r0)
        k1_ = 0.5 / q
        k2_ = -0.25 / (q * r0)
        k3_ = 0.375 / (q * r0 * r0)
        den = np.empty((4, 2, X.shape[1]))
        den[0, 0], den[1, 0], den[2, 0], den[3, 0] = G0, G1, G2, 0.0
        den[0, 1] = q
        den[1, 1] = k1_ * r1
        den[2, 1] = k2_ * r1 * r1 + k1_ * r2
        den[3, 1] = k3_ * r1 * r1 * r1 + 3.0 * k2_ * r1 * r2 + k1_ * r3
        att = _atan2((h0, h1, h2, h3), den)  # [4, 2, n]: theta_d, phi_d
        att = self._limit_tilt(att)
        self.desired = att[0, ::-1]

        # attitude steps: theta for x (u3), phi for y (u2), side by side
        ea = X[8:5:-2] - att[0]
        fa0, fa1 = self.sig3.derivs(ea, order=1)
        ca = self.ca
        rate = X[9:6:-2]
        ffm = self.gains.feedforward_max
        dphi3 = np.minimum(np.maximum(att[2] - ca * fa1 * (rate - att[1]), -ffm), ffm)
        s32 = rate - (att[1] - ca * fa0)
        st32 = self._reach(s32, self.k1[2:0:-1], self.xi[2:0:-1], self.k_sign[2:0:-1])
        u = np.empty((4, X.shape[1]))
        u[0] = u1
        u[1] = self.kx * (-co.i1 * dth * dpsi + co.jr_x * dth * omega_d + dphi3[1] + st32[1])
        u[2] = self.ky * (-co.i2 * dphi * dpsi - co.jr_y * dphi * omega_d + dphi3[0] + st32[0])
        u[3] = u4
        s_ = self.s
        s_[0] = s14[0]
        s_[1] = s32[1]
        s_[2] = s32[0]
        s_[3] = s14[1]
        return u

    def _limit_tilt(self, a: np.ndarray) -> np.ndarray:
        """``bsst._limit_tilt`` on [4, 2, n] jets: the tilt limit (derivatives zeroed), else the rate limit."""
        tm = self.gains.tilt_max
        rm = self.gains.tilt_rate_max
        over = np.abs(a[0]) > tm
        fast = ~over & ((a[1] > rm) | (a[1] < -rm))
        if not (over.any() or fast.any()):
            return a
        out = a.copy()
        out[0] = np.where(over, np.clip(a[0], -tm, tm), a[0])
        out[1] = np.where(over, 0.0, np.where(fast, np.clip(a[1], -rm, rm), a[1]))
        out[2] = np.where(over | fast, 0.0, a[2])
        out[3] = np.where(over | fast, 0.0, a[3])
        return out


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
        r = np.minimum(np.maximum(u, self.lo), self.u_max)
        sat = r != u
        b, d = self.b, self.d
        s24 = 0.5 * (r[0] / b + r[3] / d)
        s13 = 0.5 * (r[0] / b - r[3] / d)
        w = np.sqrt(np.maximum(0.5 * np.stack((s13 - r[2] / b, s24 - r[1] / b, s13 + r[2] / b, s24 + r[1] / b)), 0.0))
        return r, r / self.u_max, sat, w[1] + w[3] - w[0] - w[2]

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

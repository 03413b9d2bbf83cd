"""The paper's finite-time backstepping super-twisting law (eq. 24-40), corrected.

Four subsystems (docs/law.md, "The law, step by step"):
- z in 2 steps (eq. 24-34): phi1 = zd' - c' sig(e_z); s1 = z' - phi1;
  u1 = m [g + phi1' + ST(s1)] / (cos phi cos theta).
- x through theta and y through phi, 4 steps each (eq. 35-38): position and velocity
  steps give the desired accelerations a_x, a_y; with a_z = phi1' they are inverted
  jointly for (phi_d, theta_d) (replacing the singular asin/acos of eq. 36/38); the
  attitude steps phi33 = theta_d' - c' sig(theta - theta_d), s3 = theta' - phi33 and
  u3 = (I_y/l)[-I2 phi' psi' - (J_r/I_y) phi' w_d + phi33' + ST(s3)], likewise u2.
- psi in 2 steps (eq. 39-40).

Here ST(s) = -k1 |s|^1/2 sign(s) + xi, xi' = -k2 sign(s) (eq. 22), or -k sign(s) for the
first-order SMC baseline (``reaching="sign"``). c' = c 2^-alpha and sig = sig_beta with
beta = 2 alpha - 1 (regularised, :mod:`controller.power`).

The derivatives phi33' needs (theta_d'' and so the reference's snap and the state's jerk)
are computed exactly with :mod:`controller.jets`: the reference gives its derivatives
analytically, the state's higher derivatives come from the nominal model with the inputs
of this step held (u1' = 0).
"""

from __future__ import annotations

from math import cos, pi, sin

from controller import jets as J
from controller.gains import Backstep, Gains
from controller.nominal import Coefficients, Nominal
from controller.power import SignedPower
from controller.supertwisting import SignReaching, SuperTwisting
from missions.references import Sample

Quad = tuple[float, float, float, float]
TWO_PI = 2.0 * pi


def wrap_angle(a: float) -> float:
    """Wrap to (-pi, pi]."""
    a = (a + pi) % TWO_PI - pi
    return pi if a == -pi else a


class _Step:
    """One finite-time backstepping step: phi = r' - c' sig_beta(e)."""

    __slots__ = ("c", "sig")

    def __init__(self, g: Backstep) -> None:
        self.c = g.c * 2.0 ** (-g.alpha)
        self.sig = SignedPower(2.0 * g.alpha - 1.0, g.eps)

    def jet(self, e: J.Jet, lead: J.Jet) -> J.Jet:
        """The virtual control lead - c' sig_beta(e) as a jet (eq. 17/29 with its derivatives).

        ``J.sub(lead, J.scale(self.sig.jet(e), self.c))`` written out, the same operations in
        the same order (so the same result to the last bit), without the intermediate jets:
        the x/y and z loops call it five times per control step.
        """
        c = self.c
        f0, f1, f2, f3 = self.sig.derivs(e[0])
        _, e1, e2, e3 = e
        return (
            lead[0] - f0 * c,
            lead[1] - f1 * e1 * c,
            lead[2] - (f2 * e1 * e1 + f1 * e2) * c,
            lead[3] - (f3 * e1 * e1 * e1 + 3.0 * f2 * e1 * e2 + f1 * e3) * c,
        )


def _clip(v: float, m: float) -> float:
    return m if v > m else -m if v < -m else v


class BacksteppingSuperTwisting:
    """The BS-ST law. ``update`` computes the wrench; ``advance`` steps the integrators.

    ``reaching="sign"`` gives the first-order sliding-mode baseline (same backstepping,
    sign function in the last step).
    """

    name = "bsst"

    def __init__(self, nominal: Nominal, gains: Gains, rate_hz: float, reaching: str = "st") -> None:
        self.nominal = nominal
        self.gains = gains
        self.dt = 1.0 / rate_hz
        n = nominal
        self._m = n.mass
        self._g = n.gravity
        c = Coefficients.of(n)
        self._i1, self._i2, self._i3 = c.i1, c.i2, c.i3
        self._jr_x, self._jr_y = c.jr_x, c.jr_y
        self._kx, self._ky, self._kz = n.ixx / n.arm, n.iyy / n.arm, n.izz / n.arm  # I/l of eq. (36)-(40)
        self._lz = c.l_z
        self._z = _Step(gains.z)
        self._p = _Step(gains.position)
        self._v = _Step(gains.velocity)
        self._a = _Step(gains.attitude)
        self._psi = _Step(gains.yaw)
        if reaching == "st":
            mk = SuperTwisting
            self.reach = [
                mk(gains.z_st.k1, gains.z_st.k2, gains.z_st.xi_max),
                mk(gains.attitude_st.k1, gains.attitude_st.k2, gains.attitude_st.xi_max),
                mk(gains.attitude_st.k1, gains.attitude_st.k2, gains.attitude_st.xi_max),
                mk(gains.yaw_st.k1, gains.yaw_st.k2, gains.yaw_st.xi_max),
            ]
        elif reaching == "sign":
            k = gains.smc_scale
            self.name = "smc"
            self.reach = [
                SignReaching(k * gains.z_st.k1),
                SignReaching(k * gains.attitude_st.k1),
                SignReaching(k * gains.attitude_st.k1),
                SignReaching(k * gains.yaw_st.k1),
            ]
        else:
            raise ValueError(f"reaching must be 'st' or 'sign', got {reaching!r}")
        self.s: Quad = (0.0, 0.0, 0.0, 0.0)
        self.desired: tuple[float, float] = (0.0, 0.0)  # (phi_d, theta_d), for the trace

    def reset(self) -> None:
        for r in self.reach:
            r.reset()

    def advance(self, saturated: tuple[bool, bool, bool, bool], hold: bool = False) -> None:
        """Step the super-twisting integrators over one control period (eq. 22)."""
        dt = self.dt
        for r, s, sat in zip(self.reach, self.s, saturated, strict=True):
            r.advance(s, dt, hold or sat)

    def update(self, t: float, X: tuple[float, ...], ref: Sample, omega_d: float) -> Quad:
        """The wrench (u1, u2, u3, u4) for state X (eq. 7 order) and reference sample."""
        x, vx, y, vy, z, vz, phi, dphi, th, dth, psi, dpsi = X
        rx, ry, rz, rpsi = ref
        g = self._g
        m = self._m
        gn = self.gains
        r1, r2, r3, r4 = self.reach

        # psi, 2 steps (eq. 39-40)
        st = self._psi
        e4 = wrap_angle(psi - rpsi[0])
        f0, f1, _, _ = st.sig.derivs(e4)
        phi4 = rpsi[1] - st.c * f0
        dphi4 = rpsi[2] - st.c * f1 * (dpsi - rpsi[1])
        s4 = dpsi - phi4
        u4 = self._kz * (-self._i3 * dphi * dth + dphi4 + r4(s4))

        # z, 2 steps (eq. 24-34); its jets also give a_z = phi1' for the x/y inversion
        cphi = cos(phi)
        sphi = sin(phi)
        cth = cos(th)
        sth = sin(th)
        cpsi = cos(psi)
        spsi = sin(psi)
        st = self._z
        ez = z - rz[0]
        f0, f1, _, _ = st.sig.derivs(ez)
        phi1 = rz[1] - st.c * f0
        dphi1 = rz[2] - st.c * f1 * (vz - rz[1])
        s1 = vz - phi1
        tilt = cphi * cth
        u1 = m * (g + dphi1 + r1(s1)) / (tilt if tilt > 0.2 else 0.2)
        u1m = self.nominal.u_max[0]
        u1n = 0.0 if u1 < 0.0 else u1m if u1 > u1m else u1

        # the state's 2nd and 3rd derivatives along the nominal model, inputs held
        a = u1n / m
        A = cphi * sth * cpsi + sphi * spsi
        B = cphi * sth * spsi - sphi * cpsi
        dA = (-sphi * sth * cpsi + cphi * spsi) * dphi + cphi * cth * cpsi * dth \
            + (-cphi * sth * spsi + sphi * cpsi) * dpsi
        dB = (-sphi * sth * spsi - cphi * cpsi) * dphi + cphi * cth * spsi * dth \
            + (cphi * sth * cpsi + sphi * spsi) * dpsi
        dC = -sphi * cth * dphi - cphi * sth * dth
        ddpsi = self._i3 * dphi * dth + self._lz * u4

        # position and velocity steps for x and y, jets to order 3 (valid to order 2 after shift)
        px = (x, vx, A * a, dA * a)
        py = (y, vy, B * a, dB * a)
        pz = (z, vz, tilt * a - g, dC * a)
        ax = self._accel(px, rx)
        ay = self._accel(py, ry)
        phi1j = self._z.jet((pz[0] - rz[0], pz[1] - rz[1], pz[2] - rz[2], pz[3] - rz[3]), (rz[1], rz[2], rz[3], rz[4]))
        G = J.shift(phi1j)
        G = (G[0] + g, G[1], G[2], G[3])
        if G[0] < 0.2 * g:
            G = (0.2 * g, 0.0, 0.0, 0.0)
        sj, cj = J.sin_cos((psi, dpsi, ddpsi, 0.0))
        hx = J.add(J.mul(ax, cj), J.mul(ay, sj))
        hy = J.sub(J.mul(ax, sj), J.mul(ay, cj))
        th_d = J.atan2(hx, G)
        ph_d = J.atan2(hy, J.sqrt_(J.add(J.mul(hx, hx), J.mul(G, G))))
        th_d = self._limit_tilt(th_d)
        ph_d = self._limit_tilt(ph_d)
        self.desired = (ph_d[0], th_d[0])

        # attitude steps: theta for x (u3), phi for y (u2)
        st = self._a
        ffm = gn.feedforward_max
        e3 = th - th_d[0]
        f0, f1, _, _ = st.sig.derivs(e3)
        phi33 = th_d[1] - st.c * f0
        dphi33 = _clip(th_d[2] - st.c * f1 * (dth - th_d[1]), ffm)
        s3 = dth - phi33
        u3 = self._ky * (-self._i2 * dphi * dpsi - self._jr_y * dphi * omega_d + dphi33 + r3(s3))
        e2 = phi - ph_d[0]
        f0, f1, _, _ = st.sig.derivs(e2)
        phi23 = ph_d[1] - st.c * f0
        dphi23 = _clip(ph_d[2] - st.c * f1 * (dphi - ph_d[1]), ffm)
        s2 = dphi - phi23
        u2 = self._kx * (-self._i1 * dth * dpsi + self._jr_x * dth * omega_d + dphi23 + r2(s2))

        self.s = (s1, s2, s3, s4)
        return (u1, u2, u3, u4)

    def _accel(self, p: J.Jet, r: tuple[float, ...]) -> J.Jet:
        """Desired acceleration jet of one horizontal axis (steps 1-2 of eq. 36/38): phi31 = q."""
        p0, p1, p2, p3 = p
        q0, q1, q2, q3 = self._p.jet((p0 - r[0], p1 - r[1], p2 - r[2], p3 - r[3]), (r[1], r[2], r[3], r[4]))
        z31 = (p1 - q0, p2 - q1, p3 - q2, 0.0 - q3)  # shift(p) - phi31
        return self._v.jet(z31, (q1, q2, q3, 0.0))  # shift(phi31) - c_v' sig(z31)

    def _limit_tilt(self, a: J.Jet) -> J.Jet:
        m = self.gains.tilt_max
        if a[0] > m:
            return (m, 0.0, 0.0, 0.0)
        if a[0] < -m:
            return (-m, 0.0, 0.0, 0.0)
        rm = self.gains.tilt_rate_max
        if a[1] > rm or a[1] < -rm:
            return (a[0], _clip(a[1], rm), 0.0, 0.0)
        return a

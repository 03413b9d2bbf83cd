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
first-order SMC baseline (``reaching="sign"``). ST is stepped over the control period either implicitly
(backward Euler in closed form, :func:`controller.supertwisting.implicit_twisting`; the default) or explicitly
(the paper as printed): ``discretization`` of :class:`BacksteppingSuperTwisting`,
``LawConstants.h``. c' = c 2^-alpha and sig = sig_beta with beta = 2 alpha - 1 (regularised,
:mod:`controller.power`).

The derivatives phi33' needs (theta_d'' and so the reference's snap and the state's jerk)
are computed exactly with :mod:`controller.jets`: the reference gives its derivatives
analytically, the state's higher derivatives come from the nominal model with the inputs
of this step held (u1' = 0).

In:  the state X (eq. 7: m, m/s, rad, rad/s), the reference sample (x, y, z in m, psi in rad, each with
     its first four time derivatives), omega_d (rad/s, eq. 5), the super-twisting integrators xi (m/s^2,
     rad/s^2), the law's constants (:class:`LawConstants`) and sig_beta tables (:func:`law_tables`)
Out: the wrench (u1 N; u2, u3, u4 N, the torques being l u), the sliding variables s1..s4 (m/s, rad/s)
     and the attitude (phi_d, theta_d) in rad the outer loop asks for

:func:`backstepping` is that step as one plain-float function: the class below calls it, and the batch
engine compiles the same function for its cells (numba, bridge.batch.kernels).
"""

from __future__ import annotations

from math import cos, sin
from typing import NamedTuple

from controller import jets as J
from controller.gains import Backstep, Gains
from controller.nominal import Coefficients, Nominal
from controller.power import SigTable, sig_derivs, sig_table
from controller.supertwisting import advance_xi, advance_xi_implicit, implicit_twisting, reaching
from missions.mission import DEFAULT_DISCRETIZATION, DISCRETIZATIONS
from missions.references import Sample
from plant.angles import wrap_angle  # (-pi, pi]: the project's one (examples import it from here)

Quad = tuple[float, float, float, float]


def _clip(v: float, m: float) -> float:
    return m if v > m else -m if v < -m else v


class LawConstants(NamedTuple):
    """The numbers :func:`backstepping` reads: the nominal model's (kg, m/s^2, eq. 6's factors), the limits
    (N, rad, rad/s, rad/s^2), the steps' c' = c 2^-alpha (1/s-ish: eq. 17/29) and the reaching gains."""

    m: float
    g: float
    i1: float
    i2: float
    i3: float
    jr_x: float
    jr_y: float
    kx: float  # I_x / l, I_y / l, I_z / l of eq. (36)-(40)
    ky: float
    kz: float
    l_z: float
    u1_max: float
    tilt_max: float
    rate_max: float
    ff_max: float
    c_yaw: float
    c_z: float
    c_p: float
    c_v: float
    c_a: float
    k1_z: float  # super-twisting k1 per channel: z, phi (u2), theta (u3), yaw
    k1_phi: float
    k1_th: float
    k1_yaw: float
    ks_z: float  # sign reaching k = smc_scale k1 per channel
    ks_phi: float
    ks_th: float
    ks_yaw: float
    k2_z: float  # super-twisting k2 per channel, as k1 (the implicit step needs it in the command)
    k2_phi: float
    k2_th: float
    k2_yaw: float
    h: float  # the implicit step's control period (s); 0: the explicit step (the paper as printed)

LawTables = tuple[SigTable, SigTable, SigTable, SigTable, SigTable]  # sig_beta of yaw, z, position, velocity, attitude


def _c(g: Backstep) -> float:
    return g.c * 2.0 ** (-g.alpha)


def law_constants(nominal: Nominal, gains: Gains, h: float = 0.0) -> LawConstants:
    """:class:`LawConstants` of a nominal model and a gain set; ``h`` the control period (s) for the implicit
    super-twisting step, 0 for the explicit one."""
    n, g = nominal, gains
    co = Coefficients.of(n)
    st = (g.z_st, g.attitude_st, g.attitude_st, g.yaw_st)
    k = g.smc_scale
    return LawConstants(n.mass, n.gravity, co.i1, co.i2, co.i3, co.jr_x, co.jr_y, n.ixx / n.arm, n.iyy / n.arm,
                        n.izz / n.arm, co.l_z, n.u_max[0], g.tilt_max, g.tilt_rate_max, g.feedforward_max,
                        _c(g.yaw), _c(g.z), _c(g.position), _c(g.velocity), _c(g.attitude),
                        *(s.k1 for s in st), *(k * s.k1 for s in st), *(s.k2 for s in st), h)


def law_tables(gains: Gains) -> LawTables:
    """The sig_beta tables (:func:`controller.power.sig_table`, beta = 2 alpha - 1) of the yaw, z, position,
    velocity and attitude steps."""
    g = gains
    return tuple(sig_table(2.0 * b.alpha - 1.0, b.eps)  # type: ignore[return-value]
                 for b in (g.yaw, g.z, g.position, g.velocity, g.attitude))


def virtual_jet(f: tuple[float, float, float, float], e: J.Jet, lead: J.Jet, c: float) -> J.Jet:
    """One finite-time step's virtual control lead - c' sig_beta(e) as a jet (eq. 17/29 and its derivatives),
    f = sig_beta and its derivatives at e[0]: ``J.sub(lead, J.scale(J.chain(*f, e), c))`` written out, the
    same operations in the same order."""
    f0, f1, f2, f3 = f
    _, e1, e2, e3 = e
    return (
        lead[0] - f0 * c,
        lead[1] - f1 * e1 * c,
        lead[2] - (f2 * e1 * e1 + f1 * e2) * c,
        lead[3] - (f3 * e1 * e1 * e1 + 3.0 * f2 * e1 * e2 + f1 * e3) * c,
    )


def _accel(p: J.Jet, r: tuple[float, ...], cp: float, Pp: SigTable, cv: float, Pv: SigTable) -> J.Jet:
    """Desired acceleration jet of one horizontal axis (steps 1-2 of eq. 36/38): phi31 = q, then the velocity
    step on z31 = p' - phi31."""
    p0, p1, p2, p3 = p
    e = (p0 - r[0], p1 - r[1], p2 - r[2], p3 - r[3])
    q0, q1, q2, q3 = virtual_jet(sig_derivs(e[0], Pp), e, (r[1], r[2], r[3], r[4]), cp)
    z31 = (p1 - q0, p2 - q1, p3 - q2, 0.0 - q3)  # shift(p) - phi31
    return virtual_jet(sig_derivs(z31[0], Pv), z31, (q1, q2, q3, 0.0), cv)  # shift(phi31) - c_v' sig(z31)


def _limit_tilt(a: J.Jet, tm: float, rm: float) -> J.Jet:
    """A desired angle's jet inside |angle| <= tm (rad) and |rate| <= rm (rad/s)."""
    if a[0] > tm:
        return (tm, 0.0, 0.0, 0.0)
    if a[0] < -tm:
        return (-tm, 0.0, 0.0, 0.0)
    if a[1] > rm or a[1] < -rm:
        return (a[0], _clip(a[1], rm), 0.0, 0.0)
    return a


def desired_attitude(ax: J.Jet, ay: J.Jet, G: J.Jet, sj: J.Jet, cj: J.Jet, tm: float,
                     rm: float) -> tuple[J.Jet, J.Jet]:
    """(phi_d, theta_d) as jets from the desired accelerations a_x, a_y, G = g + a_z and the jets of sin psi,
    cos psi: the joint inversion that replaces eq. (36)/(38), limited."""
    hx = J.add(J.mul(ax, cj), J.mul(ay, sj))
    hy = J.sub(J.mul(ax, sj), J.mul(ay, cj))
    th_d = J.atan2(hx, G)
    ph_d = J.atan2(hy, J.sqrt_(J.add(J.mul(hx, hx), J.mul(G, G))))
    return _limit_tilt(ph_d, tm, rm), _limit_tilt(th_d, tm, rm)


def _attitude_step(angle: float, rate: float, d: J.Jet, c: float, P: SigTable, ffm: float) -> tuple[float, float]:
    """The attitude step of eq. (36)/(38) for one angle toward its desired jet d: (phi', clipped to ffm; s)."""
    f0, f1, _, _ = sig_derivs(angle - d[0], P)
    phi = d[1] - c * f0
    return _clip(d[2] - c * f1 * (rate - d[1]), ffm), rate - phi


def _reach(s: float, k1: float, k2: float, xi: float, k_sign: float, sign: bool, h: float) -> float:
    """The last step's reaching term: sign reaching (``sign``), else super-twisting stepped explicitly (h = 0,
    :func:`controller.supertwisting.reaching`) or implicitly over h (:func:`implicit_twisting`)."""
    if sign or h == 0.0:
        return reaching(s, k1, xi, k_sign, sign)
    return implicit_twisting(s, xi, k1, k2, h)[0]


def backstepping(X: tuple[float, ...], ref: Sample, omega_d: float, xi: Quad, sign: bool, K: LawConstants,
                 P: LawTables) -> tuple[float, float, float, float, float, float, float, float, float, float]:
    """One step of the BS-ST law (module docstring; ``sign``: the SMC baseline's reaching) for state X and
    reference sample ``ref``: (u1, u2, u3, u4, s1, s2, s3, s4, phi_d, theta_d). Plain floats and tuples:
    the batch engine compiles this same function."""
    x, vx, y, vy, z, vz, phi, dphi, th, dth, psi, dpsi = X
    rx, ry, rz, rpsi = ref
    (m, g, i1, i2, i3, jr_x, jr_y, kx, ky, kz, l_z, u1m, tm, rm, ffm, c_yaw, c_z, c_p, c_v, c_a,
     k1_z, k1_phi, k1_th, k1_yaw, ks_z, ks_phi, ks_th, ks_yaw, k2_z, k2_phi, k2_th, k2_yaw, h) = K
    P_yaw, P_z, P_p, P_v, P_a = P

    # psi, 2 steps (eq. 39-40)
    f0, f1, _, _ = sig_derivs(wrap_angle(psi - rpsi[0]), P_yaw)
    phi4 = rpsi[1] - c_yaw * f0
    dphi4 = rpsi[2] - c_yaw * f1 * (dpsi - rpsi[1])
    s4 = dpsi - phi4
    u4 = kz * (-i3 * dphi * dth + dphi4 + _reach(s4, k1_yaw, k2_yaw, xi[3], ks_yaw, sign, h))

    # z, 2 steps (eq. 24-34); its jets also give a_z = phi1' for the x/y inversion
    cphi = cos(phi)
    sphi = sin(phi)
    cth = cos(th)
    sth = sin(th)
    cpsi = cos(psi)
    spsi = sin(psi)
    fz = sig_derivs(z - rz[0], P_z)
    phi1 = rz[1] - c_z * fz[0]
    dphi1 = rz[2] - c_z * fz[1] * (vz - rz[1])
    s1 = vz - phi1
    tilt = cphi * cth
    u1 = m * (g + dphi1 + _reach(s1, k1_z, k2_z, xi[0], ks_z, sign, h)) / (tilt if tilt > 0.2 else 0.2)
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
    ddpsi = i3 * dphi * dth + l_z * u4

    # position and velocity steps for x and y, jets to order 3 (valid to order 2 after shift)
    ax = _accel((x, vx, A * a, dA * a), rx, c_p, P_p, c_v, P_v)
    ay = _accel((y, vy, B * a, dB * a), ry, c_p, P_p, c_v, P_v)
    ez = (z - rz[0], vz - rz[1], tilt * a - g - rz[2], dC * a - rz[3])
    phi1j = virtual_jet(fz, ez, (rz[1], rz[2], rz[3], rz[4]), c_z)
    G = (phi1j[1] + g, phi1j[2], phi1j[3], 0.0)  # shift(phi1) + g
    if G[0] < 0.2 * g:
        G = (0.2 * g, 0.0, 0.0, 0.0)
    pj = (psi, dpsi, ddpsi, 0.0)  # J.sin_cos of it, with the sine and cosine above
    ph_d, th_d = desired_attitude(ax, ay, G, J.chain(spsi, cpsi, -spsi, -cpsi, pj),
                                  J.chain(cpsi, -spsi, -cpsi, spsi, pj), tm, rm)

    # attitude steps: theta for x (u3), phi for y (u2)
    dphi33, s3 = _attitude_step(th, dth, th_d, c_a, P_a, ffm)
    u3 = ky * (-i2 * dphi * dpsi - jr_y * dphi * omega_d + dphi33 + _reach(s3, k1_th, k2_th, xi[2], ks_th, sign, h))
    dphi23, s2 = _attitude_step(phi, dphi, ph_d, c_a, P_a, ffm)
    u2 = kx * (-i1 * dth * dpsi + jr_x * dth * omega_d + dphi23 + _reach(s2, k1_phi, k2_phi, xi[1], ks_phi, sign, h))
    return (u1, u2, u3, u4, s1, s2, s3, s4, ph_d[0], th_d[0])


class BacksteppingSuperTwisting:
    """The BS-ST law. ``update`` computes the wrench (:func:`backstepping`); ``advance`` steps the
    integrators (:func:`controller.supertwisting.advance_xi`).

    ``reaching="sign"`` gives the first-order sliding-mode baseline (same backstepping,
    sign function in the last step). ``discretization``: the super-twisting step stepped ``implicit`` (the
    default: backward Euler, :func:`controller.supertwisting.implicit_twisting`) or ``explicit`` (the paper
    as printed); the sign baseline is always flown as printed.
    """

    name = "bsst"

    def __init__(self, nominal: Nominal, gains: Gains, rate_hz: float, reaching: str = "st",
                 discretization: str = DEFAULT_DISCRETIZATION) -> None:
        if reaching not in ("st", "sign"):
            raise ValueError(f"reaching must be 'st' or 'sign', got {reaching!r}")
        if discretization not in DISCRETIZATIONS:
            raise ValueError(f"discretization must be one of {', '.join(DISCRETIZATIONS)}, got {discretization!r}")
        self.nominal = nominal
        self.gains = gains
        self.dt = 1.0 / rate_hz
        self.sign = reaching == "sign"
        if self.sign:
            self.name = "smc"
        self.implicit = discretization == "implicit" and not self.sign
        self.constants = law_constants(nominal, gains, self.dt if self.implicit else 0.0)
        self.tables = law_tables(gains)
        st = (gains.z_st, gains.attitude_st, gains.attitude_st, gains.yaw_st)  # z, phi (u2), theta (u3), yaw
        self._k2 = tuple(s.k2 for s in st)
        self._xi_max = tuple(s.xi_max for s in st)
        self.xi: Quad = (0.0, 0.0, 0.0, 0.0)  # the super-twisting integrators (eq. 22), per channel
        self.s: Quad = (0.0, 0.0, 0.0, 0.0)
        self.desired: tuple[float, float] = (0.0, 0.0)  # (phi_d, theta_d), for the trace

    def reset(self) -> None:
        self.xi = (0.0, 0.0, 0.0, 0.0)

    def advance(self, saturated: tuple[bool, bool, bool, bool], hold: bool = False) -> None:
        """Step the super-twisting integrators over one control period (eq. 22); none with sign reaching."""
        if self.sign:
            return
        dt, xi, s, k2, xm = self.dt, self.xi, self.s, self._k2, self._xi_max
        if self.implicit:
            K = self.constants
            k1 = (K.k1_z, K.k1_phi, K.k1_th, K.k1_yaw)
            self.xi = (advance_xi_implicit(xi[0], s[0], k1[0], k2[0], dt, xm[0], hold or saturated[0]),
                       advance_xi_implicit(xi[1], s[1], k1[1], k2[1], dt, xm[1], hold or saturated[1]),
                       advance_xi_implicit(xi[2], s[2], k1[2], k2[2], dt, xm[2], hold or saturated[2]),
                       advance_xi_implicit(xi[3], s[3], k1[3], k2[3], dt, xm[3], hold or saturated[3]))
            return
        self.xi = (advance_xi(xi[0], s[0], k2[0], dt, xm[0], hold or saturated[0]),
                   advance_xi(xi[1], s[1], k2[1], dt, xm[1], hold or saturated[1]),
                   advance_xi(xi[2], s[2], k2[2], dt, xm[2], hold or saturated[2]),
                   advance_xi(xi[3], s[3], k2[3], dt, xm[3], hold or saturated[3]))

    def update(self, t: float, X: tuple[float, ...], ref: Sample, omega_d: float) -> Quad:
        """The wrench (u1, u2, u3, u4) for state X (eq. 7 order) and reference sample."""
        r = backstepping(X, ref, omega_d, self.xi, self.sign, self.constants, self.tables)
        self.s = (r[4], r[5], r[6], r[7])
        self.desired = (r[8], r[9])
        return (r[0], r[1], r[2], r[3])

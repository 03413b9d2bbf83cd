"""The built-in BS-ST controller's whole control step as one plain-float function: law, actuation, integrators.

In:  the state X (eq. 7: m, m/s, rad, rad/s), the reference sample (x, y, z in m, psi in rad, each with its
     first four time derivatives), omega_d of the last allocation (rad/s, eq. 5), the super-twisting
     integrators xi (m/s^2, rad/s^2), ``hold`` (integrators frozen), the law's ``sign`` reaching, constants
     and tables (:func:`controller.bsst.law_constants`, :func:`~controller.bsst.law_tables`), the integrators'
     k2 and clamps (per channel z, phi, theta, yaw) and period dt (s), and the actuation: ``motors`` (rotor
     allocation, else the ideal wrench) with :data:`Alloc` (u_max N, b, d, omega_max rad/s, omega_max^2)
Out: (u demanded N, u realisable N, the normalised command, omega_d rad/s, xi of the next step, the sliding
     variables s1..s4, (phi_d, theta_d) rad): what ``Controller.step`` with the law's ``update`` and
     ``advance`` and the actuation's ``allocate`` gives, the same operations in the same order

One call per control step: :class:`controller.Controller` calls it for the built-in ``bsst`` and ``smc`` laws,
plain or compiled by numba (bridge.core.scalarkernels: the same source, bit for bit; the pure package never imports
numba). A user's law and ``pid`` take the generic path (law.update, allocate, law.advance).
"""

from __future__ import annotations

from controller.actuation import allocate_motors, allocate_wrench
from controller.bsst import LawConstants, LawTables, Quad, backstepping
from controller.supertwisting import advance_xi, advance_xi_implicit
from missions.references import Sample

Alloc = tuple[float, float, float, float, float, float, float, float]  # u_max (4), b, d, omega_max, omega_max^2
Flags = tuple[bool, bool, bool, bool]
Step = tuple[Quad, Quad, Quad, float, Quad, Quad, tuple[float, float]]


def control_step(X: tuple[float, ...], ref: Sample, omega_d: float, xi: Quad, hold: bool, sign: bool,
                 K: LawConstants, P: LawTables, k2: Quad, xm: Quad, dt: float, motors: bool, A: Alloc) -> Step:
    """One control step (module docstring): (u, realisable, normalised, omega_d, xi, s, desired)."""
    r = backstepping(X, ref, omega_d, xi, sign, K, P)
    u = (r[0], r[1], r[2], r[3])
    if motors:
        real, c, sat, od = allocate_motors(u, A[4], A[5], A[6], A[7])
    else:
        real, c, sat, od = allocate_wrench(u, (A[0], A[1], A[2], A[3]), A[4], A[5])
    s = (r[4], r[5], r[6], r[7])
    if not sign:
        if K[32] != 0.0:  # K.h: the implicit step (controller.bsst.BacksteppingSuperTwisting.advance)
            xi = (advance_xi_implicit(xi[0], s[0], K[20], k2[0], dt, xm[0], hold or sat[0]),
                  advance_xi_implicit(xi[1], s[1], K[21], k2[1], dt, xm[1], hold or sat[1]),
                  advance_xi_implicit(xi[2], s[2], K[22], k2[2], dt, xm[2], hold or sat[2]),
                  advance_xi_implicit(xi[3], s[3], K[23], k2[3], dt, xm[3], hold or sat[3]))
        else:
            xi = (advance_xi(xi[0], s[0], k2[0], dt, xm[0], hold or sat[0]),
                  advance_xi(xi[1], s[1], k2[1], dt, xm[1], hold or sat[1]),
                  advance_xi(xi[2], s[2], k2[2], dt, xm[2], hold or sat[2]),
                  advance_xi(xi[3], s[3], k2[3], dt, xm[3], hold or sat[3]))
    return u, real, c, od, xi, s, (r[8], r[9])

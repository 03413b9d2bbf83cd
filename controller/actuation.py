"""From the law's wrench (u1..u4) to what goes on the wire (docs/law.md, "Actuation").

- :class:`WrenchActuation`: clamp to the profile's limits and normalise,
  c = (u1/u1_max, u2/u2_max, u3/u3_max, u4/u4_max) in the paper's frame.
- :class:`MotorActuation`: allocate to rotors by inverting eq. (4) inside the rotor
  envelope, thrust first, then roll/pitch, then yaw (PX4's mixer priority), and send
  c_i = omega_i / omega_max in [0, 1].

Both report the wrench the command really asks for and which channels saturated, so the
super-twisting integrators can stop winding up.

In:  the law's wrench (u1 N; u2, u3, u4 N), the nominal model's limits u_max, thrust and drag factors
     b (N s^2), d (N m s^2), omega_max (rad/s)
Out: the realisable wrench (same units), the normalised command (paper frame, or omega_i / omega_max),
     the saturation flag per channel, omega_d (rad/s, eq. 5) of the rotor speeds it gives

:func:`allocate_wrench` and :func:`allocate_motors` are plain-float functions: the classes below call them,
the batch engine compiles the same ones (numba, bridge.batch.kernels).
"""

from __future__ import annotations

from math import sqrt

from controller.nominal import Nominal

Quad = tuple[float, float, float, float]


def _clip(v: float, lo: float, hi: float) -> float:
    return lo if v < lo else hi if v > hi else v


Flags = tuple[bool, bool, bool, bool]


def allocate_wrench(u: Quad, u_max: Quad, b: float, d: float) -> tuple[Quad, Quad, Flags, float]:
    """Ideal actuation: (the wrench clamped to [0, u1_max] and [-u_max, u_max], it normalised, the
    saturation flags, omega_d of the rotor speeds that realise it)."""
    m1, m2, m3, m4 = u_max
    r = (_clip(u[0], 0.0, m1), _clip(u[1], -m2, m2), _clip(u[2], -m3, m3), _clip(u[3], -m4, m4))
    sat = (r[0] != u[0], r[1] != u[1], r[2] != u[2], r[3] != u[3])
    return r, (r[0] / m1, r[1] / m2, r[2] / m3, r[3] / m4), sat, _omega_d(rotor_squares(r, b, d))


class WrenchActuation:
    """Ideal actuation: the four virtual inputs themselves, clamped and normalised."""

    def __init__(self, nominal: Nominal) -> None:
        self.u_max = nominal.u_max
        self._b = nominal.thrust_coeff
        self._d = nominal.drag_coeff
        self.omega_d = 0.0

    def allocate(self, u: Quad) -> tuple[Quad, Quad, Flags]:
        r, c, sat, self.omega_d = allocate_wrench(u, self.u_max, self._b, self._d)
        return r, c, sat


def rotor_squares(u: Quad, b: float, d: float) -> Quad:
    """Eq. (4) inverted: squared rotor speeds for (u1..u4), clipped at 0."""
    u1, u2, u3, u4 = u
    s24 = 0.5 * (u1 / b + u4 / d)
    s13 = 0.5 * (u1 / b - u4 / d)
    return (
        max(0.5 * (s13 - u3 / b), 0.0),
        max(0.5 * (s24 - u2 / b), 0.0),
        max(0.5 * (s13 + u3 / b), 0.0),
        max(0.5 * (s24 + u2 / b), 0.0),
    )


def _omega_d(w2: Quad) -> float:
    """Eq. (5) from squared speeds."""
    return sqrt(w2[1]) + sqrt(w2[3]) - sqrt(w2[0]) - sqrt(w2[2])


def allocate_motors(u: Quad, b: float, d: float, omega_max: float, top: float) -> tuple[Quad, Quad, Flags, float]:
    """Squared speeds for (u1..u4) inside [0, top = omega_max^2], by priority (eq. 4 inverted): (the wrench they
    realise, omega_i / omega_max, the saturation flags, omega_d).

    With t = u1/(4b), a2 = u2/(2b), a3 = u3/(2b) and the yaw share Q (demanded
    q = u4/(4d)), eq. (4) gives w^2 = (t - k a3 - Q, t - k a2 + Q, t + k a3 - Q,
    t + k a2 + Q) for k = 1, Q = q. Thrust t is kept (clipped to the envelope); the
    roll/pitch fraction k in [0, 1] is the largest for which some yaw share Q between 0
    and q fits every rotor; then Q is the share closest to q that fits with that k. So a
    wrench inside the envelope is realised exactly, roll/pitch keep their direction, and
    yaw is given up first and never reversed. Each rotor gives two linear bounds on Q
    in k; the largest k is the smallest crossing of a lower and an upper bound.
    """
    u1 = _clip(u[0], 0.0, 4.0 * b * top)
    t = u1 / (4.0 * b)
    a2 = 0.5 * u[1] / b
    a3 = 0.5 * u[2] / b
    q = 0.25 * u[3] / d
    r2 = abs(a2)
    r3 = abs(a3)
    q_lo, q_hi = (q, 0.0) if q < 0.0 else (0.0, q)
    # lower bounds on Q: k r3 + t - top, k r2 - t, q_lo; upper: t - k r3, top - t - k r2, q_hi
    k = 1.0
    for ls, li in ((r3, t - top), (r2, -t), (0.0, q_lo)):
        for us, ui in ((-r3, t), (-r2, top - t), (0.0, q_hi)):
            slope = ls - us
            if slope > 0.0 and (ui - li) < k * slope:
                k = (ui - li) / slope
    k = max(k, 0.0)
    lo = max(k * r3 + t - top, k * r2 - t, q_lo)
    hi = min(t - k * r3, top - t - k * r2, q_hi)
    Q = q if lo <= q <= hi else (lo if q < lo else hi)
    ka2 = k * a2
    ka3 = k * a3
    w2 = (
        _clip(t - ka3 - Q, 0.0, top),
        _clip(t - ka2 + Q, 0.0, top),
        _clip(t + ka3 - Q, 0.0, top),
        _clip(t + ka2 + Q, 0.0, top),
    )
    omega = (sqrt(w2[0]), sqrt(w2[1]), sqrt(w2[2]), sqrt(w2[3]))
    real = (
        b * (w2[0] + w2[1] + w2[2] + w2[3]),
        b * (w2[3] - w2[1]),
        b * (w2[2] - w2[0]),
        d * (w2[1] + w2[3] - w2[0] - w2[2]),
    )
    sat = (u1 != u[0], k < 1.0, k < 1.0, Q != q)
    w = omega_max
    return (real, (omega[0] / w, omega[1] / w, omega[2] / w, omega[3] / w), sat,
            omega[1] + omega[3] - omega[0] - omega[2])


class MotorActuation:
    """Allocation to four rotors inside [0, omega_max], thrust > roll/pitch > yaw (:func:`allocate_motors`)."""

    def __init__(self, nominal: Nominal) -> None:
        self.b = nominal.thrust_coeff
        self.d = nominal.drag_coeff
        self.omega_max = nominal.omega_max
        self.w2_max = nominal.omega_max**2
        self.omega_d = 0.0

    def allocate(self, u: Quad) -> tuple[Quad, Quad, Flags]:
        real, c, sat, self.omega_d = allocate_motors(u, self.b, self.d, self.omega_max, self.w2_max)
        return real, c, sat


def make_actuation(nominal: Nominal) -> WrenchActuation | MotorActuation:
    return MotorActuation(nominal) if nominal.actuation == "motors" else WrenchActuation(nominal)

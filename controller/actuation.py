"""From the law's wrench (u1..u4) to what goes on the wire (DESIGN.md section 3).

- :class:`WrenchActuation`: clamp to the profile's limits and normalise,
  c = (u1/u1_max, u2/u2_max, u3/u3_max, u4/u4_max) in the paper's frame.
- :class:`MotorActuation`: allocate to rotors by inverting eq. (4) inside the rotor
  envelope, thrust first, then roll/pitch, then yaw (PX4's mixer priority), and send
  c_i = omega_i / omega_max in [0, 1].

Both report the wrench the command really asks for and which channels saturated, so the
super-twisting integrators can stop winding up.
"""

from __future__ import annotations

from math import sqrt

from controller.nominal import Nominal

Quad = tuple[float, float, float, float]


def _clip(v: float, lo: float, hi: float) -> float:
    return lo if v < lo else hi if v > hi else v


class WrenchActuation:
    """Ideal actuation: the four virtual inputs themselves, clamped and normalised."""

    def __init__(self, nominal: Nominal) -> None:
        self.u_max = nominal.u_max
        self._b = nominal.thrust_coeff
        self._d = nominal.drag_coeff
        self.omega_d = 0.0

    def allocate(self, u: Quad) -> tuple[Quad, Quad, tuple[bool, bool, bool, bool]]:
        m1, m2, m3, m4 = self.u_max
        r = (_clip(u[0], 0.0, m1), _clip(u[1], -m2, m2), _clip(u[2], -m3, m3), _clip(u[3], -m4, m4))
        sat = (r[0] != u[0], r[1] != u[1], r[2] != u[2], r[3] != u[3])
        self.omega_d = _omega_d(rotor_squares(r, self._b, self._d))
        return r, (r[0] / m1, r[1] / m2, r[2] / m3, r[3] / m4), sat


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


def _fit(base: Quad, delta: Quad, top: float) -> float:
    """Largest k in [0, 1] with 0 <= base_i + k delta_i <= top for every rotor."""
    k = 1.0
    for b0, dl in zip(base, delta, strict=True):
        if dl > 0.0:
            room = (top - b0) / dl
        elif dl < 0.0:
            room = b0 / -dl
        else:
            continue
        if room < k:
            k = room
    return max(k, 0.0)


class MotorActuation:
    """Allocation to four rotors inside [0, omega_max], thrust > roll/pitch > yaw."""

    def __init__(self, nominal: Nominal) -> None:
        self.b = nominal.thrust_coeff
        self.d = nominal.drag_coeff
        self.omega_max = nominal.omega_max
        self.w2_max = nominal.omega_max**2
        self.omega_d = 0.0

    def allocate(self, u: Quad) -> tuple[Quad, Quad, tuple[bool, bool, bool, bool]]:
        b, d, top = self.b, self.d, self.w2_max
        u1 = _clip(u[0], 0.0, 4.0 * b * top)
        t = u1 / (4.0 * b)
        base = (t, t, t, t)
        rp = (-0.5 * u[2] / b, -0.5 * u[1] / b, 0.5 * u[2] / b, 0.5 * u[1] / b)
        k_rp = _fit(base, rp, top)
        base = tuple(x + k_rp * y for x, y in zip(base, rp, strict=True))  # type: ignore[assignment]
        q = 0.25 * u[3] / d
        yaw = (-q, q, -q, q)
        k_yaw = _fit(base, yaw, top)
        w2 = tuple(_clip(x + k_yaw * y, 0.0, top) for x, y in zip(base, yaw, strict=True))
        omega = tuple(sqrt(w) for w in w2)
        self.omega_d = omega[1] + omega[3] - omega[0] - omega[2]
        real = (
            b * (w2[0] + w2[1] + w2[2] + w2[3]),
            b * (w2[3] - w2[1]),
            b * (w2[2] - w2[0]),
            d * (w2[1] + w2[3] - w2[0] - w2[2]),
        )
        sat = (u1 != u[0], k_rp < 1.0, k_rp < 1.0, k_yaw < 1.0)
        c = tuple(o / self.omega_max for o in omega)
        return real, c, sat  # type: ignore[return-value]


def make_actuation(nominal: Nominal) -> WrenchActuation | MotorActuation:
    return MotorActuation(nominal) if nominal.actuation == "motors" else WrenchActuation(nominal)

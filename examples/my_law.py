"""A control law of your own: copy this file, change the maths, fly it.

    bsst sim missions/sine.toml --controller examples/my_law.py:MyLaw
    bsst sitl missions/sine.toml --controller examples/my_law.py:MyLaw

``MyLaw`` is a PD position loop (with the reference's acceleration fed forward) over an
attitude PD loop: the smallest law that flies the paper's missions. It fits the ``Law``
interface of ``controller/law.py``; ``tests/test_laws.py`` checks that every law does, this
one included. What a law is given and must give, with units:

- built as ``MyLaw(nominal, gains, rate_hz)``: the law's model of the vehicle
  (``controller.nominal.Nominal``: mass kg, gravity m/s², inertias kg m², arm l m), the
  mission's gains (``controller.gains.Gains``; ignored here) and the control rate (Hz);
- ``update(t, state, ref, omega_d)`` once per control period: mission time t (s); the state
  of the paper's eq. (7), (x, ẋ, y, ẏ, z, ż, φ, φ̇, θ, θ̇, ψ, ψ̇) in m, m/s, rad, rad/s
  (x forward, y left, z up); the reference ``ref`` = (x, y, z, ψ), each the value and its
  first four time derivatives; the signed rotor speed sum ω_d (rad/s). It returns
  (u1, u2, u3, u4): thrust u1 in N and the torque inputs in N (the plant turns u2 into the
  roll torque l·u2 N m, and so on); the actuation clamps what the rotors cannot give;
- ``advance(saturated, hold)`` after each update: step integrators (none here);
- ``reset()``: forget them; and the attribute ``desired`` = (φ_d, θ_d) in rad, for the trace.
"""

from __future__ import annotations

from math import cos

from controller.bsst import wrap_angle
from controller.gains import Gains
from controller.nominal import Nominal
from controller.pid import tilt_from_acceleration
from missions.references import Sample

TILT_MAX = 0.6  # rad: never ask for more tilt than this


class MyLaw:
    """PD on position, PD on attitude (see the module docstring)."""

    KP_POS, KD_POS = 4.0, 4.0  # 1/s², 1/s: horizontal position loop
    KP_Z, KD_Z = 6.0, 5.0  # 1/s², 1/s: height loop
    KP_ATT, KD_ATT = 100.0, 20.0  # 1/s², 1/s: roll and pitch loop
    KP_YAW, KD_YAW = 16.0, 8.0  # 1/s², 1/s: yaw loop

    def __init__(self, nominal: Nominal, gains: Gains, rate_hz: float) -> None:
        self.n = nominal
        self.desired: tuple[float, float] = (0.0, 0.0)

    def update(self, t: float, state: tuple[float, ...], ref: Sample, omega_d: float) -> tuple[float, float, float,
                                                                                                 float]:
        n = self.n
        x, vx, y, vy, z, vz, phi, dphi, th, dth, psi, dpsi = state
        rx, ry, rz, rpsi = ref
        # outer loop: the accelerations that bring the position onto the reference
        ax = rx[2] + self.KP_POS * (rx[0] - x) + self.KD_POS * (rx[1] - vx)
        ay = ry[2] + self.KP_POS * (ry[0] - y) + self.KD_POS * (ry[1] - vy)
        gz = max(n.gravity + rz[2] + self.KP_Z * (rz[0] - z) + self.KD_Z * (rz[1] - vz), 0.2 * n.gravity)
        phi_d, th_d = tilt_from_acceleration(ax, ay, gz, psi)
        phi_d = max(-TILT_MAX, min(TILT_MAX, phi_d))
        th_d = max(-TILT_MAX, min(TILT_MAX, th_d))
        self.desired = (phi_d, th_d)
        # thrust along the body axis that gives the vertical acceleration asked for
        u1 = n.mass * gz / max(cos(phi) * cos(th), 0.2)
        # inner loop: attitude PD; the model has (l/I)·u, so u = (I/l)·(angular acceleration)
        u2 = n.ixx / n.arm * (self.KP_ATT * (phi_d - phi) - self.KD_ATT * dphi)
        u3 = n.iyy / n.arm * (self.KP_ATT * (th_d - th) - self.KD_ATT * dth)
        u4 = n.izz / n.arm * (self.KP_YAW * wrap_angle(rpsi[0] - psi) + self.KD_YAW * (rpsi[1] - dpsi))
        return (u1, u2, u3, u4)

    def advance(self, saturated: tuple[bool, bool, bool, bool], hold: bool = False) -> None:
        pass  # no integrators

    def reset(self) -> None:
        pass

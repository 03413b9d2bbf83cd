"""Cascaded PID baseline: position PID -> desired accelerations -> tilt -> attitude PD.

Same interface as the BS-ST law, same tilt inversion and limits, no finite-time terms and
no derivative chain: the attitude set-point's derivatives are taken as zero.

In:  the state X (eq. 7: m, m/s, rad, rad/s), the reference sample (x, y, z in m, psi in rad, each with
     four derivatives), the position integrals (m s), the gains (:class:`PidConstants`: 1/s^2, 1/s, 1/s^3)
Out: the wrench (u1 N; u2, u3, u4 N), the position errors (m) the integrals take in, (phi_d, theta_d) rad

:func:`pid` and :func:`pid_integrals` are plain-float functions: the class below calls them, the batch
engine compiles the same ones (numba, bridge.batch.kernels).
"""

from __future__ import annotations

from math import atan2, cos, sin, sqrt
from typing import NamedTuple

from controller.bsst import wrap_angle
from controller.gains import Gains
from controller.nominal import Nominal
from missions.references import Sample

Quad = tuple[float, float, float, float]


def _clip(v: float, m: float) -> float:
    return m if v > m else -m if v < -m else v


def tilt_from_acceleration(ax: float, ay: float, gz: float, psi: float) -> tuple[float, float]:
    """(phi_d, theta_d) that point the thrust along (ax, ay, gz = g + a_z), yaw psi.

    The joint inversion that replaces the paper's eq. (36)/(38): rotating the demanded
    acceleration by -psi gives cos(phi) sin(theta), sin(phi), cos(phi) cos(theta) (times T).
    """
    c = cos(psi)
    s = sin(psi)
    hx = ax * c + ay * s
    hy = ax * s - ay * c
    return atan2(hy, sqrt(hx * hx + gz * gz)), atan2(hx, gz)


class PidConstants(NamedTuple):
    """What :func:`pid` reads: the gains (controller.gains.PID_DEFAULTS), the tilt limit (rad), the nominal
    mass (kg), gravity (m/s^2) and I/l (kg m) per axis."""

    kp_pos: float
    kd_pos: float
    ki_pos: float
    kp_z: float
    kd_z: float
    ki_z: float
    kp_att: float
    kd_att: float
    kp_yaw: float
    kd_yaw: float
    tilt_max: float
    m: float
    g: float
    kx: float
    ky: float
    kz: float


def pid_constants(nominal: Nominal, gains: Gains) -> PidConstants:
    k, n = gains.pid, nominal
    return PidConstants(k["kp_pos"], k["kd_pos"], k["ki_pos"], k["kp_z"], k["kd_z"], k["ki_z"], k["kp_att"],
                        k["kd_att"], k["kp_yaw"], k["kd_yaw"], gains.tilt_max, n.mass, n.gravity, n.ixx / n.arm,
                        n.iyy / n.arm, n.izz / n.arm)


def pid(X: tuple[float, ...], ref: Sample, integral: tuple[float, float, float],
        K: PidConstants) -> tuple[float, float, float, float, float, float, float, float, float]:
    """One step of the cascade for state X and reference ``ref``: (u1, u2, u3, u4, e_x, e_y, e_z, phi_d,
    theta_d). Plain floats and tuples: the batch engine compiles this same function."""
    kp_pos, kd_pos, ki_pos, kp_z, kd_z, ki_z, kp_att, kd_att, kp_yaw, kd_yaw, tm, m, g, kx, ky, kz = K
    x, vx, y, vy, z, vz, phi, dphi, th, dth, psi, dpsi = X
    rx, ry, rz, rpsi = ref
    ex, ey, ez = rx[0] - x, ry[0] - y, rz[0] - z
    ix, iy, iz = integral
    ax = rx[2] + kp_pos * ex + kd_pos * (rx[1] - vx) + ki_pos * ix
    ay = ry[2] + kp_pos * ey + kd_pos * (ry[1] - vy) + ki_pos * iy
    az = rz[2] + kp_z * ez + kd_z * (rz[1] - vz) + ki_z * iz
    gz = max(g + az, 0.2 * g)
    phi_d, th_d = tilt_from_acceleration(ax, ay, gz, psi)
    phi_d, th_d = _clip(phi_d, tm), _clip(th_d, tm)
    tilt = max(cos(phi) * cos(th), 0.2)
    u1 = m * gz / tilt
    u2 = kx * (kp_att * (phi_d - phi) - kd_att * dphi)
    u3 = ky * (kp_att * (th_d - th) - kd_att * dth)
    u4 = kz * (kp_yaw * wrap_angle(rpsi[0] - psi) + kd_yaw * (rpsi[1] - dpsi))
    return (u1, u2, u3, u4, ex, ey, ez, phi_d, th_d)


def pid_integrals(integral: tuple[float, float, float], err: tuple[float, float, float], dt: float,
                  i_max: float) -> tuple[float, float, float]:
    """The position integrals (m s) after one control period dt (s) of the errors ``err`` (m), each clamped
    to |i| <= i_max."""
    return (_clip(integral[0] + err[0] * dt, i_max), _clip(integral[1] + err[1] * dt, i_max),
            _clip(integral[2] + err[2] * dt, i_max))


class CascadedPid:
    name = "pid"

    def __init__(self, nominal: Nominal, gains: Gains, rate_hz: float) -> None:
        self.nominal = nominal
        self.gains = gains
        self.constants = pid_constants(nominal, gains)
        self.i_max = gains.pid["i_max"]
        self.dt = 1.0 / rate_hz
        self.integral = (0.0, 0.0, 0.0)
        self._err = (0.0, 0.0, 0.0)
        self.s: Quad = (0.0, 0.0, 0.0, 0.0)
        self.desired = (0.0, 0.0)

    def reset(self) -> None:
        self.integral = (0.0, 0.0, 0.0)

    def advance(self, saturated: tuple[bool, bool, bool, bool], hold: bool = False) -> None:
        if hold or saturated[0]:
            return
        self.integral = pid_integrals(self.integral, self._err, self.dt, self.i_max)

    def update(self, t: float, X: tuple[float, ...], ref: Sample, omega_d: float) -> Quad:
        r = pid(X, ref, self.integral, self.constants)
        self._err = (r[4], r[5], r[6])
        self.desired = (r[7], r[8])
        return (r[0], r[1], r[2], r[3])

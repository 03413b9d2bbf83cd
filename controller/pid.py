"""Cascaded PID baseline: position PID -> desired accelerations -> tilt -> attitude PD.

Same interface as the BS-ST law, same tilt inversion and limits, no finite-time terms and
no derivative chain: the attitude set-point's derivatives are taken as zero.
"""

from __future__ import annotations

from math import atan2, cos, sin, sqrt

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


class CascadedPid:
    name = "pid"

    def __init__(self, nominal: Nominal, gains: Gains, rate_hz: float) -> None:
        self.nominal = nominal
        self.gains = gains
        self.k = dict(gains.pid)
        self.dt = 1.0 / rate_hz
        self.integral = [0.0, 0.0, 0.0]
        self._err = (0.0, 0.0, 0.0)
        self.s: Quad = (0.0, 0.0, 0.0, 0.0)
        self.desired = (0.0, 0.0)

    def reset(self) -> None:
        self.integral = [0.0, 0.0, 0.0]

    def advance(self, saturated: tuple[bool, bool, bool, bool], hold: bool = False) -> None:
        if hold or saturated[0]:
            return
        m = self.k["i_max"]
        for i, e in enumerate(self._err):
            self.integral[i] = _clip(self.integral[i] + e * self.dt, m)

    def update(self, t: float, X: tuple[float, ...], ref: Sample, omega_d: float) -> Quad:
        k = self.k
        n = self.nominal
        x, vx, y, vy, z, vz, phi, dphi, th, dth, psi, dpsi = X
        rx, ry, rz, rpsi = ref
        ex, ey, ez = rx[0] - x, ry[0] - y, rz[0] - z
        self._err = (ex, ey, ez)
        ix, iy, iz = self.integral
        ax = rx[2] + k["kp_pos"] * ex + k["kd_pos"] * (rx[1] - vx) + k["ki_pos"] * ix
        ay = ry[2] + k["kp_pos"] * ey + k["kd_pos"] * (ry[1] - vy) + k["ki_pos"] * iy
        az = rz[2] + k["kp_z"] * ez + k["kd_z"] * (rz[1] - vz) + k["ki_z"] * iz
        gz = max(n.gravity + az, 0.2 * n.gravity)
        phi_d, th_d = tilt_from_acceleration(ax, ay, gz, psi)
        tm = self.gains.tilt_max
        phi_d, th_d = _clip(phi_d, tm), _clip(th_d, tm)
        self.desired = (phi_d, th_d)
        tilt = max(cos(phi) * cos(th), 0.2)
        u1 = n.mass * gz / tilt
        u2 = n.ixx / n.arm * (k["kp_att"] * (phi_d - phi) - k["kd_att"] * dphi)
        u3 = n.iyy / n.arm * (k["kp_att"] * (th_d - th) - k["kd_att"] * dth)
        u4 = n.izz / n.arm * (k["kp_yaw"] * wrap_angle(rpsi[0] - psi) + k["kd_yaw"] * (rpsi[1] - dpsi))
        return (u1, u2, u3, u4)

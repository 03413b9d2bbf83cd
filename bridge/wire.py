"""The wire's conventions, in one place: frames NWU <-> NED, and actuator normalisation.

The plant and the law work in the paper's frame: inertial x north, y west, z up (NWU),
body FLU, Z-Y-X Euler angles (phi, theta, psi). MAVLink speaks NED / FRD. At the wire
(DESIGN.md section 2):

    north = x, east = -y, down = -z;  roll = phi, pitch = -theta, yaw = -psi (wrapped)

and body rates are the exact kinematic transform of the Euler rates in the wire's frame.
"""

from __future__ import annotations

from math import asin, atan2, cos, pi, sin, tan

Quad = tuple[float, float, float, float]
TWO_PI = 2.0 * pi


def wrap_pi(a: float) -> float:
    """Wrap an angle to (-pi, pi]."""
    a = (a + pi) % TWO_PI - pi
    return pi if a == -pi else a


# -- actuator targets ---------------------------------------------------------------
def wrench_to_wire(c: Quad) -> Quad:
    """Normalised paper-frame wrench (u1, u2, u3, u4)/limits -> SET_ACTUATOR_CONTROL_TARGET
    group 0 controls[0..3] = (roll, pitch, yaw, thrust) in FRD: roll = u2, pitch = -u3,
    yaw = -u4, thrust = u1 (DESIGN.md section 3)."""
    return (c[1], -c[2], -c[3], c[0])


def wrench_from_wire(w: Quad) -> Quad:
    """Inverse of :func:`wrench_to_wire`."""
    return (w[3], w[0], -w[1], -w[2])


def command_to_wire(actuation: str, c: Quad) -> Quad:
    """What goes on the wire for a normalised paper-frame command: motor commands pass
    unchanged, a wrench is reordered and re-signed (also the trace's c1..c4)."""
    return wrench_to_wire(c) if actuation == "wrench" else c


def command_from_wire(actuation: str, w: Quad) -> Quad:
    return wrench_from_wire(w) if actuation == "wrench" else w


# -- state ---------------------------------------------------------------------------
def euler_rates_to_body_rates(
    roll: float, pitch: float, droll: float, dpitch: float, dyaw: float
) -> tuple[float, float, float]:
    """Z-Y-X Euler rates -> body rates (p, q, r) of the same frame."""
    sr, cr = sin(roll), cos(roll)
    sp, cp = sin(pitch), cos(pitch)
    return (droll - sp * dyaw, cr * dpitch + sr * cp * dyaw, -sr * dpitch + cr * cp * dyaw)


def body_rates_to_euler_rates(roll: float, pitch: float, p: float, q: float, r: float) -> tuple[float, float, float]:
    """Inverse of :func:`euler_rates_to_body_rates` (singular at pitch = +-90 deg)."""
    sr, cr = sin(roll), cos(roll)
    cp = cos(pitch)
    a = q * sr + r * cr
    return (p + a * tan(pitch), q * cr - r * sr, a / cp)


def euler_to_quaternion(roll: float, pitch: float, yaw: float) -> Quad:
    """Z-Y-X Euler angles -> unit quaternion (w, x, y, z)."""
    cr, sr = cos(0.5 * roll), sin(0.5 * roll)
    cp, sp = cos(0.5 * pitch), sin(0.5 * pitch)
    cy, sy = cos(0.5 * yaw), sin(0.5 * yaw)
    return (
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    )


def quaternion_to_euler(q: Quad) -> tuple[float, float, float]:
    """Unit quaternion (w, x, y, z) -> Z-Y-X Euler angles (roll, pitch, yaw)."""
    w, x, y, z = q
    n = w * w + x * x + y * y + z * z
    s = 2.0 * (w * y - z * x) / n
    s = 1.0 if s > 1.0 else -1.0 if s < -1.0 else s
    return (
        atan2(2.0 * (w * x + y * z), n - 2.0 * (x * x + y * y)),
        asin(s),
        atan2(2.0 * (w * z + x * y), n - 2.0 * (y * y + z * z)),
    )


def paper_to_ned(X: tuple[float, ...]) -> dict[str, float | Quad]:
    """Paper state (eq. 7, NWU) -> NED position, NED velocity, attitude and FRD body rates."""
    x, vx, y, vy, z, vz, phi, dphi, th, dth, psi, dpsi = X
    roll, pitch, yaw = phi, -th, wrap_pi(-psi)
    p, q, r = euler_rates_to_body_rates(roll, pitch, dphi, -dth, -dpsi)
    return {
        "pos": (x, -y, -z),
        "vel": (vx, -vy, -vz),
        "euler": (roll, pitch, yaw),
        "q": euler_to_quaternion(roll, pitch, yaw),
        "rates": (p, q, r),
    }


def ned_to_paper(pos: tuple[float, float, float], vel: tuple[float, float, float], q: Quad,
                 rates: tuple[float, float, float]) -> tuple[float, ...]:
    """Inverse of :func:`paper_to_ned` (psi comes back wrapped to (-pi, pi])."""
    roll, pitch, yaw = quaternion_to_euler(q)
    droll, dpitch, dyaw = body_rates_to_euler_rates(roll, pitch, *rates)
    return (pos[0], vel[0], -pos[1], -vel[1], -pos[2], -vel[2],
            roll, droll, -pitch, -dpitch, wrap_pi(-yaw), -dyaw)

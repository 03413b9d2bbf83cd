"""The wire's conventions, in one place: frames NWU <-> NED, and actuator normalisation.

In:  the paper state (eq. 7, NWU / FLU: m, m/s, rad, rad/s), normalised paper-frame commands, control
     step numbers; and the same fields back from the wire
Out: NED position (m), NED or FRD body velocity (m/s), quaternion (w, x, y, z; FRD body to NED), Euler
     angles (rad, yaw wrapped to (-pi, pi]), FRD body rates (rad/s); actuator controls[0..3] in the
     wire's order and signs; ``time_usec`` stamps (us) and the steps they stamp; the paper state back

The state and the command over the wire (:func:`odometry_fields`, :func:`state_from_odometry_fields`,
:func:`wrench_to_wire`, :func:`wrench_from_wire`) are plain-float functions: the batch engine compiles
these same ones for its cells (numba, bridge.batch.wire).

The plant and the law work in the paper's frame: inertial x north, y west, z up (NWU),
body FLU, Z-Y-X Euler angles (phi, theta, psi). MAVLink speaks NED / FRD. At the wire
(docs/design.md, "Frames and units"):

    north = x, east = -y, down = -z;  roll = phi, pitch = -theta, yaw = -psi (wrapped)

and body rates are the exact kinematic transform of the Euler rates in the wire's frame.
"""

from __future__ import annotations

import struct
from math import asin, atan2, cos, sin, sqrt, tan

from controller.bsst import wrap_angle  # (-pi, pi]: the law's own, one function for both

Quad = tuple[float, float, float, float]


# -- actuator targets ---------------------------------------------------------------
def wrench_to_wire(c: Quad) -> Quad:
    """Normalised paper-frame wrench (u1, u2, u3, u4)/limits -> SET_ACTUATOR_CONTROL_TARGET
    group 0 controls[0..3] = (roll, pitch, yaw, thrust) in FRD: roll = u2, pitch = -u3,
    yaw = -u4, thrust = u1 (docs/design.md, "Frames and units")."""
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
    roll, pitch, yaw = phi, -th, wrap_angle(-psi)
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
            roll, droll, -pitch, -dpitch, wrap_angle(-yaw), -dyaw)


# -- ODOMETRY (frame LOCAL_NED, child BODY_FRD) ---------------------------------------
# MAVLink's ODOMETRY gives the pose in ``frame_id`` and the twist in ``child_frame_id``:
# with child BODY_FRD the velocity (vx, vy, vz) is the body-frame velocity, so it is
# rotated into FRD on the way out and back into NED on the way in.
Vec3 = tuple[float, float, float]


def rotate(q: Quad, v: Vec3) -> Vec3:
    """Rotate body-frame vector v into the frame of unit quaternion q = (w, x, y, z): R(q) v."""
    w, x, y, z = q
    vx, vy, vz = v
    # v + 2 w (u x v) + 2 u x (u x v), u = (x, y, z): no matrix built
    cx = y * vz - z * vy
    cy = z * vx - x * vz
    cz = x * vy - y * vx
    return (
        vx + 2.0 * (w * cx + y * cz - z * cy),
        vy + 2.0 * (w * cy + z * cx - x * cz),
        vz + 2.0 * (w * cz + x * cy - y * cx),
    )


def rotate_inverse(q: Quad, v: Vec3) -> Vec3:
    """Rotate a frame vector into the body: R(q)^T v (the conjugate rotation)."""
    return rotate((q[0], -q[1], -q[2], -q[3]), v)


def state_to_odometry(X: tuple[float, ...]) -> tuple[Vec3, Quad, Vec3, Vec3]:
    """Paper state (eq. 7, NWU) -> ODOMETRY fields: NED position (m), attitude quaternion
    (w, x, y, z; FRD body to NED), FRD body velocity (m/s), FRD body rates (rad/s)."""
    x, vx, y, vy, z, vz, phi, dphi, th, dth, psi, dpsi = X
    roll, pitch, yaw = phi, -th, wrap_angle(-psi)
    q = euler_to_quaternion(roll, pitch, yaw)
    return (x, -y, -z), q, rotate_inverse(q, (vx, -vy, -vz)), euler_rates_to_body_rates(roll, pitch, dphi, -dth, -dpsi)


def odometry_to_state(pos: Vec3, q: Quad, vel_body: Vec3, rates: Vec3) -> tuple[float, ...]:
    """Inverse of :func:`state_to_odometry` (psi comes back wrapped to (-pi, pi]). The
    quaternion is normalised first: a float32 one is unit only to ~1e-7."""
    n = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    q = (q[0] / n, q[1] / n, q[2] / n, q[3] / n)
    return ned_to_paper(pos, rotate(q, vel_body), q, rates)


_FLOAT32_13 = struct.Struct("<13f")
_FLOAT32_4 = struct.Struct("<4f")


def odometry_fields(X: tuple[float, ...]) -> tuple[float, ...]:
    """:func:`state_to_odometry` written out, flat: the 13 fields (NED position m, quaternion w x y z, FRD body
    velocity m/s, FRD body rates rad/s) in float64, before MAVLink rounds them to float32. The same operations
    in the same order (tested). Plain floats: the batch engine compiles this same function."""
    x, vx, y, vy, z, vz, phi, dphi, th, dth, psi, dpsi = X
    roll, pitch, yaw = phi, -th, wrap_angle(-psi)
    cr, sr = cos(0.5 * roll), sin(0.5 * roll)
    cp, sp = cos(0.5 * pitch), sin(0.5 * pitch)
    cy, sy = cos(0.5 * yaw), sin(0.5 * yaw)
    qw = cr * cp * cy + sr * sp * sy
    qx = sr * cp * cy - cr * sp * sy
    qy = cr * sp * cy + sr * cp * sy
    qz = cr * cp * sy - sr * sp * cy
    a, b, c = -qx, -qy, -qz  # rotate_inverse: the conjugate's rotation of the NED velocity
    ux, uy, uz = vx, -vy, -vz
    kx = b * uz - c * uy
    ky = c * ux - a * uz
    kz = a * uy - b * ux
    sR, cR = sin(roll), cos(roll)
    sP, cP = sin(pitch), cos(pitch)
    dp, dy = -dth, -dpsi
    return (x, -y, -z, qw, qx, qy, qz,
            ux + 2.0 * (qw * kx + b * kz - c * ky), uy + 2.0 * (qw * ky + c * kx - a * kz),
            uz + 2.0 * (qw * kz + a * ky - b * kx),
            dphi - sP * dy, cR * dp + sR * cP * dy, -sR * dp + cR * cP * dy)


def state_from_odometry_fields(f: tuple[float, ...]) -> tuple[float, ...]:
    """:func:`odometry_to_state` of the 13 fields of :func:`odometry_fields` (as read from the wire) written
    out: normalise, rotate back, quaternion to Euler, body rates to Euler rates; the paper state (psi wrapped).
    The same operations in the same order (tested). Plain floats: the batch engine compiles this same one."""
    w, qx, qy, qz = f[3], f[4], f[5], f[6]
    n = sqrt(w * w + qx * qx + qy * qy + qz * qz)
    w, qx, qy, qz = w / n, qx / n, qy / n, qz / n
    ux, uy, uz = f[7], f[8], f[9]
    kx = qy * uz - qz * uy
    ky = qz * ux - qx * uz
    kz = qx * uy - qy * ux
    v0 = ux + 2.0 * (w * kx + qy * kz - qz * ky)
    v1 = uy + 2.0 * (w * ky + qz * kx - qx * kz)
    v2 = uz + 2.0 * (w * kz + qx * ky - qy * kx)
    nn = w * w + qx * qx + qy * qy + qz * qz
    s = 2.0 * (w * qy - qz * qx) / nn
    s = 1.0 if s > 1.0 else -1.0 if s < -1.0 else s
    roll = atan2(2.0 * (w * qx + qy * qz), nn - 2.0 * (qx * qx + qy * qy))
    pitch = asin(s)
    yaw = atan2(2.0 * (w * qz + qx * qy), nn - 2.0 * (qy * qy + qz * qz))
    sR, cR = sin(roll), cos(roll)
    p, q, r = f[10], f[11], f[12]
    k = q * sR + r * cR
    return (f[0], v0, -f[1], -v1, -f[2], -v2,
            roll, p + k * tan(pitch), -pitch, -(q * cR - r * sR), wrap_angle(-yaw), -(k / cos(pitch)))


def state_over_wire(X: tuple[float, ...]) -> tuple[float, ...]:
    """The state as the controller reads it from ODOMETRY: through :func:`state_to_odometry`, each
    field rounded to float32 as MAVLink carries it, back through :func:`odometry_to_state` (psi
    wrapped). The offline loop hands its law this, so that it flies what a lockstep flight flies.

    :func:`odometry_fields` and :func:`state_from_odometry_fields` (the two functions written out: the same
    floats to the bit, ``tests/test_wire.py``) around one float32 pack: it runs once per control step of
    every offline flight, and the batch engine compiles the same two halves."""
    return state_from_odometry_fields(_FLOAT32_13.unpack(_FLOAT32_13.pack(*odometry_fields(X))))


def state_over_wire_reference(X: tuple[float, ...]) -> tuple[float, ...]:
    """:func:`state_over_wire` by its definition (the two functions and a float32 pack between): the
    reference ``tests/test_wire.py`` holds the fast one to."""
    pos, q, vel, rates = state_to_odometry(X)
    f = _FLOAT32_13.unpack(_FLOAT32_13.pack(*pos, *q, *vel, *rates))
    return odometry_to_state(f[0:3], f[3:7], f[7:10], f[10:13])


def command_over_wire(actuation: str, c: Quad) -> tuple[Quad, Quad]:
    """(the normalised command the vehicle reads, the wire values) of the normalised command ``c``
    sent as MAVLink's float32 actuator target (HIL_ACTUATOR_CONTROLS or SET_ACTUATOR_CONTROL_TARGET)."""
    w = _FLOAT32_4.unpack(_FLOAT32_4.pack(*command_to_wire(actuation, c)))
    return command_from_wire(actuation, w), w  # type: ignore[arg-type]


def step_usec(k: int, rate_hz: float) -> int:
    """time_usec of control step k at ``rate_hz``: t_k = k / rate_hz, rounded to 1 us."""
    return int(round(k * 1e6 / rate_hz))


def step_of_usec(usec: int, rate_hz: float) -> int:
    """The control step a time_usec stamps (inverse of :func:`step_usec` for rates up to
    1 MHz), so that each side recomputes t_k = k / rate_hz exactly instead of from us."""
    return int(round(usec * rate_hz / 1e6))

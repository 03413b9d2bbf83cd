"""The rigid-body model of the paper, eq. (6) with the errata of DESIGN.md section 8.

State X = (x, vx, y, vy, z, vz, phi, dphi, theta, dtheta, psi, dpsi), eq. (7): inertial
frame x north, y west, z up (NWU); Z-Y-X Euler angles and their rates.

Corrections to the printed eq. (6):
- phi'' uses l/I_x u2 (printed l/I_y).
- theta'' coupling is (I_z - I_x)/I_y (printed (I_x - I_z)/I_y): Euler's equations.
- the gyroscopic term uses the signed rotor-speed sum omega_d of eq. (5).
Outside the paper's model, and off unless asked for: linear drag (Table 1's k1..k6 as
-k*v on the translation and -k*rate on the rotation) and an external force/torque.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import cos, sin

State = tuple[float, float, float, float, float, float, float, float, float, float, float, float]


@dataclass(frozen=True, slots=True)
class RigidBody:
    """The constants eq. (6) needs, precomputed for speed.

    Build it with :func:`rigid_body`; ``i1, i2, i3`` are the paper's undefined shorthands
    (I_y - I_z)/I_x, (I_z - I_x)/I_y, (I_x - I_y)/I_z.
    """

    mass: float
    gravity: float
    ixx: float
    iyy: float
    izz: float
    i1: float
    i2: float
    i3: float
    jr_x: float  # J_r / I_x
    jr_y: float  # J_r / I_y
    l_x: float  # l / I_x
    l_y: float  # l / I_y
    l_z: float  # l / I_z
    kv: tuple[float, float, float]  # k1..k3 / m   (translational drag, 1/s)
    kw: tuple[float, float, float]  # k4..k6 / I   (rotational drag, 1/s)


def rigid_body(
    mass: float,
    ixx: float,
    iyy: float,
    izz: float,
    arm: float,
    rotor_inertia: float,
    gravity: float = 9.81,
    drag: tuple[float, ...] = (0.0,) * 6,
) -> RigidBody:
    """Precompute the constants of eq. (6) for one airframe (drag k1..k6 in N s/m, N m s)."""
    return RigidBody(
        mass=mass,
        gravity=gravity,
        ixx=ixx,
        iyy=iyy,
        izz=izz,
        i1=(iyy - izz) / ixx,
        i2=(izz - ixx) / iyy,
        i3=(ixx - iyy) / izz,
        jr_x=rotor_inertia / ixx,
        jr_y=rotor_inertia / iyy,
        l_x=arm / ixx,
        l_y=arm / iyy,
        l_z=arm / izz,
        kv=(drag[0] / mass, drag[1] / mass, drag[2] / mass),
        kw=(drag[3] / ixx, drag[4] / iyy, drag[5] / izz),
    )


def state_derivative(
    X: State,
    u1: float,
    u2: float,
    u3: float,
    u4: float,
    omega_d: float,
    body: RigidBody,
    ext: tuple[float, float, float, float, float, float] | None = None,
) -> State:
    """dX/dt of eq. (6), corrected (see module docstring).

    ``u1`` is the total thrust (N), ``u2..u4`` the paper's roll/pitch/yaw inputs (the torques
    are l*u), ``omega_d`` the signed rotor-speed sum of eq. (5) (rad/s). ``ext`` is an
    optional external (fx, fy, fz) in N (inertial frame) and (tx, ty, tz) in N m.
    """
    _, vx, _, vy, _, vz, phi, dphi, theta, dtheta, psi, dpsi = X
    cphi = cos(phi)
    sphi = sin(phi)
    cth = cos(theta)
    sth = sin(theta)
    cpsi = cos(psi)
    spsi = sin(psi)
    a = u1 / body.mass
    kv = body.kv
    kw = body.kw
    ax = (cphi * sth * cpsi + sphi * spsi) * a - kv[0] * vx
    ay = (cphi * sth * spsi - sphi * cpsi) * a - kv[1] * vy
    az = cphi * cth * a - body.gravity - kv[2] * vz
    ddphi = body.i1 * dtheta * dpsi - body.jr_x * dtheta * omega_d + body.l_x * u2 - kw[0] * dphi
    ddtheta = body.i2 * dphi * dpsi + body.jr_y * dphi * omega_d + body.l_y * u3 - kw[1] * dtheta
    ddpsi = body.i3 * dphi * dtheta + body.l_z * u4 - kw[2] * dpsi
    if ext is not None:
        m = body.mass
        ax += ext[0] / m
        ay += ext[1] / m
        az += ext[2] / m
        ddphi += ext[3] / body.ixx
        ddtheta += ext[4] / body.iyy
        ddpsi += ext[5] / body.izz
    return (vx, ax, vy, ay, vz, az, dphi, ddphi, dtheta, ddtheta, dpsi, ddpsi)

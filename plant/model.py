"""The rigid-body model of the paper, eq. (6) with errata 1-4 of docs/law.md ("Errata").

State X = (x, vx, y, vy, z, vz, phi, dphi, theta, dtheta, psi, dpsi), eq. (7): inertial
frame x north, y west, z up (NWU); Z-Y-X Euler angles and their rates.

Corrections to the printed eq. (6):
- phi'' uses l/I_x u2 (printed l/I_y).
- theta'' coupling is (I_z - I_x)/I_y (printed (I_x - I_z)/I_y): Euler's equations.
- the gyroscopic term uses the signed rotor-speed sum omega_d of eq. (5).
Outside the paper's model, and off unless asked for: linear drag (Table 1's k1..k6 as
-k*v on the translation and -k*rate on the rotation), an external force/torque, and the air
(wind: the drag on the airspeed and the rotors' induced drag, :func:`rk4_held`'s ``air``).

:func:`state_derivative` is eq. (6) itself; :func:`rk4_step_held` is one RK4 step of it
with the inputs held, specialised for speed (the plant's 1 kHz step): :func:`rk4_held`, a plain-float
function the batch engine compiles for its cells (numba, bridge.batch.kernels).

In:  the state X (eq. 7: m, m/s, rad, rad/s), the inputs u1 (N), u2..u4 (N; the torques are l u), omega_d
     (rad/s, eq. 5), the airframe's constants (:class:`RigidBody`: kg, m/s^2, kg m^2, m), the step h (s),
     optionally an external force (N) and torque (N m), the wind (m/s) and the rotor-drag coefficient (s/m)
Out: dX/dt, or the state after one RK4 step
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
    constants: tuple[float, ...]  # what rk4_held reads (:func:`rk4_constants`)


def rk4_constants(mass: float, gravity: float, i1: float, i2: float, i3: float, jr_x: float, jr_y: float,
                  l_x: float, l_y: float, l_z: float, kv: tuple[float, float, float], kw: tuple[float, float, float],
                  ixx: float, iyy: float, izz: float) -> tuple[float, ...]:
    """The flat tuple :func:`rk4_held` reads: m, g, i1..i3, jr_x, jr_y, l_x..l_z, kv0..kv2, kw0..kw2, Ixx..Izz."""
    return (mass, gravity, i1, i2, i3, jr_x, jr_y, l_x, l_y, l_z, *kv, *kw, ixx, iyy, izz)


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
    i1, i2, i3 = (iyy - izz) / ixx, (izz - ixx) / iyy, (ixx - iyy) / izz
    jr_x, jr_y = rotor_inertia / ixx, rotor_inertia / iyy
    l_x, l_y, l_z = arm / ixx, arm / iyy, arm / izz
    kv = (drag[0] / mass, drag[1] / mass, drag[2] / mass)
    kw = (drag[3] / ixx, drag[4] / iyy, drag[5] / izz)
    return RigidBody(mass=mass, gravity=gravity, ixx=ixx, iyy=iyy, izz=izz, i1=i1, i2=i2, i3=i3, jr_x=jr_x,
                     jr_y=jr_y, l_x=l_x, l_y=l_y, l_z=l_z, kv=kv, kw=kw,
                     constants=rk4_constants(mass, gravity, i1, i2, i3, jr_x, jr_y, l_x, l_y, l_z, kv, kw, ixx,
                                             iyy, izz))


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


Ext = tuple[float, float, float, float, float, float]


def rk4_step_held(
    X: State,
    u1: float,
    u2: float,
    u3: float,
    u4: float,
    omega_d: float,
    body: RigidBody,
    h: float,
    ext: tuple[Ext, Ext, Ext] | None = None,
    air: tuple[float, float, float, float] | None = None,
) -> State:
    """One classical RK4 step of eq. (6) over h (s), inputs and omega_d held (zero-order hold):
    :func:`rk4_held` with the body's constants (``air``: the held wind and rotor drag, or None)."""
    if air is None:
        return rk4_held(X, u1, u2, u3, u4, omega_d, body.constants, h, ext)  # type: ignore[return-value]
    return rk4_held(X, u1, u2, u3, u4, omega_d, body.constants, h, ext, air)  # type: ignore[return-value]


def rk4_held(X: tuple[float, ...], u1: float, u2: float, u3: float, u4: float, omega_d: float,
             K: tuple[float, ...], h: float, ext: tuple[Ext, Ext, Ext] | None,
             air: tuple[float, float, float, float] | None = None) -> tuple[float, ...]:
    """One classical RK4 step of eq. (6) over h (s), inputs (u1 N, u2..u4 N) and omega_d (rad/s) held;
    K = :func:`rk4_constants`; ``ext`` the external (fx, fy, fz, tx, ty, tz) at t, t + h/2 and t + h
    (N, N m), or None.

    ``air`` = (wx, wy, wz, c_r): the wind (m/s, NWU) held over the step and the rotor-drag coefficient
    (s/m), or None (still air: drag on the ground velocity, no rotor drag, the paper's eq. 6 exactly).
    With it the translational drag acts on the airspeed v_a = v − w, and the rotors add the induced drag
    −c_r u1 (v_a − (v_a·n) n), n the thrust axis: proportional to the thrust and to the airspeed in the
    rotor plane (docs/weather.md).

    Bit for bit the step ``plant.integrate.rk4_step(f, t, X, h)`` takes with f the
    derivative of :func:`state_derivative` (same operations in the same order; tested), in
    about half the time: positions and angles never enter the derivative, so each stage
    carries only the 9 velocities, angles and rates in local floats; the input terms are
    computed once; and no intermediate state tuple is built. Plain floats and tuples: the batch
    engine compiles this same function.
    """
    m, g, i1, i2, i3, jr_x, jr_y, l_x, l_y, l_z, kv0, kv1, kv2, kw0, kw1, kw2, ixx, iyy, izz = K
    a = u1 / m
    tx = l_x * u2
    ty = l_y * u3
    tz = l_z * u4
    x, vx, y, vy, z, vz, phi, dphi, th, dth, psi, dpsi = X
    v1, v2, v3, f, df, t, dt, p, dp = vx, vy, vz, phi, dphi, th, dth, psi, dpsi  # the stage's values
    h2 = 0.5 * h
    k1 = k2 = k3 = k4 = X  # the four stage derivatives, 12 values each (eq. 7 order)
    stage = 0
    # (step from X to the next stage along this stage's derivative, index of its time in ext)
    for c, i in ((h2, 0), (h2, 1), (h, 1), (0.0, 2)):
        cf = cos(f)
        sf = sin(f)
        st = sin(t)
        cp = cos(p)
        sp = sin(p)
        cf_st = cf * st
        if air is None:
            ax = (cf_st * cp + sf * sp) * a - kv0 * v1
            ay = (cf_st * sp - sf * cp) * a - kv1 * v2
            az = cf * cos(t) * a - g - kv2 * v3
        else:  # through the air: drag on the airspeed, rotor drag in the rotor plane
            nx, ny, nz = cf_st * cp + sf * sp, cf_st * sp - sf * cp, cf * cos(t)
            rx, ry, rz = v1 - air[0], v2 - air[1], v3 - air[2]
            dot = rx * nx + ry * ny + rz * nz
            kr = air[3] * a
            ax = nx * a - kv0 * rx - kr * (rx - dot * nx)
            ay = ny * a - kv1 * ry - kr * (ry - dot * ny)
            az = nz * a - g - kv2 * rz - kr * (rz - dot * nz)
        ddf = i1 * dt * dp - jr_x * dt * omega_d + tx - kw0 * df
        ddt = i2 * df * dp + jr_y * df * omega_d + ty - kw1 * dt
        ddp = i3 * df * dt + tz - kw2 * dp
        if ext is not None:
            e = ext[i]
            ax += e[0] / m
            ay += e[1] / m
            az += e[2] / m
            ddf += e[3] / ixx
            ddt += e[4] / iyy
            ddp += e[5] / izz
        k = (v1, ax, v2, ay, v3, az, df, ddf, dt, ddt, dp, ddp)
        if stage == 0:
            k1 = k
        elif stage == 1:
            k2 = k
        elif stage == 2:
            k3 = k
        else:
            k4 = k
        stage += 1
        v1, v2, v3 = vx + c * ax, vy + c * ay, vz + c * az
        f, df, t, dt, p, dp = phi + c * df, dphi + c * ddf, th + c * dt, dth + c * ddt, psi + c * dp, dpsi + c * ddp
    h6 = h / 6.0
    return (  # rk4_step's x + h/6 (k1 + 2 (k2 + k3) + k4), term by term: the same rounding
        x + h6 * (k1[0] + 2.0 * (k2[0] + k3[0]) + k4[0]),
        vx + h6 * (k1[1] + 2.0 * (k2[1] + k3[1]) + k4[1]),
        y + h6 * (k1[2] + 2.0 * (k2[2] + k3[2]) + k4[2]),
        vy + h6 * (k1[3] + 2.0 * (k2[3] + k3[3]) + k4[3]),
        z + h6 * (k1[4] + 2.0 * (k2[4] + k3[4]) + k4[4]),
        vz + h6 * (k1[5] + 2.0 * (k2[5] + k3[5]) + k4[5]),
        phi + h6 * (k1[6] + 2.0 * (k2[6] + k3[6]) + k4[6]),
        dphi + h6 * (k1[7] + 2.0 * (k2[7] + k3[7]) + k4[7]),
        th + h6 * (k1[8] + 2.0 * (k2[8] + k3[8]) + k4[8]),
        dth + h6 * (k1[9] + 2.0 * (k2[9] + k3[9]) + k4[9]),
        psi + h6 * (k1[10] + 2.0 * (k2[10] + k3[10]) + k4[10]),
        dpsi + h6 * (k1[11] + 2.0 * (k2[11] + k3[11]) + k4[11]),
    )


def rk4_held_steps(X: tuple[float, ...], u1: float, u2: float, u3: float, u4: float, omega_d: float,
                   K: tuple[float, ...], h: float, n: int, ground: bool) -> tuple[tuple[float, ...], int]:
    """Up to n RK4 steps of eq. (6), h (s) each, inputs (N, N m) and omega_d (rad/s) held, in still air with no
    external force: a control period's physics steps in one call (the compiled twin's call costs about as
    much as one step's arithmetic). With ``ground``, it stops after the first step that ends below the ground
    plane (z < 0 m), which its caller resolves. Returns the state and the steps taken; each step is
    :func:`rk4_held`'s, so n steps here are the bits of n calls of it."""
    for i in range(n):
        X = rk4_held(X, u1, u2, u3, u4, omega_d, K, h, None)
        if ground and X[4] < 0.0:
            return X, i + 1
    return X, n

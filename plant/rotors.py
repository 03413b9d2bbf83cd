"""Rotor equations of the paper, eq. (4)-(5), and a first-order motor lag.

Rotor numbering of eq. (4) in the '+' geometry: rotor 1 front (+x), 2 right (-y), 3 back
(-x), 4 left (+y); rotors 2 and 4 react +z yaw torque.

In:  rotor speeds (rad/s) or a wrench (u1 N; u2, u3, u4 N) or a normalised wrench command, the thrust and
     drag factors b (N s^2), d (N m s^2), the motor time constant (s)
Out: the wrench, the rotor speeds, omega_d (rad/s, eq. 5), the lagged speeds after a step. Plain floats:
     the batch engine compiles these same functions (numba, bridge.batch.kernels).
"""

from __future__ import annotations

from math import exp, sqrt

Quad = tuple[float, float, float, float]


def clip(v: float, lo: float, hi: float) -> float:
    return lo if v < lo else hi if v > hi else v


def wrench_command(c: Quad, u_max: Quad) -> Quad:
    """What a ``wrench`` profile applies for the normalised command c: u1 part in [0, 1], the others in
    [-1, 1], times the profile's limits u_max (N)."""
    return (
        clip(c[0], 0.0, 1.0) * u_max[0],
        clip(c[1], -1.0, 1.0) * u_max[1],
        clip(c[2], -1.0, 1.0) * u_max[2],
        clip(c[3], -1.0, 1.0) * u_max[3],
    )


def wrench_from_motor_speeds(omega: Quad, b: float, d: float) -> Quad:
    """Eq. (4): rotor speeds (rad/s) -> (u1, u2, u3, u4)."""
    w1, w2, w3, w4 = (o * o for o in omega)
    return (b * (w1 + w2 + w3 + w4), b * (w4 - w2), b * (w3 - w1), d * (w2 + w4 - w1 - w3))


def wrench_from_degraded_rotors(omega: Quad, effectiveness: Quad, b: float, d: float) -> Quad:
    """Eq. (4) with rotor i giving ``effectiveness[i]`` (0..1) of its thrust and drag torque (a damaged or
    failed rotor: 0 is off)."""
    e = effectiveness  # (plain arithmetic, no zip: the batch engine compiles this function)
    w1, w2, w3, w4 = (omega[0] * omega[0] * e[0], omega[1] * omega[1] * e[1], omega[2] * omega[2] * e[2],
                      omega[3] * omega[3] * e[3])
    return (b * (w1 + w2 + w3 + w4), b * (w4 - w2), b * (w3 - w1), d * (w2 + w4 - w1 - w3))


def motor_speeds_from_wrench(u: Quad, b: float, d: float) -> Quad:
    """Eq. (4) inverted, with no envelope: (u1..u4) -> rotor speeds (rad/s).

    A wrench that would need a negative squared speed gets 0 for that rotor: ideal
    (`wrench`) actuation applies u directly and uses these speeds only for the gyroscopic
    term of eq. (1).
    """
    u1, u2, u3, u4 = u
    s24 = 0.5 * (u1 / b + u4 / d)
    s13 = 0.5 * (u1 / b - u4 / d)
    w1 = 0.5 * (s13 - u3 / b)
    w2 = 0.5 * (s24 - u2 / b)
    w3 = 0.5 * (s13 + u3 / b)
    w4 = 0.5 * (s24 + u2 / b)
    return (sqrt(max(w1, 0.0)), sqrt(max(w2, 0.0)), sqrt(max(w3, 0.0)), sqrt(max(w4, 0.0)))


def signed_speed_sum(omega: Quad) -> float:
    """Eq. (5): omega_d = omega2 + omega4 - omega1 - omega3 (rad/s)."""
    return omega[1] + omega[3] - omega[0] - omega[2]


def motor_lag_step(omega: Quad, target: Quad, dt: float, tau: float) -> Quad:
    """Exact step of the first-order lag d(omega)/dt = (target - omega)/tau over dt."""
    k = 1.0 - exp(-dt / tau)
    return tuple(o + (g - o) * k for o, g in zip(omega, target, strict=True))  # type: ignore[return-value]

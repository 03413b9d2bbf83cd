"""Covers plant.model and plant.quadrotor: eq. (6) with errata 1-4 of docs/law.md ("Errata").

- phi'' uses l/I_x u2 (printed l/I_y); theta'' coupling is (I_z - I_x)/I_y (printed
  I_x - I_z); the gyroscopic term uses the signed omega_d of eq. (5).
- The translational part is checked against an independent rotation matrix
  R = Rz(psi) Ry(theta) Rx(phi) applied to the body thrust.
- Hover is an equilibrium, and the optional effects act as documented.
- A state that is its own step (at rest on the ground, motors off) is not computed again while the inputs hold: the
  same bits and clock as each step computed, and computed again once a command changes; nor is the very command
  given again.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from plant import Disturbance, Effects, Quadrotor, load_profile, quadrotor
from plant.model import rigid_body, rk4_held, state_derivative
from plant.quadrotor import ground_contact
from plant.rotors import signed_speed_sum, wrench_from_motor_speeds

# distinct inertias so that every I_x / I_y / I_z mix-up shows
M, IX, IY, IZ, L, JR, G = 1.5, 0.3, 0.5, 0.9, 0.25, 0.01, 9.81
BODY = rigid_body(M, IX, IY, IZ, L, JR, G)
REST = (0.0,) * 12


def deriv(X: tuple[float, ...] = REST, u: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0), omega_d: float = 0.0,
          ext: tuple[float, ...] | None = None, body=BODY) -> tuple[float, ...]:
    return state_derivative(X, *u, omega_d, body, ext)  # type: ignore[arg-type]


def with_rates(dphi: float, dtheta: float, dpsi: float) -> tuple[float, ...]:
    X = list(REST)
    X[7], X[9], X[11] = dphi, dtheta, dpsi
    return tuple(X)


def test_roll_uses_l_over_ix() -> None:
    """Erratum 1: phi'' = (l/I_x) u2, not (l/I_y) u2."""
    d = deriv(u=(0.0, 2.0, 0.0, 0.0))
    assert d[7] == pytest.approx(L / IX * 2.0) and d[9] == 0.0 and d[11] == 0.0
    d = deriv(u=(0.0, 0.0, 3.0, 0.0))
    assert d[9] == pytest.approx(L / IY * 3.0) and d[7] == 0.0
    d = deriv(u=(0.0, 0.0, 0.0, 4.0))
    assert d[11] == pytest.approx(L / IZ * 4.0)  # erratum 4: psi'' = (l/I_z) u4


def test_coupling_terms() -> None:
    """Erratum 2: I1 = (Iy - Iz)/Ix, I2 = (Iz - Ix)/Iy (printed Ix - Iz), I3 = (Ix - Iy)/Iz."""
    p, q, r = 0.7, -1.3, 2.1
    d = deriv(with_rates(p, q, r))
    assert d[7] == pytest.approx((IY - IZ) / IX * q * r)
    assert d[9] == pytest.approx((IZ - IX) / IY * p * r)
    assert d[11] == pytest.approx((IX - IY) / IZ * p * q)
    # the same as Euler's equations I w' = (I w) x w at zero attitude (body rates = Euler rates)
    w = np.array([p, q, r])
    inertia = np.diag([IX, IY, IZ])
    euler = np.linalg.solve(inertia, np.cross(inertia @ w, w))
    assert (d[7], d[9], d[11]) == pytest.approx(tuple(euler))


def test_gyroscopic_term_uses_signed_omega_d() -> None:
    """Erratum 3: phi'' gets -(J_r/I_x) theta' omega_d, theta'' gets +(J_r/I_y) phi' omega_d."""
    omega = (100.0, 120.0, 90.0, 130.0)
    wd = signed_speed_sum(omega)
    assert wd == 120.0 + 130.0 - 100.0 - 90.0
    d0 = deriv(with_rates(0.4, 0.6, 0.0))
    d = deriv(with_rates(0.4, 0.6, 0.0), omega_d=wd)
    assert d[7] - d0[7] == pytest.approx(-JR / IX * 0.6 * wd)
    assert d[9] - d0[9] == pytest.approx(JR / IY * 0.4 * wd)
    # equal rotor speeds cancel: no gyroscopic torque (an unsigned sum would give one)
    assert deriv(with_rates(0.4, 0.6, 0.0), omega_d=signed_speed_sum((100.0,) * 4)) == d0


def rotation(phi: float, theta: float, psi: float) -> np.ndarray:
    cf, sf, ct, stt, cp, sp = (math.cos(phi), math.sin(phi), math.cos(theta), math.sin(theta),
                               math.cos(psi), math.sin(psi))
    rx = np.array([[1, 0, 0], [0, cf, -sf], [0, sf, cf]])
    ry = np.array([[ct, 0, stt], [0, 1, 0], [-stt, 0, ct]])
    rz = np.array([[cp, -sp, 0], [sp, cp, 0], [0, 0, 1]])
    return rz @ ry @ rx


angle = st.floats(-1.2, 1.2)


@given(angle, angle, st.floats(-math.pi, math.pi), st.floats(0.0, 40.0))
def test_translation_is_the_rotated_thrust(phi: float, theta: float, psi: float, u1: float) -> None:
    X = (0.0,) * 6 + (phi, 0.0, theta, 0.0, psi, 0.0)
    d = deriv(X, (u1, 0.0, 0.0, 0.0))
    acc = rotation(phi, theta, psi) @ np.array([0.0, 0.0, u1 / M]) - np.array([0.0, 0.0, G])
    assert (d[1], d[3], d[5]) == pytest.approx(tuple(acc), abs=1e-12)


def test_kinematics_and_velocities_pass_through() -> None:
    X = (1.0, 0.1, 2.0, 0.2, 3.0, 0.3, 0.0, 0.4, 0.0, 0.5, 0.0, 0.6)
    d = deriv(X, (M * G, 0, 0, 0))
    assert (d[0], d[2], d[4], d[6], d[8], d[10]) == (0.1, 0.2, 0.3, 0.4, 0.5, 0.6)


def test_hover_is_an_equilibrium() -> None:
    X = (1.0, 0.0, -2.0, 0.0, 5.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.7, 0.0)
    assert deriv(X, (M * G, 0.0, 0.0, 0.0)) == pytest.approx((0.0,) * 12, abs=1e-15)


@pytest.mark.parametrize("name", ["paper", "x500"])
def test_quadrotor_hovers(name: str) -> None:
    """The plant at hover thrust (wrench or rotor speeds) stays where it is for 2 s."""
    p = load_profile(name)
    start = (0.5, 0.0, -0.5, 0.0, 2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.3, 0.0)
    q = Quadrotor(p, state=start)
    if p.actuation == "wrench":
        q.command((p.mass * p.gravity / p.u_max[0], 0.0, 0.0, 0.0))
    else:
        q.command((p.hover_omega / p.omega_max,) * 4)
    assert q.realised == pytest.approx((p.mass * p.gravity, 0.0, 0.0, 0.0), abs=1e-12)
    for _ in range(2000):
        q.step()
    assert q.t == pytest.approx(2.0)
    assert q.state == pytest.approx(start, abs=1e-9)


def test_quadrotor_realises_eq4_and_feeds_signed_omega_d() -> None:
    p = load_profile("x500")
    q = Quadrotor(p, ground=False, state=(0.0,) * 4 + (10.0,) + (0.0,) * 7)
    c = (0.60, 0.70, 0.65, 0.75)
    q.command(c)
    omega = tuple(ci * p.omega_max for ci in c)
    assert q.realised == pytest.approx(wrench_from_motor_speeds(omega, p.thrust_coeff, p.drag_coeff))
    X = (0.0,) * 4 + (10.0, 0.0, 0.0, 0.3, 0.0, -0.2, 0.0, 0.0)
    u = q.realised
    expected = state_derivative(X, *u, signed_speed_sum(omega), q.body)  # type: ignore[arg-type]
    assert q.derivative(0.0, X) == pytest.approx(expected)
    # commands outside [0, 1] are clipped to the rotor range
    q.command((1.5, -0.2, 0.5, 0.5))
    assert q.omega == pytest.approx((p.omega_max, 0.0, 0.5 * p.omega_max, 0.5 * p.omega_max))


def test_motor_lag_delays_the_rotors() -> None:
    p = load_profile("x500")
    q = Quadrotor(p, Effects(motor_lag=True), ground=False, state=(0.0,) * 4 + (10.0,) + (0.0,) * 7)
    h = p.hover_omega
    q.command((1.0,) * 4)
    assert q.omega == pytest.approx((h,) * 4)  # nothing yet
    q.step()
    k = 1.0 - math.exp(-0.001 / p.motor_time_constant)
    assert q.omega == pytest.approx((h + (p.omega_max - h) * k,) * 4)


def test_drag_disturbance_and_mismatch() -> None:
    p = load_profile("paper")
    X = (0.0, 1.0, 0.0, -2.0, 5.0, 0.5, 0.0, 0.3, 0.0, -0.4, 0.0, 0.2)
    hover = (p.mass * p.gravity / p.u_max[0], 0.0, 0.0, 0.0)
    plain = Quadrotor(p, ground=False)
    plain.command(hover)
    dragged = Quadrotor(p, Effects(drag=True), ground=False)
    dragged.command(hover)
    a, b = plain.derivative(0.0, X), dragged.derivative(0.0, X)
    k = p.drag
    assert b[1] - a[1] == pytest.approx(-k[0] * 1.0 / p.mass)
    assert b[3] - a[3] == pytest.approx(-k[1] * -2.0 / p.mass)
    assert b[5] - a[5] == pytest.approx(-k[2] * 0.5 / p.mass)
    assert b[7] - a[7] == pytest.approx(-k[3] * 0.3 / p.ixx)
    assert b[9] - a[9] == pytest.approx(-k[4] * -0.4 / p.iyy)
    assert b[11] - a[11] == pytest.approx(-k[5] * 0.2 / p.izz)

    dist = Disturbance(force_const=(0.5, 0.0, 0.0), torque_amp=(0.0, 0.2, 0.0), freq_hz=0.25)
    pushed = Quadrotor(p, Effects(disturbance=dist), ground=False)
    pushed.command(hover)
    t = 1.0  # sin(2 pi 0.25 1) = 1
    c = pushed.derivative(t, X)
    assert c[1] - a[1] == pytest.approx(0.5 / p.mass)
    assert c[9] - a[9] == pytest.approx(0.2 / p.iyy)

    heavy = Quadrotor(p, Effects(mass_scale=1.2, inertia_scale=1.2), ground=False)
    heavy.command(hover)
    assert heavy.body.mass == pytest.approx(1.2 * p.mass) and heavy.body.ixx == pytest.approx(1.2 * p.ixx)
    assert heavy.derivative(0.0, REST)[5] == pytest.approx(p.gravity / 1.2 - p.gravity)


def test_ground_and_divergence() -> None:
    p = load_profile("paper")
    q = Quadrotor(p)  # at rest on the ground, no thrust: stays there
    for _ in range(100):
        q.step()
    assert q.state == (0.0,) * 12 and q.on_ground
    assert q.diverged() is None
    q.state = (200.0,) + (0.0,) * 11  # type: ignore[assignment]
    assert q.diverged() == "position beyond 100 m"
    q.state = (0.0,) * 6 + (2.0,) + (0.0,) * 5  # type: ignore[assignment]
    assert q.diverged() == "tilt beyond 90 degrees"
    q.state = (math.nan,) + (0.0,) * 11  # type: ignore[assignment]
    assert q.diverged() == "state is not finite"
    q.state = (0.0,) * 11 + (-math.inf,)  # type: ignore[assignment]
    assert q.diverged() == "state is not finite"
    q.state = (1e308, 0.0, 1e308) + (0.0,) * 9  # type: ignore[assignment]  # finite, but the sum overflows
    assert q.diverged() == "position beyond 100 m"


@pytest.mark.parametrize("profile", ["paper", "x500"])
def test_a_state_that_is_its_own_step_is_not_computed_again_and_gives_the_same_bits(profile: str) -> None:
    """On the ground, motors off (a landing's disarm wait, a vehicle before take-off), each step's RK4 gives the
    resting state back bit for bit (the ground's contact takes the fall out): Quadrotor.step computes it once (the
    step that finds it), not 1 000 times, and its state and clock are each step's computed by hand. A
    command that lifts it is computed again at once (the same bits as by hand, climbing)."""
    q = Quadrotor(load_profile(profile), state=(1.25, 0.0, -0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.3, 0.0))
    calls = []

    def counted(*args: object) -> tuple[float, ...]:
        calls.append(1)
        return rk4_held(*args)

    q.rk4 = counted
    X, t = q.state, q.t
    for _ in range(1000):
        q.step()
        Y = rk4_held(X, *q.realised, q._omega_d, q.body.constants, q.dt, None)
        X = ground_contact(Y) if Y[4] < 0.0 else Y
        t += q.dt
        assert q.state == X and [math.copysign(1.0, v) for v in q.state] == [math.copysign(1.0, v) for v in X]
        assert q.t == t
    assert len(calls) == 1, len(calls)
    lift = (1.0,) * 4 if q.profile.actuation == "motors" else (1.0, 0.0, 0.0, 0.0)
    q.command(lift)
    for _ in range(50):
        q.step()
        Y = rk4_held(X, *q.realised, q._omega_d, q.body.constants, q.dt, None)
        X = ground_contact(Y) if Y[4] < 0.0 else Y
        assert q.state == X
    assert len(calls) == 51 and q.state[4] > 0.0, (len(calls), q.state[4])


@pytest.mark.parametrize("profile", ["paper", "x500"])
def test_the_very_command_given_again_is_not_computed_again(profile: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Quadrotor.command with the same tuple as its last (a vehicle's motors-off command each physics step of its
    disarm wait) changes nothing and computes nothing; an equal new tuple is computed again; the same one after a
    rotor's fault gives the fault's wrench: each the wrench a fresh plant realises for it."""
    c = (0.6, 0.1, -0.1, 0.05) if profile == "paper" else (0.6, 0.5, 0.55, 0.7)
    fresh = Quadrotor(load_profile(profile))
    fresh.command(c)
    name = "wrench_command" if profile == "paper" else "wrench_from_motor_speeds"
    computed = []
    real = getattr(quadrotor, name)
    monkeypatch.setattr(quadrotor, name, lambda *a: computed.append(1) or real(*a))
    q = Quadrotor(load_profile(profile))
    for _ in range(100):
        q.command(c)
    assert len(computed) == 2, len(computed)  # (the plant's own first command, then c once)
    assert q.realised == fresh.realised and q.omega == fresh.omega
    q.command(tuple(c))  # (tuple() of a tuple is that very tuple: not computed)
    q.command((*c,))  # (a new tuple, equal: computed)
    assert len(computed) == 3 and q.realised == fresh.realised
    if profile == "x500":  # a rotor's fault, then the same command: the fault's wrench, as a fresh plant's
        q.set_effectiveness(2, 0.5)
        q.command(q._commanded[0])
        fresh.set_effectiveness(2, 0.5)
        fresh.command(c)
        assert q.realised == fresh.realised != quadrotor.wrench_from_motor_speeds(
            q.omega, q.profile.thrust_coeff, q.profile.drag_coeff)


def test_a_command_buffer_filled_again_and_a_ground_taken_away_are_computed_again() -> None:
    """The plant's two caches (a command given again, a state that is its own step) hold only what cannot change
    under them: a list given again, its values changed in place, is the new command (a caller's buffer); a resting
    state whose ground is taken away (``ground = False``: free flight) falls, not rests on."""
    q = Quadrotor(load_profile("paper"))
    buffer = [0.6, 0.0, 0.0, 0.0]
    q.command(buffer)  # type: ignore[arg-type]
    first = q.realised
    buffer[0] = 0.2
    q.command(buffer)  # type: ignore[arg-type]
    fresh = Quadrotor(load_profile("paper"))
    fresh.command((0.2, 0.0, 0.0, 0.0))
    assert q.realised == fresh.realised != first
    rest = Quadrotor(load_profile("paper"))
    for _ in range(3):
        rest.step()
    assert rest.state[4] == 0.0
    rest.ground = False
    rest.step()
    assert rest.state[4] < 0.0 and rest.state[5] < 0.0

"""Covers controller.kernel, bridge.core.scalarkernels and bridge.core.scalar: the scalar engine's compiled kernels.

The built-in BS-ST law's one-call step and the RK4 plant step, compiled by numba, give the very bits the plain
functions give: step by step on random inputs, and over whole offline flights (the trace, float for float).
Which of the two flies (``BSST_KERNELS``) is checked as the pure function it is.
"""

from __future__ import annotations

import dataclasses
import sys

import numpy as np
import pytest

from bridge.core import scalar
from bridge.core.flight import prepare
from bridge.loop import simulate
from controller import Nominal
from controller.bsst import law_constants, law_tables
from controller.gains import Gains
from controller.kernel import control_step
from missions import MISSION_DIR, load_mission
from params import ConfigError
from plant import load_profile
from plant.model import rigid_body, rk4_held, rk4_held_steps


def test_the_one_call_step_is_the_generic_path_to_the_bit() -> None:
    """Controller.step through controller.kernel (plain) == law.update, allocate, law.advance, step by step."""
    f = prepare(MISSION_DIR / "sine.toml")
    for law in ("bsst", "smc"):
        a, b = f.make_controller(), f.make_controller()
        b._kernel = None  # the generic path
        traj = f.mission.trajectory
        X = (0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        rng = np.random.default_rng(3)
        for k in range(400):
            t = k * 0.004
            X = tuple(float(v) for v in np.asarray(X) + rng.normal(0.0, 0.01, 12))
            ca, cb = a.step(t, X, traj.sample(t), hold=k % 50 == 0), b.step(t, X, traj.sample(t), hold=k % 50 == 0)
            assert ca == cb, (law, k)
            assert (a.law.xi, a.law.s, a.law.desired, a.actuation.omega_d) == \
                (b.law.xi, b.law.s, b.law.desired, b.actuation.omega_d), (law, k)


def test_compiled_twins_give_the_plain_bits_on_random_inputs() -> None:
    """bridge.core.scalarkernels' control_step, rk4_held and rk4_held_steps against the plain functions: both
    reachings, both super-twisting steps, both actuations, with and without external forces and wind."""
    from bridge.core import scalarkernels as K

    rng = np.random.default_rng(25)
    for name in ("paper", "x500"):
        pr = load_profile(name)
        n = Nominal.from_profile(pr)
        gains = Gains()
        tables = law_tables(gains)
        alloc = (*n.u_max, n.thrust_coeff, n.drag_coeff, n.omega_max, n.omega_max**2)
        body = rigid_body(pr.mass, pr.ixx, pr.iyy, pr.izz, pr.arm, pr.rotor_inertia, pr.gravity, (0.1,) * 6)
        for i in range(200):
            X = tuple(float(v) for v in rng.normal(0.0, 0.4, 12))
            ref = tuple(tuple(float(v) for v in rng.normal(0.0, 0.5, 5)) for _ in range(4))
            xi = tuple(float(v) for v in rng.normal(0.0, 1.0, 4))
            K_ = tuple(law_constants(n, gains, 4e-3 if i % 2 else 0.0))
            for sign in (False, True):
                for motors in (False, True):
                    args = (X, ref, float(rng.normal(0.0, 50.0)), xi, i % 7 == 0, sign, K_, tables,
                            (1.0, 2.0, 3.0, 4.0), (5.0,) * 4, 4e-3, motors, alloc)
                    fast = (*args[:5], *K.kernel_arrays(args[5:]))  # the constants as the twin takes them
                    assert K.control_step(*fast) == control_step(*args), (name, i, sign, motors)
            u = (float(rng.uniform(0.0, pr.u_max[0])), *(float(v) for v in rng.normal(0.0, 0.5, 3)))
            ext = tuple(tuple(float(v) for v in rng.normal(0.0, 0.3, 6)) for _ in range(3))
            air = (*(float(v) for v in rng.normal(0.0, 3.0, 3)), 0.05)
            for e, w in ((None, None), (ext, None), (None, air), (ext, air)):
                a = (X, *u, float(rng.normal(0.0, 50.0)), body.constants, 1e-3, e, w)
                assert K.rk4_held(*a) == rk4_held(*a), (name, i)
            for steps, ground in ((4, False), (4, True), (1, True)):  # several steps in one call; z < 0 stops it
                a = (X, *u, float(rng.normal(0.0, 50.0)), body.constants, 1e-3, steps, ground)
                assert K.rk4_held_steps(*a) == rk4_held_steps(*a), (name, i, steps, ground)


@pytest.mark.parametrize("mission, law", [("sine.toml", "bsst"), ("robust-x500.toml", "smc"),
                                          ("step.toml", "pid")])
def test_an_offline_flight_with_compiled_kernels_is_the_plain_flight(monkeypatch, mission, law) -> None:
    """The whole trace, float for float (pid: its plant compiled, its law plain), over the mission's first 12 s
    (past the step's first set-point change, the robust disturbance's first periods): a closed loop amplifies
    any difference of the last bit within a few steps, and the twins' steps are pinned on random inputs above."""
    m = dataclasses.replace(load_mission(MISSION_DIR / mission), duration_s=12.0)
    monkeypatch.setenv(scalar.KERNELS_ENV, "plain")
    plain = simulate(m, controller=law, plots=False)
    monkeypatch.setenv(scalar.KERNELS_ENV, "compiled")
    fast = simulate(m, controller=law, plots=False)
    assert list(plain.trace) == list(fast.trace)
    for c in plain.trace:
        assert np.array_equal(plain.trace[c], fast.trace[c], equal_nan=True), c


def test_which_kernels_fly(monkeypatch) -> None:
    """``auto`` flies a long flight compiled, and a short one compiled only where this process holds the kernels
    already (this test process does: conftest loads them; a process without them is one where their module was
    never imported)."""
    assert scalar.compiled_loaded()
    monkeypatch.delenv(scalar.KERNELS_ENV, raising=False)
    assert scalar.compiled_wanted(7500) and scalar.compiled_wanted(scalar.AUTO_STEPS)
    monkeypatch.delitem(sys.modules, "bridge.core.scalarkernels")  # as in a process that never loaded them
    assert not scalar.compiled_loaded()
    assert not scalar.compiled_wanted(7500) and scalar.compiled_wanted(scalar.AUTO_STEPS)
    for value, short, long in (("plain", False, False), ("compiled", True, True), ("AUTO", False, True)):
        monkeypatch.setenv(scalar.KERNELS_ENV, value)
        assert (scalar.compiled_wanted(7500), scalar.compiled_wanted(1e6)) == (short, long), value
    monkeypatch.setenv(scalar.KERNELS_ENV, "fast")
    with pytest.raises(ConfigError, match="BSST_KERNELS='fast'.*plain, compiled, auto"):
        scalar.compiled_wanted(7500)


@pytest.mark.parametrize("compiled", [False, True])
def test_a_periods_steps_in_one_call_are_the_steps_one_by_one(compiled) -> None:
    """Quadrotor.steps(4) (one kernel call in still air) == four Quadrotor.step calls, state, clock and impact to
    the bit: in flight, and falling onto the ground, where the call stops at the step that ends below it."""
    from bridge.core.scalarkernels import compile_scalar
    from plant import Quadrotor

    rng = np.random.default_rng(7)
    for start_z, c in ((2.0, (0.6, 0.02, -0.01, 0.0)), (0.004, (0.0, 0.0, 0.0, 0.0)), (0.03, (0.1, 0.3, 0.0, 0.0))):
        one, four = (Quadrotor(load_profile("paper")) for _ in range(2))
        if compiled:
            compile_scalar(plant=one)
            compile_scalar(plant=four)
        for q in (one, four):
            q.state = (0.1, 0.0, 0.0, -0.1, start_z, -3.0 if start_z < 1.0 else 0.2, 0.05, 0.0, -0.02, 0.0, 0.0, 0.0)
        for _ in range(50):
            kick = tuple(float(v) for v in np.clip(np.asarray(c) + rng.normal(0.0, 0.05, 4), -1.0, 1.0))
            one.command(kick)
            four.command(kick)
            for _ in range(4):
                one.step()
            four.steps(4)
            assert (four.state, four.t, four.impact) == (one.state, one.t, one.impact)
        assert one.impact is not None or start_z > 1.0  # the falling ones did hit the ground


def test_the_wire_twins_give_the_plain_bits_on_random_states() -> None:
    """bridge.core.scalar.wire_for(True): a state's ODOMETRY fields and the state of those fields, compiled, against
    bridge.core.wire's plain functions (the vehicle's state out and the controller's state in, in lockstep)."""
    from bridge.core import wire

    out, into = scalar.wire_for(True)
    assert scalar.wire_for(False) == (wire.odometry_fields, wire.state_from_odometry_fields)
    rng = np.random.default_rng(11)
    for _ in range(500):
        X = tuple(float(v) for v in rng.normal(0.0, 2.0, 12))
        f = wire.odometry_fields(X)
        assert out(X) == f
        assert into(f) == wire.state_from_odometry_fields(f)

"""The batch engine's kernels: the scalar engine's own plain-float functions, compiled with numba.

In:  nothing at import but the pure functions of controller/, plant/, bridge/core/wire.py and
     bridge/autopilot/failsafe.py
Out: their compiled twins, called per cell by the batch engine (bridge.batch.flight, .control, .plant,
     .predict, .wire): the BS-ST law (eq. 24-40), PID, the super-twisting integrator (eq. 22, both steps), the
     actuation and allocation (eq. 4 inverted), the RK4 plant step (eq. 6), the predictor's nominal RK4,
     the state and command over the wire, the on-board landing law

One source per equation (issue 21): each function here is ``numba.njit(f)`` of the very function the
scalar engine calls, so the two engines cannot drift apart. The helpers those functions call by name are
registered as jitable first (``register_jitable``: numba compiles the same Python function wherever a
compiled caller names it); the pure packages themselves never import numba.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numba.extending import register_jitable

from bridge.autopilot import failsafe
from bridge.core import wire
from controller import actuation, bsst, jets, pid, power, predict, supertwisting
from plant import model, quadrotor, rotors

for _helper in (
    jets.add, jets.sub, jets.mul, jets.chain, jets.sqrt_, jets.atan2,
    power.sig_derivs, supertwisting.reaching, supertwisting.advance_xi, supertwisting.implicit_twisting,
    bsst.wrap_angle, bsst._reach, bsst._clip, bsst.virtual_jet, bsst._accel, bsst._limit_tilt, bsst.desired_attitude,
    bsst._attitude_step,
    pid._clip, pid.tilt_from_acceleration, pid.pid_integrals,
    actuation._clip, actuation.rotor_squares, actuation._omega_d,
    rotors.clip, rotors.motor_speeds_from_wrench, rotors.signed_speed_sum, rotors.wrench_command,
    quadrotor.ground_contact,
    wire.wrap_pi, wire.wrench_to_wire, wire.wrench_from_wire,
):
    register_jitable(_helper)

backstepping = njit(cache=True)(bsst.backstepping)
advance_xi = njit(cache=True)(supertwisting.advance_xi)
advance_xi_implicit = njit(cache=True)(supertwisting.advance_xi_implicit)
pid_law = njit(cache=True)(pid.pid)
pid_integrals = njit(cache=True)(pid.pid_integrals)
allocate_wrench = njit(cache=True)(actuation.allocate_wrench)
allocate_motors = njit(cache=True)(actuation.allocate_motors)
rk4_held = njit(cache=True)(model.rk4_held)
ground_contact = njit(cache=True)(quadrotor.ground_contact)
wrench_command = njit(cache=True)(rotors.wrench_command)
motor_speeds_from_wrench = njit(cache=True)(rotors.motor_speeds_from_wrench)
signed_speed_sum = njit(cache=True)(rotors.signed_speed_sum)
nominal_rk4 = njit(cache=True)(predict.nominal_rk4)
odometry_fields = njit(cache=True)(wire.odometry_fields)
state_from_odometry_fields = njit(cache=True)(wire.state_from_odometry_fields)
wrench_to_wire = njit(cache=True)(wire.wrench_to_wire)
wrench_from_wire = njit(cache=True)(wire.wrench_from_wire)
level_wrench = njit(cache=True)(failsafe.level_wrench)


@njit(cache=True, inline="always")
def column(X: np.ndarray, j: int) -> tuple[float, ...]:  # pragma: no cover
    """The 12 states of cell j of X [12, n] as a tuple (eq. 7 order)."""
    return (X[0, j], X[1, j], X[2, j], X[3, j], X[4, j], X[5, j], X[6, j], X[7, j], X[8, j], X[9, j], X[10, j],
            X[11, j])


@njit(cache=True, inline="always")
def put_column(X: np.ndarray, j: int, v: tuple[float, ...]) -> None:  # pragma: no cover
    """Write the 12-tuple v into column j of X [12, n]."""
    for i in range(12):
        X[i, j] = v[i]


@njit(cache=True, inline="always")
def sample(ref: np.ndarray, r: int) -> tuple[tuple[float, ...], ...]:  # pragma: no cover
    """The reference sample of column r of ref [4, 5, n]: four tuples (x, y, z, psi) of value and 4 derivatives."""
    return ((ref[0, 0, r], ref[0, 1, r], ref[0, 2, r], ref[0, 3, r], ref[0, 4, r]),
            (ref[1, 0, r], ref[1, 1, r], ref[1, 2, r], ref[1, 3, r], ref[1, 4, r]),
            (ref[2, 0, r], ref[2, 1, r], ref[2, 2, r], ref[2, 3, r], ref[2, 4, r]),
            (ref[3, 0, r], ref[3, 1, r], ref[3, 2, r], ref[3, 3, r], ref[3, 4, r]))

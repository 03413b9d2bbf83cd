"""The compiled kernels, one per equation: the plain-float functions of controller/, plant/, bridge/core/wire.py
and bridge/autopilot/onboard.py, compiled with numba for the batch engine and the scalar engine alike.

In:  nothing at import but those pure functions (importing this module imports numba: ~0.6-1.2 s)
Out: their compiled twins: the BS-ST law (eq. 24-40), PID, the super-twisting integrator (eq. 22, both steps),
     the actuation and allocation (eq. 4 inverted), eq. 4 with rotor faults, the battery's step, the RK4 plant
     step (eq. 6), the predictor's nominal RK4, the state and command over the wire, the on-board landing law
     (called per cell by bridge.batch); the scalar engine's own (the one-call control step, the plant's RK4
     step) are :mod:`bridge.core.scalarkernels`

One source per equation (issue 21): each function here is ``numba.njit(f)`` of the very function the scalar
engine calls, so the two engines cannot drift apart. The helpers those functions call by name are registered as
jitable first (``register_jitable``: numba compiles the same Python function wherever a compiled caller names
it); the pure packages themselves never import numba. No ``fastmath``: numba's default (no contraction into
fused multiply-adds, the same libm) gives bit for bit what the plain functions give (tests/test_kernels.py).
"""

from __future__ import annotations

from numba.extending import register_jitable

from bridge.autopilot import onboard
from bridge.autopilot.kernelcache import njit
from bridge.core import wire
from controller import actuation, bsst, jets, pid, power, predict, supertwisting
from plant import battery, model, quadrotor, rotors

for _helper in (
    jets.add, jets.sub, jets.mul, jets.chain, jets.sqrt_, jets.atan2,
    power.sig_derivs, supertwisting.reaching, supertwisting.advance_xi, supertwisting.advance_xi_implicit,
    supertwisting.implicit_twisting,
    bsst.wrap_angle, bsst._reach, bsst._clip, bsst.virtual_jet, bsst._accel, bsst._limit_tilt, bsst.desired_attitude,
    bsst._attitude_step, bsst.backstepping,
    pid._clip, pid.tilt_from_acceleration, pid.pid_integrals,
    actuation._clip, actuation.rotor_squares, actuation._omega_d, actuation.allocate_wrench, actuation.allocate_motors,
    rotors.clip, rotors.motor_speeds_from_wrench, rotors.signed_speed_sum, rotors.wrench_command,
    quadrotor.ground_contact, model.rk4_held,
    wire.wrench_to_wire, wire.wrench_from_wire, battery.open_circuit_v,
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
wrench_from_degraded_rotors = njit(cache=True)(rotors.wrench_from_degraded_rotors)
clip = njit(cache=True)(rotors.clip)
pack_step = njit(cache=True)(battery.pack_step)
nominal_rk4 = njit(cache=True)(predict.nominal_rk4)
odometry_fields = njit(cache=True)(wire.odometry_fields)
state_from_odometry_fields = njit(cache=True)(wire.state_from_odometry_fields)
wrench_to_wire = njit(cache=True)(wire.wrench_to_wire)
wrench_from_wire = njit(cache=True)(wire.wrench_from_wire)
level_wrench = njit(cache=True)(onboard.level_wrench)

"""The scalar engine's compiled kernels: a built-in BS-ST law's one-call control step, the plant's RK4 step, and
the state's wire conversion both ways.

In:  a :class:`~controller.Controller` and a :class:`~plant.Quadrotor` (importing this module imports numba,
     ~0.6-1.2 s, and registers the helpers: :mod:`bridge.core.kernels`)
Out: the two given their compiled twins (:func:`compile_scalar`): ``numba.njit`` of
     :func:`controller.kernel.control_step` and of :func:`plant.model.rk4_held` (and ``rk4_held_steps``), no
     ``fastmath``, bit for bit the plain functions (tests/test_kernels.py); the ODOMETRY fields of a state and
     the state of ODOMETRY's fields (:func:`wire_twins`: bridge.core.kernels' twins of bridge.core.wire's, checked)

Dispatchers of their own (the batch engine's ``rk4_held`` is another, over the same source and the same cache
on disk), so that the compiling notice (bridge.autopilot.compiling) looks at these two only.
"""

from __future__ import annotations

from typing import Any

import numpy as np

import bridge.core.kernels  # noqa: F401  (registers the helpers these kernels call by name)
from bridge.autopilot.kernelcache import njit
from bridge.core import wire
from bridge.core.kernels import odometry_fields, state_from_odometry_fields
from controller import Controller, kernel
from plant import model
from plant.quadrotor import Quadrotor

control_step = njit(cache=True)(kernel.control_step)
rk4_held = njit(cache=True)(model.rk4_held)
rk4_held_steps = njit(cache=True)(model.rk4_held_steps)


def compile_scalar(ctl: Controller | None = None, plant: Quadrotor | None = None) -> None:
    """Give ``ctl`` (a built-in BS-ST law's one-call step) and ``plant`` (its RK4 step) their compiled twins,
    loaded from numba's cache on disk or compiled (said first: bridge.autopilot.compiling), each checked against
    the plain function on one step with this flight's own constants: a twin that does not give the very same bits
    (a stale cache: numba checks only the file of the function it caches, not the helpers it inlines) is compiled
    again from source."""
    from bridge.autopilot.compiling import announce_compiling  # (its import only where kernels are loaded)

    announce_compiling(__name__)
    X = (0.3, -0.2, 0.1, 0.4, 1.2, -0.1, 0.05, -0.3, -0.04, 0.2, 0.6, 0.1)
    if ctl is not None and ctl.kernel is not None:
        ref = ((0.5, 0.1, -0.2, 0.03, 0.01), (0.2, -0.1, 0.1, 0.02, -0.01), (1.0, 0.1, 0.0, 0.0, 0.0),
               (0.5, 0.0, 0.0, 0.0, 0.0))
        head = (X, ref, 400.0, (0.1, -0.2, 0.3, 0.01), False)
        args = kernel_arrays(ctl.kernel_args)
        _checked(control_step, kernel.control_step, (*head, *args), (*head, *ctl.kernel_args))
        control_step.disable_compile()  # its one signature (floats): an integer in a reference is converted to it
        ctl.use_kernel(control_step, args)
    if plant is not None:
        _checked(rk4_held, model.rk4_held, (X, 9.0, 0.1, -0.1, 0.01, 30.0, plant.body.constants, plant.dt, None))
        _checked(rk4_held_steps, model.rk4_held_steps,
                 (X, 9.0, 0.1, -0.1, 0.01, 30.0, plant.body.constants, plant.dt, 4, plant.ground))
        plant.rk4 = rk4_held
        plant.rk4_steps = rk4_held_steps


def wire_twins() -> tuple[Any, Any]:
    """The compiled :func:`bridge.core.wire.odometry_fields` and :func:`~bridge.core.wire.state_from_odometry_fields`
    (a vehicle's state out, a controller's state in: each on the lockstep's critical path, ~0.45 us a call against
    ~1.3 us plain), each checked against the plain function on one state as :func:`compile_scalar` checks its own."""
    X = (0.3, -0.2, 0.1, 0.4, 1.2, -0.1, 0.05, -0.3, -0.04, 0.2, 0.6, 0.1)
    _checked(odometry_fields, wire.odometry_fields, (X,))
    _checked(state_from_odometry_fields, wire.state_from_odometry_fields, (wire.odometry_fields(X),))
    return odometry_fields, state_from_odometry_fields


def kernel_arrays(args: tuple[Any, ...]) -> tuple[Any, ...]:
    """A law's constants (:attr:`controller.Controller.kernel_args`) as its compiled step takes them: the constants
    and the sig_beta tables as float arrays, the rest as they are. numba types an array by its kind, where it
    walks a tuple element by element at every call: ~0.9 us less a control step, the same values."""
    sign, constants, tables, *rest = args
    return (sign, np.array(constants, dtype=np.float64), np.array(tables, dtype=np.float64), *rest)


def _checked(twin: Any, plain: Any, args: tuple[Any, ...], plain_args: tuple[Any, ...] | None = None) -> None:
    """Compile ``twin`` again if it does not give the plain function's bits for ``args`` (the plain function's own
    ``plain_args``, if they differ: the same values)."""
    if twin(*args) != plain(*(args if plain_args is None else plain_args)):
        twin.recompile()

"""The scalar engine's compiled kernels: a built-in BS-ST law's one-call control step and the plant's RK4 step.

In:  a :class:`~controller.Controller` and a :class:`~plant.Quadrotor` (importing this module imports numba,
     ~0.6-1.2 s, and registers the helpers: :mod:`bridge.core.kernels`)
Out: the two given their compiled twins (:func:`compile_scalar`): ``numba.njit`` of
     :func:`controller.kernel.control_step` and of :func:`plant.model.rk4_held`, no ``fastmath``, bit for bit
     the plain functions (tests/test_kernels.py)

Dispatchers of their own (the batch engine's ``rk4_held`` is another, over the same source and the same cache
on disk), so that the compiling notice (bridge.autopilot.compiling) looks at these two only.
"""

from __future__ import annotations

from typing import Any

from numba import njit

import bridge.core.kernels  # noqa: F401  (registers the helpers these kernels call by name)
from controller import Controller, kernel
from plant import model
from plant.quadrotor import Quadrotor

control_step = njit(cache=True)(kernel.control_step)
rk4_held = njit(cache=True)(model.rk4_held)


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
        _checked(control_step, kernel.control_step, (X, ref, 400.0, (0.1, -0.2, 0.3, 0.01), False, *ctl.kernel_args))
        control_step.disable_compile()  # its one signature (floats): an integer in a reference is converted to it
        ctl.use_kernel(control_step)
    if plant is not None:
        _checked(rk4_held, model.rk4_held, (X, 9.0, 0.1, -0.1, 0.01, 30.0, plant.body.constants, plant.dt, None))
        plant.rk4 = rk4_held


def _checked(twin: Any, plain: Any, args: tuple[Any, ...]) -> None:
    """Compile ``twin`` again if it does not give the plain function's bits for ``args``."""
    if twin(*args) != plain(*args):
        twin.recompile()

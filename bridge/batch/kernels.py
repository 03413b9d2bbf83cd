"""The batch engine's kernels: the scalar engine's own plain-float functions, compiled with numba.

In:  nothing at import but the compiled kernels of :mod:`bridge.core.kernels`
Out: those kernels, called per cell by the batch engine (bridge.batch.flight, .control, .plant, .predict,
     .wire): the BS-ST law (eq. 24-40), PID, the super-twisting integrator (eq. 22, both steps), the actuation
     and allocation (eq. 4 inverted), the RK4 plant step (eq. 6), the predictor's nominal RK4, the state and
     command over the wire, the on-board landing law; and the batch's own column helpers

One source per equation (issue 21): the kernels are compiled once, in :mod:`bridge.core.kernels` (``numba.njit``
of the very functions the scalar engine calls; the scalar engine's lockstep and offline paths use the same
dispatchers), so the two engines cannot drift apart and numba registers each helper once.
"""

from __future__ import annotations

import numpy as np

from bridge.autopilot.kernelcache import njit
from bridge.core.kernels import (  # noqa: F401  (the batch's names for them)
    advance_xi,
    advance_xi_implicit,
    allocate_motors,
    allocate_wrench,
    backstepping,
    clip,
    ground_contact,
    level_wrench,
    motor_speeds_from_wrench,
    nominal_rk4,
    odometry_fields,
    pack_step,
    pid_integrals,
    pid_law,
    rk4_held,
    signed_speed_sum,
    state_from_odometry_fields,
    wrench_command,
    wrench_from_degraded_rotors,
    wrench_from_wire,
    wrench_to_wire,
)


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

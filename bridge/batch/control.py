"""The built-in laws the batch flies and the actuation of one cell, compiled.

In:  the nominal model (its actuation, limits N, rotor coefficients, top rotor speed rad/s); per cell and
     step the wrench demanded (u1 N, u2..u4 N)
Out: the realisable wrench, the normalised command, the saturation flags and the
     signed rotor-speed sum omega_d (rad/s) of :func:`allocate_cell` (the laws' names:
     :data:`bridge.batch.scope.BATCH_LAWS`)

The laws themselves (:func:`controller.bsst.backstepping` with the explicit or implicit super-twisting
step, ``smc`` the same arithmetic with the sign reaching law, :func:`controller.pid.pid`) are called cell
by cell in the flight's kernel (bridge.batch.flight), compiled (bridge.batch.kernels).
"""

from __future__ import annotations

import numpy as np

from bridge.autopilot.kernelcache import njit
from bridge.batch import kernels as K
from controller.nominal import Nominal


class BatchActuation:
    """The numbers :func:`allocate_cell` takes for a nominal model (:func:`controller.actuation.make_actuation`'s
    choice: clamp for ``wrench``, rotor allocation for ``motors``)."""

    def __init__(self, nominal: Nominal, n: int) -> None:
        self.motors = nominal.actuation == "motors"
        self.u_max = tuple(float(v) for v in nominal.u_max)
        self.b = nominal.thrust_coeff
        self.d = nominal.drag_coeff
        self.omega_max = nominal.omega_max
        self.w2_max = nominal.omega_max**2
        self.omega_d = np.zeros(n)


@njit(cache=True, inline="always")
def allocate_cell(u: tuple, motors: bool, u_max: tuple, b: float, d: float, omega_max: float,
                  w2_max: float) -> tuple:  # pragma: no cover
    """:func:`controller.actuation.allocate_motors` (``motors``) or ``allocate_wrench`` of one cell's wrench u:
    (realisable, normalised, saturated, omega_d)."""
    if motors:
        return K.allocate_motors(u, b, d, omega_max, w2_max)
    return K.allocate_wrench(u, u_max, b, d)

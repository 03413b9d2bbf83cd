"""The wire for one cell of the batch: the state as the laws read it from ODOMETRY, the command as the vehicle
reads it from the actuator target.

In:  a cell's state (eq. 7, NWU: m, m/s, rad, rad/s; a 12-tuple); its normalised paper-frame command (4-tuple)
Out: the same after MAVLink's float32 (ODOMETRY's 13 fields; the actuator target's 4), back in the paper frame

Each cell runs the scalar engine's own functions (bridge.core.wire: :func:`~bridge.core.wire.odometry_fields`
and :func:`~bridge.core.wire.state_from_odometry_fields` around the float32 rounding, as
:func:`~bridge.core.wire.state_over_wire`; :func:`~bridge.core.wire.wrench_to_wire` and back, as
:func:`~bridge.core.wire.command_over_wire`), compiled (bridge.batch.kernels).
"""

from __future__ import annotations

import numpy as np

from bridge.autopilot.kernelcache import njit
from bridge.batch import kernels as K


@njit(cache=True, inline="always")
def _f32(v: float) -> float:
    """v rounded to float32, as MAVLink carries it (struct's "<f" in the scalar engine)."""
    return np.float64(np.float32(v))


@njit(cache=True, inline="always")
def state_over_wire(x: tuple[float, ...]) -> tuple[float, ...]:  # pragma: no cover
    """:func:`bridge.core.wire.state_over_wire` of one cell's 12 states (a tuple, eq. 7 order)."""
    f = K.odometry_fields(x)
    r = (_f32(f[0]), _f32(f[1]), _f32(f[2]), _f32(f[3]), _f32(f[4]), _f32(f[5]), _f32(f[6]), _f32(f[7]),
         _f32(f[8]), _f32(f[9]), _f32(f[10]), _f32(f[11]), _f32(f[12]))
    return K.state_from_odometry_fields(r)


@njit(cache=True, inline="always")
def command_over_wire(v: tuple[float, float, float, float],
                      wrench: bool) -> tuple[float, float, float, float]:  # pragma: no cover
    """:func:`bridge.core.wire.command_over_wire`'s command as the vehicle reads it, for one cell's normalised
    command v (``wrench``: that actuation, else ``motors``)."""
    if wrench:
        w = K.wrench_to_wire(v)
        return K.wrench_from_wire((_f32(w[0]), _f32(w[1]), _f32(w[2]), _f32(w[3])))
    return (_f32(v[0]), _f32(v[1]), _f32(v[2]), _f32(v[3]))

"""The vehicle's half of the trace: ``vehicle.bin`` (:mod:`bridge.record.halves`), one record per control step flown.

In:  the step k, the plant's true state X taken at t_k (paper frame, eq. 7), the flight mode, the target
     in force (wire units: ``motors`` omega / omega_max, ``wrench`` normalised), the failsafe's demand and
     command, the realised command, ages and wall times (s), the published estimate and its NEES, and a count of
     the targets of new steps taken from the link so far
Out: rows of :data:`~bridge.record.columns.VEHICLE_COLUMNS` (``mode`` coded by :data:`MODE_CODES`)
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

from bridge.autopilot.modes import RTL, TERMINATION
from bridge.autopilot.simvehicle import FAILSAFE, HOLD, LAND, LANDED, OFFBOARD, TAKEOFF, SimVehicle
from bridge.core.wire import command_to_wire
from bridge.record.columns import VEHICLE_COLUMNS, state_columns
from bridge.record.halves import HalfWriter

# the half's ``mode``: one code a mode (bridge.autopilot.modes.MODES; tests/test_joiner.py checks)
MODE_CODES = {OFFBOARD: 0, FAILSAFE: 1, LANDED: 2, HOLD: 3, LAND: 4, TAKEOFF: 5, RTL: 6, TERMINATION: 7}
NAN4 = (math.nan,) * 4
Estimate = tuple[tuple[float, ...], float]  # (the published estimate, its NEES)


class Rows:
    """``vehicle.bin``, written in batches."""

    def __init__(self, path: Path, rate_hz: float, arrived: Callable[[], int]) -> None:
        """``arrived``: how many targets of new steps the vehicle has taken so far (each row records those since
        the previous row: ``cmd_arrived``)."""
        self.rate = rate_hz
        self.out = HalfWriter(path, VEHICLE_COLUMNS, batch=100)
        self._arrived = arrived
        self._arrived_before = 0

    def write(self, k: int, X: tuple[float, ...], mode: str, key: int, wire: tuple[float, ...],
              dem: tuple[float, ...], real: tuple[float, ...], age: float, rtt: float, sent: float, recv: float,
              est: Estimate) -> None:
        """One row; ``est``: (estimate, NEES) taken with ``X``."""
        E, nees = est
        code = MODE_CODES[mode]
        so_far = self._arrived()
        arrived, self._arrived_before = so_far - self._arrived_before, so_far
        self.out.write((k, k / self.rate, *state_columns(X), code, key, *wire, *dem, *real, age, rtt, sent, recv,
                        *state_columns(E), nees, arrived))

    def lockstep(self, k: int, X: tuple[float, ...], mode: str, wire: tuple[float, ...] | None,
                 real: tuple[float, ...], age: float, rtt: float, sent: float, recv: float, est: Estimate) -> None:
        """Step k flown in lockstep with its answer (``wire`` None: the no-target acknowledgement)."""
        self.write(k, X, mode, k, NAN4 if wire is None else wire, NAN4, real, age, rtt, sent, recv, est)

    def free_running(self, k: int, X: tuple[float, ...], sim: SimVehicle, actuation: str,
                     applied: tuple[int, tuple[float, ...], float] | None, odo_sent: dict[int, float], now: float,
                     estimate: Callable[[], Estimate]) -> None:
        """Step k flown on the wall clock (armed): the target in force (``applied``: its step, wire, wall time
        received), none yet, or the failsafe's own landing loop in command."""
        real = sim.plant.realised
        if sim.mode == OFFBOARD and applied is not None:
            key, wire, recv = applied
            sent = odo_sent.get(key, math.nan)
            self.write(k, X, sim.mode, key, wire, NAN4, real, k / self.rate - key / self.rate, recv - sent, now,
                       recv, estimate())
        elif sim.mode == OFFBOARD:  # armed, no target yet
            self.write(k, X, sim.mode, -1, NAN4, NAN4, real, math.nan, math.nan, now, math.nan, estimate())
        else:  # failsafe: the vehicle's own landing loop is in command
            dem = sim.onboard.demand(X)
            wire = command_to_wire(actuation, sim.onboard.command(X))
            self.write(k, X, sim.mode, -1, wire, dem, real, sim.plant.t - sim.last_command_t, math.nan, now,
                       math.nan, estimate())

    def flush(self) -> None:
        self.out.flush()

    def close(self) -> None:
        self.out.close()

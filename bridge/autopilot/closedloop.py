"""The estimator's offline harness: plant, sensors, estimator and law in the vehicle loop's order.

In:  a plant (:class:`plant.Quadrotor`: state eq. (7), step ``dt`` s), a :class:`controller.Controller`,
     a reference ``t -> sample`` (s -> m, rad and their derivatives), a
     :class:`~plant.sensors.SensorSuite`, an :class:`~bridge.autopilot.estimator.Estimator`, the number of
     control steps and their rate (Hz)
Out: a :class:`ClosedLoopRecord`: per control step the time (s), the true and estimated 12-states, the
     reference (m, rad), the wrench demanded (N), the NEES and the estimate's σ where computed, the outcome

For the estimator's own tests: the product's loops carry the estimator in
:class:`~bridge.autopilot.simvehicle.SimVehicle`, and ``benchmarks/estimation.py`` flies those.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from bridge.autopilot.estimator import NAN, Estimator, nees
from plant.sensors import SensorSuite


@dataclass
class ClosedLoopRecord:
    """One flight of :func:`fly_closed_loop`, one row per control step (arrays, SI units)."""

    t: np.ndarray  # (N,) s
    truth: np.ndarray  # (N, 12) eq. (7) order
    estimate: np.ndarray  # (N, 12)
    reference: np.ndarray  # (N, 4) x, y, z, psi
    demanded: np.ndarray  # (N, 4) u1..u4, N
    nees: np.ndarray  # (N,) NaN where not computed
    outcome: str  # completed | diverged: why
    sigma: np.ndarray  # (N, 12) the estimate's sigma (NaN where not computed)


def fly_closed_loop(plant: Any, controller: Any, reference: Callable[[float], Any], suite: SensorSuite,
                    estimator: Estimator, *, steps: int, rate_hz: float, law_on: str = "estimate",
                    nees_every: int = 0) -> ClosedLoopRecord:
    """Fly a plant (:class:`plant.Quadrotor`) with a :class:`controller.Controller` at ``rate_hz``.

    Each control step k (t_k = k / rate_hz): the law reads ``estimator.estimate(t_k)`` (or, with
    ``law_on="truth"``, the true state), its command is held over the period's physics steps, and
    after each physics step the sensors sample the true state and the estimator takes what arrived.
    Every ``nees_every`` steps (0: never) the NEES of the estimate is recorded with its σ.
    """
    substeps = int(round(1.0 / (rate_hz * plant.dt)))
    estimator.step(plant.t, suite.sample(plant.t, plant.state))
    ts, truth, est, refs, dem, ne, sig = [], [], [], [], [], [], []
    nan12 = (NAN,) * 12
    outcome = "completed"
    for k in range(steps):
        t = k / rate_hz
        X = plant.state
        e = estimator.estimate(t)
        ref = reference(t)
        cmd = controller.step(t, e if law_on == "estimate" else X, ref)
        plant.command(cmd.normalised)
        if nees_every and k % nees_every == 0:
            cov = estimator.covariance()
            ne.append(nees(X, e, cov))
            sig.append(cov.sigma())
        else:
            ne.append(NAN)
            sig.append(nan12)
        ts.append(t)
        truth.append(X)
        est.append(e)
        refs.append((ref[0][0], ref[1][0], ref[2][0], ref[3][0]))
        dem.append(cmd.demanded)
        for _ in range(substeps):
            plant.step()
            estimator.step(plant.t, suite.sample(plant.t, plant.state))
        why = plant.diverged()
        if why:
            outcome = f"diverged: {why}"
            break
    return ClosedLoopRecord(np.array(ts), np.array(truth), np.array(est), np.array(refs), np.array(dem),
                            np.array(ne), outcome, np.array(sig))

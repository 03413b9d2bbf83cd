"""The vehicle's on-board estimator: from its sensors' measurements to the 12-state the law needs.

In:  :class:`~plant.sensors.Measurement` s as they arrive (``step(t, measurements)``, once per
     physics step), the sensor set they come from (:class:`~plant.sensors.SensorConfig`), the start
     state and gravity (m/s²)
Out: ``estimate(t)``: the 12-state of eq. (7) (x, ẋ, y, ẏ, z, ż, φ, φ̇, θ, θ̇, ψ, ψ̇; paper frame
     NWU, m, m/s, rad, rad/s; ψ continuous, not wrapped); ``covariance()``: a :class:`Covariance`

Three kinds, one interface (``kind``, ``step``, ``estimate``, ``covariance``):

- ``truth`` (:class:`TruthEstimator`): the true state, passed through; covariance 0.
- ``raw`` (:class:`RawEstimator`): each quantity from the sensor that measures it, the latest
  value, no fusion and no latency handling, as a naive user would: position (and, from motion
  capture, attitude) as measured; linear velocity by finite differences of successive positions
  (GNSS: its velocity); angular rates from the raw gyro through the Euler kinematics; without an
  attitude sensor, attitude integrated from the raw gyro with ψ reset by each heading reading.
- ``ekf`` (:class:`Ekf`): an error-state extended Kalman filter, below.

**The EKF.** Nominal state: position p and velocity v (paper frame, m, m/s), attitude R (body FLU
→ NWU), gyro bias b_g (rad/s) and accelerometer bias b_a (m/s²). Error state, 15 values,
δx = (δp, δv, δθ, δb_g, δb_a) with p = p̂ + δp, v = v̂ + δv, R = Exp(δθ)·R̂ (δθ a small rotation in
the paper frame, rad), b = b̂ + δb.

*Propagation*, at each IMU sample: the sample is the mean specific force f_m and body rate ω_m
over its interval T (s) (:mod:`plant.sensors`). With ω = ω_m − b̂_g, f = f_m − b̂_a,
M = R̂·Exp(ωT/2) (the attitude half-way) and a = M f − g e_z:

    p̂ += v̂ T + a T²/2,   v̂ += a T,   R̂ ← M·Exp(ωT/2)

and the error evolves as

    δṗ = δv,  δv̇ = −[M f]× δθ − M δb_a − M n_a,  δθ̇ = −M δb_g − M n_g,  δḃ_g = w_g,  δḃ_a = w_a

P is carried over the samples since it was last carried, before each update and at least every
:data:`COVARIANCE_STEP_MAX_S` (as flight-control EKFs predict their covariance at a lower rate
than the state), in one step of the elapsed T with Φ = I + A T + (A T)²/2 at the newest sample:
P ← Φ P Φᵀ + Q, Q the continuous white noise over T: Q_pp = σ_a² T³/3, Q_pv = σ_a² T²/2,
Q_vv = σ_a² T, Q_θθ = σ_g² T, Q_bg = w_g² T, Q_ba = w_a² T (each times the 3×3 identity), for the
accelerometer and gyro noise densities σ_a (m/s²/√Hz), σ_g (rad/s/√Hz) and bias walks
w_a (m/s³/√Hz), w_g (rad/s²/√Hz) of the sensor set.

*Updates*, as measurements arrive, each against the state at its time of validity t_v: the
filter keeps the nominal state at each IMU sample over the longest latency (a short buffer,
interpolated in time) with the corrections applied since, so that the innovation is
z − h(x̂(t_v)); the error at t_v is taken as the error now (over a latency Δ it differs by about
Δ·δv: 5 ms × mm/s for motion capture, 0.12 s × cm/s against a metre for GNSS). Readings, each
with white noise of the sensor's σ:

    position (m):          z = p(t_v),            H = [I, 0, 0, 0, 0]
    GNSS velocity (m/s):   z = v(t_v),            H = [0, I, 0, 0, 0]
    pose attitude (rad):   z = (φ, θ, ψ)(t_v),    fused as the small rotation E·r of its residual
                           r, noise E·diag(σ²)·Eᵀ, H = [0, 0, I, 0, 0]
    baro altitude (m):     z = p_z(t_v),          H = e_z on δp
    heading (rad):         z = ψ(t_v),            H = (cψ tθ, sψ tθ, 1) on δθ

with E = [[cψ cθ, −sψ, 0], [sψ cθ, cψ, 0], [−sθ, 0, 1]] (Euler-angle errors → a small rotation in
the paper frame; its inverse gives the heading's row) and angle residuals wrapped to (−π, π].
A 6-value reading is fused as two 3-value blocks in turn (exact: their noises are independent).
Each σ has a floor (:data:`SIGMA_FLOOR`: the filter never trusts a reading completely, so the
ideal set works too). The gain is K = P Hᵀ S⁻¹, S = H P Hᵀ + R; a block whose normalised
innovation squared rᵀS⁻¹r exceeds the χ² quantile of probability 1 − 10⁻⁶ is refused (counted
in ``rejected``; after 20 refusals in a row of one kind the next is fused anyway, as a reset).
The correction δx = K r is injected into the nominal state (R̂ ← Exp(δθ)·R̂) and P ← P − K S Kᵀ.

*Output*: p̂, v̂, the Euler angles of R̂ (ψ unwrapped), and the Euler rates of the bias-corrected
gyro ω_m − b̂_g through the Z-Y-X kinematics (:func:`plant.sensors.euler_rates`); at a time after
the last IMU sample, carried forward at constant velocity and rates.

*Initial state*: the given start (a vehicle at rest on its start point); P0 = diag of σ² with
position the sensor's σ (at least 1 cm), velocity 1 cm/s, attitude 10 mrad, gyro bias 1 mrad/s,
accelerometer bias 0.05 m/s².

**Offline harness.** :func:`fly_closed_loop` flies plant, sensors, estimator and a
:class:`~controller.Controller` fed the estimate (or the truth) with the vehicle loop's order,
for the estimator's own tests (the product's loops carry the estimator in
:class:`~bridge.core.simvehicle.SimVehicle`; ``benchmarks/estimation.py`` flies those).

**Speed.** The filter runs once per physics step in every clock, so its arithmetic is written for
CPython: 3-vectors and 3×3 matrices as plain floats, numpy only for the 15×15 covariance, through
``np.dot`` (a third less call overhead than ``@`` at this size), one product where two would do.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from plant.sensors import (
    BARO,
    GNSS,
    HEADING,
    IMU,
    POSE,
    Measurement,
    SensorConfig,
    SensorSuite,
    euler,
    euler_rates,
    matmul,
    rotation,
    rotation_of,
    wrap_angle,
)

State = tuple[float, ...]
ESTIMATOR_KINDS = ("truth", "ekf", "raw")
NAN = float("nan")

# the filter's least sigma per reading (m, rad, m/s; densities per sqrt(Hz)): no reading is exact to it
SIGMA_FLOOR = {"position": 1e-4, "attitude": 1e-4, "velocity": 1e-3, "baro": 1e-3, "heading": 1e-4,
               "accel": 1e-4, "gyro": 1e-5, "accel_walk": 1e-5, "gyro_walk": 1e-7}
# which floor each value of a reading has
FLOORS_OF = {POSE: ("position",) * 3 + ("attitude",) * 3, GNSS: ("position",) * 3 + ("velocity",) * 3,
             BARO: ("baro",), HEADING: ("heading",)}
GATE_PROBABILITY = 1e-6  # a reading this unlikely under the filter's own covariance is refused
RESET_AFTER = 20  # refusals in a row of one kind before the next is fused anyway
COVARIANCE_STEP_MAX_S = 0.02  # P is carried at least this often (s), and before every update


@dataclass(frozen=True, slots=True)
class Covariance:
    """The estimate's covariance, paper frame.

    ``state``: 9×9 row-major over (x, y, z, ẋ, ẏ, ż, φ, θ, ψ): m², m²/s², rad² (attitude as Euler
    angles); ``rates``: 3×3 row-major over the body rates (p, q, r), (rad/s)². NaN where unknown.
    """

    state: tuple[float, ...]
    rates: tuple[float, ...]

    def pose(self) -> tuple[float, ...]:
        """6×6 row-major over (x, y, z, φ, θ, ψ) (ODOMETRY's pose_covariance before the wire's frames)."""
        idx = (0, 1, 2, 6, 7, 8)
        return tuple(self.state[9 * i + j] for i in idx for j in idx)

    def twist(self) -> tuple[float, ...]:
        """6×6 row-major over (ẋ, ẏ, ż, p, q, r): inertial velocity and body rates, no cross terms."""
        out = []
        for i in range(6):
            for j in range(6):
                if i < 3 and j < 3:
                    out.append(self.state[9 * (3 + i) + 3 + j])
                elif i >= 3 and j >= 3:
                    out.append(self.rates[3 * (i - 3) + j - 3])
                else:
                    out.append(0.0)
        return tuple(out)

    def sigma(self) -> State:
        """σ of each value in the eq. (7) order; the Euler rates' σ are the body rates' (level flight)."""
        d = [math.sqrt(self.state[10 * i]) if self.state[10 * i] >= 0 else NAN for i in range(9)]
        r = [math.sqrt(self.rates[4 * i]) if self.rates[4 * i] >= 0 else NAN for i in range(3)]
        return (d[0], d[3], d[1], d[4], d[2], d[5], d[6], r[0], d[7], r[1], d[8], r[2])


ZERO_COVARIANCE = Covariance((0.0,) * 81, (0.0,) * 9)


def upper_triangle(m: Sequence[float], n: int = 6) -> tuple[float, ...]:
    """The upper-right triangle of an n×n row-major matrix, row by row (MAVLink's 21 of a 6×6)."""
    return tuple(m[n * i + j] for i in range(n) for j in range(i, n))


def estimation_error(truth: State, est: State) -> tuple[float, ...]:
    """(x, y, z, ẋ, ẏ, ż, φ, θ, ψ) of truth − estimate (ψ wrapped), the order of ``Covariance.state``."""
    return (truth[0] - est[0], truth[2] - est[2], truth[4] - est[4], truth[1] - est[1], truth[3] - est[3],
            truth[5] - est[5], truth[6] - est[6], truth[8] - est[8], wrap_angle(truth[10] - est[10]))


def nees(truth: State, est: State, cov: Covariance) -> float:
    """Normalised estimation error squared over position, velocity and attitude (9 degrees of
    freedom: χ²(9) if the covariance is right); NaN if the covariance is unknown or singular."""
    return _nees_of(truth, est, np.array(cov.state).reshape(9, 9))


def estimator_nees(estimator: Estimator, truth: State, est: State) -> float:
    """:func:`nees` of ``est`` against ``estimator``'s covariance now (the EKF's 9×9 straight from its P,
    without the :class:`Covariance` tuples between: the same floats, a control step's worth less work)."""
    if isinstance(estimator, Ekf):
        return _nees_of(truth, est, estimator.state_covariance())
    return nees(truth, est, estimator.covariance())


def _nees_of(truth: State, est: State, C: np.ndarray) -> float:
    """:func:`nees` with the state covariance as a 9×9 array."""
    e = np.array(estimation_error(truth, est))
    if not np.isfinite(C).all():
        return NAN
    try:
        return float(np.dot(e, np.linalg.solve(C, e)))
    except np.linalg.LinAlgError:
        return NAN


def chi2_quantile(dof: int, tail: float) -> float:
    """Approximate χ² quantile with upper tail probability ``tail`` (Wilson–Hilferty)."""
    z = _normal_quantile(1.0 - tail)
    k = 2.0 / (9.0 * dof)
    return dof * (1.0 - k + z * math.sqrt(k)) ** 3


def _normal_quantile(p: float) -> float:
    """The standard normal quantile, by bisection of erf (a handful of calls: only at start)."""
    lo, hi = -10.0, 10.0
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        if 0.5 * (1.0 + math.erf(mid / math.sqrt(2.0))) < p:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


class Estimator(Protocol):
    """What the vehicle runs on board: fed every physics step, read at each control step."""

    kind: str

    def step(self, t: float, measurements: Sequence[Measurement]) -> None: ...

    def estimate(self, t: float) -> State: ...

    def covariance(self) -> Covariance: ...


class TruthEstimator:
    """The true state, passed through (today's behaviour)."""

    kind = "truth"

    def __init__(self, truth: Callable[[], State]) -> None:
        self._truth = truth

    def step(self, t: float, measurements: Sequence[Measurement]) -> None:
        return None

    def estimate(self, t: float) -> State:
        return tuple(self._truth())

    def covariance(self) -> Covariance:
        return ZERO_COVARIANCE


def _unwrap(new: float, previous: float) -> float:
    """The angle equal to ``new`` modulo 2π nearest to ``previous``."""
    return previous + wrap_angle(new - previous)


class RawEstimator:
    """Measurements passed on as a naive user would (see the module docstring)."""

    kind = "raw"

    def __init__(self, config: SensorConfig, start: State) -> None:
        self._pose = config.position_class == "mocap"
        X = start
        self._p = [X[0], X[2], X[4]]
        self._v = [X[1], X[3], X[5]]
        self._att = [X[6], X[8], X[10]]
        self._R = rotation(X[6], X[8], X[10])
        self._gyro = (0.0, 0.0, 0.0)
        self._last_fix: tuple[float, tuple[float, ...], tuple[float, ...]] | None = None  # (t_valid, values, sigma)
        self._var = [NAN] * 12  # variances in the order x, y, z, vx, vy, vz, phi, theta, psi, p, q, r

    def step(self, t: float, measurements: Sequence[Measurement]) -> None:
        for m in measurements:
            k = m.kind
            if k == IMU:
                self._gyro = m.values[3:6]
                self._var[9:12] = [s * s for s in m.sigma[3:6]]
                if not self._pose:  # no attitude sensor: the raw gyro, integrated
                    w = m.values[3:6]
                    T = m.interval_s
                    self._R = matmul(self._R, rotation_of(w[0] * T, w[1] * T, w[2] * T))
                    phi, theta, psi = euler(self._R)
                    self._att = [phi, theta, _unwrap(psi, self._att[2])]
            elif k in (POSE, GNSS):
                vals, sig = m.values, m.sigma
                self._p = list(vals[0:3])
                self._var[0:3] = [s * s for s in sig[0:3]]
                if k == GNSS:
                    self._v = list(vals[3:6])
                    self._var[3:6] = [s * s for s in sig[3:6]]
                else:
                    self._att = [vals[3], vals[4], _unwrap(vals[5], self._att[2])]
                    self._var[6:9] = [s * s for s in sig[3:6]]
                    last = self._last_fix
                    if last is not None and m.t_valid > last[0]:
                        dt = m.t_valid - last[0]
                        self._v = [(vals[i] - last[1][i]) / dt for i in range(3)]
                        self._var[3:6] = [(sig[i] ** 2 + last[2][i] ** 2) / dt**2 for i in range(3)]
                    self._last_fix = (m.t_valid, vals, sig)
            elif k == HEADING and not self._pose:
                phi, theta, _ = self._att
                psi = _unwrap(m.values[0], self._att[2])
                self._att = [phi, theta, psi]
                self._R = rotation(phi, theta, psi)
                self._var[8] = m.sigma[0] ** 2

    def estimate(self, t: float) -> State:
        phi, theta, psi = self._att
        dphi, dtheta, dpsi = euler_rates(phi, theta, *self._gyro)
        p, v = self._p, self._v
        return (p[0], v[0], p[1], v[1], p[2], v[2], phi, dphi, theta, dtheta, psi, dpsi)

    def covariance(self) -> Covariance:
        d = self._var
        state = [0.0] * 81
        for i in range(9):
            state[10 * i] = d[i]
        rates = [0.0] * 9
        for i in range(3):
            rates[4 * i] = d[9 + i]
        return Covariance(tuple(state), tuple(rates))


def _euler_jacobian(phi: float, theta: float, psi: float) -> np.ndarray:
    """E⁻¹: a small rotation in the paper frame → the Euler-angle errors (dφ, dθ, dψ)."""
    cp, sp, ct, tt = math.cos(psi), math.sin(psi), math.cos(theta), math.tan(theta)
    return np.array(((cp / ct, sp / ct, 0.0), (-sp, cp, 0.0), (cp * tt, sp * tt, 1.0)))


class Ekf:
    """The error-state EKF of the module docstring (15 error states)."""

    kind = "ekf"

    def __init__(self, config: SensorConfig, start: State, gravity: float = 9.81) -> None:
        c = config
        self.config = c
        self.gravity = gravity
        f = SIGMA_FLOOR
        self._na2 = max(c.accel_noise_density, f["accel"]) ** 2
        self._ng2 = max(c.gyro_noise_density, f["gyro"]) ** 2
        self._wa2 = max(c.accel_bias_walk, f["accel_walk"]) ** 2
        self._wg2 = max(c.gyro_bias_walk, f["gyro_walk"]) ** 2
        X = start
        self._p = [X[0], X[2], X[4]]
        self._v = [X[1], X[3], X[5]]
        self._R = rotation(X[6], X[8], X[10])
        self._bg = [0.0, 0.0, 0.0]
        self._ba = [0.0, 0.0, 0.0]
        self._psi = X[10]  # the output's continuous heading
        self._t = 0.0  # time of the nominal state (the last IMU sample)
        self._omega = (0.0, 0.0, 0.0)  # bias-corrected body rate of the last IMU sample
        self._accel = (0.0, 0.0, 0.0)  # inertial acceleration of the last IMU sample
        self._af = (0.0, 0.0, gravity)  # specific force in the paper frame (M f) of the last sample
        self._M = self._R
        self._euler: tuple[float, float, float] | None = None  # Euler angles of R (psi unwrapped), None: not yet
        self._gyro_var = self._ng2 * min(c.imu_rate_hz, 1e4)  # white variance of one gyro sample (set per sample)
        s_pos = max(c.position_noise_m, 0.01)
        s_z = max(c.position_noise_z_m, 0.01)
        self.P = np.diag([s_pos**2, s_pos**2, s_z**2] + [1e-4] * 3 + [1e-4] * 3 + [1e-6] * 3 + [0.05**2] * 3)
        self._Phi = np.eye(15)
        self._T = -1.0  # the period T (s) the coefficients and Q below are set for
        self._phi_coef = np.zeros(len(_PHI_INDEX))
        self._Q = np.zeros((15, 15))
        self._predictions = 0
        self._pending_T = 0.0  # IMU time P has not been carried over yet (s)
        self._periods: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._h_heading = np.zeros(15)  # the heading's row of H: (cψ tθ, sψ tθ, 1) on δθ
        self._h_heading[8] = 1.0
        self._corr = [0.0] * 9  # corrections applied so far to (p, v, phi, theta, psi), summed
        latency = c.position_latency_ms / 1000.0
        depth = int(math.ceil((latency + 0.05) * min(c.imu_rate_hz, 1e4))) + 4  # IMU samples over the latency
        self._history: deque[tuple[float, ...]] = deque(maxlen=depth)
        self._remember()
        self.rejected: dict[str, int] = {}
        self._refused_in_row: dict[str, int] = {}
        self._gates = {m: chi2_quantile(m, GATE_PROBABILITY) for m in (1, 3, 6)}
        self._kept_variances: dict[str, tuple[tuple[float, ...], tuple[float, ...]]] = {}
        self.fused = 0

    # -- reading the state ---------------------------------------------------------------
    @property
    def biases(self) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """The estimated (gyro bias rad/s, accelerometer bias m/s²), body axes."""
        return (self._bg[0], self._bg[1], self._bg[2]), (self._ba[0], self._ba[1], self._ba[2])

    def bias_sigma(self) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """σ of the estimated biases, as :attr:`biases`."""
        d = np.sqrt(np.diag(self._current_P())[9:15]).tolist()
        return (d[0], d[1], d[2]), (d[3], d[4], d[5])

    def _euler_now(self) -> tuple[float, float, float]:
        """(φ, θ, ψ) of R̂, ψ continuous; kept until R̂ changes (read at every IMU sample and control step)."""
        e = self._euler
        if e is None:
            phi, theta, psi = euler(self._R)
            self._psi = _unwrap(psi, self._psi)
            e = self._euler = (phi, theta, self._psi)
        return e

    def _remember(self) -> None:
        phi, theta, psi = self._euler_now()
        p0, p1, p2 = self._p
        v0, v1, v2 = self._v
        c0, c1, c2, c3, c4, c5, c6, c7, c8 = self._corr
        self._history.append((self._t, p0, p1, p2, v0, v1, v2, phi, theta, psi, c0, c1, c2, c3, c4, c5, c6, c7, c8))

    def _state_at(self, t: float) -> list[float]:
        """(x, y, z, vx, vy, vz, phi, theta, psi) at time t, as known now (buffer + corrections since)."""
        h = self._history
        c0, c1, c2, c3, c4, c5, c6, c7, c8 = self._corr
        newest = h[-1]
        if t >= newest[0]:
            tb, x, y, z, vx, vy, vz, phi, theta, psi, k0, k1, k2, k3, k4, k5, k6, k7, k8 = newest
            dt = t - tb
            return [x + vx * dt + c0 - k0, y + vy * dt + c1 - k1, z + vz * dt + c2 - k2, vx + c3 - k3, vy + c4 - k4,
                    vz + c5 - k5, phi + c6 - k6, theta + c7 - k7, psi + c8 - k8]
        for i in range(len(h) - 1, 0, -1):
            a = h[i - 1]
            if a[0] <= t:
                ta, a0, a1, a2, a3, a4, a5, a6, a7, a8, m0, m1, m2, m3, m4, m5, m6, m7, m8 = a
                tb, b0, b1, b2, b3, b4, b5, b6, b7, b8, n0, n1, n2, n3, n4, n5, n6, n7, n8 = h[i]
                w = (t - ta) / (tb - ta)  # the state, and the corrections it had then, both interpolated
                return [a0 + w * (b0 - a0) + c0 - (m0 + w * (n0 - m0)), a1 + w * (b1 - a1) + c1 - (m1 + w * (n1 - m1)),
                        a2 + w * (b2 - a2) + c2 - (m2 + w * (n2 - m2)), a3 + w * (b3 - a3) + c3 - (m3 + w * (n3 - m3)),
                        a4 + w * (b4 - a4) + c4 - (m4 + w * (n4 - m4)), a5 + w * (b5 - a5) + c5 - (m5 + w * (n5 - m5)),
                        a6 + w * (b6 - a6) + c6 - (m6 + w * (n6 - m6)), a7 + w * (b7 - a7) + c7 - (m7 + w * (n7 - m7)),
                        a8 + w * (b8 - a8) + c8 - (m8 + w * (n8 - m8))]
        older = h[0]
        c = (c0, c1, c2, c3, c4, c5, c6, c7, c8)
        return [older[1 + k] + c[k] - older[10 + k] for k in range(9)]

    def estimate(self, t: float) -> State:
        phi, theta, psi = self._euler_now()
        dphi, dtheta, dpsi = euler_rates(phi, theta, *self._omega)
        dt = t - self._t
        p, v = self._p, self._v
        if dt > 0.0:
            a = self._accel
            return (p[0] + v[0] * dt, v[0] + a[0] * dt, p[1] + v[1] * dt, v[1] + a[1] * dt, p[2] + v[2] * dt,
                    v[2] + a[2] * dt, phi + dphi * dt, dphi, theta + dtheta * dt, dtheta, psi + dpsi * dt, dpsi)
        return (p[0], v[0], p[1], v[1], p[2], v[2], phi, dphi, theta, dtheta, psi, dpsi)

    def state_covariance(self, P: np.ndarray | None = None) -> np.ndarray:
        """:attr:`Covariance.state` as a 9×9 array (of ``P``, the covariance carried to now if None)."""
        if P is None:
            P = self._current_P()
        # J P Jᵀ with J = diag(I₆, E⁻¹) on (δp, δv, δθ): only the attitude's rows and columns change
        Ja = _euler_jacobian(*self._euler_now())
        state = P[:9, :9].copy()
        state[6:9] = np.dot(Ja, state[6:9])
        state[:, 6:9] = np.dot(state[:, 6:9], Ja.T)
        return state

    def covariance(self) -> Covariance:
        P = self._current_P()
        state = self.state_covariance(P)
        g = self._gyro_var
        (b00, b01, b02), (b10, b11, b12), (b20, b21, b22) = P[9:12, 9:12].tolist()
        rates = (b00 + g, b01, b02, b10, b11 + g, b12, b20, b21, b22 + g)
        return Covariance(tuple(state.ravel().tolist()), rates)

    # -- the filter ----------------------------------------------------------------------
    def step(self, t: float, measurements: Sequence[Measurement]) -> None:
        for m in measurements:
            k = m.kind
            if k == IMU:
                self._propagate(m)
            elif k == POSE:
                self._fuse_pose(t, m)
            elif k == GNSS:
                self._fuse_gnss(t, m)
            elif k == BARO:
                self._fuse_baro(t, m)
            elif k == HEADING:
                self._fuse_heading(t, m)

    def _propagate(self, m: Measurement) -> None:
        T = m.interval_s
        fm = m.values
        bg, ba = self._bg, self._ba
        wx, wy, wz = fm[3] - bg[0], fm[4] - bg[1], fm[5] - bg[2]
        fx, fy, fz = fm[0] - ba[0], fm[1] - ba[1], fm[2] - ba[2]
        H = rotation_of(0.5 * wx * T, 0.5 * wy * T, 0.5 * wz * T)  # Exp(ωT/2)
        M = matmul(self._R, H)  # the attitude at mid-interval
        m0, m1, m2, m3, m4, m5, m6, m7, m8 = M
        afx = m0 * fx + m1 * fy + m2 * fz
        afy = m3 * fx + m4 * fy + m5 * fz
        afz = m6 * fx + m7 * fy + m8 * fz
        ax, ay, az = afx, afy, afz - self.gravity
        p, v = self._p, self._v
        hT2 = 0.5 * T * T
        p[0] += v[0] * T + ax * hT2
        p[1] += v[1] * T + ay * hT2
        p[2] += v[2] * T + az * hT2
        v[0] += ax * T
        v[1] += ay * T
        v[2] += az * T
        self._R = matmul(M, H)
        self._euler = None
        self._t = m.t_valid
        self._omega = (wx, wy, wz)
        self._gyro_var = self._ng2 / T  # white variance of this sample's mean rate
        self._accel = (ax, ay, az)
        self._af = (afx, afy, afz)
        self._M = M
        self._pending_T += T
        if self._pending_T >= COVARIANCE_STEP_MAX_S:
            self._flush_covariance()
        self._remember()

    def _flush_covariance(self) -> None:
        """Carry P over the IMU samples since the last time it was carried (one step, Φ at the
        newest sample's attitude and specific force): before each update and at least every
        COVARIANCE_STEP_MAX_S. Reading the covariance never does (so that reading it, or not,
        changes nothing of the flight)."""
        T = self._pending_T
        if T > 0.0:
            self._pending_T = 0.0
            P = self._carried(T, self._af, self._M)
            self._predictions += 1
            if self._predictions % 64 == 0:  # rounding makes P drift from symmetric, slowly
                P = 0.5 * (P + P.T)
            self.P = P

    def _current_P(self) -> np.ndarray:
        """P carried to now, without storing it."""
        T = self._pending_T
        return self._carried(T, self._af, self._M) if T > 0.0 else self.P

    def _carried(self, T: float, af: tuple[float, float, float], M: tuple[float, ...]) -> np.ndarray:
        """Φ P Φᵀ + Q over T: Φ's varying blocks written in place with one scatter, Q cached per T."""
        if T != self._T:
            self._set_period(T)
        ax, ay, az = af
        Sk = (0.0, -az, ay, az, 0.0, -ax, -ay, ax, 0.0)
        Phi = self._Phi
        # the entries in _PHI_INDEX's order, gathered in Python (a numpy take less)
        # np.dot, not @: a third less call overhead on arrays this small
        Phi.put(_PHI_INDEX, np.array(Sk + M + M + Sk + M + matmul(Sk, M) + _ONES3) * self._phi_coef)
        P = np.dot(np.dot(Phi, self.P), Phi.T)
        P += self._Q
        return P

    def _set_period(self, T: float) -> None:
        """The coefficients of Φ's varying entries and Q of a step T (s), cached per T."""
        self._T = T
        key = round(T * 1e9)
        cached = self._periods.get(key)
        if cached is None:
            coef = np.array([-T] * 27 + [-0.5 * T * T] * 18 + [0.5 * T * T] * 9 + [T] * 3)
            na2, T2 = self._na2, T * T
            Q = np.zeros((15, 15))
            for i in range(3):
                Q[i, i] = na2 * T2 * T / 3.0
                Q[i, 3 + i] = Q[3 + i, i] = 0.5 * na2 * T2
                Q[3 + i, 3 + i] = na2 * T
                Q[6 + i, 6 + i] = self._ng2 * T
                Q[9 + i, 9 + i] = self._wg2 * T
                Q[12 + i, 12 + i] = self._wa2 * T
            cached = self._periods[key] = (coef, Q)
        self._phi_coef, self._Q = cached

    def _gate(self, kind: str, nis: float, dof: int) -> bool:
        """Whether to fuse a reading of this normalised innovation squared (counts refusals)."""
        if nis <= self._gates[dof]:
            self._refused_in_row[kind] = 0
            return True
        n = self._refused_in_row.get(kind, 0) + 1
        self._refused_in_row[kind] = n
        self.rejected[kind] = self.rejected.get(kind, 0) + 1
        if n > RESET_AFTER:
            self._refused_in_row[kind] = 0
            return True
        return False

    def _update_block(self, kind: str, i0: int, r: Sequence[float], Rm: Sequence[float],
                      dx: list[float] | None) -> list[float] | None:
        """One 3-value reading of the error states i0..i0+2 (H selects them) with noise covariance
        ``Rm`` (3×3 row-major), after the correction ``dx`` of an earlier block of the same reading
        (sequential blocks: exact, their noises being independent); returns the correction so far,
        or None if refused."""
        P = self.P
        PHt = P[:, i0:i0 + 3]
        (s00, s01, s02), (s10, s11, s12), (s20, s21, s22) = P[i0:i0 + 3, i0:i0 + 3].tolist()
        s00 += Rm[0]
        s01 += Rm[1]
        s02 += Rm[2]
        s10 += Rm[3]
        s11 += Rm[4]
        s12 += Rm[5]
        s20 += Rm[6]
        s21 += Rm[7]
        s22 += Rm[8]
        c00 = s11 * s22 - s12 * s21
        c01 = s02 * s21 - s01 * s22
        c02 = s01 * s12 - s02 * s11
        det = s00 * c00 + s10 * c01 + s20 * c02
        if not det > 0.0:
            self.rejected[kind] = self.rejected.get(kind, 0) + 1
            return None
        k = 1.0 / det
        i00, i01, i02 = c00 * k, c01 * k, c02 * k
        i10, i11, i12 = (s12 * s20 - s10 * s22) * k, (s00 * s22 - s02 * s20) * k, (s02 * s10 - s00 * s12) * k
        i20, i21, i22 = (s10 * s21 - s11 * s20) * k, (s01 * s20 - s00 * s21) * k, (s00 * s11 - s01 * s10) * k
        r0, r1, r2 = r
        if dx is not None:
            r0, r1, r2 = r0 - dx[i0], r1 - dx[i0 + 1], r2 - dx[i0 + 2]
        y0 = i00 * r0 + i01 * r1 + i02 * r2
        y1 = i10 * r0 + i11 * r1 + i12 * r2
        y2 = i20 * r0 + i21 * r1 + i22 * r2
        if not self._gate(kind, r0 * y0 + r1 * y1 + r2 * y2, 3):
            return None
        # one product gives the gain K = P Hᵀ S⁻¹ (first 3 columns) and the correction P Hᵀ S⁻¹ r (the 4th);
        # np.dot, not @: a third less call overhead on arrays this small
        Ky = np.dot(PHt, np.array(((i00, i01, i02, y0), (i10, i11, i12, y1), (i20, i21, i22, y2))))
        step = Ky[:, 3].tolist()
        P -= np.dot(Ky[:, :3], PHt.T)  # in place: the product is evaluated before P changes
        if dx is None:
            return step
        return [a + b for a, b in zip(dx, step, strict=True)]

    def _update_scalar(self, kind: str, h: np.ndarray | int, r: float, var: float) -> None:
        """One scalar reading: h a 15-row of the error, or the index of the one error state it reads."""
        P = self.P
        if isinstance(h, int):
            PHt = P[:, h].copy()
            s = PHt.item(h) + var
        else:
            PHt = np.dot(P, h)
            s = float(np.dot(h, PHt)) + var
        if not s > 0.0 or not self._gate(kind, r * r / s, 1):
            return
        K = PHt / s
        P -= np.dot(K.reshape(15, 1), PHt.reshape(1, 15))  # np.outer costs three times as much
        self._inject((K * r).tolist())
        self.fused += 1

    def _inject(self, dx: list[float]) -> None:
        """Add a correction to the nominal state, and to the corrections applied so far (the
        attitude's as Euler-angle changes, E⁻¹ δθ)."""
        d0, d1, d2, d3, d4, d5, w0, w1, w2, g0, g1, g2, a0, a1, a2 = dx
        p, v, bg, ba, c = self._p, self._v, self._bg, self._ba, self._corr
        p[0] += d0
        p[1] += d1
        p[2] += d2
        v[0] += d3
        v[1] += d4
        v[2] += d5
        bg[0] += g0
        bg[1] += g1
        bg[2] += g2
        ba[0] += a0
        ba[1] += a1
        ba[2] += a2
        c[0] += d0
        c[1] += d1
        c[2] += d2
        c[3] += d3
        c[4] += d4
        c[5] += d5
        R = self._R
        cp, sp = math.cos(self._psi), math.sin(self._psi)
        ct = math.sqrt(max(1e-12, 1.0 - R[6] * R[6]))  # cos theta
        a = (cp * w0 + sp * w1) / ct
        c[6] += a
        c[7] += cp * w1 - sp * w0
        c[8] += w2 - R[6] * a  # + tan(theta) cos(theta) a, sin(theta) = -R[6]
        e0, e1, e2, e3, e4, e5, e6, e7, e8 = rotation_of(w0, w1, w2)
        r0, r1, r2, r3, r4, r5, r6, r7, r8 = R
        self._R = (e0 * r0 + e1 * r3 + e2 * r6, e0 * r1 + e1 * r4 + e2 * r7, e0 * r2 + e1 * r5 + e2 * r8,
                   e3 * r0 + e4 * r3 + e5 * r6, e3 * r1 + e4 * r4 + e5 * r7, e3 * r2 + e4 * r5 + e5 * r8,
                   e6 * r0 + e7 * r3 + e8 * r6, e6 * r1 + e7 * r4 + e8 * r7, e6 * r2 + e7 * r5 + e8 * r8)  # Exp(δθ)·R
        self._euler = None

    def _variances(self, kind: str, sigma: tuple[float, ...]) -> tuple[float, ...]:
        """The filter's noise variances of a reading's σ (floored, :data:`SIGMA_FLOOR`), kept per kind
        while the σ stay the same (a sensor's σ are fixed: this runs once per sensor)."""
        kept = self._kept_variances.get(kind)
        if kept is not None and kept[0] == sigma:
            return kept[1]
        v = tuple(max(s, SIGMA_FLOOR[f]) ** 2 for s, f in zip(sigma, FLOORS_OF[kind], strict=True))
        self._kept_variances[kind] = (sigma, v)
        return v

    def _fuse_pose(self, t: float, m: Measurement) -> None:
        self._flush_covariance()
        s = self._state_at(m.t_valid)
        z = m.values
        vp0, vp1, vp2, v0, v1, v2 = self._variances(POSE, m.sigma)
        dx = self._update_block(POSE, 0, (z[0] - s[0], z[1] - s[1], z[2] - s[2]),
                                (vp0, 0.0, 0.0, 0.0, vp1, 0.0, 0.0, 0.0, vp2), None)
        # the Euler-angle residual as a small rotation, r = E·(dφ, dθ, dψ), its noise E·diag(σ²)·Eᵀ
        e0, e1, e2 = wrap_angle(z[3] - s[6]), wrap_angle(z[4] - s[7]), wrap_angle(z[5] - s[8])
        cp, sp, ct, st = math.cos(s[8]), math.sin(s[8]), math.cos(s[7]), math.sin(s[7])
        a, b = cp * ct, sp * ct  # E = [[a, -sp, 0], [b, cp, 0], [-st, 0, 1]]
        r = (a * e0 - sp * e1, b * e0 + cp * e1, e2 - st * e0)
        r01 = a * b * v0 - sp * cp * v1
        r02 = -a * st * v0
        r12 = -b * st * v0
        Rm = (a * a * v0 + sp * sp * v1, r01, r02, r01, b * b * v0 + cp * cp * v1, r12, r02, r12, st * st * v0 + v2)
        dx2 = self._update_block(POSE, 6, r, Rm, dx)
        dx = dx2 if dx2 is not None else dx
        if dx is not None:
            self._inject(dx)
            self.fused += 1

    def _fuse_gnss(self, t: float, m: Measurement) -> None:
        self._flush_covariance()
        s = self._state_at(m.t_valid)
        z = m.values
        vp0, vp1, vp2, vv0, vv1, vv2 = self._variances(GNSS, m.sigma)
        dx = self._update_block(GNSS, 0, (z[0] - s[0], z[1] - s[1], z[2] - s[2]),
                                (vp0, 0.0, 0.0, 0.0, vp1, 0.0, 0.0, 0.0, vp2), None)
        dx2 = self._update_block(GNSS, 3, (z[3] - s[3], z[4] - s[4], z[5] - s[5]),
                                 (vv0, 0.0, 0.0, 0.0, vv1, 0.0, 0.0, 0.0, vv2), dx)
        dx = dx2 if dx2 is not None else dx
        if dx is not None:
            self._inject(dx)
            self.fused += 1

    def _fuse_baro(self, t: float, m: Measurement) -> None:
        self._flush_covariance()
        s = self._state_at(m.t_valid)
        self._update_scalar(BARO, 2, m.values[0] - s[2], self._variances(BARO, m.sigma)[0])

    def _fuse_heading(self, t: float, m: Measurement) -> None:
        self._flush_covariance()
        s = self._state_at(m.t_valid)
        h = self._h_heading
        cp, sp, tt = math.cos(s[8]), math.sin(s[8]), math.tan(s[7])
        h[6] = cp * tt
        h[7] = sp * tt
        self._update_scalar(HEADING, h, wrap_angle(m.values[0] - s[8]), self._variances(HEADING, m.sigma)[0])


def _block(r0: int, c0: int) -> list[int]:
    return [15 * (r0 + i) + c0 + j for i in range(3) for j in range(3)]


# Φ's entries other than its unit diagonal (flat indices), each from one of (Sk, M, Sk·M, 1),
# Sk = [M f]x: -T Sk at (v, θ), -T M at (v, b_a) and (θ, b_g), -T²/2 Sk at (p, θ), -T²/2 M at (p, b_a),
# T²/2 Sk M at (v, b_g), T at (p, v) (its diagonal)
_PHI_INDEX = np.array(_block(3, 6) + _block(3, 12) + _block(6, 9) + _block(0, 6) + _block(0, 12) + _block(3, 9)
                      + [15 * i + 3 + i for i in range(3)])
_ONES3 = (1.0, 1.0, 1.0)  # T at (p, v): _carried gathers (Sk, M, M, Sk, M, Sk·M, 1, 1, 1), _PHI_INDEX's order


def make_estimator(kind: str, config: SensorConfig, start: State, gravity: float,
                   truth: Callable[[], State]) -> Estimator:
    """The estimator of a kind (``truth``, ``ekf``, ``raw``); ``truth`` reads the true state from ``truth()``."""
    if kind == "truth":
        return TruthEstimator(truth)
    if kind == "raw":
        return RawEstimator(config, start)
    if kind == "ekf":
        return Ekf(config, start, gravity)
    raise ValueError(f"estimator must be one of {', '.join(ESTIMATOR_KINDS)}; got {kind!r}")


# -- the offline harness -------------------------------------------------------------------------

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

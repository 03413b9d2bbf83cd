"""The vehicle's on-board estimator: from its sensors' measurements to the 12-state the law needs.

In:  :class:`~plant.sensors.Measurement` s as they arrive (``step(t, measurements)``, once per
     physics step), the sensor set they come from (:class:`~plant.sensors.SensorConfig`), the start
     state and gravity (m/s²)
Out: ``estimate(t)``: the 12-state of eq. (7) (x, ẋ, y, ẏ, z, ż, φ, φ̇, θ, θ̇, ψ, ψ̇; paper frame
     NWU, m, m/s, rad, rad/s; ψ continuous, not wrapped); ``covariance()``: a :class:`Covariance`; ``aided_t``
     (s): when a reading that constrains the horizontal position was last taken in (a GNSS fix or a pose fused;
     ``raw``: arrived; ``truth``: always, inf), whose age bridge.autopilot.positionloss judges

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

*Initial state*: the given start, which the vehicle's loop takes from its sensors at rest
(:func:`plant.alignment.aligned_start`: the mean of its readings over 10 s on its pad, as EKF2 has them by
take-off); P0 = diag of σ² with position the σ of those means (:func:`plant.alignment.alignment_variances`,
each reading's σ floored: the gnss set's height 9 mm, its horizontal 0.14 m), velocity 1 cm/s, attitude
10 mrad (the tilt an accelerometer bias of 0.05 m/s² hides), gyro bias 1 mrad/s, accelerometer bias 0.05 m/s².
Until the forty-fifth session the position's σ was one reading's (gnss: 2 m of height), the first fix pulled the
exact start half way to itself (0.29 m up on the sine, seed 0) and the barometer took seconds to bring it back.

**Offline harness.** :func:`bridge.autopilot.closedloop.fly_closed_loop` flies plant, sensors,
an estimator and a :class:`~controller.Controller` fed the estimate (or the truth) with the vehicle
loop's order, for the estimator's own tests (the product's loops carry the estimator in
:class:`~bridge.autopilot.simvehicle.SimVehicle`; ``benchmarks/estimation.py`` flies those).

**Speed.** The filter runs at every measurement in every clock, so its arithmetic is compiled:
:class:`Ekf` owns the state as arrays and each measurement is one call of a numba kernel of
:mod:`bridge.autopilot.ekfkernels` (about 2 µs for an IMU sample, 4 µs for a pose reading). numba is imported,
and the kernels loaded from their on-disk cache (~0.8 s), only when an EKF is built; the first EKF on
a machine compiles them first (~7 s on the 2-core VM).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from types import ModuleType
from typing import Protocol

import numpy as np

from bridge.autopilot.cholesky import weighted_square
from bridge.autopilot.compiling import announce_compiling, cache_off
from plant.alignment import alignment_variances
from plant.sensors import (
    BARO,
    GNSS,
    HEADING,
    IMU,
    POSE,
    Measurement,
    SensorConfig,
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
    freedom: χ²(9) if the covariance is right); NaN if the covariance is unknown or not positive definite."""
    return weighted_square(cov.state, estimation_error(truth, est))


def estimator_nees(estimator: Estimator, truth: State, est: State) -> float:
    """:func:`nees` of ``est`` against ``estimator``'s covariance now (the EKF's straight from its P,
    without the :class:`Covariance` tuples between: the same floats, a control step's worth less work)."""
    if isinstance(estimator, Ekf):
        return estimator.nees(truth, est)
    return nees(truth, est, estimator.covariance())


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
    aided_t: float  # s: the newest horizontal aiding taken in (module docstring)

    def step(self, t: float, measurements: Sequence[Measurement]) -> None: ...

    def estimate(self, t: float) -> State: ...

    def covariance(self) -> Covariance: ...


class TruthEstimator:
    """The true state, passed through (today's behaviour)."""

    kind = "truth"
    aided_t = math.inf  # the true state never drifts

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
        self.aided_t = 0.0  # s: at rest on its start, its position is known

    def step(self, t: float, measurements: Sequence[Measurement]) -> None:
        for m in measurements:
            k = m.kind
            if k in (POSE, GNSS):
                self.aided_t = t
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


class Ekf:
    """The error-state EKF of the module docstring (15 error states); its arithmetic is
    :mod:`bridge.autopilot.ekfkernels`, on the arrays this object owns."""

    kind = "ekf"

    def __init__(self, config: SensorConfig, start: State, gravity: float = 9.81) -> None:
        k = self._k = load_ekf_kernels()
        c = config
        self.config = c
        self.gravity = gravity
        f = SIGMA_FLOOR
        consts = np.zeros(k.C_SIZE)
        consts[k.C_G] = gravity
        consts[k.C_NA2] = max(c.accel_noise_density, f["accel"]) ** 2
        consts[k.C_NG2] = ng2 = max(c.gyro_noise_density, f["gyro"]) ** 2
        consts[k.C_WA2] = max(c.accel_bias_walk, f["accel_walk"]) ** 2
        consts[k.C_WG2] = max(c.gyro_bias_walk, f["gyro_walk"]) ** 2
        consts[k.C_STEPMAX] = COVARIANCE_STEP_MAX_S
        consts[k.C_GATE1] = chi2_quantile(1, GATE_PROBABILITY)
        consts[k.C_GATE3] = chi2_quantile(3, GATE_PROBABILITY)
        consts[k.C_RESET] = RESET_AFTER
        self._c = consts
        X = start
        x = self._x = np.zeros(k.X_SIZE)
        x[k.X_P:k.X_P + 3] = X[0], X[2], X[4]
        x[k.X_V:k.X_V + 3] = X[1], X[3], X[5]
        x[k.X_R:k.X_R + 9] = rotation(X[6], X[8], X[10])
        x[k.X_M:k.X_M + 9] = x[k.X_R:k.X_R + 9]
        x[k.X_PSI] = X[10]  # the output's continuous heading
        x[k.X_AF + 2] = gravity  # specific force in the paper frame (M f) at rest
        x[k.X_GVAR] = ng2 * min(c.imu_rate_hz, 1e4)  # white variance of one gyro sample (set per sample)
        v_pos, v_z, _, _ = alignment_variances(c, gravity, f)  # what its readings at rest told it (plant.alignment)
        self.P = np.diag([v_pos, v_pos, v_z] + [1e-4] * 3 + [1e-4] * 3 + [1e-6] * 3 + [0.05**2] * 3)
        latency = c.position_latency_ms / 1000.0
        depth = int(math.ceil((latency + 0.05) * min(c.imu_rate_hz, 1e4))) + 4  # IMU samples over the latency
        self._hist = np.zeros((depth, k.HIST_COLS))  # the nominal state at each IMU sample, newest last
        self._hs = np.zeros(2, np.int64)  # the buffer's (start, count)
        self._counts = np.zeros((4, 2), np.int64)  # per kind: refused in all, refused in a row
        k.remember(x, self._hist, self._hs)
        self._kept_variances: dict[str, tuple[tuple[float, ...], tuple[float, ...]]] = {}
        self._C9 = np.empty((9, 9))
        self._P15 = np.empty((15, 15))
        self.aided_t = 0.0  # s: the newest pose or GNSS fix fused (at rest on its start, its position is known)

    # -- reading the state ---------------------------------------------------------------
    @property
    def biases(self) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """The estimated (gyro bias rad/s, accelerometer bias m/s²), body axes."""
        k, x = self._k, self._x
        bg, ba = x[k.X_BG:k.X_BG + 3].tolist(), x[k.X_BA:k.X_BA + 3].tolist()
        return (bg[0], bg[1], bg[2]), (ba[0], ba[1], ba[2])

    def bias_sigma(self) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """σ of the estimated biases, as :attr:`biases`."""
        self._k.current_P(self._x, self._c, self.P, self._P15)
        d = np.sqrt(np.diag(self._P15)[9:15]).tolist()
        return (d[0], d[1], d[2]), (d[3], d[4], d[5])

    @property
    def rejected(self) -> dict[str, int]:
        """Readings refused so far, by kind (a gate's refusal, or a singular innovation covariance)."""
        return {kind: int(n) for kind, n in zip((POSE, GNSS, BARO, HEADING), self._counts[:, 0]) if n}

    @property
    def fused(self) -> int:
        """Readings fused so far."""
        return int(self._x[self._k.X_FUSED])

    def estimate(self, t: float) -> State:
        return self._k.estimate(self._x, t)

    def covariance(self) -> Covariance:
        k = self._k
        k.state_covariance(self._x, self._c, self.P, self._C9, self._P15)  # P carried to now once, for both
        g = float(self._x[k.X_GVAR])
        (b00, b01, b02), (b10, b11, b12), (b20, b21, b22) = self._P15[9:12, 9:12].tolist()
        rates = (b00 + g, b01, b02, b10, b11 + g, b12, b20, b21, b22 + g)
        return Covariance(tuple(self._C9.ravel().tolist()), rates)

    def nees(self, truth: State, est: State) -> float:
        """:func:`nees` of ``est`` against the covariance now (computed from P directly)."""
        return self._k.nees(self._x, self._c, self.P, estimation_error(truth, est))

    # -- the filter ----------------------------------------------------------------------
    def step(self, t: float, measurements: Sequence[Measurement]) -> None:
        k, x, c, P, hist, hs = self._k, self._x, self._c, self.P, self._hist, self._hs
        for m in measurements:
            kind = m.kind
            z = m.values
            if kind == IMU:
                k.propagate(x, c, P, hist, hs, z[0], z[1], z[2], z[3], z[4], z[5], m.interval_s, m.t_valid)
            elif kind == POSE or kind == GNSS:
                fused = x[k.X_FUSED]
                v = self._variances(kind, m.sigma)
                fuse = k.fuse_pose if kind == POSE else k.fuse_gnss
                fuse(x, c, P, hist, hs, self._counts, m.t_valid, z[0], z[1], z[2], z[3], z[4], z[5], v[0], v[1], v[2],
                     v[3], v[4], v[5])
                if x[k.X_FUSED] > fused:  # taken in, not refused by the gate: horizontal aiding
                    self.aided_t = t
            elif kind == BARO:
                k.fuse_baro(x, c, P, hist, hs, self._counts, m.t_valid, z[0], self._variances(BARO, m.sigma)[0])
            elif kind == HEADING:
                k.fuse_heading(x, c, P, hist, hs, self._counts, m.t_valid, z[0],
                               self._variances(HEADING, m.sigma)[0])

    def _variances(self, kind: str, sigma: tuple[float, ...]) -> tuple[float, ...]:
        """The filter's noise variances of a reading's σ (floored, :data:`SIGMA_FLOOR`), kept per kind
        while the σ stay the same (a sensor's σ are fixed: this runs once per sensor)."""
        kept = self._kept_variances.get(kind)
        if kept is not None and kept[0] == sigma:
            return kept[1]
        v = tuple(max(s, SIGMA_FLOOR[f]) ** 2 for s, f in zip(sigma, FLOORS_OF[kind], strict=True))
        self._kept_variances[kind] = (sigma, v)
        return v


def compile_estimator(kind: str) -> None:
    """Compile, or load from numba's cache on disk, what an estimator of ``kind`` runs on (the EKF's kernels;
    nothing for the others): a launcher whose children are exec'd calls it before it starts a vehicle (a fork server
    loads them itself before it forks one: bridge.core.kernelpreload), so that a first EKF on a machine compiles
    once, here, and the vehicle loads it from the cache instead of compiling it in its start-up time.
    Where numba has no cache (no writable place for it: kernelcache.enable_cache) nothing is compiled here: the
    vehicle would compile it again (~7 s); the process that flies it compiles it, once (the vehicle, or the fork
    server it is forked from: bridge.core.kernelpreload)."""
    if kind == "ekf":
        from bridge.autopilot import ekfkernels  # numba's import costs ~0.3 s: only an EKF flight pays it

        if not cache_off(ekfkernels.__name__):
            load_ekf_kernels()


def load_ekf_kernels() -> ModuleType:
    """The EKF's kernels (:mod:`bridge.autopilot.ekfkernels`), compiled or loaded from numba's cache in this
    process, once (said first where it compiles: bridge.autopilot.compiling)."""
    from bridge.autopilot import ekfkernels  # numba's import costs ~0.3 s: only an EKF flight pays it

    announce_compiling(ekfkernels.__name__)  # a cold cache: say so before ~7 s of silence
    ekfkernels.ready()
    return ekfkernels


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

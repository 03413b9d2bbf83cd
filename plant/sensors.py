"""The vehicle's own sensors: what they report about the true state (pure, seeded, no I/O).

In:  a :class:`SensorConfig` (one named set of a profile's ``[sensors]`` table, SI units), a seed,
     the physics rate (Hz); then, once per physics step, the time t (s) and the true 12-state of
     eq. (7) (paper frame NWU, body forward-left-up, Z-Y-X Euler angles)
Out: the :class:`Measurement` s whose arrival time has come at that step

The sensors (every σ below is one standard deviation; densities are per √Hz):

- **IMU** (``imu_rate_hz``): accelerometer and gyro, body axes. Each sample is the *mean* over
  its sample interval T ending at t, as an integrating IMU reports it (delta velocity and
  delta angle / T), by the midpoint rule: the specific force f = R_midᵀ (Δv/T + g e_z), Δv the
  change of the true inertial velocity over the interval and R_mid the attitude half-way (the
  mean of the ends' Euler angles), and the body rate of the mean Euler rate Δ(φ, θ, ψ)/T there.
  Derived from the true states alone: it needs nothing but the state from the plant, handles
  ground contact (Δv = 0 there: f = +g e_z), and costs nothing at physics steps where no sample
  is due. To each axis: a bias that walks (b += walk·√T·n at each sample) and white noise of
  σ = density/√T (the mean over T of white noise of that density).
- **position** (``position_rate_hz``, ``position_latency_ms``), one of two classes:
  ``mocap`` measures the pose: x, y, z with σ ``position_noise_m`` (horizontal) and
  ``position_noise_z_m``, and φ, θ, ψ each with σ ``attitude_noise_rad`` (ψ wrapped to
  (−π, π]); ``gnss`` measures x, y, z and the inertial velocity (σ ``velocity_noise_mps``,
  ``velocity_noise_z_mps``).
- **barometer** (``baro_rate_hz``, 0 for none): altitude z with σ ``baro_noise_m``.
- **heading** (``heading_rate_hz``, 0 for none): the magnetometer's heading ψ, wrapped, σ
  ``heading_noise_rad``.

A sensor samples at the first physics step at or after each of its due times n / rate (a rate
at or above the physics rate samples every step); its measurement is valid at that step's time
and is released ``latency`` later (at the first step at or after t_valid + latency).

**Seeding.** Every noise source draws from its own numpy ``Generator`` seeded with
(seed, the source's fixed number), consumed in order: the n-th sample of a sensor always gets
the n-th draws of its stream, whatever the calls in between, so one seed gives the same
measurements twice and another seed other ones. A σ of 0 draws nothing.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np

from params import Table
from plant.angles import wrap_angle  # re-exported: the estimator and the tests read it here
from plant.sensorfaults import SensorFaults

State = tuple[float, ...]
Vec3 = tuple[float, float, float]
Mat3 = tuple[float, float, float, float, float, float, float, float, float]  # row-major 3x3

POSITION_CLASSES = ("mocap", "gnss")
SENSOR_SET_NAMES = ("ideal", "mocap", "gnss")  # the sets every built-in profile defines

# One range per key: (lo, hi, lo_open, unit). Every set of a profile and every mission override is
# checked against it (rates: a rate at or above the physics rate means every physics step).
SENSOR_RANGES: dict[str, tuple[float, float, bool, str]] = {
    "imu_rate_hz": (0.0, 10000.0, True, "Hz"),
    "accel_noise_density": (0.0, 10.0, False, "m/s^2/sqrt(Hz)"),
    "accel_bias_walk": (0.0, 10.0, False, "m/s^3/sqrt(Hz)"),
    "gyro_noise_density": (0.0, 1.0, False, "rad/s/sqrt(Hz)"),
    "gyro_bias_walk": (0.0, 1.0, False, "rad/s^2/sqrt(Hz)"),
    "position_rate_hz": (0.0, 10000.0, True, "Hz"),
    "position_latency_ms": (0.0, 2000.0, False, "ms"),
    "position_noise_m": (0.0, 100.0, False, "m"),
    "position_noise_z_m": (0.0, 100.0, False, "m"),
    "attitude_noise_rad": (0.0, 1.0, False, "rad"),
    "velocity_noise_mps": (0.0, 100.0, False, "m/s"),
    "velocity_noise_z_mps": (0.0, 100.0, False, "m/s"),
    "baro_rate_hz": (0.0, 10000.0, False, "Hz"),  # 0: no barometer
    "baro_noise_m": (0.0, 100.0, False, "m"),
    "heading_rate_hz": (0.0, 10000.0, False, "Hz"),  # 0: no heading sensor
    "heading_noise_rad": (0.0, math.pi, False, "rad"),
}
CLASS_KEYS = {"mocap": ("attitude_noise_rad",), "gnss": ("velocity_noise_mps", "velocity_noise_z_mps")}
# the sigmas a noise scale multiplies (rates and latencies stay)
SIGMA_KEYS = tuple(k for k in SENSOR_RANGES if "noise" in k or "walk" in k)


@dataclass(frozen=True, slots=True)
class SensorConfig:
    """One sensor set (see the module docstring; units in the field names and SENSOR_RANGES).

    ``attitude_noise_rad`` is None unless ``position_class`` is ``mocap``; the velocity noises
    are None unless it is ``gnss``.
    """

    name: str
    imu_rate_hz: float
    accel_noise_density: float
    accel_bias_walk: float
    gyro_noise_density: float
    gyro_bias_walk: float
    position_class: str
    position_rate_hz: float
    position_latency_ms: float
    position_noise_m: float
    position_noise_z_m: float
    baro_rate_hz: float
    baro_noise_m: float
    heading_rate_hz: float
    heading_noise_rad: float
    attitude_noise_rad: float | None = None
    velocity_noise_mps: float | None = None
    velocity_noise_z_mps: float | None = None

    def scaled(self, factor: float) -> SensorConfig:
        """The same set with every σ (noise, density, bias walk) multiplied by ``factor``."""
        return replace(self, **{k: getattr(self, k) * factor for k in SIGMA_KEYS if getattr(self, k) is not None})

    def as_table(self) -> dict[str, Any]:
        """The set as a TOML-ready table (no name; keys the class does not use left out)."""
        return {f.name: getattr(self, f.name) for f in fields(self)
                if f.name != "name" and getattr(self, f.name) is not None}


def sensor_config_from_table(t: Table, name: str) -> SensorConfig:
    """Validate one sensor set; every error names the file, the key and the allowed range."""
    cls = t.string("position_class", choices=POSITION_CLASSES)
    for other, keys in CLASS_KEYS.items():
        for k in keys:
            if other != cls and t.has(k):
                raise t.error(k, f"is not used by position_class {cls!r} (only by {other!r})")
    values: dict[str, float | None] = {}
    for key, (lo, hi, lo_open, _unit) in SENSOR_RANGES.items():
        if key in CLASS_KEYS["mocap"] + CLASS_KEYS["gnss"] and key not in CLASS_KEYS[cls]:
            values[key] = None
            continue
        values[key] = t.number(key, lo=lo, hi=hi, lo_open=lo_open)
    t.done()
    return SensorConfig(name=name, position_class=cls, **values)  # type: ignore[arg-type]


def sensor_sets_from_table(data: Mapping[str, Any], source: str) -> tuple[tuple[str, SensorConfig], ...]:
    """A profile's ``[sensors]`` table: named sets, each a table of every key of its class."""
    t = Table(data, source, "sensors")
    sets = []
    for name in data:
        sets.append((name, sensor_config_from_table(t.table(name), name)))
    t.done()
    return tuple(sets)


IDEAL = SensorConfig(  # what a profile without a [sensors] table has: exact, instant, every physics step
    name="ideal", imu_rate_hz=10000.0, accel_noise_density=0.0, accel_bias_walk=0.0, gyro_noise_density=0.0,
    gyro_bias_walk=0.0, position_class="mocap", position_rate_hz=10000.0, position_latency_ms=0.0,
    position_noise_m=0.0, position_noise_z_m=0.0, baro_rate_hz=10000.0, baro_noise_m=0.0,
    heading_rate_hz=10000.0, heading_noise_rad=0.0, attitude_noise_rad=0.0)


# -- measurements ----------------------------------------------------------------------------

IMU, POSE, GNSS, BARO, HEADING = "imu", "pose", "gnss", "baro", "heading"


@dataclass(frozen=True, slots=True)
class Measurement:
    """One sensor reading.

    ``kind`` and ``values`` (paper frame, SI):

    - ``imu``: (fx, fy, fz, p, q, r): mean specific force (m/s²) and body rate (rad/s) over
      (t_valid − interval_s, t_valid], body axes
    - ``pose``: (x, y, z, φ, θ, ψ) in m and rad, ψ wrapped to (−π, π]
    - ``gnss``: (x, y, z, ẋ, ẏ, ż) in m and m/s
    - ``baro``: (z,) in m;  ``heading``: (ψ,) in rad, wrapped

    ``sigma`` is the white-noise σ of each value (same units); the IMU's bias walk is not in it.
    """

    kind: str
    t_valid: float
    t_arrival: float
    values: tuple[float, ...]
    sigma: tuple[float, ...]
    interval_s: float = 0.0


# -- rotations (Z-Y-X Euler, body -> inertial R = Rz(psi) Ry(theta) Rx(phi)) ---------------------

def rotation(phi: float, theta: float, psi: float) -> Mat3:
    """R = Rz(ψ)·Ry(θ)·Rx(φ), row-major (body forward-left-up → paper frame NWU)."""
    cf, sf, ct, st = math.cos(phi), math.sin(phi), math.cos(theta), math.sin(theta)
    cp, sp = math.cos(psi), math.sin(psi)
    return (cp * ct, cp * st * sf - sp * cf, cp * st * cf + sp * sf,
            sp * ct, sp * st * sf + cp * cf, sp * st * cf - cp * sf,
            -st, ct * sf, ct * cf)


def euler(R: Mat3) -> Vec3:
    """(φ, θ, ψ) of a rotation (ψ in (−π, π])."""
    s = -R[6]
    theta = math.asin(1.0 if s > 1.0 else -1.0 if s < -1.0 else s)
    return math.atan2(R[7], R[8]), theta, math.atan2(R[3], R[0])


def body_rates(phi: float, theta: float, dphi: float, dtheta: float, dpsi: float) -> Vec3:
    """Body rates (p, q, r) from Euler rates (Z-Y-X kinematics)."""
    cf, sf, ct, st = math.cos(phi), math.sin(phi), math.cos(theta), math.sin(theta)
    return dphi - dpsi * st, dtheta * cf + dpsi * sf * ct, -dtheta * sf + dpsi * cf * ct


def euler_rates(phi: float, theta: float, p: float, q: float, r: float) -> Vec3:
    """Euler rates (φ̇, θ̇, ψ̇) from body rates: the inverse of :func:`body_rates` (θ ≠ ±π/2)."""
    cf, sf, ct = math.cos(phi), math.sin(phi), math.cos(theta)
    w = q * sf + r * cf
    return p + w * math.tan(theta), q * cf - r * sf, w / ct


def rotvec_of(R: Mat3) -> Vec3:
    """Log map: the rotation vector (axis × angle, rad) of a rotation matrix (angle < π)."""
    c = 0.5 * (R[0] + R[4] + R[8] - 1.0)
    angle = math.acos(1.0 if c > 1.0 else -1.0 if c < -1.0 else c)
    k = 0.5 + angle * angle / 12.0 if angle < 1e-4 else 0.5 * angle / math.sin(angle)
    return k * (R[7] - R[5]), k * (R[2] - R[6]), k * (R[3] - R[1])


def rotation_of(v0: float, v1: float, v2: float) -> Mat3:
    """Exp map: the rotation matrix of a rotation vector (Rodrigues)."""
    a2 = v0 * v0 + v1 * v1 + v2 * v2
    if a2 < 1e-12:
        s, c = 1.0 - a2 / 6.0, 0.5 - a2 / 24.0  # sin(a)/a, (1 - cos a)/a^2
    else:
        a = math.sqrt(a2)
        s, c = math.sin(a) / a, (1.0 - math.cos(a)) / a2
    return (1.0 - c * (v1 * v1 + v2 * v2), c * v0 * v1 - s * v2, c * v0 * v2 + s * v1,
            c * v0 * v1 + s * v2, 1.0 - c * (v0 * v0 + v2 * v2), c * v1 * v2 - s * v0,
            c * v0 * v2 - s * v1, c * v1 * v2 + s * v0, 1.0 - c * (v0 * v0 + v1 * v1))


def matmul(A: Mat3, B: Mat3) -> Mat3:
    """A·B of two row-major 3x3 matrices."""
    return (A[0] * B[0] + A[1] * B[3] + A[2] * B[6], A[0] * B[1] + A[1] * B[4] + A[2] * B[7],
            A[0] * B[2] + A[1] * B[5] + A[2] * B[8],
            A[3] * B[0] + A[4] * B[3] + A[5] * B[6], A[3] * B[1] + A[4] * B[4] + A[5] * B[7],
            A[3] * B[2] + A[4] * B[5] + A[5] * B[8],
            A[6] * B[0] + A[7] * B[3] + A[8] * B[6], A[6] * B[1] + A[7] * B[4] + A[8] * B[7],
            A[6] * B[2] + A[7] * B[5] + A[8] * B[8])


def transpose_mul(A: Mat3, B: Mat3) -> Mat3:
    """Aᵀ·B."""
    return matmul((A[0], A[3], A[6], A[1], A[4], A[7], A[2], A[5], A[8]), B)


def imu_mean(X0: State, X1: State, dt: float, gravity: float) -> tuple[float, ...]:
    """(fx, fy, fz, p, q, r): the true mean specific force and body rate over an interval dt
    between the states X0 and X1, by the midpoint rule (second order in dt): the attitude and the
    Euler rates half-way are the means of the ends' angles and their differences over dt."""
    # body_rates and rotation written out, sharing their sines (the same operations in the same order, so
    # the same floats to the bit): it runs at every IMU sample
    phi, theta, psi = 0.5 * (X0[6] + X1[6]), 0.5 * (X0[8] + X1[8]), 0.5 * (X0[10] + X1[10])
    dphi, dtheta, dpsi = (X1[6] - X0[6]) / dt, (X1[8] - X0[8]) / dt, (X1[10] - X0[10]) / dt
    cf, sf, ct, st = math.cos(phi), math.sin(phi), math.cos(theta), math.sin(theta)
    cp, sp = math.cos(psi), math.sin(psi)
    ax = (X1[1] - X0[1]) / dt
    ay = (X1[3] - X0[3]) / dt
    az = (X1[5] - X0[5]) / dt + gravity
    # R's columns: (cp ct, sp ct, -st), (cp st sf - sp cf, sp st sf + cp cf, ct sf), (cp st cf + sp sf, ...)
    return ((cp * ct) * ax + (sp * ct) * ay + (-st) * az,
            (cp * st * sf - sp * cf) * ax + (sp * st * sf + cp * cf) * ay + (ct * sf) * az,
            (cp * st * cf + sp * sf) * ax + (sp * st * cf - cp * sf) * ay + (ct * cf) * az,
            dphi - dpsi * st, dtheta * cf + dpsi * sf * ct, -dtheta * sf + dpsi * cf * ct)


# -- noise and schedules ---------------------------------------------------------------------

_STREAMS = {"accel": 1, "gyro": 2, "accel_bias": 3, "gyro_bias": 4, "position": 5, "baro": 6, "heading": 7}
_DOMAIN = 0x5E45  # keeps these streams apart from any other use of the same seed


class _Normals:
    """Standard normal draws of one noise source, ``dim`` at a time, in a fixed order.

    Drawn from the generator in blocks (numpy's per-call cost), handed out as Python floats."""

    __slots__ = ("_gen", "_dim", "_block", "_rows", "_i")

    def __init__(self, seed: int, stream: str, dim: int, block: int = 256) -> None:
        self._gen = np.random.default_rng([seed, _DOMAIN, _STREAMS[stream]])
        self._dim = dim
        self._block = block
        self._rows: list[list[float]] = []
        self._i = 0

    def next(self) -> list[float]:
        if self._i >= len(self._rows):
            self._rows = self._gen.standard_normal((self._block, self._dim)).tolist()
            self._i = 0
        row = self._rows[self._i]
        self._i += 1
        return row


class _Schedule:
    """Due times n / rate, met at the first physics step at or after each (every step above the
    physics rate); a missed one is skipped, never sampled twice. ``next_due`` is the time from
    which it is due again (−inf: every step; inf: rate 0, never)."""

    __slots__ = ("rate", "_every_step", "next_due", "_eps")

    def __init__(self, rate_hz: float, physics_hz: float) -> None:
        self.rate = rate_hz
        self._every_step = rate_hz >= physics_hz
        self._eps = 0.25 / physics_hz  # a quarter physics step: the caller's t accumulates rounding
        self.next_due = -math.inf if self._every_step else 0.0 if rate_hz > 0.0 else math.inf

    def due(self, t: float) -> bool:
        if t + self._eps < self.next_due:
            return False
        if not self._every_step:
            self.next_due = (math.floor((t + self._eps) * self.rate) + 1) / self.rate
        return True


class SensorSuite:
    """All sensors of one set, sampled once per physics step (see the module docstring).

    ``sample(t, state)`` returns what arrives at t: the IMU's sample first (no latency), then
    the others in order of arrival. The first call only starts the IMU's first interval. While
    ``t + eps < next_event`` nothing is due and ``sample`` returns [] at once (a caller at every
    physics step may test it first and skip the call: most steps bring nothing).
    """

    def __init__(self, config: SensorConfig, seed: int, physics_hz: float, gravity: float = 9.81) -> None:
        self.config = config
        c = config
        self.gravity = gravity
        self.eps = 0.25 / physics_hz  # s: a quarter physics step, the rounding a caller's t accumulates
        self._imu = _Schedule(c.imu_rate_hz, physics_hz)
        self._pos = _Schedule(c.position_rate_hz, physics_hz)
        self._baro = _Schedule(c.baro_rate_hz, physics_hz)
        self._heading = _Schedule(c.heading_rate_hz, physics_hz)
        self._gnss = c.position_class == "gnss"
        self._pos_latency = c.position_latency_ms / 1000.0
        self._n_accel = _Normals(seed, "accel", 3)
        self._n_gyro = _Normals(seed, "gyro", 3)
        self._n_accel_bias = _Normals(seed, "accel_bias", 3)
        self._n_gyro_bias = _Normals(seed, "gyro_bias", 3)
        self._n_pos = _Normals(seed, "position", 6)
        self._n_baro = _Normals(seed, "baro", 1)
        self._n_heading = _Normals(seed, "heading", 1)
        self.accel_bias = [0.0, 0.0, 0.0]  # the true biases now (m/s^2, rad/s), for tests and records
        self.gyro_bias = [0.0, 0.0, 0.0]
        self._last: tuple[float, State] | None = None  # (t, true state) at the last IMU sample
        self._pending: deque[Measurement] = deque()  # latent position fixes, in order of arrival
        self.next_event = -math.inf  # nothing to do before this time (s), give or take eps
        self._latest: dict[str, Measurement] = {}  # kind -> the newest released (what a ground station is shown)
        # the first position fix taken (at the first sample, t = 0), released or still in its latency: what a vehicle
        # at rest at its start has had since before its clock began (a ground station is shown it until one arrives)
        self.first_fix: Measurement | None = None
        self.faults = SensorFaults()  # what a timeline's sensor events changed (plant/events.py)
        if self._gnss:
            h, z, vh, vz = c.position_noise_m, c.position_noise_z_m, c.velocity_noise_mps, c.velocity_noise_z_mps
            self._pos_sigma = (h, h, z, vh, vh, vz)
        else:
            h, z, a = c.position_noise_m, c.position_noise_z_m, c.attitude_noise_rad
            self._pos_sigma = (h, h, z, a, a, a)

    def sample(self, t: float, state: State) -> list[Measurement]:
        """The measurements that arrive at time t (s), given the true state at t."""
        if t + self.eps < self.next_event:
            return []
        out = self._sample(t, state)
        for m in out:
            self._latest[m.kind] = m
        nxt = min(self._imu.next_due, self._pos.next_due, self._baro.next_due, self._heading.next_due)
        self.next_event = min(nxt, self._pending[0].t_arrival) if self._pending else nxt
        return out

    def latest(self, kind: str) -> Measurement | None:
        """The newest measurement of ``kind`` (``imu``, ``pose``, ``gnss``, ``baro``, ``heading``) that has
        arrived (released after its latency), None before the first; reading it changes nothing."""
        return self._latest.get(kind)

    def _sample(self, t: float, state: State) -> list[Measurement]:
        out: list[Measurement] = []
        te = t + self.eps  # each schedule's own test first (its eps is this one): no call while it is not due
        if te >= self._imu.next_due and self._imu.due(t):
            m = self._sample_imu(t, state)
            if m is not None:
                out.append(m)
        if te >= self._pos.next_due and self._pos.due(t):
            fix = self._sample_position(t, state)
            if self.faults.gps_on:  # off: drawn and dropped (plant/sensorfaults.py)
                self._pending.append(fix)
                if self.first_fix is None:
                    self.first_fix = fix
        pending = self._pending
        while pending and pending[0].t_arrival <= te:
            out.append(pending.popleft())
        c = self.config
        if te >= self._baro.next_due and self._baro.due(t):
            s = c.baro_noise_m
            z = state[4] + (s * self._n_baro.next()[0] if s else 0.0)
            if self.faults.baro_drift_mps or self.faults.baro_offset_m:
                z += self.faults.baro_error(t)
            out.append(Measurement(BARO, t, t, (z,), (s,)))
        if te >= self._heading.next_due and self._heading.due(t):
            s = c.heading_noise_rad
            psi = wrap_angle(state[10] + (s * self._n_heading.next()[0] if s else 0.0))
            if self.faults.mag_on:
                out.append(Measurement(HEADING, t, t, (psi,), (s,)))
        return out

    def _sample_imu(self, t: float, X: State) -> Measurement | None:
        last = self._last
        self._last = (t, X)
        if last is None or t - last[0] <= 0.0:
            return None
        dt = t - last[0]
        fx, fy, fz, p, q, r = imu_mean(last[1], X, dt, self.gravity)
        c = self.config
        ba, bg = self.accel_bias, self.gyro_bias
        root = math.sqrt(dt)
        if c.accel_bias_walk:
            n = self._n_accel_bias.next()
            k = c.accel_bias_walk * root
            ba[0] += k * n[0]
            ba[1] += k * n[1]
            ba[2] += k * n[2]
        if c.gyro_bias_walk:
            n = self._n_gyro_bias.next()
            k = c.gyro_bias_walk * root
            bg[0] += k * n[0]
            bg[1] += k * n[1]
            bg[2] += k * n[2]
        sa = c.accel_noise_density / root
        sg = c.gyro_noise_density / root
        na = self._n_accel.next() if sa else (0.0, 0.0, 0.0)
        ng = self._n_gyro.next() if sg else (0.0, 0.0, 0.0)
        values = (fx + ba[0] + sa * na[0], fy + ba[1] + sa * na[1], fz + ba[2] + sa * na[2],
                  p + bg[0] + sg * ng[0], q + bg[1] + sg * ng[1], r + bg[2] + sg * ng[2])
        return Measurement(IMU, t, t, values, (sa, sa, sa, sg, sg, sg), dt)

    def _sample_position(self, t: float, X: State) -> Measurement:
        s = self._pos_sigma
        n = self._n_pos.next() if any(s) else (0.0,) * 6
        if self.faults.position_offset != (0.0, 0.0, 0.0):  # a GPS jump: the fixes from then on shifted
            dx, dy, dz = self.faults.position_offset
            X = (X[0] + dx, X[1], X[2] + dy, X[3], X[4] + dz, *X[5:])
        if self._gnss:
            values = (X[0] + s[0] * n[0], X[2] + s[1] * n[1], X[4] + s[2] * n[2],
                      X[1] + s[3] * n[3], X[3] + s[4] * n[4], X[5] + s[5] * n[5])
            kind = GNSS
        else:
            values = (X[0] + s[0] * n[0], X[2] + s[1] * n[1], X[4] + s[2] * n[2],
                      X[6] + s[3] * n[3], X[8] + s[4] * n[4], wrap_angle(X[10] + s[5] * n[5]))
            kind = POSE
        return Measurement(kind, t, t + self._pos_latency, values, s)


__all__ = [
    "IDEAL", "POSITION_CLASSES", "SENSOR_RANGES", "SENSOR_SET_NAMES", "Measurement", "SensorConfig",
    "SensorSuite", "body_rates", "euler", "euler_rates", "rotation", "sensor_config_from_table",
    "sensor_sets_from_table", "wrap_angle",
]

"""What an EKF aligned at rest knows of where the vehicle stands: its sensors' readings at rest, averaged.

In:  a :class:`~plant.sensors.SensorConfig` (its σ, densities per √Hz and rates, SI units), gravity (m/s²), the
     true state of a vehicle at rest on its start (the 12-state of eq. (7): m, m/s, rad, rad/s), a seed
Out: :func:`alignment_variances`: the variance of the mean of each reading over :data:`ALIGNMENT_S` at rest, for
     (x, y, z) (m²), the tilt (φ, θ) and ψ (rad²); :func:`aligned_start`: the 12-state the filter starts from (m,
     rad; at rest: velocity and rates 0)

A flight controller's EKF does not start in the air: it runs from boot with the vehicle standing on its pad, and
PX4's EKF2 uses a GNSS only after its checks have passed for 10 s (``_min_gps_health_time_us``). By take-off it has
averaged its readings at rest: its height from the barometer (and the position sensor's vertical), its tilt from
the accelerometer's mean specific force, its heading from the pose or the compass. The mean of N readings of white
noise σ has σ/√N; independent sources combine as 1/Σ(1/σ²). The sensors' biases are 0 at the start
(:mod:`plant.sensors`), so the means are unbiased: what is left is drawn here, once, from the seed's own stream (one
draw stands for the mean of all the readings at rest, which it equals in distribution). Horizontally the filter
starts where the vehicle stands, undrawn: EKF2's local frame has its origin where it started (the vehicle's pad), and
the missions here are flown in that frame; its variance is still its fixes' mean's, what they tell it of that point.

Not modelled: a set with neither a pose nor a heading sensor has no heading at rest (PX4 would align it in
flight); its ψ is the start's (None here: the filter keeps its default σ).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from plant.sensors import SensorConfig

State = tuple[float, ...]
ALIGNMENT_S = 10.0  # s at rest before the clock starts: EKF2's 10 s of GNSS checks
_DOMAIN = 0xA119  # keeps this draw apart from any other use of the same seed


def _mean_variance(sigma: float, rate_hz: float, floor: float) -> float:
    """The variance of the mean of a reading of white σ taken at ``rate_hz`` over ALIGNMENT_S (inf: none)."""
    if rate_hz <= 0.0:
        return math.inf
    n = max(1, math.floor(rate_hz * ALIGNMENT_S))
    return max(sigma, floor) ** 2 / n


def _combined(*variances: float) -> float:
    """Independent estimates of one quantity fused: 1/Σ(1/v) (0 if one is exact, inf if there are none)."""
    if any(v == 0.0 for v in variances):
        return 0.0
    info = sum(1.0 / v for v in variances)
    return 1.0 / info if info > 0.0 else math.inf


def alignment_variances(c: SensorConfig, gravity: float,
                        floors: Mapping[str, float] | None = None) -> tuple[float, float, float, float | None]:
    """Variances of the means at rest: (x or y, z, φ or θ, ψ or None without a heading source); each σ at least its
    ``floors`` entry (keys position, baro, attitude, heading, accel; none: no floor)."""
    f = floors or {}
    pos = _mean_variance(c.position_noise_m, c.position_rate_hz, f.get("position", 0.0))
    z = _combined(_mean_variance(c.position_noise_z_m, c.position_rate_hz, f.get("position", 0.0)),
                  _mean_variance(c.baro_noise_m, c.baro_rate_hz, f.get("baro", 0.0)))
    # the accelerometer's mean over ALIGNMENT_S: density² / T (m/s²)², a tilt of that over g
    tilt_var = max(c.accel_noise_density, f.get("accel", 0.0)) ** 2 / ALIGNMENT_S / gravity**2
    pose_att = (_mean_variance(c.attitude_noise_rad, c.position_rate_hz, f.get("attitude", 0.0))
                if c.position_class == "mocap" and c.attitude_noise_rad is not None else math.inf)
    tilt = _combined(tilt_var, pose_att)
    psi = _combined(pose_att, _mean_variance(c.heading_noise_rad, c.heading_rate_hz, f.get("heading", 0.0)))
    return pos, z, tilt, (psi if math.isfinite(psi) else None)


def aligned_start(c: SensorConfig, gravity: float, state: State, seed: int) -> State:
    """The 12-state an EKF aligned at rest in ``state`` starts from: x and y where it stands, its height and attitude
    off by one draw of each mean's σ (seeded), velocity and rates 0."""
    pos, z, tilt, psi = alignment_variances(c, gravity)
    n = np.random.default_rng([seed, _DOMAIN]).standard_normal(4).tolist()
    s = (math.sqrt(z), math.sqrt(tilt), math.sqrt(tilt), math.sqrt(psi) if psi is not None else 0.0)
    d = [si * ni for si, ni in zip(s, n, strict=True)]
    X = state
    return (X[0], 0.0, X[2], 0.0, X[4] + d[0], 0.0, X[6] + d[1], 0.0, X[8] + d[2], 0.0, X[10] + d[3], 0.0)

"""Covers bridge.autopilot.estimator, bridge.autopilot.ekfkernels and bridge.autopilot.closedloop.

bridge/autopilot/estimator.py: the on-board EKF, the raw and truth estimators.

Truth comes from the real plant (plant.Quadrotor) flown along the paper's sine with the real
controller.Controller; the sensors are plant.sensors.SensorSuite with the profiles' sets. The
EKF must be consistent (its errors within the covariance it reports: NEES against χ² bounds),
follow the truth exactly on ideal sensors, handle latency, estimate the biases, and buy the
smooth control the paper claims (BS-ST's u2 ripple).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
import pytest

from bridge.autopilot.closedloop import ClosedLoopRecord, fly_closed_loop
from bridge.autopilot.estimator import (
    ESTIMATOR_KINDS,
    ZERO_COVARIANCE,
    Covariance,
    Ekf,
    RawEstimator,
    TruthEstimator,
    estimation_error,
    make_estimator,
    nees,
    upper_triangle,
)
from bridge.core.flight import prepare
from bridge.sweep.cells import ripple_rms
from plant.alignment import aligned_start, alignment_variances
from plant.sensors import IDEAL, Measurement, SensorConfig, SensorSuite, rotation

SINE = "missions/sine.toml"


def chi2_ppf(q: float, dof: float) -> float:
    """The χ² distribution's quantile ``q`` for ``dof`` degrees of freedom (scipy.stats, imported here: it costs
    every pytest worker ~1.3 s, and each worker collects every test file)."""
    from scipy.stats import chi2

    return float(chi2.ppf(q, dof))


def fly(kind: str, sensors: str | SensorConfig = "mocap", *, profile: str | None = None, seconds: float = 10.0,
        seed: int = 0, law_on: str = "estimate", nees_every: int = 0, controller: str = "bsst",
        relabel: bool = False, gyro_bias: Sequence[float] | None = None,
        accel_bias: Sequence[float] | None = None) -> tuple[ClosedLoopRecord, object, SensorSuite]:
    """Fly the sine with sensors and an estimator; ``relabel`` makes every reading claim to be
    valid when it arrives (a filter that ignores latency); the biases start where given."""
    f = prepare(SINE, profile=profile, controller=controller)
    m = f.mission
    plant = f.make_plant()
    cfg = f.profile.sensor_set(sensors) if isinstance(sensors, str) else sensors
    suite = SensorSuite(cfg, seed, m.physics_hz, f.profile.gravity)
    if gyro_bias is not None:
        suite.gyro_bias[:] = gyro_bias
    if accel_bias is not None:
        suite.accel_bias[:] = accel_bias
    est = make_estimator(kind, cfg, plant.state, f.profile.gravity, lambda: plant.state)
    source = _Relabelled(suite) if relabel else suite
    rec = fly_closed_loop(plant, f.make_controller(), m.trajectory.sample, source, est,  # type: ignore[arg-type]
                          steps=int(round(seconds * m.rate_hz)), rate_hz=m.rate_hz, law_on=law_on,
                          nees_every=nees_every)
    assert rec.outcome == "completed", rec.outcome
    return rec, est, suite


class _Relabelled:
    """A suite whose readings say they are valid when they arrive (their latency hidden)."""

    def __init__(self, suite: SensorSuite) -> None:
        self._suite = suite

    def sample(self, t: float, state: tuple[float, ...]) -> list[Measurement]:
        return [dataclasses.replace(m, t_valid=m.t_arrival) for m in self._suite.sample(t, state)]


def position_error_rms(rec: ClosedLoopRecord, t_from: float = 2.0) -> float:
    late = rec.t >= t_from
    e = rec.truth[late][:, [0, 2, 4]] - rec.estimate[late][:, [0, 2, 4]]
    return float(np.sqrt(np.mean(np.sum(e**2, axis=1))))


def nees_samples(rec: ClosedLoopRecord, t_from: float = 1.0) -> np.ndarray:
    sel = np.isfinite(rec.nees) & (rec.t >= t_from)
    return rec.nees[sel]


def test_ekf_is_consistent_with_motion_capture() -> None:
    """NEES over position, velocity and attitude, sampled every 0.5 s of four closed-loop flights
    (the law on the estimate): its mean within the two-sided 99 % χ² bounds, and each value's error
    in units of its reported σ of RMS close to 1."""
    samples, z = [], []
    for seed in range(4):
        rec, _, _ = fly("ekf", seed=seed, nees_every=125)
        samples.append(nees_samples(rec))
        ok = np.isfinite(rec.sigma[:, 0]) & (rec.t >= 1.0)
        z.append((rec.truth[ok] - rec.estimate[ok]) / rec.sigma[ok])
    ne = np.concatenate(samples)
    n = len(ne)
    assert n == 4 * 18
    lo, hi = chi2_ppf(0.005, 9 * n) / n, chi2_ppf(0.995, 9 * n) / n
    assert lo <= ne.mean() <= hi, (ne.mean(), lo, hi)
    zr = np.sqrt(np.mean(np.concatenate(z) ** 2, axis=0))
    positions_velocities_angles = zr[[0, 1, 2, 3, 4, 5, 6, 8, 10]]
    assert np.all((positions_velocities_angles > 0.6) & (positions_velocities_angles < 1.5)), zr


def test_ekf_is_not_overconfident_with_gnss() -> None:
    """GNSS on the x500 (metre noise, 5 Hz, 120 ms late): the errors stay within the reported
    covariance (NEES mostly under its 99 % χ² quantile, mean not above 9 by much) and the filter is
    not uselessly pessimistic either."""
    rec, est, _ = fly("ekf", "gnss", profile="x500", nees_every=25)
    ne = nees_samples(rec)
    assert (ne <= chi2_ppf(0.99, 9)).mean() >= 0.97
    assert 9 / 3 <= ne.mean() <= 9 * 1.3, ne.mean()
    assert est.rejected == {}  # type: ignore[attr-defined]


def test_ekf_on_ideal_sensors_follows_the_truth() -> None:
    """No noise, no latency, every physics step: the filter's mechanisation (propagation with the
    mean IMU sample, the updates) reproduces the plant's motion."""
    rec, _, _ = fly("ekf", "ideal", seconds=5.0)
    err = np.abs(rec.truth - rec.estimate).max(axis=0)
    assert err[[0, 2, 4]].max() < 2e-6  # m
    assert err[[1, 3, 5]].max() < 2e-5  # m/s
    assert err[[6, 8, 10]].max() < 2e-6  # rad
    # rad/s: the rates are the gyro's mean over its last interval (1 ms): half a step behind, at the
    # sine's angular accelerations of about 10 rad/s^2 some 5 mrad/s
    assert err[[7, 9, 11]].max() < 1e-2


def test_the_flight_is_reproducible_and_reading_the_covariance_changes_nothing() -> None:
    """One seed, the same estimates to the bit, whether the covariance is read every step (as a
    vehicle sending ODOMETRY would) or never; another seed, other estimates."""
    a, _, _ = fly("ekf", seconds=2.0, seed=5)
    b, _, _ = fly("ekf", seconds=2.0, seed=5, nees_every=1)
    c, _, _ = fly("ekf", seconds=2.0, seed=6)
    assert np.array_equal(a.estimate, b.estimate) and np.array_equal(a.truth, b.truth)
    assert not np.array_equal(a.estimate, c.estimate)


def test_latency_is_handled_against_the_state_at_the_time_of_validity() -> None:
    """Motion capture 60 ms late: fused against the state it describes, the position estimate is
    several times better than if each reading were taken as valid when it arrives."""
    late = dataclasses.replace(prepare(SINE).profile.sensor_set("mocap"), position_latency_ms=60.0)
    good, _, _ = fly("ekf", late, law_on="truth")
    naive, _, _ = fly("ekf", late, law_on="truth", relabel=True)
    assert position_error_rms(good) < 0.002
    assert position_error_rms(naive) > 4 * position_error_rms(good)


def test_ekf_estimates_the_imu_biases() -> None:
    gyro = (0.002, -0.0015, 0.001)  # rad/s, about 2 sigma of the filter's prior
    accel = (0.04, -0.03, 0.05)  # m/s^2, about 1 sigma
    rec, est, suite = fly("ekf", law_on="truth", gyro_bias=gyro, accel_bias=accel)
    (bg, ba), (sg, sa) = est.biases, est.bias_sigma()  # type: ignore[attr-defined]
    for b_hat, b_true, s, prior in ((bg, suite.gyro_bias, sg, 1e-3), (ba, suite.accel_bias, sa, 0.05)):
        err = np.abs(np.array(b_hat) - np.array(b_true))
        assert np.all(err <= 3.5 * np.array(s)), (b_hat, b_true, s)
        assert np.all(np.array(s) < 0.2 * prior)  # learned: the sigma shrank well below the prior's


def test_ekf_buys_the_smooth_control_raw_measurements_lose() -> None:
    """The sine with motion capture, BS-ST fed the estimate: with the EKF the ripple of u2 (RMS about
    its centred 0.1 s average) is at least 5 times lower than with the raw measurements, and the
    tracking no worse."""
    out = {}
    for kind in ("raw", "ekf"):
        rec, _, _ = fly(kind, seconds=15.0)
        late = rec.t >= 5.0
        e = rec.truth[late][:, [0, 2, 4]] - rec.reference[late][:, :3]
        out[kind] = (ripple_rms(rec.t, rec.demanded[:, 1], 250.0, 0.1), float(np.sqrt(np.mean(np.sum(e**2, axis=1)))))
    (rip_raw, rms_raw), (rip_ekf, rms_ekf) = out["raw"], out["ekf"]
    assert rip_ekf * 5 <= rip_raw, out
    assert rms_ekf <= rms_raw, out


# -- the raw and truth estimators ------------------------------------------------------------------

def _m(kind: str, t: float, values: tuple[float, ...], sigma: tuple[float, ...], latency: float = 0.0,
       interval: float = 0.0) -> Measurement:
    return Measurement(kind, t, t + latency, values, sigma, interval)


def test_raw_passes_the_pose_on_and_differences_positions() -> None:
    cfg = prepare(SINE).profile.sensor_set("mocap")
    raw = RawEstimator(cfg, (0.0,) * 12)
    s = (0.001,) * 6
    raw.step(0.005, [_m("pose", 0.0, (1.0, 2.0, 3.0, 0.1, -0.1, 3.1), s, 0.005)])
    raw.step(0.015, [_m("pose", 0.01, (1.01, 1.98, 3.0, 0.1, -0.1, -3.1), s, 0.005),
                     _m("imu", 0.015, (0.0, 0.0, 9.81, 0.2, 0.0, 0.0), (0.03,) * 3 + (0.003,) * 3, 0.0, 0.004),
                     _m("heading", 0.015, (0.5,), (0.02,))])  # ignored: the pose measures the heading
    X = raw.estimate(0.015)
    assert X[0:6] == pytest.approx((1.01, 1.0, 1.98, -2.0, 3.0, 0.0))  # the latest position, as is; no latency handling
    assert X[6] == 0.1 and X[8] == -0.1
    assert X[10] == pytest.approx(-3.1 + 2 * math.pi)  # unwrapped from 3.1 across pi, not a jump of -6.2
    assert X[7] == pytest.approx(0.2 + 0.0) and X[9] == pytest.approx(0.0) and X[11] == pytest.approx(0.0, abs=1e-12)
    cov = raw.covariance()
    assert cov.sigma()[1] == pytest.approx(math.sqrt(2) * 0.001 / 0.01)  # a difference of two 1 mm readings
    assert cov.sigma()[0] == 0.001 and cov.sigma()[6] == 0.001 and cov.sigma()[7] == 0.003


def test_raw_without_an_attitude_sensor_integrates_the_gyro_and_takes_gnss_velocity() -> None:
    cfg = prepare(SINE, profile="x500").profile.sensor_set("gnss")
    raw = RawEstimator(cfg, (0.0,) * 12)
    for k in range(1, 101):  # 0.4 s of a 0.5 rad/s roll
        raw.step(k * 0.004, [_m("imu", k * 0.004, (0.0, 0.0, 9.81, 0.5, 0.0, 0.0), (0.03,) * 6, 0.0, 0.004)])
    raw.step(0.4, [_m("gnss", 0.3, (5.0, 6.0, 7.0, 0.5, 0.6, 0.7), (1.0, 1.0, 2.0, 0.1, 0.1, 0.2), 0.1),
                   _m("heading", 0.4, (1.0,), (0.02,))])
    X = raw.estimate(0.4)
    assert X[0:6] == (5.0, 0.5, 6.0, 0.6, 7.0, 0.7)
    assert X[6] == pytest.approx(0.2, abs=1e-12) and X[10] == pytest.approx(1.0)
    sig = raw.covariance().sigma()
    assert sig[10] == pytest.approx(0.02)  # the heading's, as measured
    assert math.isnan(sig[6]) and math.isnan(sig[8])  # roll and pitch integrated from the gyro: unknown


def test_truth_passes_the_state_through() -> None:
    state = [tuple(float(i) for i in range(12))]
    est = TruthEstimator(lambda: state[0])
    est.step(0.0, [])
    assert est.estimate(0.0) == state[0]
    state[0] = (1.0,) * 12
    assert est.estimate(1.0) == (1.0,) * 12
    assert est.covariance() == ZERO_COVARIANCE
    assert est.kind == "truth"


def test_make_estimator_builds_each_kind_and_refuses_others() -> None:
    cfg = IDEAL
    for kind in ESTIMATOR_KINDS:
        assert make_estimator(kind, cfg, (0.0,) * 12, 9.81, lambda: (0.0,) * 12).kind == kind
    assert isinstance(make_estimator("ekf", cfg, (0.0,) * 12, 9.81, lambda: (0.0,) * 12), Ekf)
    with pytest.raises(ValueError, match="estimator must be one of truth, ekf, raw; got 'ukf'"):
        make_estimator("ukf", cfg, (0.0,) * 12, 9.81, lambda: (0.0,) * 12)


def test_the_ekf_starts_with_what_its_readings_at_rest_tell_it() -> None:
    """plant.alignment: 10 s on the pad. gnss: height from 500 barometer readings of 0.2 m and 50 fixes of 2 m (σ 9 mm),
    the horizontal from 50 fixes of 1 m (0.14 m); P0 is those variances (it was one fix's: 1 m and 2 m). The start
    drawn from them is seeded: x, y where the vehicle stands, the height and attitude off by a draw, at rest."""
    f = prepare(SINE)
    cfg, g = f.profile.sensor_set("gnss"), f.profile.gravity
    pos, z, tilt, psi = alignment_variances(cfg, g)
    assert math.sqrt(pos) == pytest.approx(1.0 / math.sqrt(50))
    assert math.sqrt(z) == pytest.approx(1.0 / math.sqrt(500 / 0.2**2 + 50 / 2.0**2))  # 8.9 mm
    assert math.sqrt(tilt) < 1e-3 and psi is not None and math.sqrt(psi) == pytest.approx(0.02 / math.sqrt(1000))
    P = Ekf(cfg, (0.0,) * 12, g).P
    assert (P[0, 0], P[1, 1], P[2, 2]) == pytest.approx((pos, pos, z))
    start = (1.0, 0.0, 2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.5, 0.0)
    a, b = aligned_start(cfg, g, start, 0), aligned_start(cfg, g, start, 1)
    assert a == aligned_start(cfg, g, start, 0) and a != b
    for s in (a, b):
        assert s[0] == 1.0 and s[2] == 2.0 and s[1] == s[3] == s[5] == s[7] == s[9] == s[11] == 0.0
        assert abs(s[4]) < 5 * math.sqrt(z) and abs(s[10] - 0.5) < 5 * math.sqrt(psi)
    assert aligned_start(f.profile.sensor_set("ideal"), g, start, 0) == start  # exact readings: nothing to draw


# -- the covariance as ODOMETRY wants it -----------------------------------------------------------

def test_covariance_blocks_and_nees() -> None:
    cfg = prepare(SINE).profile.sensor_set("mocap")
    ekf = Ekf(cfg, (0.0,) * 12)
    cov = ekf.covariance()
    C = np.array(cov.state).reshape(9, 9)
    assert np.allclose(C, C.T) and np.all(np.linalg.eigvalsh(C) > 0)
    pose = np.array(cov.pose()).reshape(6, 6)
    assert pose[0, 0] == C[0, 0] and pose[3, 3] == C[6, 6] and pose[0, 5] == C[0, 8]
    twist = np.array(cov.twist()).reshape(6, 6)
    assert twist[1, 1] == C[4, 4] and twist[3, 3] == cov.rates[0] and twist[0, 3] == 0.0
    assert len(upper_triangle(cov.pose())) == 21 and upper_triangle(cov.pose())[6] == pose[1, 1]
    sig = cov.sigma()
    assert sig[0] == pytest.approx(math.sqrt(C[0, 0])) and sig[1] == pytest.approx(math.sqrt(C[3, 3]))
    truth = (0.01, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    assert nees(truth, (0.0,) * 12, cov) == pytest.approx(0.01**2 / C[0, 0], rel=0.05)  # nearly uncorrelated at start
    assert estimation_error(truth, (0.0,) * 12)[0] == 0.01
    unknown = Covariance((math.nan,) * 81, (math.nan,) * 9)
    assert math.isnan(nees(truth, truth, unknown))


# -- the compiled arithmetic (bridge/autopilot/ekfkernels.py) against numpy written from the docstrings ---------

def test_weighted_square_is_the_quadratic_form_and_nan_unless_positive_definite() -> None:
    from bridge.autopilot import ekfkernels
    from bridge.autopilot.cholesky import weighted_square

    rng = np.random.default_rng(3)
    for n in (1, 3, 9):
        A = rng.standard_normal((n, n))
        C = A @ A.T + 0.1 * np.eye(n)
        e = rng.standard_normal(n)
        want = float(e @ np.linalg.solve(C, e))
        assert weighted_square(tuple(C.ravel()), tuple(e)) == pytest.approx(want, rel=1e-12)
        assert ekfkernels._weighted_square(C.ravel(), e) == pytest.approx(want, rel=1e-12)
    e3 = (1.0, 2.0, 3.0)
    for bad in (np.diag([1.0, -1.0, 1.0]), np.zeros((3, 3)), np.diag([1.0, math.nan, 1.0]),
                np.diag([1.0, math.inf, 1.0])):
        assert math.isnan(weighted_square(tuple(bad.ravel()), e3))
        assert math.isnan(ekfkernels._weighted_square(bad.ravel(), np.array(e3)))


def test_the_compiled_covariance_step_is_phi_p_phi_transpose_plus_q() -> None:
    """carry() builds Φ = I + A from its blocks sparsely; here Φ and Q are written densely from the
    module docstring and multiplied by numpy."""
    from bridge.autopilot import ekfkernels as k

    rng = np.random.default_rng(5)
    x = np.zeros(k.X_SIZE)
    M = rotation(0.2, -0.1, 0.7)
    x[k.X_M:k.X_M + 9] = M
    af = (0.3, -0.2, 9.6)
    x[k.X_AF:k.X_AF + 3] = af
    c = np.zeros(k.C_SIZE)
    c[k.C_NA2], c[k.C_NG2], c[k.C_WA2], c[k.C_WG2] = 4e-4, 1e-6, 1e-8, 1e-10
    A0 = rng.standard_normal((15, 15))
    P = A0 @ A0.T
    T = 0.004
    out = np.empty((15, 15))
    k.carry(x, c, P, T, out)
    Mm = np.array(M).reshape(3, 3)
    Sk = np.array([[0.0, -af[2], af[1]], [af[2], 0.0, -af[0]], [-af[1], af[0], 0.0]])
    Phi = np.eye(15)
    Phi[0:3, 3:6] = T * np.eye(3)
    Phi[0:3, 6:9] = -0.5 * T * T * Sk
    Phi[0:3, 12:15] = -0.5 * T * T * Mm
    Phi[3:6, 6:9] = -T * Sk
    Phi[3:6, 9:12] = 0.5 * T * T * Sk @ Mm
    Phi[3:6, 12:15] = -T * Mm
    Phi[6:9, 9:12] = -T * Mm
    na2, ng2, wa2, wg2 = 4e-4, 1e-6, 1e-8, 1e-10
    Q = np.zeros((15, 15))
    I3 = np.eye(3)
    Q[0:3, 0:3], Q[0:3, 3:6], Q[3:6, 0:3] = na2 * T**3 / 3 * I3, na2 * T**2 / 2 * I3, na2 * T**2 / 2 * I3
    Q[3:6, 3:6], Q[6:9, 6:9], Q[9:12, 9:12], Q[12:15, 12:15] = na2 * T * I3, ng2 * T * I3, wg2 * T * I3, wa2 * T * I3
    assert np.allclose(out, Phi @ P @ Phi.T + Q, rtol=1e-12, atol=1e-15)


def test_the_kernel_nees_equals_the_nees_of_the_reported_covariance() -> None:
    """The vehicle's NEES (straight from P, compiled) and nees() of the Covariance that ODOMETRY carries
    (the tuples, in Python) are the same number, mid-flight, between covariance steps."""
    f = prepare(SINE)
    cfg = f.profile.sensor_set("mocap")
    plant = f.make_plant()
    ctl = f.make_controller()
    suite = SensorSuite(cfg, 0, f.mission.physics_hz, f.profile.gravity)
    ekf = Ekf(cfg, plant.state, f.profile.gravity)
    ekf.step(plant.t, suite.sample(plant.t, plant.state))
    checked = 0
    for step in range(500):
        t = step / f.mission.rate_hz
        e = ekf.estimate(t)
        plant.command(ctl.step(t, e, f.mission.trajectory.sample(t)).normalised)
        if step % 37 == 0:
            a, b = ekf.nees(plant.state, e), nees(plant.state, e, ekf.covariance())
            assert a == pytest.approx(b, rel=1e-9) and a > 0
            checked += 1
        for _ in range(f.substeps):
            plant.step()
            ekf.step(plant.t, suite.sample(plant.t, plant.state))
    assert checked == 14 and ekf.fused > 100 and ekf.rejected == {}

"""Covers plant.sensors.

plant/sensors.py and the profiles' [sensors] sets: noise statistics, rates, latency, seeding,
what the IMU measures, and the validation of every key (file, key and range named)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from params import ConfigError
from plant import Quadrotor, load_profile
from plant.profiles import PROFILE_DIR, sensors_from_table
from plant.sensors import (
    IDEAL,
    SENSOR_RANGES,
    SENSOR_SET_NAMES,
    Measurement,
    SensorConfig,
    SensorSuite,
    body_rates,
    euler,
    euler_rates,
    rotation,
    wrap_angle,
)

PHYSICS_HZ = 1000.0
G = 9.81
HOVER: tuple[float, ...] = (0.3, 0.0, -0.2, 0.0, 1.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.4, 0.0)  # at rest, in the air


def mocap() -> SensorConfig:
    return load_profile("paper").sensor_set("mocap")


def gnss() -> SensorConfig:
    return load_profile("x500").sensor_set("gnss")


def collect(config: SensorConfig, seconds: float, state: tuple[float, ...] = HOVER, seed: int = 0,
            physics_hz: float = PHYSICS_HZ) -> list[tuple[float, Measurement]]:
    """(physics step time, measurement) of every measurement over ``seconds`` at a constant state."""
    suite = SensorSuite(config, seed, physics_hz, G)
    out = []
    for k in range(int(round(seconds * physics_hz)) + 1):
        t = k / physics_hz
        out += [(t, m) for m in suite.sample(t, state)]
    return out


def values(stream: list[tuple[float, Measurement]], kind: str) -> np.ndarray:
    return np.array([m.values for _, m in stream if m.kind == kind])


# -- statistics --------------------------------------------------------------------------------

def test_imu_white_noise_has_the_configured_sigma_and_no_bias_at_rest() -> None:
    cfg = dataclasses.replace(mocap(), accel_bias_walk=0.0, gyro_bias_walk=0.0)
    imu = values(collect(cfg, 40.0), "imu")  # 10 000 samples at 250 Hz
    assert len(imu) == 10000
    sa = cfg.accel_noise_density * math.sqrt(cfg.imu_rate_hz)  # the mean over 4 ms of that density
    sg = cfg.gyro_noise_density * math.sqrt(cfg.imu_rate_hz)
    assert imu[:, 0:3].std(axis=0) == pytest.approx([sa] * 3, rel=0.04)
    assert imu[:, 3:6].std(axis=0) == pytest.approx([sg] * 3, rel=0.04)
    # at rest the accelerometer feels +g along body z (up) and nothing else; the gyro, nothing
    assert imu[:, 0:3].mean(axis=0) == pytest.approx([0.0, 0.0, G], abs=4 * sa / 100)
    assert imu[:, 3:6].mean(axis=0) == pytest.approx([0.0, 0.0, 0.0], abs=4 * sg / 100)


def test_imu_bias_walks_at_the_configured_rate() -> None:
    cfg = dataclasses.replace(mocap(), accel_noise_density=0.0, gyro_noise_density=0.0)
    imu = values(collect(cfg, 40.0), "imu")
    steps = np.diff(imu, axis=0)  # no white noise and a constant state: the bias increments alone
    T = 1.0 / cfg.imu_rate_hz
    assert steps[:, 0:3].std(axis=0) == pytest.approx([cfg.accel_bias_walk * math.sqrt(T)] * 3, rel=0.04)
    assert steps[:, 3:6].std(axis=0) == pytest.approx([cfg.gyro_bias_walk * math.sqrt(T)] * 3, rel=0.04)
    bound = 5 * np.array([cfg.accel_bias_walk] * 3 + [cfg.gyro_bias_walk] * 3) * math.sqrt(T / len(steps))
    assert np.all(np.abs(steps.mean(axis=0)) < bound)  # a walk, not a drift


def test_position_baro_heading_noise_sigmas() -> None:
    s = collect(dataclasses.replace(mocap(), heading_rate_hz=100.0), 60.0)
    pose = values(s, "pose")
    truth = np.array([HOVER[0], HOVER[2], HOVER[4], HOVER[6], HOVER[8], HOVER[10]])
    err = pose - truth
    assert err.std(axis=0) == pytest.approx([0.001] * 6, rel=0.05)
    assert np.abs(err.mean(axis=0)).max() < 4 * 0.001 / math.sqrt(len(pose))
    baro = values(s, "baro")[:, 0] - HOVER[4]
    assert baro.std() == pytest.approx(0.2, rel=0.06)
    heading = values(s, "heading")[:, 0] - HOVER[10]
    assert heading.std() == pytest.approx(0.02, rel=0.05)
    fixes = values(collect(gnss(), 400.0, physics_hz=100.0), "gnss")  # 2000 fixes at 5 Hz
    assert len(fixes) == 2000
    gerr = fixes - np.array([HOVER[0], HOVER[2], HOVER[4], HOVER[1], HOVER[3], HOVER[5]])
    assert gerr.std(axis=0) == pytest.approx([1.0, 1.0, 2.0, 0.1, 0.1, 0.2], rel=0.07)


def test_measurements_carry_their_sigma() -> None:
    s = collect(mocap(), 0.1)
    imu = next(m for _, m in s if m.kind == "imu")
    assert imu.sigma == pytest.approx((0.00186 * math.sqrt(250),) * 3 + (0.00018665 * math.sqrt(250),) * 3)
    assert imu.interval_s == pytest.approx(0.004)
    pose = next(m for _, m in s if m.kind == "pose")
    assert pose.sigma == (0.001,) * 6
    with pytest.raises(dataclasses.FrozenInstanceError):
        pose.t_valid = 0.0  # type: ignore[misc]


# -- rates and latency ---------------------------------------------------------------------------

def test_each_sensor_samples_at_its_rate() -> None:
    counts: dict[str, int] = {}
    for _, m in collect(mocap(), 10.0):
        counts[m.kind] = counts.get(m.kind, 0) + 1
    # over [0, 10] s: the IMU's first sample ends its first interval at 4 ms; the pose's last
    # ones (valid after 9.995 s) have not arrived yet; no heading sensor in the mocap set
    assert counts == {"imu": 2500, "pose": 1000, "baro": 501}
    fixes = [m for _, m in collect(gnss(), 10.0) if m.kind == "gnss"]
    assert len(fixes) == 50  # valid at 0, 0.2, ... 9.8 s (9.8 + 0.12 <= 10; 10.0 not arrived)
    assert all(abs(b.t_valid - a.t_valid - 0.2) < 1e-9 for a, b in zip(fixes, fixes[1:]))


def test_a_rate_at_or_above_the_physics_rate_samples_every_step() -> None:
    s = collect(IDEAL, 1.0, physics_hz=250.0)
    per_kind = {k: sum(1 for _, m in s if m.kind == k) for k in ("imu", "pose", "baro", "heading")}
    assert per_kind == {"imu": 250, "pose": 251, "baro": 251, "heading": 251}


def test_latency_releases_each_reading_its_latency_after_its_time_of_validity() -> None:
    for cfg, latency in ((mocap(), 0.005), (gnss(), 0.120)):
        s = [(t, m) for t, m in collect(cfg, 3.0) if m.kind in ("pose", "gnss")]
        assert s
        for t, m in s:
            assert m.t_arrival == pytest.approx(m.t_valid + latency, abs=1e-12)
            assert t == pytest.approx(m.t_arrival, abs=0.5 / PHYSICS_HZ)  # released at that physics step
    imu = [(t, m) for t, m in collect(mocap(), 1.0) if m.kind in ("imu", "baro")]
    assert all(t == m.t_valid == m.t_arrival for t, m in imu)  # no latency


def test_zero_rate_means_no_such_sensor() -> None:
    cfg = dataclasses.replace(gnss(), baro_rate_hz=0.0, heading_rate_hz=0.0)
    kinds = {m.kind for _, m in collect(cfg, 2.0)}
    assert kinds == {"imu", "gnss"}


# -- seeding -------------------------------------------------------------------------------------

def test_one_seed_gives_the_same_measurements_another_seed_others() -> None:
    a = collect(mocap(), 2.0, seed=7)
    b = collect(mocap(), 2.0, seed=7)
    c = collect(mocap(), 2.0, seed=8)
    assert a == b
    assert [m.values for _, m in a] != [m.values for _, m in c]
    assert [(m.kind, m.t_valid) for _, m in a] == [(m.kind, m.t_valid) for _, m in c]


def test_each_sensor_draws_its_own_stream_whatever_else_is_sampled() -> None:
    """The n-th pose reading gets the n-th draws of the position stream: running the IMU at
    another rate, or calling the suite at another physics rate, does not change it."""
    base = mocap()
    poses_a = values(collect(base, 3.0, seed=3), "pose")
    poses_b = values(collect(dataclasses.replace(base, imu_rate_hz=1000.0), 3.0, seed=3), "pose")
    poses_c = values(collect(base, 3.0, seed=3, physics_hz=500.0), "pose")
    assert np.array_equal(poses_a, poses_b)
    assert np.array_equal(poses_a, poses_c)


def test_noise_scale_multiplies_every_sigma() -> None:
    cfg = mocap()
    half = cfg.scaled(0.5)
    for key in ("accel_noise_density", "accel_bias_walk", "gyro_noise_density", "gyro_bias_walk",
                "position_noise_m", "position_noise_z_m", "attitude_noise_rad", "baro_noise_m", "heading_noise_rad"):
        assert getattr(half, key) == pytest.approx(0.5 * getattr(cfg, key)), key
    assert (half.imu_rate_hz, half.position_latency_ms) == (cfg.imu_rate_hz, cfg.position_latency_ms)
    a = values(collect(cfg, 1.0, seed=1), "pose")
    b = values(collect(half, 1.0, seed=1), "pose")
    truth = np.array([HOVER[0], HOVER[2], HOVER[4], HOVER[6], HOVER[8], HOVER[10]])
    assert np.allclose(b - truth, 0.5 * (a - truth), atol=1e-15)
    z = values(collect(cfg.scaled(0.0), 1.0, seed=1), "pose")
    assert np.allclose(z, np.tile(truth, (len(z), 1)), rtol=0, atol=1e-15)


# -- what the IMU measures -----------------------------------------------------------------------

def test_ideal_imu_is_the_mean_specific_force_and_body_rate_of_a_real_flight() -> None:
    """Flying the plant under a held thrust and torques, the ideal IMU's sample over each 4 ms
    is the plant's own specific force Rᵀ(a + g e_z) and body rate half-way through it."""
    p = load_profile("paper")
    plant = Quadrotor(p, physics_hz=PHYSICS_HZ, state=HOVER, ground=False)
    plant.command((p.mass * p.gravity / p.u_max[0] * 1.05, 0.3, -0.2, 0.1))
    suite = SensorSuite(dataclasses.replace(IDEAL, imu_rate_hz=250.0), 0, PHYSICS_HZ, p.gravity)
    states = [plant.state]  # states[k]: the state at k ms
    samples = [m for m in suite.sample(plant.t, plant.state) if m.kind == "imu"]
    for _ in range(400):
        plant.step()
        states.append(plant.state)
        samples += [m for m in suite.sample(plant.t, plant.state) if m.kind == "imu"]
    assert len(samples) == 100
    for m in samples:
        k_mid = round((m.t_valid - 0.5 * m.interval_s) * PHYSICS_HZ)
        X = states[k_mid]
        d = plant.derivative(k_mid / PHYSICS_HZ, X)
        R = rotation(X[6], X[8], X[10])
        f_world = (d[1], d[3], d[5] + p.gravity)
        f_body = tuple(R[j] * f_world[0] + R[3 + j] * f_world[1] + R[6 + j] * f_world[2] for j in range(3))
        # the mean over 4 ms against the value half-way: equal to second order (the midpoint rule)
        assert m.values[0:3] == pytest.approx(f_body, abs=1e-4)  # against 0.03 m/s^2 of noise in mocap
        assert m.values[3:6] == pytest.approx(body_rates(X[6], X[8], X[7], X[9], X[11]), abs=1e-5)
    assert abs(samples[-1].values[3]) > 0.5  # it did roll: the comparison is not of zeros


def test_on_the_ground_the_accelerometer_feels_gravity() -> None:
    p = load_profile("paper")
    plant = Quadrotor(p, physics_hz=PHYSICS_HZ)  # at rest on the ground, no thrust
    suite = SensorSuite(dataclasses.replace(IDEAL, imu_rate_hz=250.0), 0, PHYSICS_HZ, p.gravity)
    imu = []
    for _ in range(100):
        plant.step()
        imu += [m.values for m in suite.sample(plant.t, plant.state) if m.kind == "imu"]
    assert np.allclose(imu, [(0.0, 0.0, p.gravity, 0.0, 0.0, 0.0)] * len(imu), atol=1e-12)


def test_rotation_helpers_invert_each_other() -> None:
    rng = np.random.default_rng(0)
    for _ in range(200):
        phi, theta = rng.uniform(-1.2, 1.2, 2)
        psi = rng.uniform(-math.pi, math.pi)
        assert euler(rotation(phi, theta, psi)) == pytest.approx((phi, theta, psi), abs=1e-12)
        rates = tuple(rng.normal(size=3))
        assert euler_rates(phi, theta, *body_rates(phi, theta, *rates)) == pytest.approx(rates, abs=1e-9)
    assert wrap_angle(math.pi) == pytest.approx(math.pi) and wrap_angle(-math.pi) == pytest.approx(math.pi)
    assert wrap_angle(3 * math.pi / 2) == pytest.approx(-math.pi / 2)


# -- the profiles' sets and a mission's choice -------------------------------------------------------

def test_every_builtin_profile_has_the_three_sets_and_ideal_is_exact() -> None:
    for name in ("paper", "x500"):
        p = load_profile(name)
        assert tuple(n for n, _ in p.sensors) == SENSOR_SET_NAMES
        ideal = p.sensor_set("ideal")
        assert all(getattr(ideal, k) in (0.0, None) for k in SENSOR_RANGES if "noise" in k or "walk" in k
                   or "latency" in k)
        assert ideal.imu_rate_hz >= 10000.0 and ideal.position_rate_hz >= 10000.0
        assert p.sensor_set("mocap").position_class == "mocap" and p.sensor_set("gnss").position_class == "gnss"
        g = p.sensor_set("gnss")
        assert 5.0 <= g.position_rate_hz <= 10.0 and 50.0 <= g.position_latency_ms <= 200.0
        assert g.position_noise_m >= 0.5 and g.position_noise_z_m > g.position_noise_m
        m = p.sensor_set("mocap")
        assert 100.0 <= m.position_rate_hz <= 250.0 and m.position_noise_m <= 0.002 and m.position_latency_ms <= 10.0


PAPER_TEXT = (PROFILE_DIR / "paper.toml").read_text()


def _edit(text: str, key: str, value: str | None) -> str:
    out = []
    for line in text.splitlines():
        if line.split("=")[0].strip() == key:
            if value is not None:
                out.append(f"{key} = {value}")
        else:
            out.append(line)
    return "\n".join(out) + "\n"


@pytest.mark.parametrize(
    "key, value, words",
    [
        ("sensors.mocap.position_noise_m", "-0.001", "must be in [0, 100], got -0.001"),
        ("sensors.mocap.imu_rate_hz", "0", "must be in (0, 10000], got 0"),
        ("sensors.gnss.position_latency_ms", "5000", "must be in [0, 2000], got 5000"),
        ("sensors.gnss.heading_noise_rad", "4.0", "must be in [0, 3.14159]"),
        ("sensors.mocap.position_class", '"lidar"', "must be one of mocap, gnss"),
        ("sensors.ideal.baro_noise_m", '"low"', "expected a number"),
        ("sensors.mocap.gyro_bias_walk", None, "is required"),
        ("sensors.gnss.velocity_noise_mps", None, "is required"),
        ("sensors.mocap.attitude_noise_rad", None, "is required"),
    ],
)
def test_bad_sensor_values_name_file_key_and_range(tmp_path: Path, key: str, value: str | None, words: str) -> None:
    f = tmp_path / "bad.toml"
    f.write_text(_edit(PAPER_TEXT, key, value))
    with pytest.raises(ConfigError) as exc:
        load_profile(f)
    msg = str(exc.value)
    assert msg.startswith(f"{f}: {key}:"), msg
    assert words in msg, msg


def test_a_key_of_the_other_class_or_an_unknown_key_is_refused(tmp_path: Path) -> None:
    f = tmp_path / "bad.toml"
    f.write_text(PAPER_TEXT.replace("sensors.mocap.baro_noise_m", "sensors.mocap.velocity_noise_mps = 0.1\n"
                                    "sensors.mocap.baro_noise_m"))
    with pytest.raises(ConfigError, match=r"sensors\.mocap\.velocity_noise_mps: is not used by position_class 'mocap'"):
        load_profile(f)
    f.write_text(PAPER_TEXT.replace("sensors.mocap.baro_noise_m",
                                    "sensors.mocap.lidar_hz = 10\nsensors.mocap.baro_noise_m"))
    with pytest.raises(ConfigError, match=r"sensors\.mocap\.lidar_hz: unknown key"):
        load_profile(f)


def test_a_profile_without_sensors_has_the_ideal_set_only(tmp_path: Path) -> None:
    f = tmp_path / "bare.toml"
    f.write_text("\n".join(line for line in PAPER_TEXT.splitlines() if not line.startswith("sensors.")) + "\n")
    p = load_profile(f)
    assert p.sensors == (("ideal", IDEAL),)
    with pytest.raises(ConfigError, match=r"profile 'paper' has no sensor set 'mocap'; it has: ideal"):
        p.sensor_set("mocap")


def test_a_mission_picks_a_set_and_overrides_its_keys() -> None:
    p = load_profile("paper")
    assert sensors_from_table(p, {}, "m.toml") == p.sensor_set("ideal")
    assert sensors_from_table(p, {"set": "gnss"}, "m.toml") == p.sensor_set("gnss")
    cfg = sensors_from_table(p, {"set": "mocap", "position_latency_ms": 20.0, "noise_scale": 2.0}, "m.toml")
    assert cfg.position_latency_ms == 20.0 and cfg.position_noise_m == pytest.approx(0.002)
    assert cfg.name == "mocap"
    switched = sensors_from_table(p, {"set": "mocap", "position_class": "gnss", "velocity_noise_mps": 0.1,
                                      "velocity_noise_z_mps": 0.2}, "m.toml")
    assert switched.position_class == "gnss" and switched.attitude_noise_rad is None


@pytest.mark.parametrize(
    "table, words",
    [
        ({"set": "indoor"}, "sensors.set: must be one of ideal, mocap, gnss; got 'indoor'"),
        ({"set": "mocap", "noise_scale": -1.0}, "sensors.noise_scale: must be in [0, 100], got -1"),
        ({"set": "mocap", "baro_rate_hz": -5.0}, "sensors.baro_rate_hz: must be in [0, 10000], got -5"),
        ({"set": "mocap", "position_class": "gnss"}, "sensors.velocity_noise_mps: is required"),
        ({"set": "mocap", "velocity_noise_mps": 0.1}, "sensors.velocity_noise_mps: is not used by position_class"),
        ({"set": "gnss", "lidar": 1}, "sensors.lidar: unknown key"),
        ({"set": 3}, "sensors.set: expected a string"),
    ],
)
def test_a_bad_mission_table_names_the_file_and_key(table: dict, words: str) -> None:
    with pytest.raises(ConfigError) as exc:
        sensors_from_table(load_profile("paper"), table, "missions/m.toml")
    assert str(exc.value).startswith(f"missions/m.toml: {words}"), str(exc.value)

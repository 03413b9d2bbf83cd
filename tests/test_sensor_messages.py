"""Covers bridge.mavlink.telemetry and bridge.nodes.vehicle.

HIGHRES_IMU and GPS_RAW_INT: the vehicle's sensors on the GCS link (issue 12, "On the wire").

The pure builders of bridge/mavlink/telemetry.py (units, NWU/FLU -> NED/FRD against bridge/core/wire.py,
packing with pymavlink), the suite's ``latest`` accessor, and a real ``bsst vehicle`` process with a
pymavlink ground station: the streams at their rates with plausible values, SET_MESSAGE_INTERVAL on
them, ``vehicle.tlog`` holding them; and under truth, none of them.
"""

from __future__ import annotations

import dataclasses
import math
import os
import time

import numpy as np
import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from bridge.autopilot.estimator import Covariance, upper_triangle
from bridge.core.wire import euler_to_quaternion, paper_to_ned, rotate_inverse
from bridge.mavlink import telemetry as tm
from bridge.mavlink.endpoint import GCS_PORT
from bridge.nodes.report import Ready
from bridge.nodes.vehicle import odometry_covariance
from bridge.session import instance_slot
from plant import load_profile
from plant.sensors import BARO, GNSS, IMU, Measurement, SensorSuite, body_rates, rotation
from tests.sitlkit import Proc

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast

M = mavlink
G = 9.81
HOME = tm.Home()
HIGHRES, GPS = M.MAVLINK_MSG_ID_HIGHRES_IMU, M.MAVLINK_MSG_ID_GPS_RAW_INT


def _wire(msg):
    """``msg`` through real MAVLink 2 bytes and back (every field in its wire type and range)."""
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    return mav.parse_char(msg.pack(mav))


def _imu(values: tuple[float, ...], t: float = 1.5) -> Measurement:
    return Measurement(IMU, t, t, values, (0.0,) * 6, 0.004)


# -- pure: units and frames -------------------------------------------------------------------------
def test_highres_imu_at_rest_level_feels_minus_g_in_frd_and_the_isa_pressure():
    baro = Measurement(BARO, 1.49, 1.49, (2.0,), (0.2,))
    m = _wire(tm.highres_imu(_imu((0.0, 0.0, G, 0.0, 0.0, 0.0)), baro, HOME, 7))
    assert (m.xacc, m.yacc) == (0.0, 0.0) and m.zacc == pytest.approx(-G)  # FRD: z down, specific force up
    assert m.time_usec == 1_500_000  # the IMU sample's simulation time, not the caller's fallback
    assert m.pressure_alt == pytest.approx(490.0)  # m AMSL: home 488 m + the baro's 2 m
    assert m.abs_pressure == pytest.approx(tm.isa_pressure_hpa(490.0), rel=1e-6)
    bits = (M.HIGHRES_IMU_UPDATED_XACC | M.HIGHRES_IMU_UPDATED_YACC | M.HIGHRES_IMU_UPDATED_ZACC
            | M.HIGHRES_IMU_UPDATED_XGYRO | M.HIGHRES_IMU_UPDATED_YGYRO | M.HIGHRES_IMU_UPDATED_ZGYRO
            | M.HIGHRES_IMU_UPDATED_ABS_PRESSURE | M.HIGHRES_IMU_UPDATED_PRESSURE_ALT)
    assert m.fields_updated == bits  # no magnetometer, differential pressure or temperature


def test_isa_pressure_in_hpa_matches_the_standard_atmosphere_table():
    assert tm.isa_pressure_hpa(0.0) == pytest.approx(1013.25)
    assert tm.isa_pressure_hpa(1000.0) == pytest.approx(898.75, abs=0.05)  # ISA table: 898.76 hPa at 1 km
    assert tm.isa_pressure_hpa(500.0) == pytest.approx(954.61, abs=0.05)  # and 954.61 hPa at 500 m


def test_highres_imu_body_vectors_are_frd_as_the_wire_says():
    """A tilted, turning vehicle: the gyro is the FRD body rate of bridge/core/wire.py's ODOMETRY,
    and a resting specific force is gravity rotated into FRD with the wire's quaternion."""
    X = (1.0, 0.5, -2.0, 0.3, 3.0, -0.2, 0.3, 0.7, -0.2, -0.4, 2.5, 1.1)  # NWU, FLU, Z-Y-X
    phi, theta, psi = X[6], X[8], X[10]
    p, q, r = body_rates(phi, theta, X[7], X[9], X[11])  # FLU, as the IMU model computes them
    R = rotation(phi, theta, psi)
    f_flu = (R[6] * G, R[7] * G, R[8] * G)  # R^T (0, 0, g): at rest, the specific force points up
    m = tm.highres_imu(_imu((*f_flu, p, q, r)), None, HOME, 0)
    ned = paper_to_ned(X)
    assert (m.xgyro, m.ygyro, m.zgyro) == pytest.approx(ned["rates"], abs=1e-12)
    assert (m.xacc, m.yacc, m.zacc) == pytest.approx(rotate_inverse(ned["q"], (0.0, 0.0, -G)), abs=1e-12)


def test_highres_imu_says_what_is_missing():
    only_baro = tm.highres_imu(None, Measurement(BARO, 0.0, 0.0, (0.0,), (0.2,)), HOME, 9)
    assert only_baro.fields_updated == M.HIGHRES_IMU_UPDATED_ABS_PRESSURE | M.HIGHRES_IMU_UPDATED_PRESSURE_ALT
    assert (only_baro.zacc, only_baro.time_usec) == (0.0, 0)
    nothing = tm.highres_imu(None, None, HOME, 9)
    assert nothing.fields_updated == 0 and nothing.time_usec == 9


def test_gps_raw_int_units_frames_and_accuracies():
    # 100 m north, 50 m east (y = -50, west positive), 10 m up; moving 3 m/s north and 4 m/s east
    fix = Measurement(GNSS, 2.0, 2.12, (100.0, -50.0, 10.0, 3.0, -4.0, 0.5), (1.0, 1.0, 2.0, 0.1, 0.1, 0.2))
    m = _wire(tm.gps_raw_int(fix, HOME))
    lat, lon, alt = HOME.global_of(100.0, 50.0, -10.0)
    assert (m.lat, m.lon, m.alt) == (round(lat * 1e7), round(lon * 1e7), round(alt * 1000.0))
    assert m.lat > 473977420 and m.lon > 85455940 and m.alt == 498_000  # north, east, mm AMSL
    assert m.fix_type == M.GPS_FIX_TYPE_3D_FIX and m.satellites_visible == tm.SATELLITES_VISIBLE
    assert (m.vel, m.cog) == (500, round(math.degrees(math.atan2(4.0, 3.0)) * 100))  # cm/s, cdeg
    assert (m.eph, m.epv) == (100, 200)  # the sigmas in cm
    assert (m.h_acc, m.v_acc, m.vel_acc) == (1000, 2000, 100)  # mm, mm, mm/s
    assert m.time_usec == 2_000_000  # when the fix was valid, not when it arrived
    back_west = Measurement(GNSS, 0.0, 0.0, (0.0, 0.0, 0.0, -1.0, 1.0, 0.0), (1.0, 1.0, 2.0, 0.1, 0.1, 0.2))
    assert tm.gps_raw_int(back_west, HOME).cog == 22500  # south-west: 225 deg, wrapped into 0..35999


def test_gps_before_a_fix_is_a_receiver_without_one():
    m = _wire(tm.gps_no_fix(123))
    assert (m.fix_type, m.satellites_visible, m.time_usec) == (M.GPS_FIX_TYPE_NO_FIX, 0, 123)
    assert m.eph == m.epv == m.vel == m.cog == tm.UINT16_UNKNOWN


def test_sensor_streams_follow_the_sets_rates_capped_for_the_wall_clock():
    paper = load_profile("paper")
    gnss, mocap = paper.sensor_set("gnss"), paper.sensor_set("mocap")
    assert tm.sensor_streams(None) == {}  # truth: no sensors, no sensor streams
    assert tm.sensor_streams(gnss) == {HIGHRES: pytest.approx(1 / 50), GPS: pytest.approx(1 / gnss.position_rate_hz)}
    assert tm.sensor_streams(mocap) == {HIGHRES: pytest.approx(1 / 50)}  # a pose sensor is no GPS
    slow = dataclasses.replace(gnss, imu_rate_hz=20.0, position_rate_hz=10.0)
    assert tm.sensor_streams(slow) == {HIGHRES: pytest.approx(0.05), GPS: pytest.approx(0.1)}
    fast = dataclasses.replace(gnss, position_rate_hz=1000.0)
    assert tm.sensor_streams(fast)[GPS] == pytest.approx(1 / tm.SENSOR_STREAM_MAX_HZ)


def test_the_suite_keeps_the_newest_of_each_kind_and_the_messages_come_from_it():
    gnss = load_profile("paper").sensor_set("gnss")
    suite = SensorSuite(gnss, 3, 1000.0, G)
    rest = (0.0,) * 12
    assert suite.latest(IMU) is None and tm.sensor_message(GPS, suite, HOME, 5)[0].fix_type == M.GPS_FIX_TYPE_NO_FIX
    seen: dict[str, Measurement] = {}
    for k in range(400):
        for m in suite.sample(k / 1000.0, rest):
            seen[m.kind] = m
    assert {kind: suite.latest(kind) for kind in seen} == seen and {IMU, GNSS, BARO} <= set(seen)
    assert suite.latest(GNSS).t_arrival - suite.latest(GNSS).t_valid == pytest.approx(0.12)  # released late
    (imu,) = tm.sensor_message(HIGHRES, suite, HOME, 0)
    assert imu.time_usec == round(seen[IMU].t_valid * 1e6) and imu.zacc == pytest.approx(-seen[IMU].values[2])
    (fix,) = tm.sensor_message(GPS, suite, HOME, 0)
    assert fix.fix_type == M.GPS_FIX_TYPE_3D_FIX and fix.time_usec == round(seen[GNSS].t_valid * 1e6)
    assert tm.sensor_message(HIGHRES, None, HOME, 0) == []  # truth
    pose_suite = SensorSuite(load_profile("paper").sensor_set("mocap"), 3, 1000.0, G)
    assert tm.sensor_message(GPS, pose_suite, HOME, 0) == []  # motion capture: no GPS_RAW_INT


# -- a real vehicle process and a pymavlink ground station -------------------------------------------------
def _gcs(n: int):
    os.environ["MAVLINK20"] = "1"
    return mavutil.mavlink_connection(f"udpin:127.0.0.1:{GCS_PORT + n}", source_system=255, source_component=190,
                                      dialect="common")


def _command(gcs, command: int, *params: float):
    gcs.mav.command_long_send(gcs.target_system, gcs.target_component, command, 0, *params,
                              *(0.0,) * (7 - len(params)))
    ack = gcs.recv_match(type="COMMAND_ACK", blocking=True, timeout=10, condition=f"COMMAND_ACK.command=={command}")
    assert ack is not None, f"no COMMAND_ACK for {command}"
    return ack.result


def _listen(gcs, seconds: float) -> list[tuple[float, object]]:
    """Every message heard for ``seconds`` of wall time, with its arrival time (a measurement window)."""
    out = []
    end = time.monotonic() + seconds
    while (left := end - time.monotonic()) > 0:
        m = gcs.recv_match(blocking=True, timeout=left)
        if m is not None:
            out.append((time.monotonic(), m))
    return out


def _of(heard, kind: str) -> list:
    return [m for _, m in heard if m.get_type() == kind]


def _tlog_counts(path) -> dict[str, int]:
    log = mavutil.mavlink_connection(str(path), dialect="common")
    counts: dict[str, int] = {}
    while (m := log.recv_match()) is not None:
        counts[m.get_type()] = counts.get(m.get_type(), 0) + 1
    log.close()
    return counts


def test_gnss_ekf_vehicle_streams_its_sensors_to_the_ground_station(tmp_path):
    """Real time, at rest on the ground: HIGHRES_IMU at 50 Hz (the 250 Hz IMU capped), the accelerometer
    at -g in FRD, GPS_RAW_INT at the 5 Hz fix rate near home; SET_MESSAGE_INTERVAL slows it; the tlog has them."""
    with instance_slot() as n:
        gcs = _gcs(n)
        v = Proc.bsst("vehicle", "--instance", str(n), "--out", str(tmp_path), "--realtime",
                      "--sensors", "gnss", "--estimator", "ekf")
        try:
            v.wait_report(Ready)
            assert gcs.wait_heartbeat(timeout=20) is not None
            assert gcs.recv_match(type="GPS_RAW_INT", blocking=True, timeout=5, condition="GPS_RAW_INT.fix_type==3")
            heard = _listen(gcs, 1.5)
            imu, gps = _of(heard, "HIGHRES_IMU"), _of(heard, "GPS_RAW_INT")
            times = [t for t, m in heard if m.get_type() == "HIGHRES_IMU"]
            assert len(times) > 10, [m.get_type() for _, m in heard][:20]
            rate = (len(times) - 1) / (times[-1] - times[0])
            assert 35.0 <= rate <= 60.0, rate  # 50 Hz, not the IMU's 250 Hz
            stamps = [m.time_usec for m in imu]
            assert stamps == sorted(stamps) and len(set(stamps)) >= 0.9 * len(stamps)  # fresh samples, sim time
            zacc = sum(m.zacc for m in imu) / len(imu)
            assert zacc == pytest.approx(-G, abs=0.15), zacc  # FRD, at rest on the ground
            assert all(abs(m.xacc) < 0.3 and abs(m.yacc) < 0.3 and abs(m.xgyro) < 0.05 for m in imu)
            assert all(m.abs_pressure == pytest.approx(tm.isa_pressure_hpa(488.0), abs=0.5) for m in imu)
            assert 4 <= len(gps) <= 12, len(gps)  # 5 Hz for 1.5 s
            for m in gps:
                assert m.fix_type == M.GPS_FIX_TYPE_3D_FIX and (m.eph, m.epv) == (100, 200)
                assert abs(m.lat - 473977420) < 900 and abs(m.lon - 85455940) < 1300  # within ~10 m of home
                assert abs(m.alt - 488_000) < 20_000  # mm AMSL, sigma 2 m
            assert _command(gcs, M.MAV_CMD_REQUEST_MESSAGE, GPS) == M.MAV_RESULT_ACCEPTED

            assert _command(gcs, M.MAV_CMD_SET_MESSAGE_INTERVAL, HIGHRES, 200_000) == M.MAV_RESULT_ACCEPTED
            slow = len(_of(_listen(gcs, 1.0), "HIGHRES_IMU"))
            assert 3 <= slow <= 8, slow  # 5 Hz now
            assert _command(gcs, M.MAV_CMD_SET_MESSAGE_INTERVAL, GPS, -1) == M.MAV_RESULT_ACCEPTED
            assert not _of(_listen(gcs, 0.5), "GPS_RAW_INT")  # off
        finally:
            assert v.stop() == 0
            gcs.close()
    counts = _tlog_counts(tmp_path / "vehicle.tlog")
    assert counts.get("HIGHRES_IMU", 0) >= len(imu) + slow and counts.get("GPS_RAW_INT", 0) >= len(gps)
    assert counts.get("COMMAND_LONG", 0) >= 3  # and what the ground station sent: both directions


@pytest.mark.parametrize("estimator", ["truth", "raw"])
def test_the_ground_station_sees_what_the_vehicle_knows(tmp_path, estimator):
    """LOCAL_POSITION_NED and ATTITUDE carry the vehicle's estimate, as PX4's EKF2 publishes them: at rest on the
    ground under truth the position is home exactly; with the GNSS read raw, it wanders with the metre-class
    fixes (it was the true state whatever the estimator)."""
    flags = [] if estimator == "truth" else ["--sensors", "gnss", "--estimator", estimator]
    with instance_slot() as n:
        gcs = _gcs(n)
        v = Proc.bsst("vehicle", "--instance", str(n), "--out", str(tmp_path), "--realtime", *flags)
        try:
            v.wait_report(Ready)
            assert gcs.wait_heartbeat(timeout=20) is not None
            if estimator != "truth":
                assert gcs.recv_match(type="GPS_RAW_INT", blocking=True, timeout=5,
                                      condition="GPS_RAW_INT.fix_type==3")
            local = _of(_listen(gcs, 1.5), "LOCAL_POSITION_NED")
        finally:
            assert v.stop() == 0
            gcs.close()
    assert len(local) >= 10, len(local)
    spread = max(math.hypot(m.x, m.y) for m in local)
    assert spread == 0.0 if estimator == "truth" else spread > 0.05, [(m.x, m.y) for m in local][:10]


def test_truth_vehicle_has_no_sensor_messages(tmp_path):
    """Under truth there are no sensors: no stream; REQUEST_MESSAGE DENIED and SET_MESSAGE_INTERVAL FAILED, as PX4's
    receiver answers a message it cannot send and a stream it cannot make (they were UNSUPPORTED)."""
    with instance_slot() as n:
        gcs = _gcs(n)
        v = Proc.bsst("vehicle", "--instance", str(n), "--out", str(tmp_path))
        try:
            v.wait_report(Ready)
            assert gcs.wait_heartbeat(timeout=20) is not None
            for mid in (HIGHRES, GPS):
                assert _command(gcs, M.MAV_CMD_REQUEST_MESSAGE, mid) == M.MAV_RESULT_DENIED
                assert _command(gcs, M.MAV_CMD_SET_MESSAGE_INTERVAL, mid, 20_000) == M.MAV_RESULT_FAILED
            heard = _listen(gcs, 0.6)
            assert len(_of(heard, "ATTITUDE")) >= 5  # the other streams flow meanwhile
            assert not _of(heard, "HIGHRES_IMU") and not _of(heard, "GPS_RAW_INT")
        finally:
            assert v.stop() == 0
            gcs.close()
    counts = _tlog_counts(tmp_path / "vehicle.tlog")
    assert "HIGHRES_IMU" not in counts and "GPS_RAW_INT" not in counts and counts.get("ATTITUDE", 0) > 0


def test_odometry_covariance_is_the_dense_frame_change():
    """ODOMETRY's covariances (bridge.nodes.vehicle.odometry_covariance, plain floats) against the frame
    change written densely in numpy: pose S P S with S = diag(1, -1, -1, 1, -1, -1) over (x, y, z, φ, θ, ψ);
    twist T C Tᵀ, T = blockdiag(R, diag(1, -1, -1)), R's column j the NWU axis j in the FRD body; both
    as their 21-entry upper triangles. And NaN stays where it was."""
    rng = np.random.default_rng(3)
    for _ in range(50):
        A, B = rng.normal(size=(9, 9)), rng.normal(size=(3, 3))
        cov = Covariance(tuple((A @ A.T).ravel()), tuple((B @ B.T).ravel()))
        q = euler_to_quaternion(*rng.uniform(-1.0, 1.0, 3))
        pose, twist = odometry_covariance(q, cov)
        P = np.array(cov.pose()).reshape(6, 6)
        S = np.diag([1.0, -1.0, -1.0, 1.0, -1.0, -1.0])
        T = np.zeros((6, 6))
        for j, e in enumerate(((1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, -1.0))):
            T[0:3, j] = rotate_inverse(q, e)
        T[3:6, 3:6] = np.diag([1.0, -1.0, -1.0])
        C = T @ np.array(cov.twist()).reshape(6, 6) @ T.T
        assert np.allclose(pose, upper_triangle((S @ P @ S).ravel().tolist()), rtol=1e-12, atol=1e-12)
        assert np.allclose(twist, upper_triangle(C.ravel().tolist()), rtol=1e-12, atol=1e-12)
    unknown = Covariance((math.nan,) + (0.0,) * 80, (math.nan,) + (0.0,) * 8)
    pose, twist = odometry_covariance((1.0, 0.0, 0.0, 0.0), unknown)
    assert math.isnan(pose[0]) and math.isnan(twist[15]) and not any(math.isnan(v) for v in pose[1:])

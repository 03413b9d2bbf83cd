"""Covers bridge.mavlink.telemetry, bridge.nodes.vehicle.streams and plant.sensors: a GPS that stops, as telemetry.

What a ground station is told of the vehicle's GNSS receiver, as PX4 v1.14 tells it: GPS_RAW_INT carries each fix
while they come; once none has arrived for 1 s of simulation time (a ``gps off``: the fixes are dropped) it says
NO_GPS (fix type 0, figures unknown, satellites 255), as PX4's stream does once its ``sensor_gps`` stops, and
SYS_STATUS's GPS bit stays present and enabled but not healthy: MAVSDK's ``health.is_global_position_ok`` and
``is_local_position_ok`` read it; a motion-capture vehicle has no GPS bit. Before the first fix arrives (a lockstep
vehicle's clock stands still until its first flight), the fix its receiver took at t = 0 is shown, and the bit is
healthy: GPS_RAW_INT, SYS_STATUS and ``is_armable`` agree. Built from the real stream registry through MAVLink 2
bytes, then against a real ``bsst vehicle`` (x500, gnss, EKF) with MAVSDK's Failure plugin over UDP on 127.0.0.1.
"""

from __future__ import annotations

import pytest
from pymavlink.dialects.v20 import common as M

from bridge.mavlink import telemetry as tm
from bridge.nodes.vehicle.streams import VehicleView, message
from bridge.session import instance_slot
from plant import load_profile
from plant.sensors import GNSS, SensorSuite
from tests.test_ground_stations import _mavsdk
from tests.test_vehicle import _vehicle

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast

HZ = 1000.0  # physics rate of the suites below
REST = (0.0,) * 12
HOME = tm.Home()
GPS_BIT = M.MAV_SYS_STATUS_SENSOR_GPS


def _suite(name: str = "gnss") -> SensorSuite:
    return SensorSuite(load_profile("x500").sensor_set(name), 0, HZ, 9.81)


def _run(suite: SensorSuite, t0: float, t1: float) -> None:
    """Sample the suite at rest at every physics step from t0 to before t1 (s)."""
    for k in range(round(t0 * HZ), round(t1 * HZ)):
        suite.sample(k / HZ, REST)


def _sent(mid: int, suite: SensorSuite | None, t: float, position_valid: bool = True) -> list:
    """Message ``mid`` of a vehicle at rest with ``suite`` at simulation time ``t``, through MAVLink 2 bytes."""
    view = VehicleView(REST, t, "hold", None, False, False, True, (0.0,) * 4, 1000.0, 0, suite, HOME, 1,
                       position_valid=position_valid)
    mav = M.MAVLink(None, srcSystem=1, srcComponent=1)
    return [mav.parse_char(m.pack(mav)) for m in message(mid, view)]


def _gps_bits(suite: SensorSuite | None, t: float, position_valid: bool = True) -> tuple[bool, bool, bool, bool]:
    """SYS_STATUS's GPS bit (present, enabled, healthy) and its pre-arm bit (healthy)."""
    (s,) = _sent(M.MAVLINK_MSG_ID_SYS_STATUS, suite, t, position_valid)
    return (bool(s.onboard_control_sensors_present & GPS_BIT), bool(s.onboard_control_sensors_enabled & GPS_BIT),
            bool(s.onboard_control_sensors_health & GPS_BIT),
            bool(s.onboard_control_sensors_health & M.MAV_SYS_STATUS_PREARM_CHECK))


def test_before_its_first_fix_arrives_the_vehicle_shows_the_one_its_receiver_took():
    """At t = 0 (a lockstep vehicle idle before its first flight) the first fix is still in its 120 ms latency:
    GPS_RAW_INT shows it (a 3-D fix stamped 0), and SYS_STATUS calls the GPS healthy; a suite that has taken no
    fix at all says NO_FIX, and its bit is not healthy."""
    suite = _suite()
    _run(suite, 0.0, 0.001)
    assert suite.latest(GNSS) is None and suite.first_fix is not None
    (gps,) = _sent(M.MAVLINK_MSG_ID_GPS_RAW_INT, suite, 0.0)
    want = tm.gps_raw_int(suite.first_fix, HOME)
    assert (gps.fix_type, gps.satellites_visible, gps.time_usec) == (M.GPS_FIX_TYPE_3D_FIX, tm.SATELLITES_VISIBLE, 0)
    assert (gps.lat, gps.lon, gps.alt) == (want.lat, want.lon, want.alt)
    assert _gps_bits(suite, 0.0) == (True, True, True, True)
    _run(suite, 0.001, 0.2)
    assert suite.latest(GNSS) is suite.first_fix  # the same fix, arrived
    untouched = _suite()
    (none,) = _sent(M.MAVLINK_MSG_ID_GPS_RAW_INT, untouched, 0.0)
    assert none.fix_type == M.GPS_FIX_TYPE_NO_FIX and _gps_bits(untouched, 0.0) == (True, True, False, True)


def test_a_gps_off_is_no_gps_a_second_after_its_last_fix_and_its_health_bit_clears():
    """Fixes dropped from t = 2 s (``gps off``, as SimVehicle.inject sets it): the last one (taken at 1.8 s) is
    shown until 1 s after it arrived, then NO_GPS as PX4's stream sends it, the GPS bit present, enabled and not
    healthy, the rest (the pre-arm bit, the gyro) healthy; on again, the next fix is shown, 120 ms late."""
    suite = _suite()
    _run(suite, 0.0, 2.0)
    suite.faults.gps_on = False
    _run(suite, 2.0, 4.0)
    last = suite.latest(GNSS)
    assert last.t_valid == pytest.approx(1.8) and last.t_arrival == pytest.approx(1.92)
    (held,) = _sent(M.MAVLINK_MSG_ID_GPS_RAW_INT, suite, last.t_arrival + 0.99)
    assert held.fix_type == M.GPS_FIX_TYPE_3D_FIX and held.time_usec == round(last.t_valid * 1e6)
    assert _gps_bits(suite, last.t_arrival + 0.99) == (True, True, True, True)
    assert not tm.gps_lost(suite, last.t_arrival + 0.99) and tm.gps_lost(suite, last.t_arrival + 1.01)
    (lost,) = _sent(M.MAVLINK_MSG_ID_GPS_RAW_INT, suite, last.t_arrival + 1.01)
    assert (lost.fix_type, lost.satellites_visible, lost.lat, lost.lon, lost.alt, lost.time_usec) == (
        M.GPS_FIX_TYPE_NO_GPS, 255, 0, 0, 0, 0)
    assert lost.eph == lost.epv == lost.vel == lost.cog == tm.UINT16_UNKNOWN
    assert _gps_bits(suite, 3.9) == (True, True, False, True)
    (status,) = _sent(M.MAVLINK_MSG_ID_SYS_STATUS, suite, 3.9)
    assert status.onboard_control_sensors_health & M.MAV_SYS_STATUS_SENSOR_3D_GYRO
    suite.faults.gps_on = True
    _run(suite, 4.0, 4.2)
    (back,) = _sent(M.MAVLINK_MSG_ID_GPS_RAW_INT, suite, 4.2)
    assert back.fix_type == M.GPS_FIX_TYPE_3D_FIX and back.time_usec == 4_000_000
    assert _gps_bits(suite, 4.2) == (True, True, True, True)


def test_a_fix_back_is_no_healthy_gps_until_the_estimate_has_a_position_again():
    """A fix shown (GPS_RAW_INT) while the estimate's horizontal position is still invalid (a GPS back after
    EKF2_NOAID_TOUT, before EKF2 fuses it): the GPS bit is not healthy, as PX4 sets it only while EKF2 fuses a
    GNSS. It was, so MAVSDK read global and local position ok while the commander refused LAND for want of one
    (tests/test_gps_telemetry.py's MAVSDK flight, under load)."""
    suite = _suite()
    _run(suite, 0.0, 0.2)
    (fix,) = _sent(M.MAVLINK_MSG_ID_GPS_RAW_INT, suite, 0.2, position_valid=False)
    assert fix.fix_type == M.GPS_FIX_TYPE_3D_FIX
    assert _gps_bits(suite, 0.2, position_valid=False) == (True, True, False, True)
    assert _gps_bits(suite, 0.2) == (True, True, True, True)


def test_motion_capture_is_no_gps_and_truth_keeps_its_gps_bit():
    """A pose sensor (motion capture) is no GPS: no GPS_RAW_INT, and SYS_STATUS's GPS bit neither present, enabled
    nor healthy (PX4 sets it only while EKF2 fuses a GNSS), the rest as ever; under truth (no sensors) the bit stays
    present and healthy, as before."""
    mocap = _suite("mocap")
    _run(mocap, 0.0, 3.0)
    for suite, bits in ((None, (True, True, True, True)), (mocap, (False, False, False, True))):
        assert not tm.gps_lost(suite, 3.0) and _sent(M.MAVLINK_MSG_ID_GPS_RAW_INT, suite, 3.0) == []
        assert _gps_bits(suite, 3.0) == bits
    (status,), (truth,) = (_sent(M.MAVLINK_MSG_ID_SYS_STATUS, suite, 3.0) for suite in (mocap, None))
    for field in ("present", "enabled", "health"):  # the rest as under truth
        name = f"onboard_control_sensors_{field}"
        assert getattr(status, name) == getattr(truth, name) & ~GPS_BIT, field


# -- a real vehicle and MAVSDK's Failure plugin -----------------------------------------------------------------
# a MAVSDK script's GPS failure through the Failure plugin: SUCCESS or why not (tests/test_gps_failsafe.py too)
INJECT_GPS = """
def inject(ftype):
    try:
        failure.inject(FailureUnit.SENSOR_GPS, ftype, 0)
        return "SUCCESS"
    except FailureError as e:
        return e.result.name
"""
MAVSDK_GPS_LOSS = r"""
import json, sys, threading
from mavsdk import Mavsdk, Configuration, ComponentType
from mavsdk.plugins.action import Action
from mavsdk.plugins.failure import Failure, FailureError, FailureType, FailureUnit
from mavsdk.plugins.telemetry import Telemetry

sdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
sdk.add_any_connection(sys.argv[1])
system = sdk.first_autopilot(30.0)
out = {"found": system is not None}
tel, act, failure = Telemetry(system), Action(system), Failure(system)
cond = threading.Condition()
seen = {"health": None, "gps": None, "rel": None, "armed": None, "mode": None}
def put(key, value):
    with cond:
        seen[key] = value
        cond.notify_all()
tel.subscribe_health(lambda h, ud=None: put("health", [h.is_global_position_ok, h.is_local_position_ok,
                                                       h.is_home_position_ok, h.is_armable]))
tel.subscribe_gps_info(lambda g, ud=None: put("gps", [g.fix_type.name, g.num_satellites]))
tel.subscribe_position(lambda p, ud=None: put("rel", p.relative_altitude_m))
tel.subscribe_armed(lambda a, ud=None: put("armed", a))
tel.subscribe_flight_mode(lambda m, ud=None: put("mode", m.name))
def until(what, pred, timeout):
    with cond:
        out[what] = cond.wait_for(pred, timeout)
        out[what + "_saw"] = {k: seen[k] for k in ("health", "gps")}
""" + INJECT_GPS + r"""fixed = lambda: seen["gps"] == ["FIX_3D", 10]
# before the first arm (the lockstep vehicle's clock stands still): fixed, healthy and armable, all at once
until("ready", lambda: fixed() and seen["health"] == [True, True, True, True], 20)
out["arm"] = act.arm().name
out["set_takeoff_altitude"] = act.set_takeoff_altitude(8.0).name
out["takeoff"] = act.takeoff().name
until("at_height", lambda: seen["mode"] == "HOLD" and seen["rel"] is not None and seen["rel"] > 7.9, 30)
out["off"] = inject(FailureType.OFF)
until("lost", lambda: seen["gps"] == ["NO_GPS", 255] and seen["health"][:3] == [False, False, True], 10)
out["on"] = inject(FailureType.OK)
until("back", lambda: fixed() and seen["health"][:3] == [True, True, True], 10)
out["land"] = act.land().name
until("disarmed", lambda: seen["armed"] is False, 30)
print("RESULT " + json.dumps(out), flush=True)
sdk.destroy()
"""


# 4x as FAST, but the failsafe's descent from 8 m at 0.7 m/s (11 s of flight, ~3 s of wall) outlasts the script's
# turn from "lost" to land(): from 3 m at 1.5 m/s (~0.5 s of wall) a loaded machine saw it land and disarm first, and
# its land() was then rightly DENIED (a disarmed vehicle is not armed in LAND)
SLOW_DESCENT = ("--speed", "4", "--param", "MPC_LAND_SPEED=0.7")


def test_mavsdk_sees_a_gps_off_and_on_on_a_gnss_ekf_x500(tmp_path):
    """A lockstep ``bsst vehicle --profile x500 --sensors gnss --estimator ekf`` at 4x, SYS_FAILURE_EN = 1: before
    the first arm MAVSDK sees a 3-D fix with 10 satellites, global and local position ok and armable; taken off
    to 8 m and holding, ``Failure.inject(SENSOR_GPS, OFF, 0)``: its GPS info turns NO_GPS with 255 satellites and
    its global and local position health false (home stays ok); OK again: a 3-D fix and both ok; it lands. The
    vehicle's events name MAVSDK's injections."""
    with instance_slot() as n:
        v = _vehicle(n, tmp_path, "missions/sine.toml", "--profile", "x500", "--sensors", "gnss", "--estimator",
                     "ekf", "--param", "SYS_FAILURE_EN=1", *SLOW_DESCENT)
        try:
            got = _mavsdk(n, "gps", MAVSDK_GPS_LOSS)
        finally:
            assert v.stop() == 0
    steps = ("found", "ready", "at_height", "lost", "back", "disarmed")
    assert {k: got[k] for k in steps} == dict.fromkeys(steps, True), got
    assert (got["arm"], got["takeoff"], got["off"], got["on"], got["land"]) == ("SUCCESS",) * 5, got
    faults = [e for e in v.events() if e.startswith("fault: ")]
    assert [f.split(" [by ")[0] for f in faults] == ["fault: gps off", "fault: gps on"], faults
    assert all(f.endswith(" gcs]") for f in faults), faults

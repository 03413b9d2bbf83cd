"""What the vehicle tells a ground station (docs/design.md, "The MAVLink contract"), built from the paper state.

In:  the paper state (eq. 7, NWU: m, m/s, rad, rad/s), simulation time (``time_boot_ms`` ms,
     ``time_usec`` us), rotor speeds and omega_max (rad/s), the home (deg, deg, m AMSL: the paper frame's
     origin), the vehicle's local origin (x, y m in the paper frame: the ground under its start), the
     vehicle's sysid and status (load, health, on the ground, descending)
Out: pymavlink messages in NED / FRD (listed below): angles rad, rates rad/s, position m, velocity
     m/s; ``GLOBAL_POSITION_INT`` in degE7, mm, cm/s and cdeg; rotor outputs as fractions of omega_max

Pure functions from the plant's state (eq. 7, NWU) to pymavlink messages in MAVLink's
frames (NED / FRD, via :mod:`bridge.core.wire`): ``ATTITUDE``, ``ATTITUDE_QUATERNION``,
``LOCAL_POSITION_NED`` (about the vehicle's own local origin, as PX4's EKF2: docs/ground-station.md, "Which frame
each position is in"), ``GLOBAL_POSITION_INT`` (PX4's reprojection about a configurable home: absolute),
``HOME_POSITION`` (the local origin's latitude and longitude), ``MISSION_CURRENT``, ``SYS_STATUS``,
``EXTENDED_SYS_STATE``, ``ACTUATOR_OUTPUT_STATUS``, ``AUTOPILOT_VERSION``. ``time_boot_ms`` is the vehicle's
simulation time, as PX4 stamps it in lockstep.

From the vehicle's sensors (:class:`plant.sensors.SensorSuite`, paper frame, SI), not the true state:
``HIGHRES_IMU`` (FRD specific force m/s^2 and rates rad/s, barometric pressure hPa and pressure
altitude m) and, with a GNSS position sensor, ``GPS_RAW_INT`` (degE7, mm AMSL, cm/s, cdeg; NO_GPS once its
fixes stop: :func:`gps_lost`, which SYS_STATUS's GPS bit says too); the streams they go out on and their
intervals: :func:`sensor_streams`. From the estimator's health (bridge.autopilot.positionloss.EstimateHealth):
``ESTIMATOR_STATUS`` (its solution flags, accuracies m).
"""

from __future__ import annotations

import math
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from bridge.autopilot.positionloss import EstimateHealth
from bridge.core.wire import paper_to_ned
from missions.geodetic import Home  # where the local NED origin is on earth (re-exported: the vehicle's home)
from plant.sensors import BARO, GNSS, IMU, Measurement, SensorConfig, SensorSuite

# the sensors a ground station expects to see healthy before it shows a vehicle as ready
_SENSORS = (mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO | mavlink.MAV_SYS_STATUS_SENSOR_3D_ACCEL
            | mavlink.MAV_SYS_STATUS_SENSOR_3D_MAG | mavlink.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
            | mavlink.MAV_SYS_STATUS_SENSOR_GPS | mavlink.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
            | mavlink.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION)
# AUTOPILOT_VERSION's capabilities: PX4's (mavlink_main.cpp, ``send_autopilot_capabilities``) that this vehicle
# serves: the mission protocol in both forms (MAVSDK uploads nothing to an autopilot without MISSION_INT), fence and
# rally points, MAVLink FTP (read-only: bridge.mavlink.ftp), DO_FLIGHTTERMINATION; not PX4's offboard set-points
# (SET_ATTITUDE_TARGET, SET_POSITION_TARGET_LOCAL_NED, bit 256): the controller sends actuator targets only
CAPABILITIES = (mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2 | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
                | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
                | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT
                | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_RALLY
                | mavlink.MAV_PROTOCOL_CAPABILITY_FTP | mavlink.MAV_PROTOCOL_CAPABILITY_FLIGHT_TERMINATION)
VERSION = (0 << 24) | (1 << 16) | (0 << 8) | 255  # 0.1.0, FIRMWARE_VERSION_TYPE_OFFICIAL


def finite(X: tuple[float, ...]) -> bool:
    """Whether the state can be sent (a diverged plant has NaN or inf in it). Called for
    every ODOMETRY: the sum is finite when every value is (one call for all); only if it is
    not (NaN, inf, or an overflow of finite values) are the values looked at one by one."""
    return math.isfinite(sum(X)) or all(map(math.isfinite, X))


def attitude(X: tuple[float, ...], ms: int) -> list[Any]:
    """``ATTITUDE`` (Euler, FRD rates) and ``ATTITUDE_QUATERNION`` for state X."""
    n = paper_to_ned(X)
    roll, pitch, yaw = n["euler"]
    p, q, r = n["rates"]
    w, x, y, z = n["q"]
    return [mavlink.MAVLink_attitude_message(ms, roll, pitch, yaw, p, q, r),
            mavlink.MAVLink_attitude_quaternion_message(ms, w, x, y, z, p, q, r)]


def local_position(X: tuple[float, ...], ms: int, origin: tuple[float, float] = (0.0, 0.0)) -> Any:
    """``LOCAL_POSITION_NED``: position (m) and velocity (m/s) in NED about the vehicle's local origin, ``origin``
    (x, y m in the paper frame: the ground under its start, where PX4's EKF2 sets its origin at boot)."""
    n = paper_to_ned(X)
    north, east, down = n["pos"]
    if origin != (0.0, 0.0):  # (at the world's origin the values as they are: -0.0 stays -0.0 on the wire)
        north, east = north - origin[0], east + origin[1]  # NED's east is the paper frame's -y
    return mavlink.MAVLink_local_position_ned_message(ms, north, east, down, *n["vel"])


def global_position(X: tuple[float, ...], ms: int, home: Home) -> Any:
    """``GLOBAL_POSITION_INT``: degE7, mm AMSL and above home, cm/s NED, heading cdeg."""
    n = paper_to_ned(X)
    north, east, down = n["pos"]
    vn, ve, vd = n["vel"]
    lat, lon, alt = home.global_of(north, east, down)
    hdg = int(round(math.degrees(n["euler"][2]) * 100.0)) % 36000
    return mavlink.MAVLink_global_position_int_message(
        ms, int(round(lat * 1e7)), int(round(lon * 1e7)), int(round(alt * 1000.0)), int(round(-down * 1000.0)),
        _cm(vn), _cm(ve), _cm(vd), hdg)


def vfr_hud(X: tuple[float, ...], home: Home, thrust_fraction: float) -> Any:
    """``VFR_HUD`` as PX4 fills it for a multicopter: airspeed 0 (no airspeed sensor), ground speed (m/s, the
    horizontal speed), heading (deg, 0..359), throttle (%: the rotors' thrust as a fraction of their full thrust;
    0 disarmed), altitude AMSL (m) and climb rate (m/s, up)."""
    n = paper_to_ned(X)
    vn, ve, vd = n["vel"]
    alt = home.amsl(-n["pos"][2])
    heading = int(round(math.degrees(n["euler"][2]))) % 360
    throttle = max(0, min(100, int(round(100.0 * thrust_fraction))))
    return mavlink.MAVLink_vfr_hud_message(0.0, math.hypot(vn, ve), heading, throttle, alt, -vd)


def altitude(X: tuple[float, ...], home: Home, usec: int) -> Any:
    """``ALTITUDE`` as PX4 fills it: monotonic and AMSL the altitude above the sea (m; PX4's monotonic is its
    barometer's, here the state's as every stream's), local and relative the height above the home (m, up: the
    local origin is the home); terrain and bottom clearance unknown (NaN: no distance sensor)."""
    up = X[4]
    return mavlink.MAVLink_altitude_message(usec, home.amsl(up), home.amsl(up), up, up, math.nan, math.nan)


def home_position(home: Home, origin: tuple[float, float] = (0.0, 0.0)) -> Any:
    """``HOME_POSITION``: the vehicle's local origin ``origin`` (x, y m in the paper frame about ``home``, on the
    ground: :func:`local_position`'s), level, facing north: its latitude and longitude, ``home``'s altitude, and
    x = y = z = 0 (PX4's home is where the vehicle armed on the ground, its local position there about 0)."""
    lat, lon = (home.lat, home.lon) if origin == (0.0, 0.0) else home.global_of(origin[0], -origin[1], 0.0)[:2]
    return mavlink.MAVLink_home_position_message(
        int(round(lat * 1e7)), int(round(lon * 1e7)), int(round(home.alt * 1000.0)),
        0.0, 0.0, 0.0, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0)


NO_MISSION_TOTAL = 0xFFFF  # MISSION_CURRENT.total of a vehicle without a mission (common.xml: UINT16_MAX)
# MISSION_CURRENT.mission_mode (common.xml): 0 unknown, 1 in a mode that flies mission items, 2 suspended (another)
MISSION_MODE_UNKNOWN, MISSION_MODE_IN_MISSION, MISSION_MODE_SUSPENDED = 0, 1, 2


def mission_current(seq: int, total: int, state: int, mode: int = MISSION_MODE_UNKNOWN) -> list[Any]:
    """``MISSION_CURRENT`` as PX4 sends it (mavlink_mission.cpp ``send_mission_current``): the current item of a
    mission of ``total`` items, its MISSION_STATE (NO_MISSION without one: the mission manager's) and ``mode``
    (mission_mode: :data:`MISSION_MODE_IN_MISSION` in a mode that flies mission items, :data:`MISSION_MODE_SUSPENDED`
    in another); without a mission (``total`` 0) total UINT16_MAX, as common.xml asks and PX4 sends, not silence."""
    return [mavlink.MAVLink_mission_current_message(seq, total or NO_MISSION_TOTAL, state, mode)]


def sys_status(load_permille: int, healthy: bool, battery: tuple[int, int, int] = (16800, -1, 100),
               armable: bool = True, gps: bool | None = True) -> Any:
    """``SYS_STATUS``: simulated sensors present and healthy; ``battery``: voltage mV, current cA (-1: not
    measured) and remaining % (a full 4S battery unless the plant flies one); the pre-arm check's bit healthy
    when ``armable`` (PX4's: MAVSDK's ``health.is_armable`` reads it); the GPS's bit present and enabled, healthy
    only while ``gps`` (its fixes arrive: :func:`gps_lost`; MAVSDK's ``health.is_global_position_ok`` and
    ``is_local_position_ok`` read it), and with ``gps`` None (a vehicle without a GPS: motion capture) not
    present at all, as PX4 sets it only while EKF2 fuses a GNSS (estimatorCheck.cpp)."""
    # the geofence bit is set healthy although there is no fence: MAVProxy reads a clear
    # health bit as "fence breach" even on a vehicle that has none
    prearm = mavlink.MAV_SYS_STATUS_PREARM_CHECK
    sensors = _SENSORS if gps is not None else _SENSORS & ~mavlink.MAV_SYS_STATUS_SENSOR_GPS
    lost = 0 if gps else mavlink.MAV_SYS_STATUS_SENSOR_GPS
    health = ((sensors & ~lost) | mavlink.MAV_SYS_STATUS_GEOFENCE | (prearm if armable else 0)) if healthy else 0
    return mavlink.MAVLink_sys_status_message(sensors | prearm, sensors | prearm, health,
                                              max(0, min(1000, load_permille)), *battery, 0, 0, 0, 0, 0, 0)


def estimator_status(usec: int, health: EstimateHealth) -> Any:
    """``ESTIMATOR_STATUS`` as PX4 v1.15's stream fills it from EKF2's solution flags (ekf_helper.cpp,
    ``get_ekf_soln_status``): attitude, vertical velocity and absolute vertical position good (a barometer or a
    pose always aids the height); horizontal velocity and relative and absolute horizontal position good while
    the horizontal position is valid (EKF2_NOAID_TOUT: bridge.autopilot.positionloss); the predicted horizontal
    position (relative; absolute: by GNSS) while a horizontal reading is fused (aiding now); no terrain, constant
    position mode, GPS glitch or accelerometer error. ``pos_horiz_accuracy`` / ``pos_vert_accuracy``: the
    estimate's 1-sigma (m); the innovation test ratios are not computed here (NaN)."""
    m = mavlink
    flags = m.ESTIMATOR_ATTITUDE | m.ESTIMATOR_VELOCITY_VERT | m.ESTIMATOR_POS_VERT_ABS
    if health.valid:
        flags |= m.ESTIMATOR_VELOCITY_HORIZ | m.ESTIMATOR_POS_HORIZ_REL | m.ESTIMATOR_POS_HORIZ_ABS
    if health.aiding:
        flags |= m.ESTIMATOR_PRED_POS_HORIZ_REL | (m.ESTIMATOR_PRED_POS_HORIZ_ABS if health.gnss else 0)
    nan = math.nan
    return m.MAVLink_estimator_status_message(usec, flags, nan, nan, nan, nan, nan, nan, health.eph_m, health.epv_m)


def extended_sys_state(landed_state: int) -> Any:
    """``EXTENDED_SYS_STATE``: the landed state (MAV_LANDED_STATE: on the ground, taking off, in the air, landing)."""
    return mavlink.MAVLink_extended_sys_state_message(mavlink.MAV_VTOL_STATE_UNDEFINED, landed_state)


def actuator_outputs(usec: int, omega: tuple[float, ...], omega_max: float) -> Any:
    """``ACTUATOR_OUTPUT_STATUS``: rotor speeds as fractions of omega_max, rotors 1..4."""
    return mavlink.MAVLink_actuator_output_status_message(
        usec, 0b1111, [w / omega_max for w in omega] + [0.0] * 28)


STATUSTEXT_CHUNK = 50  # characters of one STATUSTEXT's text
# bytes of one text at most (ten chunks, about 700 bytes on the wire: a reply stays one small datagram). The longest
# the vehicle says is a start refused for an item it does not fly, with the commands it does: 239 characters
STATUSTEXT_MAX = 500
CUT = b"..."  # the end of a text longer than STATUSTEXT_MAX, in its place: the reader sees it was cut


def statustext(severity: int, text: str, text_id: int) -> list[Any]:
    """STATUSTEXT(s) saying ``text`` (at most :data:`STATUSTEXT_MAX` bytes of UTF-8; a longer one is cut there and
    ends in :data:`CUT`): one message if it fits in 50, else MAVLink 2's chunks (the same ``id`` = ``text_id``,
    1..65535, and ``chunk_seq`` 0, 1, ...; a last chunk shorter than 50, empty if need be, ends it), which MAVSDK
    and QGroundControl join again; a ground station that does not shows each chunk as a line."""
    data = text.encode("utf-8", errors="replace")
    if len(data) > STATUSTEXT_MAX:
        data = data[:STATUSTEXT_MAX - len(CUT)] + CUT
    if len(data) <= STATUSTEXT_CHUNK:
        return [mavlink.MAVLink_statustext_message(severity, data)]
    chunks = [data[i:i + STATUSTEXT_CHUNK] for i in range(0, len(data), STATUSTEXT_CHUNK)]
    if len(chunks[-1]) == STATUSTEXT_CHUNK:
        chunks.append(b"")
    return [mavlink.MAVLink_statustext_message(severity, c, text_id, i) for i, c in enumerate(chunks)]


STATUSTEXT_WAIT_S = 1.0  # s a chunked text waits for its missing chunks before it is shown as it stands
STATUSTEXT_OPEN = 16  # chunked texts pending at once, at most (anyone may send chunks that never end)
MISSING_CHUNK = "[...]"  # in place of a chunk that never came


def statustext_bytes(m: Any) -> bytes:
    """The text of a received STATUSTEXT as its bytes on the wire (NULs at the end dropped): pymavlink
    decodes each chunk alone, which breaks a UTF-8 character split between two chunks."""
    buf = m.get_msgbuf()
    if len(buf) > 10 and buf[0] == 0xFD:  # MAVLink 2: the payload after the 10-byte header, zeros truncated
        return bytes(buf[11:10 + buf[1]])[:STATUSTEXT_CHUNK].rstrip(b"\x00")
    text = m.text
    return (text.encode("utf-8", errors="replace") if isinstance(text, str) else bytes(text)).rstrip(b"\x00")


class StatusTextJoiner:
    """MAVLink 2's chunked STATUSTEXTs joined again (the inverse of :func:`statustext`): a text whose
    ``id`` is 0 is whole; chunks of one (sender, ``id``) are kept by ``chunk_seq`` until one shorter than
    50 bytes ends the text. A text still missing chunks after :data:`STATUSTEXT_WAIT_S` (or pushed out by
    :data:`STATUSTEXT_OPEN` newer ones) is shown as it stands, each missing chunk :data:`MISSING_CHUNK`."""

    def __init__(self) -> None:
        self._open: dict[tuple[int, int, int], tuple[float, int, dict[int, bytes]]] = {}  # first seen, severity

    def add(self, m: Any, now: float) -> list[tuple[int, str]]:
        """The texts (severity, text) that ``m`` (a STATUSTEXT received at wall time ``now``, s) completes."""
        data = statustext_bytes(m)
        text_id = getattr(m, "id", 0) or 0
        if not text_id:
            return [(m.severity, data.decode("utf-8", errors="replace"))]
        key = (m.get_srcSystem(), m.get_srcComponent(), text_id)
        first, severity, chunks = self._open.setdefault(key, (now, m.severity, {}))
        chunks[getattr(m, "chunk_seq", 0) or 0] = data
        out: list[tuple[int, str]] = []
        if len(data) < STATUSTEXT_CHUNK:  # its last chunk
            out.append(self._close(key))
        while len(self._open) > STATUSTEXT_OPEN:
            out.append(self._close(min(self._open, key=lambda k: self._open[k][0])))
        return out

    def expired(self, now: float) -> list[tuple[int, str]]:
        """The texts whose chunks stopped coming more than :data:`STATUSTEXT_WAIT_S` ago, as they stand."""
        old = [k for k, (first, _, _) in self._open.items() if now - first > STATUSTEXT_WAIT_S]
        return [self._close(k) for k in old]

    def _close(self, key: tuple[int, int, int]) -> tuple[int, str]:
        _, severity, chunks = self._open.pop(key)
        parts: list[str] = []
        run = b""
        for i in range(max(chunks) + 1):
            if i in chunks:
                run += chunks[i]
                continue
            parts += [run.decode("utf-8", errors="replace"), MISSING_CHUNK]
            run = b""
        parts.append(run.decode("utf-8", errors="replace"))
        return severity, "".join(parts)


def autopilot_version(sysid: int) -> Any:
    """``AUTOPILOT_VERSION``: capabilities (MAVLink 2, COMMAND_INT) and a uid from the sysid."""
    return mavlink.MAVLink_autopilot_version_message(
        CAPABILITIES, VERSION, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, 0x6273_7374_0000 + sysid)


def _cm(v: float) -> int:
    return max(-32768, min(32767, int(round(v * 100.0))))


# -- from the sensors ---------------------------------------------------------------------------
# PX4 streams HIGHRES_IMU at 50 Hz on its onboard and config links (mavlink_main.cpp); the GCS streams
# go out on the wall clock, so a faster default would only resend the newest sample more often (in
# lockstep simulation time may run faster or slower than the wall) and load the ground station: a GCS
# that wants more asks with SET_MESSAGE_INTERVAL (up to the vehicle's 200 Hz floor).
SENSOR_STREAM_MAX_HZ = 50.0
SATELLITES_VISIBLE = 10  # a plausible open-sky count: the GNSS model has no constellation
UINT16_UNKNOWN = 65535  # MAVLink's "unknown" for GPS_RAW_INT's eph, epv, vel, cog
UINT8_UNKNOWN = 255  # and for its satellites_visible
# s of simulation time without a new fix before the GPS counts as lost: PX4's GPS_RAW_INT stream then sends NO_GPS
# (GPS_RAW_INT.hpp, kNoGpsSendInterval), and EKF2 calls its GNSS intermittent (2 x GNSS_MAX_INTERVAL)
GPS_LOST_S = 1.0
_IMU_FIELDS = (mavlink.HIGHRES_IMU_UPDATED_XACC | mavlink.HIGHRES_IMU_UPDATED_YACC | mavlink.HIGHRES_IMU_UPDATED_ZACC
               | mavlink.HIGHRES_IMU_UPDATED_XGYRO | mavlink.HIGHRES_IMU_UPDATED_YGYRO
               | mavlink.HIGHRES_IMU_UPDATED_ZGYRO)
_BARO_FIELDS = mavlink.HIGHRES_IMU_UPDATED_ABS_PRESSURE | mavlink.HIGHRES_IMU_UPDATED_PRESSURE_ALT
SENSOR_MESSAGES = (mavlink.MAVLINK_MSG_ID_HIGHRES_IMU, mavlink.MAVLINK_MSG_ID_GPS_RAW_INT)


def sensor_streams(config: SensorConfig | None) -> dict[int, float]:
    """The sensor streams of a vehicle (message id -> default interval, s): none under truth (``None``,
    no sensors); ``HIGHRES_IMU`` at the IMU's rate and, for a ``gnss`` position sensor, ``GPS_RAW_INT``
    at its fix rate, each at most :data:`SENSOR_STREAM_MAX_HZ`."""
    if config is None:
        return {}
    streams = {mavlink.MAVLINK_MSG_ID_HIGHRES_IMU: 1.0 / min(config.imu_rate_hz, SENSOR_STREAM_MAX_HZ)}
    if config.position_class == "gnss":
        streams[mavlink.MAVLINK_MSG_ID_GPS_RAW_INT] = 1.0 / min(config.position_rate_hz, SENSOR_STREAM_MAX_HZ)
    return streams


def sensor_message(mid: int, sensors: SensorSuite | None, home: Home, usec: int) -> list[Any]:
    """``HIGHRES_IMU`` or ``GPS_RAW_INT`` (``mid``) from the newest samples of ``sensors`` ([] under truth,
    for a GPS_RAW_INT without a GNSS sensor, or once a sample is not finite: a diverged plant); a GPS_RAW_INT of
    a GPS lost (no new fix for :data:`GPS_LOST_S`) says NO_GPS, as PX4's. ``usec``: simulation time now (us), the
    stamp of a message no sample dates yet."""
    if sensors is None:
        return []
    if mid == mavlink.MAVLINK_MSG_ID_HIGHRES_IMU:
        imu, baro = sensors.latest(IMU), sensors.latest(BARO)
        if not all(m is None or finite(m.values) for m in (imu, baro)):
            return []
        return [highres_imu(imu, baro, home, usec)]
    if mid == mavlink.MAVLINK_MSG_ID_GPS_RAW_INT and sensors.config.position_class == "gnss":
        fix = gnss_fix(sensors)
        if fix is None:
            return [gps_no_fix(usec)]
        if usec * 1e-6 - fix.t_arrival > GPS_LOST_S:
            return [gps_no_gps()]
        return [gps_raw_int(fix, home)] if finite(fix.values) else []
    return []


def gnss_fix(sensors: SensorSuite) -> Measurement | None:
    """The GNSS fix a ground station is shown: the newest that has arrived, or, before the first arrives, the first
    the receiver took (:attr:`~plant.sensors.SensorSuite.first_fix`: at rest at its start, the vehicle has had a fix
    since before its clock began; a lockstep vehicle's clock stands still until its first flight); None: none."""
    fix = sensors.latest(GNSS)
    return fix if fix is not None else sensors.first_fix


def has_gps(sensors: SensorSuite | None) -> bool:
    """Whether SYS_STATUS has a GPS bit: a GNSS receiver, or no sensors at all (truth: the true state, the GPS
    bit present and healthy as ever); a pose sensor (motion capture) is no GPS."""
    return sensors is None or sensors.config.position_class == "gnss"


def gps_lost(sensors: SensorSuite | None, t: float) -> bool:
    """Whether the vehicle's GPS is lost at simulation time ``t`` (s): a GNSS set whose newest fix
    (:func:`gnss_fix`) arrived more than :data:`GPS_LOST_S` ago (its fixes stopped: a ``gps off``), or that has
    none; never for a vehicle without a GNSS receiver (truth, or a pose sensor)."""
    if sensors is None or sensors.config.position_class != "gnss":
        return False
    fix = gnss_fix(sensors)
    return fix is None or t - fix.t_arrival > GPS_LOST_S


def isa_pressure_hpa(alt_m: float) -> float:
    """Static pressure (hPa) at ``alt_m`` m above mean sea level in the ISA troposphere:
    1013.25 (1 - 2.25577e-5 h)^5.25588 (15 degC and 1013.25 hPa at sea level, 6.5 K/km lapse)."""
    return 1013.25 * (1.0 - 2.25577e-5 * alt_m) ** 5.25588


def highres_imu(imu: Measurement | None, baro: Measurement | None, home: Home, usec: int) -> Any:
    """``HIGHRES_IMU`` of the newest IMU and barometer samples: xacc..zacc the mean specific force (m/s^2,
    FRD: at rest about (0, 0, -9.81)), xgyro..zgyro the body rate (rad/s, FRD), ``abs_pressure`` (hPa) the
    ISA pressure at the barometer's altitude, ``pressure_alt`` (m AMSL) that altitude (home.alt + z).
    ``fields_updated`` has the bits of what is present (accelerometer and gyro once the IMU has sampled,
    pressure once the barometer has); no magnetometer (the heading sensor gives no field vector),
    differential pressure or temperature. ``time_usec``: the IMU sample's simulation time (us; the end
    of its interval), else the barometer's, else ``usec``."""
    fields = 0
    acc = gyro = (0.0, 0.0, 0.0)
    pressure = alt = 0.0
    stamp = usec
    if baro is not None:
        fields |= _BARO_FIELDS
        alt = home.amsl(baro.values[0])
        pressure = isa_pressure_hpa(alt)
        stamp = _usec(baro.t_valid)
    if imu is not None:
        fields |= _IMU_FIELDS
        fx, fy, fz, p, q, r = imu.values
        acc, gyro = _frd((fx, fy, fz)), _frd((p, q, r))
        stamp = _usec(imu.t_valid)
    return mavlink.MAVLink_highres_imu_message(stamp, *acc, *gyro, 0.0, 0.0, 0.0, pressure, 0.0, alt, 0.0, fields)


def gps_raw_int(fix: Measurement, home: Home) -> Any:
    """``GPS_RAW_INT`` of a GNSS fix (x, y, z m and their rates m/s, paper frame): a 3-D fix at
    lat/lon (degE7) and alt (mm AMSL) from ``home`` (:meth:`Home.global_of`), ground speed ``vel``
    (cm/s) and course over ground ``cog`` (cdeg, 0..35999) of the measured velocity. ``eph``/``epv``:
    the sensor's horizontal / vertical σ in cm (as PX4's SITL GPS plugin fills them; MAVLink calls
    them HDOP / VDOP x 100), and the same σ in ``h_acc``/``v_acc`` (mm), the horizontal velocity σ in
    ``vel_acc`` (mm/s). ``time_usec``: the fix's simulation time (us; when it was valid, before
    its latency)."""
    x, y, z, vx, vy, vz = fix.values
    n = paper_to_ned((x, vx, y, vy, z, vz, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
    north, east, down = n["pos"]
    vn, ve, _vd = n["vel"]
    lat, lon, alt = home.global_of(north, east, down)
    sh, sz, svh = fix.sigma[0], fix.sigma[2], fix.sigma[3]
    cog = int(round(math.degrees(math.atan2(ve, vn)) * 100.0)) % 36000
    return mavlink.MAVLink_gps_raw_int_message(
        _usec(fix.t_valid), mavlink.GPS_FIX_TYPE_3D_FIX, int(round(lat * 1e7)), int(round(lon * 1e7)),
        int(round(alt * 1000.0)), _u16(sh * 100.0), _u16(sz * 100.0), _u16(math.hypot(vn, ve) * 100.0), cog,
        SATELLITES_VISIBLE, 0, _u32(sh * 1000.0), _u32(sz * 1000.0), _u32(svh * 1000.0))


def gps_no_fix(usec: int) -> Any:
    """``GPS_RAW_INT`` of a receiver that has taken no fix yet: no fix, every figure unknown."""
    return mavlink.MAVLink_gps_raw_int_message(usec, mavlink.GPS_FIX_TYPE_NO_FIX, 0, 0, 0, UINT16_UNKNOWN,
                                               UINT16_UNKNOWN, UINT16_UNKNOWN, UINT16_UNKNOWN, 0)


def gps_no_gps() -> Any:
    """``GPS_RAW_INT`` once the fixes have stopped for :data:`GPS_LOST_S`, as PX4's stream sends it then
    (GPS_RAW_INT.hpp): fix type NO_GPS, position 0, eph, epv, vel and cog unknown, satellites 255, time 0."""
    return mavlink.MAVLink_gps_raw_int_message(0, mavlink.GPS_FIX_TYPE_NO_GPS, 0, 0, 0, UINT16_UNKNOWN,
                                               UINT16_UNKNOWN, UINT16_UNKNOWN, UINT16_UNKNOWN, UINT8_UNKNOWN)


def _frd(v: tuple[float, float, float]) -> tuple[float, float, float]:
    # body FLU -> FRD: the half turn about x that bridge.core.wire applies to every body vector
    # (its roll = phi, pitch = -theta, yaw = -psi; rates q, r negated)
    return (v[0], -v[1], -v[2])


def _usec(t: float) -> int:
    return int(round(t * 1e6))


def _u16(v: float) -> int:
    return max(0, min(UINT16_UNKNOWN - 1, int(round(v))))


def _u32(v: float) -> int:
    return max(0, min(0xFFFFFFFF, int(round(v))))

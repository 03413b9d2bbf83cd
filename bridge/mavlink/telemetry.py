"""What the vehicle tells a ground station (docs/design.md, "The MAVLink contract"), built from the paper state.

In:  the paper state (eq. 7, NWU: m, m/s, rad, rad/s), simulation time (``time_boot_ms`` ms,
     ``time_usec`` us), rotor speeds and omega_max (rad/s), the home (deg, deg, m AMSL), the
     vehicle's sysid and status (load, health, on the ground, descending)
Out: pymavlink messages in NED / FRD (listed below): angles rad, rates rad/s, position m, velocity
     m/s; ``GLOBAL_POSITION_INT`` in degE7, mm, cm/s and cdeg; rotor outputs as fractions of omega_max

Pure functions from the plant's state (eq. 7, NWU) to pymavlink messages in MAVLink's
frames (NED / FRD, via :mod:`bridge.core.wire`): ``ATTITUDE``, ``ATTITUDE_QUATERNION``,
``LOCAL_POSITION_NED``, ``GLOBAL_POSITION_INT`` (flat earth around a configurable home),
``HOME_POSITION``, ``SYS_STATUS``, ``EXTENDED_SYS_STATE``, ``ACTUATOR_OUTPUT_STATUS``,
``AUTOPILOT_VERSION``. ``time_boot_ms`` is the vehicle's simulation time, as PX4 stamps it
in lockstep.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from bridge.core.wire import paper_to_ned

EARTH_RADIUS_M = 6_378_137.0  # WGS-84 equatorial radius: flat-earth offsets around home
# the sensors a ground station expects to see healthy before it shows a vehicle as ready
_SENSORS = (mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO | mavlink.MAV_SYS_STATUS_SENSOR_3D_ACCEL
            | mavlink.MAV_SYS_STATUS_SENSOR_3D_MAG | mavlink.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
            | mavlink.MAV_SYS_STATUS_SENSOR_GPS | mavlink.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
            | mavlink.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION)
CAPABILITIES = (mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2 | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
                | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT)
VERSION = (0 << 24) | (1 << 16) | (0 << 8) | 255  # 0.1.0, FIRMWARE_VERSION_TYPE_OFFICIAL


@dataclass(frozen=True)
class Home:
    """Where the local NED origin is on earth: degrees, degrees, metres above mean sea level."""

    lat: float = 47.397742  # PX4 SITL's default home (Zurich)
    lon: float = 8.545594
    alt: float = 488.0

    def to_global(self, north: float, east: float, down: float) -> tuple[float, float, float]:
        """NED offset (m) -> latitude, longitude (deg), altitude AMSL (m), flat earth."""
        lat = self.lat + math.degrees(north / EARTH_RADIUS_M)
        lon = self.lon + math.degrees(east / (EARTH_RADIUS_M * math.cos(math.radians(self.lat))))
        return lat, lon, self.alt - down


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


def local_position(X: tuple[float, ...], ms: int) -> Any:
    """``LOCAL_POSITION_NED``: position (m) and velocity (m/s) in NED."""
    n = paper_to_ned(X)
    return mavlink.MAVLink_local_position_ned_message(ms, *n["pos"], *n["vel"])


def global_position(X: tuple[float, ...], ms: int, home: Home) -> Any:
    """``GLOBAL_POSITION_INT``: degE7, mm AMSL and above home, cm/s NED, heading cdeg."""
    n = paper_to_ned(X)
    north, east, down = n["pos"]
    vn, ve, vd = n["vel"]
    lat, lon, alt = home.to_global(north, east, down)
    hdg = int(round(math.degrees(n["euler"][2]) * 100.0)) % 36000
    return mavlink.MAVLink_global_position_int_message(
        ms, int(round(lat * 1e7)), int(round(lon * 1e7)), int(round(alt * 1000.0)), int(round(-down * 1000.0)),
        _cm(vn), _cm(ve), _cm(vd), hdg)


def home_position(home: Home) -> Any:
    """``HOME_POSITION``: the local origin, level, facing north."""
    return mavlink.MAVLink_home_position_message(
        int(round(home.lat * 1e7)), int(round(home.lon * 1e7)), int(round(home.alt * 1000.0)),
        0.0, 0.0, 0.0, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0)


def sys_status(load_permille: int, healthy: bool) -> Any:
    """``SYS_STATUS``: simulated sensors present and healthy, a full 4S battery."""
    # the geofence bit is set healthy although there is no fence: MAVProxy reads a clear
    # health bit as "fence breach" even on a vehicle that has none
    health = (_SENSORS | mavlink.MAV_SYS_STATUS_GEOFENCE) if healthy else 0
    return mavlink.MAVLink_sys_status_message(_SENSORS, _SENSORS, health, max(0, min(1000, load_permille)),
                                              16800, -1, 100, 0, 0, 0, 0, 0, 0)


def extended_sys_state(on_ground: bool, descending: bool) -> Any:
    """``EXTENDED_SYS_STATE``: landed state (on ground, landing, in air)."""
    state = (mavlink.MAV_LANDED_STATE_ON_GROUND if on_ground
             else mavlink.MAV_LANDED_STATE_LANDING if descending else mavlink.MAV_LANDED_STATE_IN_AIR)
    return mavlink.MAVLink_extended_sys_state_message(mavlink.MAV_VTOL_STATE_UNDEFINED, state)


def actuator_outputs(usec: int, omega: tuple[float, ...], omega_max: float) -> Any:
    """``ACTUATOR_OUTPUT_STATUS``: rotor speeds as fractions of omega_max, rotors 1..4."""
    return mavlink.MAVLink_actuator_output_status_message(
        usec, 0b1111, [w / omega_max for w in omega] + [0.0] * 28)


def autopilot_version(sysid: int) -> Any:
    """``AUTOPILOT_VERSION``: capabilities (MAVLink 2, COMMAND_INT) and a uid from the sysid."""
    return mavlink.MAVLink_autopilot_version_message(
        CAPABILITIES, VERSION, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, 0x6273_7374_0000 + sysid)


def _cm(v: float) -> int:
    return max(-32768, min(32767, int(round(v * 100.0))))

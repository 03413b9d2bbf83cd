"""The vehicle's telemetry: a registry of streams (message id -> builder and default rate), one link's
stream table, HEARTBEAT, STATUSTEXT ids, and ODOMETRY's covariances.

In:  a :class:`VehicleView` (the vehicle as its messages read it: paper-frame state eq. 7, m, m/s, rad,
     rad/s; simulation time s; rotor speeds rad/s; load per mille; the plant's battery V, A, mAh), a message
     id, SET_MESSAGE_INTERVAL's checked interval (us), wall times (s)
Out: MAVLink messages (pymavlink): the GCS streams (``time_boot_ms`` = simulation time), HEARTBEAT
     (PX4's ``custom_mode``), STATUSTEXT; ODOMETRY to the controller (NED position m, FRD body velocity m/s,
     quaternion FRD to NED, FRD rates rad/s, ``time_usec`` = k / rate_hz; covariances in NED/FRD)

Each stream is one entry of :data:`STREAMS`, as PX4 has one class per stream: a builder and the
default interval on the GCS link (docs/design.md, "The MAVLink contract": 25 Hz and 10 Hz; 0: only on
request; None: never streamed, sent on request, or, for the sensor messages, at the sensors' own rates).
"""

from __future__ import annotations

import math
import struct
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from bridge.autopilot.estimator import Covariance
from bridge.autopilot.failsafe import Land, Level, ReturnHome, Takeoff
from bridge.autopilot.modes import TERMINATION
from bridge.autopilot.positionloss import EstimateHealth, estimate_health
from bridge.autopilot.simvehicle import FAILSAFE, LANDED, TAKEOFF, SimVehicle
from bridge.core.wire import odometry_fields, rotate_inverse, step_usec
from bridge.mavlink import compmeta
from bridge.mavlink import telemetry as tm
from bridge.mavlink.endpoint import ODOMETRY, Endpoint
from bridge.mavlink.modes import heartbeat_mode
from bridge.mavlink.receive import StepSends
from plant.battery import Battery
from plant.sensors import SensorSuite

MIN_INTERVAL_S = 0.005  # the shortest stream interval (200 Hz)
HEARTBEAT_S = 1.0
VFR_HUD_S = 0.25  # PX4's default rate of VFR_HUD on a normal link (mavlink_main.cpp: 4 Hz)
ALTITUDE_S = 1.0  # PX4's default rate of ALTITUDE on a normal link (1 Hz)
HOME_POSITION_S = 2.0  # and of HOME_POSITION (0.5 Hz)
BATTERY_STATUS_S = 2.0  # PX4's default rate of BATTERY_STATUS on a normal link (mavlink_main.cpp: 0.5 Hz)
ESTIMATOR_STATUS_S = 2.0  # and of ESTIMATOR_STATUS (0.5 Hz)


@dataclass(frozen=True)
class VehicleView:
    """The vehicle as its telemetry reads it, at one moment."""

    X: tuple[float, ...]  # the state the vehicle knows (paper frame, eq. 7): its estimate, as PX4's EKF2 publishes
    t: float  # simulation time of the current step (s)
    mode: str  # the flight mode (bridge.autopilot.simvehicle)
    target: Any  # the on-board controller's target (None: not flying one)
    armed: bool
    halted: bool  # diverged
    on_ground: bool
    omega: tuple[float, ...]  # rotor speeds (rad/s)
    omega_max: float  # rad/s
    load: int  # CPU load, per mille
    sensors: SensorSuite | None  # None: truth
    home: tm.Home
    sysid: int
    mission: tuple[int, int, int, int] = (0, 0, 1, 0)  # current item, items, MISSION_STATE, mission_mode
    battery: Battery | None = None  # the plant's flight battery ([effects] battery), None: it flies none
    battery_level: int = 0  # its level by the vehicle's BAT_*_THR: 0 none, 1 low, 2 critical, 3 emergency
    # why PX4's pre-arm checks deny an arm now, or None (SimVehicle.prearm_refusal): asked only by SYS_STATUS, which
    # alone needs it (with a fence and an estimator it costs tens of microseconds, and a view is built per message)
    prearm_refusal: Callable[[], str | None] = lambda: None
    position_valid: bool = True  # the estimate's horizontal position, as EKF2 says (positionloss): positions sent
    health: Callable[[], EstimateHealth | None] = lambda: None  # ESTIMATOR_STATUS's (None under truth: no estimator)
    # the local origin (x, y m, paper frame): the ground under the start on the GCS link, as PX4's EKF2 sets it where
    # the vehicle boots; (0, 0), the paper frame's own, on the controller link (its ODOMETRY's frame)
    origin: tuple[float, float] = (0.0, 0.0)


def battery_fields(b: Battery) -> tuple[int, int, int]:
    """SYS_STATUS's battery fields of the plant's battery: terminal voltage mV, current cA, remaining %."""
    return int(round(b.measured_v * 1000.0)), int(round(b.current * 100.0)), int(round(100.0 * b.remaining))


def battery_status(v: VehicleView) -> list[Any]:
    """BATTERY_STATUS of the plant's battery ([] without one): the pack voltage in cell 0 (the cells are not
    modelled one by one: MAVLink's convention), current, charge drawn, remaining, and the charge state by the
    vehicle's levels (BAT_LOW_THR, BAT_CRIT_THR, BAT_EMERGEN_THR: PX4's 15 %, 7 %, 5 % by default)."""
    b = v.battery
    if b is None:
        return []
    mv, ca, remaining = battery_fields(b)
    state = _CHARGE_STATES[v.battery_level]
    return [mavlink.MAVLink_battery_status_message(
        0, mavlink.MAV_BATTERY_FUNCTION_ALL, mavlink.MAV_BATTERY_TYPE_LIPO, _INT16_MAX, [mv] + [_UINT16_MAX] * 9, ca,
        int(round(b.used_mah)), -1, remaining, 0, state)]


def landed_state(v: VehicleView) -> int:
    """EXTENDED_SYS_STATE's landed state, as PX4 tells it: on the ground; off it, taking off or landing while the
    vehicle's own controller flies a takeoff or a landing (TAKEOFF; LAND, the failsafe's land or descend, Return's
    last phase), else in the air (offboard control, HOLD, Return on its way). Disarmed it is on the ground wherever it
    is, as PX4's multicopter land detector says ("When not armed, consider to be landed",
    ``MulticopterLandDetector::_get_landed_state``): a forced disarm in the air, the ``disarm`` failsafe's fall, a
    flight its plant ended; but for a terminated flight, which PX4 keeps armed, its outputs forced off, as it falls."""
    if v.on_ground or not v.armed and v.mode != TERMINATION:
        return mavlink.MAV_LANDED_STATE_ON_GROUND
    if isinstance(v.target, Takeoff) and v.mode == TAKEOFF:  # (once at its height it holds there: HOLD)
        return mavlink.MAV_LANDED_STATE_TAKEOFF
    if isinstance(v.target, (Land, Level)) or (isinstance(v.target, ReturnHome) and v.target.phase(v.X) == "land"):
        return mavlink.MAV_LANDED_STATE_LANDING
    return mavlink.MAV_LANDED_STATE_IN_AIR


def _sys_status(v: VehicleView) -> list[Any]:
    healthy = not v.halted  # (a flight over is healthy in nothing, the pre-arm bit included)
    armable = healthy and v.prearm_refusal() is None
    # healthy while the estimate fuses a GNSS, as PX4's estimatorCheck.cpp: the receiver has fixes (GPS_RAW_INT) and
    # the horizontal position is valid (a fix back after EKF2_NOAID_TOUT is not yet a position: the commander refused
    # LAND while MAVSDK read the bit healthy); motion capture: no GPS bit
    gps = not tm.gps_lost(v.sensors, v.t) and v.position_valid if tm.has_gps(v.sensors) else None
    if v.battery is None:
        return [tm.sys_status(v.load, healthy, armable=armable, gps=gps)]
    return [tm.sys_status(v.load, healthy, battery_fields(v.battery), armable, gps)]


_INT16_MAX, _UINT16_MAX = 2**15 - 1, 2**16 - 1  # MAVLink's "unknown" temperature and cell voltage
_CHARGE_STATES = (mavlink.MAV_BATTERY_CHARGE_STATE_OK, mavlink.MAV_BATTERY_CHARGE_STATE_LOW,  # by level
                  mavlink.MAV_BATTERY_CHARGE_STATE_CRITICAL, mavlink.MAV_BATTERY_CHARGE_STATE_EMERGENCY)


def heartbeat(v: VehicleView) -> Any:
    """HEARTBEAT: PX4's encoding of the mode (bridge.mavlink.modes), so that ground stations name it."""
    base, custom = heartbeat_mode(v.mode, v.target, v.armed)
    if v.mode == TERMINATION:  # a ground station terminated the flight: PX4's state for it, whatever came after
        state = mavlink.MAV_STATE_FLIGHT_TERMINATION
    elif v.halted:  # crashed, diverged or touched by another vehicle: its flight is over, its plant stepped no more
        state = mavlink.MAV_STATE_EMERGENCY
    elif v.armed:  # flying its failsafe: CRITICAL (PX4's ``vehicle_status.failsafe``)
        state = mavlink.MAV_STATE_CRITICAL if v.mode in (FAILSAFE, LANDED) else mavlink.MAV_STATE_ACTIVE
    else:  # disarmed: STANDBY, as PX4 (streams/HEARTBEAT.hpp), whose failsafe is cleared on disarm
        state = mavlink.MAV_STATE_STANDBY
    return mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4, base,
                                             custom, state, 3)


def _estimator_status(v: VehicleView) -> list[Any]:
    """ESTIMATOR_STATUS of the vehicle's estimator ([] under truth)."""
    health = v.health()
    return [] if health is None else [tm.estimator_status(round(v.t * 1e6), health)]


def _thrust(v: VehicleView) -> float:
    """The rotors' thrust as a fraction of their full thrust (thrust goes with ω²), 0 disarmed (VFR_HUD)."""
    return sum(w * w for w in v.omega) / (len(v.omega) * v.omega_max ** 2) if v.armed and v.omega else 0.0


def _ms(v: VehicleView) -> int:
    return int(v.t * 1000.0)


def _if_finite(build: Callable[[VehicleView], list[Any]]) -> Callable[[VehicleView], list[Any]]:
    """A builder of the state's messages: nothing while the state is not finite (a diverged plant)."""
    return lambda v: build(v) if tm.finite(v.X) else []


@dataclass(frozen=True)
class Stream:
    """One message: how it is built, and its default interval on the GCS link (s; 0: only on request;
    None: not a default stream)."""

    build: Callable[[VehicleView], list[Any]]
    interval_s: float | None


def _sensor(mid: int) -> Stream:
    # the sensors' newest samples, never the true state: [] under truth; their rates: tm.sensor_streams
    return Stream(lambda v: tm.sensor_message(mid, v.sensors, v.home, int(v.t * 1e6)), None)


# message id -> stream; the order of the default streams is the order they are sent in when due together
STREAMS: dict[int, Stream] = {
    mavlink.MAVLINK_MSG_ID_ATTITUDE: Stream(_if_finite(lambda v: tm.attitude(v.X, _ms(v))[:1]), 0.04),
    mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: Stream(_if_finite(lambda v: tm.attitude(v.X, _ms(v))[1:]), 0.04),
    # none while the horizontal position is invalid, as PX4's LOCAL_POSITION_NED.hpp (only with xy_valid and
    # v_xy_valid) and GLOBAL_POSITION_INT (v1.14's EKF2 publishes no global position then)
    mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: Stream(
        _if_finite(lambda v: [tm.local_position(v.X, _ms(v), v.origin)] if v.position_valid else []), 0.04),
    mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: Stream(
        _if_finite(lambda v: [tm.global_position(v.X, _ms(v), v.home)] if v.position_valid else []), 0.1),
    mavlink.MAVLINK_MSG_ID_SYS_STATUS: Stream(_sys_status, 0.1),
    mavlink.MAVLINK_MSG_ID_BATTERY_STATUS: Stream(battery_status, None),  # a battery's: battery_streams
    mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: Stream(
        lambda v: [tm.extended_sys_state(landed_state(v))], 0.1),
    mavlink.MAVLINK_MSG_ID_ACTUATOR_OUTPUT_STATUS: Stream(
        lambda v: [tm.actuator_outputs(int(v.t * 1e6), v.omega, v.omega_max)], 0.1),
    mavlink.MAVLINK_MSG_ID_VFR_HUD: Stream(_if_finite(lambda v: [tm.vfr_hud(v.X, v.home, _thrust(v))]), VFR_HUD_S),
    mavlink.MAVLINK_MSG_ID_ALTITUDE: Stream(_if_finite(lambda v: [tm.altitude(v.X, v.home, int(v.t * 1e6))]),
                                            ALTITUDE_S),
    mavlink.MAVLINK_MSG_ID_HOME_POSITION: Stream(lambda v: [tm.home_position(v.home, v.origin)], HOME_POSITION_S),
    # PX4's mission manager sends it at 1 Hz (its _slow_rate_limiter), and at once on a change
    mavlink.MAVLINK_MSG_ID_MISSION_CURRENT: Stream(lambda v: tm.mission_current(*v.mission), 1.0),
    mavlink.MAVLINK_MSG_ID_HEARTBEAT: Stream(lambda v: [heartbeat(v)], None),  # its own 1 Hz clock
    mavlink.MAVLINK_MSG_ID_ESTIMATOR_STATUS: Stream(_estimator_status, None),  # an estimator's: estimator_streams
    mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION: Stream(lambda v: [tm.autopilot_version(v.sysid)], None),
    # where the component metadata is (its files over MAVLink FTP): on request only, as PX4's
    compmeta.COMPONENT_METADATA: Stream(lambda v: [compmeta.component_metadata(_ms(v))], None),
    compmeta.COMPONENT_INFORMATION: Stream(lambda v: [compmeta.component_information(_ms(v))], None),
    **{mid: _sensor(mid) for mid in tm.SENSOR_MESSAGES},
}
# default GCS streams (message id -> interval s)
DEFAULT_STREAMS = {mid: s.interval_s for mid, s in STREAMS.items() if s.interval_s is not None}


def health_of(sim: SimVehicle) -> EstimateHealth | None:
    """ESTIMATOR_STATUS's view of ``sim``'s estimate now (bridge.autopilot.positionloss; None under truth)."""
    if sim.sensors is None or sim.estimator is None:
        return None
    return estimate_health(sim.estimator, sim.position, sim.t, tm.has_gps(sim.sensors))


def estimator_streams(sensors: SensorSuite | None) -> dict[int, float]:
    """The GCS streams of an estimator (message id -> interval s): ESTIMATOR_STATUS at PX4's 0.5 Hz on a normal
    link (mavlink_main.cpp); none under truth (no sensors, no estimator)."""
    return {mavlink.MAVLINK_MSG_ID_ESTIMATOR_STATUS: ESTIMATOR_STATUS_S} if sensors is not None else {}


def battery_streams(battery: Battery | None) -> dict[int, float]:
    """The GCS streams of the plant's battery (message id -> interval s): BATTERY_STATUS at PX4's 0.5 Hz; none
    without a battery (SYS_STATUS then says a full 4S pack, as before)."""
    return {mavlink.MAVLINK_MSG_ID_BATTERY_STATUS: BATTERY_STATUS_S} if battery is not None else {}


def message(mid: int, view: VehicleView) -> list[Any]:
    """The message(s) with id ``mid`` for a stream or a REQUEST_MESSAGE ([] if none)."""
    stream = STREAMS.get(mid)
    return stream.build(view) if stream is not None else []


class StreamTable(dict[int, float]):
    """One link's streams: message id -> interval (s; 0: only on request), and when each
    stream is due next (``due``, wall time). ``defaults`` are what an interval of 0 asks for."""

    def __init__(self, defaults: dict[int, float], now: float) -> None:
        super().__init__(defaults)
        self.defaults = defaults
        self.due = {mid: now for mid, iv in defaults.items() if iv > 0}

    def set(self, mid: int, interval_us: float, now: float) -> float | None:
        """Apply a checked SET_MESSAGE_INTERVAL (:func:`bridge.mavlink.receive.interval_arg`: -1 off,
        0 the default, else us, at least :data:`MIN_INTERVAL_S`) to a stream of this table;
        the new interval (s, 0: off), or None when it is what it was."""
        iv = 0.0 if interval_us < 0 else self.defaults[mid] if interval_us == 0 else max(interval_us * 1e-6,
                                                                                          MIN_INTERVAL_S)
        if iv == self[mid]:
            return None
        self[mid] = iv
        if iv > 0:
            self.due[mid] = now
        else:
            self.due.pop(mid, None)
        return iv

    def send_due(self, now: float, send: Callable[[int], None]) -> None:
        """``send`` each stream that is due at wall time ``now`` (s), and schedule its next."""
        for mid, due in self.due.items():
            if now >= due:
                iv = self[mid]
                self.due[mid] = due + iv if now - due < iv else now + iv
                send(mid)


class StatusTexts:
    """STATUSTEXT(s) of a text, each text its own id (one counter for every part of the vehicle)."""

    def __init__(self) -> None:
        self.text_id = 0  # the id of the last chunked STATUSTEXT

    def __call__(self, severity: int, text: str) -> list[Any]:
        """Chunked when longer than 50 characters."""
        self.text_id = self.text_id % 65535 + 1
        return tm.statustext(severity, text, self.text_id)


# -- ODOMETRY, the controller link's stream ---------------------------------------------------------------
# after the body rates: covariances unknown (NaN first, MAVLink's convention),
# frame LOCAL_NED, child BODY_FRD, reset counter, estimator type, quality (100: exact)
_COV_UNKNOWN = (math.nan,) + (0.0,) * 20
ODOMETRY_TAIL = (*_COV_UNKNOWN, *_COV_UNKNOWN, mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_BODY_FRD, 0,
                 mavlink.MAV_ESTIMATOR_TYPE_NAIVE, 100)
# a truth state's ODOMETRY packed in two: time_usec and the 13 state values (the first of the wire order), then
# ODOMETRY_TAIL's bytes, packed once (61 values packed a step cost 1.2 us, these 14 and a join 0.4 us)
_ODOMETRY_HEAD = struct.Struct("<Q13f")
_ODOMETRY_TAIL_BYTES = ODOMETRY.struct.pack(0, *(0.0,) * 13, *ODOMETRY_TAIL)[_ODOMETRY_HEAD.size:]
if _ODOMETRY_HEAD.pack(1, *range(13)) + _ODOMETRY_TAIL_BYTES != ODOMETRY.struct.pack(1, *range(13), *ODOMETRY_TAIL):
    raise RuntimeError(f"ODOMETRY's wire order is not time_usec and 13 floats first: {ODOMETRY.struct.format}")
# an estimate's (raw, ekf): its covariances follow; the autopilot's own estimator (ekf) or the sensors as read (raw)
ESTIMATOR_TYPES = {"raw": mavlink.MAV_ESTIMATOR_TYPE_NAIVE, "ekf": mavlink.MAV_ESTIMATOR_TYPE_AUTOPILOT}
# the pose block's 21 upper-triangle entries: (index in Covariance.state's 9x9, sign) over (x, y, z, roll, pitch,
# yaw); NWU/FLU -> NED/FRD flips y, z, pitch (-theta) and yaw (-psi)
_POSE_AXES = (0, 1, 2, 6, 7, 8)
_POSE_SIGNS = (1.0, -1.0, -1.0, 1.0, -1.0, -1.0)
_POSE_UPPER = tuple((9 * _POSE_AXES[i] + _POSE_AXES[j], _POSE_SIGNS[i] * _POSE_SIGNS[j])
                    for i in range(6) for j in range(i, 6))
_NWU_AXES_NED = ((1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, -1.0))


def odometry_covariance(q: tuple[float, float, float, float], cov: Covariance) -> tuple[tuple[float, ...], ...]:
    """ODOMETRY's ``pose_covariance`` and ``velocity_covariance`` (21 each, the upper triangles) of an
    estimate's covariance, in the message's frames: pose over NED (x, y, z) and the Euler angles of
    :func:`~bridge.core.wire.state_to_odometry` (roll, pitch, yaw = φ, −θ, −ψ); twist over the FRD body
    velocity and FRD body rates (``q``: the estimate's attitude, FRD to NED): R V Rᵀ, R's column j the NWU
    axis j in the body, and the rates' covariance with q and r flipped; no cross terms (the twist has
    none). NaN stays NaN. Plain floats: it runs at every lockstep step (numpy's calls cost ~100 µs)."""
    s = cov.state
    pose = tuple(s[k] * sign for k, sign in _POSE_UPPER)
    c0, c1, c2 = (rotate_inverse(q, e) for e in _NWU_AXES_NED)  # R's columns
    V = (s[30:33], s[39:42], s[48:51])  # the velocity block, rows and columns 3..5 of the 9x9
    RV = [[c0[a] * V[0][j] + c1[a] * V[1][j] + c2[a] * V[2][j] for j in range(3)] for a in range(3)]
    M = [[RV[a][0] * c0[b] + RV[a][1] * c1[b] + RV[a][2] * c2[b] for b in range(3)] for a in range(3)]
    w = cov.rates
    twist = (M[0][0], M[0][1], M[0][2], 0.0, 0.0, 0.0, M[1][1], M[1][2], 0.0, 0.0, 0.0, M[2][2], 0.0, 0.0, 0.0,
             w[0], -w[1], -w[2], w[4], w[5], w[8])
    return pose, twist


def estimate_tail(q: tuple[float, float, float, float], cov: Covariance, estimator: str) -> tuple[Any, ...]:
    """ODOMETRY after the body rates for an estimate (``estimator``: raw or ekf): its covariances, frames,
    estimator type, quality 0 (unknown: MAVLink has no scale for it)."""
    pose, twist = odometry_covariance(q, cov)
    return (*pose, *twist, mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_BODY_FRD, 0,
            ESTIMATOR_TYPES[estimator], 0)


class OdometryOut:
    """ODOMETRY of step k to the controller link: the vehicle's published state (its estimate; the true
    state under truth), and the wall time each step's state was first sent (its round trip counts from it)."""

    def __init__(self, link: Endpoint, sim: SimVehicle, rate_hz: float, estimator: str,
                 fields: Callable[[tuple[float, ...]], tuple[float, ...]] = odometry_fields) -> None:
        self.link = link
        self.fields = fields  # a state's ODOMETRY fields: bridge.core.wire's, or its compiled twin (the same bits)
        self.sim = sim
        self.rate = rate_hz
        self.estimator = estimator  # truth, raw or ekf
        self.sent_at: dict[int, float] = {}  # step -> wall time its state was first sent
        self.count = 0  # ODOMETRY messages sent
        self.resends = 0  # states sent again (nobody answered them)
        self.sends = StepSends()  # every state sent: its step, resends, when (the summary's link.down.in_flight)

    def send(self, k: int, now: float, fresh: bool) -> bool:
        """Send the state of step k at wall time ``now`` (s); ``fresh``: not a resend. False when the
        state is not finite (a diverged plant: nothing to send)."""
        sim = self.sim
        X = sim.published()
        if not tm.finite(X):
            return False
        f = self.fields(X)  # state_to_odometry written out, flat (one call: the hot path; tests/test_wire.py)
        if sim.sensors is None:  # the truth: its 14 values packed, the unchanging rest's bytes after them
            payload = _ODOMETRY_HEAD.pack(step_usec(k, self.rate), *f) + _ODOMETRY_TAIL_BYTES
        else:
            assert sim.estimator is not None
            tail = estimate_tail((f[3], f[4], f[5], f[6]), sim.estimator.covariance(), self.estimator)
            payload = ODOMETRY.struct.pack(step_usec(k, self.rate), *f, *tail)
        before = time.monotonic()  # the send left between these two (a receiver that stopped reading: docs/sitl.md)
        if self.link.send_payload(ODOMETRY, payload):
            self.count += 1
            self.sends.add(k, before, time.monotonic())
        sent_at = self.sent_at
        if fresh or k not in sent_at:  # a resent state's round trip counts from its first sending
            sent_at[k] = now
        if len(sent_at) > 256:
            for old in [s for s in sent_at if s < k - 128]:
                del sent_at[old]
        if not fresh:
            self.resends += 1
        return True

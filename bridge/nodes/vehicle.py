"""The simulated vehicle as a MAVLink 2 endpoint: ``bsst vehicle`` (docs/design.md, "The MAVLink contract").

In:  actuator targets on the controller link, stamped with the ``time_usec`` of the state they answer:
     HIL_ACTUATOR_CONTROLS (``motors``: c1..c4 = omega / omega_max, each in [0, 1]) or
     SET_ACTUATOR_CONTROL_TARGET group 0 (``wrench``: roll, pitch, yaw in [-1, 1], thrust in [0, 1]),
     or the no-target acknowledgement; COMMAND_LONG / COMMAND_INT (among them DO_SET_MODE, NAV_TAKEOFF
     m AMSL, NAV_LAND), SET_MODE, PARAM_REQUEST_LIST / PARAM_REQUEST_READ / PARAM_SET, TIMESYNC, PING,
     HEARTBEAT on either link
Out: ODOMETRY (NED position m, FRD body velocity m/s, quaternion FRD to NED, FRD rates rad/s;
     ``time_usec`` = simulation time, us), once per control step; HEARTBEAT at 1 Hz (PX4's
     ``custom_mode``), STATUSTEXT on each event, the GCS streams (25 Hz / 10 Hz, ``time_boot_ms`` =
     simulation time; with sensors HIGHRES_IMU and GPS_RAW_INT), PARAM_VALUE; ``vehicle.tlog``,
     ``vehicle.csv`` rows; status lines on stdout

Its clocks and its end of the link model: docs/design.md, "Clocks" and "Link model". Its
parameters, flight modes (OFFBOARD, HOLD, LAND, TAKEOFF, in PX4's encoding: :mod:`bridge.mavlink.modes`)
and what a ground station can do with them: docs/ground-station.md. Who may
do what on which link: docs/design.md, "Authority" (:meth:`Vehicle._authority`); every
command's numbers are checked before use (:mod:`bridge.mavlink.receive`), and every command
that changes the flight is an event naming its sender (:class:`Sender`).

It wraps :class:`bridge.autopilot.simvehicle.SimVehicle` (plant, arming, command timeout, failsafe:
the same object the offline loop flies) with two UDP links:

- the **controller link** (``--listen``, default ``udpin:127.0.0.1:14560``): ODOMETRY out
  at every control step, actuator targets in (HIL_ACTUATOR_CONTROLS for a ``motors``
  profile, SET_ACTUATOR_CONTROL_TARGET group 0 for a ``wrench`` profile), accepted only
  from the configured controller (sysid/compid) and only while armed in offboard control
  (in a lockstep flight the up-link model delivers them, and refuses them then);
- the **GCS link** (``--gcs``, default ``udpout:127.0.0.1:14550``): HEARTBEAT, ATTITUDE,
  LOCAL_POSITION_NED, GLOBAL_POSITION_INT, SYS_STATUS, ACTUATOR_OUTPUT_STATUS, ... on the
  wall clock, and STATUSTEXT on events; commands are answered on the socket they came in on.

Clocks:

- **lockstep** (default): the state of step k (time_usec = round(k / rate_hz * 1e6)) is sent
  and the vehicle advances one control period only when it holds the controller's answer
  stamped with that time_usec: an actuator target, or the **no-target acknowledgement**
  (HIL_ACTUATOR_CONTROLS with SAFETY_ARMED clear in ``mode``, for either actuation: the
  controller has no valid target this step, the step clock ticks on and the vehicle's
  timeout runs). The mission's ``[link]`` model acts here, in simulation time, on what
  crossed the socket (:class:`bridge.link.ends.VehicleEnd`, the offline loop's end): the
  target of step k enters the ``up`` model at t_k and acts at the physics step it is
  delivered in; so does an ARM_DISARM(arm) from the controller while its flight is on
  (a re-arm after a failsafe). The step clock keeps ticking while the vehicle, landed by
  its failsafe, is disarmed, for as long as the controller answers. ``speed`` caps the pace
  at that many times real time. Heartbeats and telemetry keep flowing on the wall clock
  meanwhile. A controller silent for ``lost_after_s`` of wall time is lost: the vehicle
  leaves lockstep, runs on at real-time pace (``speed`` if given) and its timeout and
  failsafe take over; it returns to lockstep when armed again.
- **realtime**: physics steps against the wall clock at the physics rate; a target is
  applied at the physics step it arrives in and held; ODOMETRY goes out at the control rate.

With ``out``, it writes ``vehicle.tlog`` (both directions) and ``vehicle.csv`` (its half of
the trace: one row per control step flown, columns :data:`VEHICLE_COLUMNS`).
Status lines (``ready ...``, ``event t=... kind: text``) go to ``status``; the session
launcher reads them.
"""

from __future__ import annotations

import json
import math
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from bridge.autopilot.estimator import Covariance
from bridge.autopilot.params import BY_NAME, PARAMS, ParamRefused, VehicleParams, read_param
from bridge.autopilot.simvehicle import FAILSAFE, GROUND_MODES, HOLD, LAND, LANDED, OFFBOARD, TAKEOFF
from bridge.core.clock import Pace
from bridge.core.flight import Flight
from bridge.core.wire import (
    command_from_wire,
    command_to_wire,
    rotate_inverse,
    state_to_odometry,
    step_of_usec,
    step_usec,
)
from bridge.link.ends import VehicleEnd
from bridge.mavlink import telemetry as tm
from bridge.mavlink.endpoint import (
    CONTROLLER_COMPID,
    CONTROLLER_SYSID,
    ODOMETRY,
    VEHICLE_COMPID,
    Address,
    Endpoint,
    Tlog,
    wait,
)
from bridge.mavlink.modes import (
    PARAM_TYPES,
    ftp_nak,
    heartbeat_mode,
    mode_name,
    param_from_wire,
    param_name,
    param_to_wire,
    requested_custom_mode,
    requested_mode,
)
from bridge.mavlink.receive import (
    FORCE_DISARM,
    Rejections,
    addressed_elsewhere,
    arm_disarm_args,
    interval_arg,
    message_id_arg,
    wire_problem,
)
from bridge.mavlink.signing import Signing
from bridge.nodes.process import on_stop_signals, status_printer
from bridge.record.columns import VEHICLE_COLUMNS, state_columns
from bridge.record.runlog import LineWriter, side_dir

CLOCKS = ("lockstep", "realtime")
MODE_CODES = {OFFBOARD: 0, FAILSAFE: 1, LANDED: 2, HOLD: 3, LAND: 4, TAKEOFF: 5}  # vehicle.csv's ``mode``
NAN4 = (math.nan,) * 4
# ODOMETRY after the body rates: covariances unknown (NaN first, MAVLink's convention),
# frame LOCAL_NED, child BODY_FRD, reset counter, estimator type, quality (100: exact)
_COV_UNKNOWN = (math.nan,) + (0.0,) * 20
ODOMETRY_TAIL = (*_COV_UNKNOWN, *_COV_UNKNOWN, mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_BODY_FRD, 0,
                 mavlink.MAV_ESTIMATOR_TYPE_NAIVE, 100)
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


# default GCS streams (message id -> interval s): docs/design.md, "The MAVLink contract" gives 25 Hz and 10 Hz
DEFAULT_STREAMS = {
    mavlink.MAVLINK_MSG_ID_ATTITUDE: 0.04,
    mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: 0.04,
    mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 0.04,
    mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 0.1,
    mavlink.MAVLINK_MSG_ID_SYS_STATUS: 0.1,
    mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 0.1,
    mavlink.MAVLINK_MSG_ID_ACTUATOR_OUTPUT_STATUS: 0.1,
    mavlink.MAVLINK_MSG_ID_HOME_POSITION: 0.0,  # 0: only on request
}
MIN_INTERVAL_S = 0.005  # the shortest stream interval (200 Hz)
HEARTBEAT_S = 1.0
HOUSEKEEPING_S = 0.02  # s of wall time between looks at the GCS socket, streams, file flushes
MAX_TEXT_MESSAGES = 12  # STATUSTEXTs in one datagram of events (the newest texts, whole)
OFFBOARD_STREAM_S = 1.0  # s of wall time: a ground station's OFFBOARD needs a target from the controller this recent
RESEND_S = 0.05  # lockstep: resend the state nobody answered (a datagram can be dropped)
IDLE_ODOMETRY_S = 0.1  # lockstep, disarmed: time stands still; the state is still shown
BY_VEHICLE = " [by vehicle]"  # the suffix of an arm or disarm the vehicle made itself (failsafe landing, divergence)
ATTRIBUTED = ("armed", "disarmed", "mode", "interval", "param")  # the events that say who caused them
_TARGETS = frozenset({"HIL_ACTUATOR_CONTROLS", "SET_ACTUATOR_CONTROL_TARGET"})
_ADDRESSED = frozenset({"COMMAND_LONG", "COMMAND_INT", "MISSION_REQUEST_LIST", "PARAM_REQUEST_LIST",
                        "PARAM_REQUEST_READ", "PARAM_SET", "SET_MODE"})  # target fields checked first
_COMMANDS = frozenset({"COMMAND_LONG", "COMMAND_INT"})
_PARAM_MESSAGES = frozenset({"PARAM_REQUEST_LIST", "PARAM_REQUEST_READ", "PARAM_SET"})


@dataclass(frozen=True)
class Sender:
    """Who sent a command: its sysid and compid, its address, and the link it came in on
    (``controller`` or ``gcs``)."""

    sysid: int
    compid: int
    addr: tuple[str, int]
    link: str

    @property
    def tag(self) -> str:
        """The suffix of the events it caused, `` [by SYSID:COMPID HOST:PORT LINK]`` (docs/design.md,
        "Authority": a policy checker parses it from events.log)."""
        return f" [by {self.sysid}:{self.compid} {self.addr[0]}:{self.addr[1]} {self.link}]"


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


@dataclass(frozen=True)
class VehicleConfig:
    """How the vehicle is reached and clocked (see the module docstring)."""

    listen: Address
    gcs: Address | None
    sysid: int = 1
    compid: int = VEHICLE_COMPID
    controller_sysid: int = CONTROLLER_SYSID
    controller_compid: int = CONTROLLER_COMPID
    clock: str = "lockstep"
    speed: float | None = None  # x real time: lockstep cap, and pace after losing the controller
    lost_after_s: float = 0.5  # s of wall time
    spin_s: float = 0.0002  # s polled (yielding) before sleeping while a lockstep answer is due: ~4x the
    # peer's median work; longer only burns a core that a busy machine needs for that peer
    home: tm.Home = field(default_factory=tm.Home)
    key: bytes | None = field(default=None, repr=False)  # MAVLink 2 signing key (never shown)
    # the only address the controller's ids are heard from on the controller link (bsst sitl pins the
    # controller's source port); None: learned from its first message, as docs/design.md says
    controller_from: tuple[str, int] | None = None


class Vehicle:
    """One simulated vehicle and its MAVLink links. :meth:`run` until :meth:`stop`."""

    def __init__(self, flight: Flight, cfg: VehicleConfig, out: Path | None = None,
                 status: Callable[[str], None] | None = None) -> None:
        if cfg.clock not in CLOCKS:
            raise ValueError(f"clock must be one of {', '.join(CLOCKS)}")
        self.flight = flight
        self.cfg = cfg
        m = flight.mission
        self.rate = m.rate_hz
        self.physics_hz = m.physics_hz
        self.substeps = flight.substeps
        self.actuation = flight.profile.actuation
        self.omega_max = flight.profile.omega_max
        self.sim = flight.make_vehicle(armed=False)
        self.plant = self.sim.plant
        self._status = status or (lambda line: None)
        self.tlog = Tlog(out / "vehicle.tlog") if out is not None else None
        # refusals of the receive path (bridge.mavlink.receive), both links, and of the up-link model's end
        self.rejected = Rejections()
        self._from_peer = False  # the message being handled came from the controller's address
        pin = cfg.controller_from  # numeric, as recvfrom gives addresses (a name would never match)
        self._pinned = (socket.gethostbyname(pin[0]), pin[1]) if pin is not None else None
        # one replay table for both links: a signed frame replayed from one link onto the other is refused
        replay: dict[tuple[int, int, int], int] = {}
        sign = ((lambda link_id: Signing(cfg.key, link_id, replay)) if cfg.key is not None
                else (lambda link_id: None))
        self.link = Endpoint(cfg.listen, sysid=cfg.sysid, compid=cfg.compid, tlog=self.tlog, name="--listen",
                             signing=sign(0), rejected=self.rejected, priority=True)
        self.link.follow = False  # ODOMETRY goes to the flight's controller only (see _handle)
        # a ground station is charged like any source, and its refusals are not the controller's
        self.gcs = (Endpoint(cfg.gcs, sysid=cfg.sysid, compid=cfg.compid, tlog=self.tlog, name="--gcs",
                             signing=sign(1), rejected=self.rejected, exempt_peer=False)
                    if cfg.gcs is not None else None)
        self.endpoints = [self.link] + ([self.gcs] if self.gcs is not None else [])
        self.rows = LineWriter(out / "vehicle.csv", ",".join(VEHICLE_COLUMNS), batch=100) if out is not None else None
        self.k = 0  # control step of the plant's state: t_k = k / rate_hz
        self.freerun = cfg.clock == "realtime"  # stepping on the wall clock (realtime, or lockstep lost)
        self.halted = False  # diverged: the plant is not stepped any more
        self.stopping = False
        # lockstep: (wire, recv wall) answering step k; wire None: the no-target acknowledgement
        self.pending: tuple[tuple[float, ...] | None, float] | None = None
        self.applied: tuple[int, tuple[float, ...], float] | None = None  # (key, wire, recv wall) in force
        self._odo_sent: dict[int, float] = {}  # step -> wall time its state was sent
        self.odometry_sent = 0
        # lockstep: the steps whose state was resent (RESEND_S unanswered), and the answers that came for
        # one of them after its first answer had been taken: the controller answers every copy, so a slow
        # answer (not a lost one) comes twice; the second is expected, not a refusal of anyone's datagram
        self._resent_steps: set[int] = set()
        self.resends = 0
        self.answered_again = 0
        now = time.monotonic()
        # the GCS link's: the defaults, and with sensors (not truth) HIGHRES_IMU and, for GNSS, GPS_RAW_INT
        sensors = self.sim.sensors.config if self.sim.sensors is not None else None
        self.streams = StreamTable({**DEFAULT_STREAMS, **tm.sensor_streams(sensors)}, now)
        self.ctl_streams = StreamTable(dict.fromkeys(self.streams, 0.0), now)  # the controller link's: none
        self._next_heartbeat = now
        self._next_house = now
        self._resend_at = self._lost_at = self._idle_odo_at = now
        self.pace = Pace(self.physics_hz, cfg.speed or 1.0, now)  # the wall clock of physics steps
        self._n = 0  # physics steps taken (realtime: for the wall-clock schedule)
        self._events_sent = 0
        self._cpu0 = time.process_time()
        self._load_at = (now, self._cpu0)
        self.load = 0
        self.accepted = 0
        # lockstep: the controller's targets and re-arms cross the mission's up-link model here
        self.vend = VehicleEnd(self.sim, flight.link.make()[0], self.actuation, rejected=self.rejected)
        self.engaged = False  # lockstep: a flight is on, the step clock runs on the controller's answers
        self._texts: list[Any] = []  # STATUSTEXTs saying why a command was refused: sent after its COMMAND_ACK
        self._text_id = 0  # the id of the last chunked STATUSTEXT
        self._target_wall = -math.inf  # wall time of the newest actuator target from the controller (checked)

    # -- public --------------------------------------------------------------------------
    def stop(self) -> None:
        """Ask :meth:`run` to return (safe from a signal handler)."""
        self.stopping = True

    def run(self) -> None:
        """Serve until :meth:`stop`: step the clock, answer the links, stream telemetry."""
        gcs = f" gcs={self.gcs.address.hostport}" if self.gcs is not None else ""
        pin = f" controller_from={self._pinned[0]}:{self._pinned[1]}" if self._pinned is not None else ""
        self._status(f"ready listen={self.link.local[0]}:{self.link.local[1]}{gcs} sysid={self.cfg.sysid} "
                     f"clock={self.cfg.clock} profile={self.flight.profile.name}{pin}")
        try:
            while not self.stopping:
                if self.halted:
                    self._idle()
                elif self.freerun:
                    self._freerun_period()
                elif self.sim.armed or self.engaged:
                    self._lockstep_wait()
                else:
                    self._idle()
                if time.monotonic() >= self._next_house:
                    self._housekeeping()
        finally:
            self.close()

    def close(self) -> None:
        """Flush and close every file and socket (idempotent)."""
        self._drain_sockets()
        self._drain_events()
        if self.rows is not None:
            self.rows.close()
        if self.tlog is not None:
            self.tlog.close()
        for ep in self.endpoints:
            ep.close()

    def _drain_sockets(self, batches: int = 64) -> None:
        """Take in what is already queued on every socket before closing, so that the final
        counts include every datagram that arrived before the stop (the others' socket is read
        lazily while the controller's is busy: see Endpoint.poll); bounded, never blocks."""
        for ep in self.endpoints:
            if ep.fileno < 0:
                continue
            for _ in range(batches):
                got = ep.poll()
                for m, addr in got:
                    self._handle(ep, m, addr)
                if not got and not ep.backlog:
                    break

    @property
    def t(self) -> float:
        """Simulation time of the current step (s)."""
        return self.k / self.rate

    # -- lockstep --------------------------------------------------------------------------
    def _lockstep_wait(self) -> None:
        """Wait for the target of step k; step when it is here, or give the controller up."""
        deadline = min(self._next_house, self._resend_at, self._lost_at)
        for ep, m, addr in wait(self.endpoints, deadline, self.link, self.cfg.spin_s):
            self._handle(ep, m, addr)
        if self.pending is not None:
            self._step_lockstep()
            return
        now = time.monotonic()
        if self.freerun or not (self.sim.armed or self.engaged):
            return
        if now >= self._lost_at:
            self.sim.event("lockstep", f"controller silent for {self.cfg.lost_after_s:g} s of wall time: "
                                       "leaving lockstep, running on the wall clock")
            self._start_freerun(now)
        elif now >= self._resend_at:
            self._send_odometry(now, fresh=False)

    def _step_lockstep(self) -> None:
        """Step k is answered: its target (if any) enters the up-link model at t_k, what the
        model delivers by t_k acts, then one control period with mid-period deliveries."""
        wire, recv = self.pending  # type: ignore[misc]
        self.pending = None
        k = self.k
        t = k / self.rate
        sent = self._odo_sent.get(k, recv)
        vend = self.vend
        if wire is not None:
            vend.receive_command(t, command_from_wire(self.actuation, wire), t)
            self.applied = (k, wire, recv)
        vend.deliver(t)
        X = self.plant.state
        est = self._estimate()
        real = self.plant.realised
        vend.advance()
        self.k = k + 1
        if self.cfg.speed is not None:
            self._wait_until(self.pace.due(self.k * self.substeps))
        if self._after_step():
            self._send_odometry(time.monotonic())
        # off the critical path: the controller is computing step k+1 meanwhile
        self._row(k, X, k, NAN4 if wire is None else wire, NAN4, real, t - vend.applied_state_t, recv - sent,
                  sent, recv, est)

    def _start_freerun(self, now: float) -> None:
        self.freerun = True
        self.engaged = False
        self.pace.restart(now, self.k * self.substeps)

    # -- free run: realtime clock, or lockstep lost --------------------------------------------
    def _freerun_period(self) -> None:
        """One control period on the wall clock: state out, row, physics steps on schedule."""
        k = self.k
        n0 = k * self.substeps
        if not self._wait_until(self.pace.due(n0)):
            return
        now = time.monotonic()
        if self.sim.armed or self.cfg.clock == "realtime":
            self._send_odometry(now)
        X = self.plant.state
        if self.sim.armed:
            self._row_freerun(k, X, now)
        self._n = n0

        def deliver(_t: float) -> None:
            # called before each physics step: wait for its wall time, taking targets meanwhile
            if self._n > n0:
                self._wait_until(self.pace.due(self._n))
            self._n += 1

        self.sim.advance(deliver)
        self.k = k + 1
        self._after_step()

    def _wait_until(self, due: float) -> bool:
        """Serve the links until wall time ``due`` of the pace; False if stopping. A pace
        stalled far behind is re-based (:meth:`Pace.rebase_if_stalled`), not caught up."""
        now = time.monotonic()
        if self.pace.rebase_if_stalled(now, due):
            return not self.stopping
        while not self.stopping:
            if now >= due:
                return True
            for ep, m, addr in wait(self.endpoints, min(due, self._next_house)):
                self._handle(ep, m, addr)
            now = time.monotonic()
            if now >= self._next_house:
                self._housekeeping()
        return False

    def _row_freerun(self, k: int, X: tuple[float, ...], now: float) -> None:
        sim = self.sim
        if sim.mode == OFFBOARD and self.applied is not None:
            key, wire, recv = self.applied
            sent = self._odo_sent.get(key, math.nan)
            self._row(k, X, key, wire, NAN4, self.plant.realised, self.t - key / self.rate, recv - sent, now, recv)
        elif sim.mode == OFFBOARD:  # armed, no target yet
            self._row(k, X, -1, NAN4, NAN4, self.plant.realised, math.nan, math.nan, now, math.nan)
        else:  # failsafe: the vehicle's own landing loop is in command
            dem = sim.landing.demand(X)
            wire = command_to_wire(self.actuation, sim.landing.command(X))
            self._row(k, X, -1, wire, dem, self.plant.realised, self.plant.t - sim.last_command_t,
                      math.nan, now, math.nan)

    # -- idle -----------------------------------------------------------------------------------
    def _idle(self) -> None:
        """Lockstep and disarmed (or halted): time stands still; serve the links."""
        deadline = min(self._next_house, self._idle_odo_at)
        for ep, m, addr in wait(self.endpoints, deadline):
            self._handle(ep, m, addr)
        now = time.monotonic()
        if now >= self._idle_odo_at and not self.halted:
            self._idle_odo_at = now + IDLE_ODOMETRY_S
            self._send_odometry(now)

    # -- after each control period -------------------------------------------------------------
    def _after_step(self) -> bool:
        """Events and divergence; False when the plant is lost (nothing more to send)."""
        if len(self.sim.events) > self._events_sent:
            self._drain_events()
        why = self.plant.diverged()
        if why:
            self.sim.event("diverged", why)
            self.sim.disarm(f"diverged: {why}")
            self.halted = True
            self.engaged = False
            self._drain_events()
            return False
        return True

    def _drain_events(self) -> None:
        """Each new event as a status line and a STATUSTEXT; then a HEARTBEAT at once, so
        that a ground station sees an arm, disarm or failsafe without waiting up to 1 s."""
        events = self.sim.events
        if self._events_sent == len(events):
            return
        texts: list[list[Any]] = []
        while self._events_sent < len(events):
            e = events[self._events_sent]
            self._events_sent += 1
            if e.kind in ATTRIBUTED and " [by " not in e.text:
                # not caused by a command handled here: an arm the up-link model delivered (the
                # flight's controller sent it), or the vehicle's own disarm (landed, diverged)
                e.text += self._controller().tag if e.kind == "armed" and self.link.peer is not None else BY_VEHICLE
            self._status(f"event t={e.t:.3f} {e.kind}: {e.text}")
            sev = (mavlink.MAV_SEVERITY_CRITICAL if e.kind in ("failsafe", "diverged", "lockstep")
                   else mavlink.MAV_SEVERITY_INFO)
            texts.append(self._statustext(sev, f"{e.kind}: {e.text}"))
        msgs: list[Any] = []
        for chunks in reversed(texts):  # the newest texts, whole, if many came at once
            if len(msgs) + len(chunks) > MAX_TEXT_MESSAGES:
                break
            msgs[:0] = chunks
        msgs.append(self._heartbeat())
        for ep in self.endpoints:
            ep.send_many(msgs)  # one datagram per link

    def _statustext(self, severity: int, text: str) -> list[Any]:
        """STATUSTEXT(s) of ``text``: chunked when longer than 50 characters, each text its own id."""
        self._text_id = self._text_id % 65535 + 1
        return tm.statustext(severity, text, self._text_id)

    # -- sending ---------------------------------------------------------------------------------
    def _send_odometry(self, now: float, fresh: bool = True) -> None:
        """ODOMETRY of step k to the controller; a ``fresh`` one (not a resend) starts the
        lockstep wait for its target."""
        k = self.k
        X = self.sim.published()  # the vehicle's estimate (the true state under the truth estimator)
        if not tm.finite(X):
            return
        pos, q, vel, rates = state_to_odometry(X)
        tail = ODOMETRY_TAIL if self.sim.sensors is None else self._estimate_tail(q)
        if self.link.send_hot(ODOMETRY, (step_usec(k, self.rate), *pos, *q, *vel, *rates, *tail)):
            self.odometry_sent += 1
        if fresh or k not in self._odo_sent:  # a resent state's round trip counts from its first sending
            self._odo_sent[k] = now
        if len(self._odo_sent) > 256:
            for old in [s for s in self._odo_sent if s < k - 128]:
                del self._odo_sent[old]
        if not fresh:
            self.resends += 1
            self._resent_steps.add(k)
            if len(self._resent_steps) > 256:
                self._resent_steps = {s for s in self._resent_steps if s >= k - 128}
        self._resend_at = now + RESEND_S
        if fresh:
            self._lost_at = now + self.cfg.lost_after_s

    def _row(self, k: int, X: tuple[float, ...], key: int, wire: tuple[float, ...], dem: tuple[float, ...],
             real: tuple[float, ...], age: float, rtt: float, sent: float, recv: float,
             est: tuple[tuple[float, ...], float] | None = None) -> None:
        """One ``vehicle.csv`` row; ``est``: (estimate, NEES) taken with ``X`` (None: now, with ``X`` current)."""
        if self.rows is None:
            return
        E, nees = est if est is not None else self._estimate()
        mode = MODE_CODES.get(self.sim.mode, 0)
        self.rows.write(",".join(map(repr, (k, k / self.rate, *state_columns(X), mode, key, *wire, *dem, *real,
                                            age, rtt, sent, recv, *state_columns(E), nees))))

    def _estimate(self) -> tuple[tuple[float, ...], float]:
        """The published estimate now and its NEES against the true state (nan under truth)."""
        E = self.sim.published()
        return E, self.sim.nees(E)

    def _estimate_tail(self, q: tuple[float, float, float, float]) -> tuple[Any, ...]:
        """ODOMETRY after the body rates for an estimate: its covariances, frames, estimator type, quality 0
        (unknown: MAVLink has no scale for it)."""
        assert self.sim.estimator is not None
        pose, twist = odometry_covariance(q, self.sim.estimator.covariance())
        return (*pose, *twist, mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_BODY_FRD, 0,
                ESTIMATOR_TYPES[self.flight.estimator], 0)

    def _heartbeat(self) -> Any:
        sim = self.sim
        # PX4's encoding of the mode (bridge.mavlink.modes): ground stations name it
        base, custom = heartbeat_mode(sim.mode, sim.onboard.target, sim.armed)
        if self.halted or sim.mode in (FAILSAFE, LANDED):
            state = mavlink.MAV_STATE_CRITICAL
        elif sim.armed:
            state = mavlink.MAV_STATE_ACTIVE
        else:
            state = mavlink.MAV_STATE_STANDBY
        return mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4, base,
                                                 custom, state, 3)

    def _message(self, mid: int) -> list[Any]:
        """The message(s) with id ``mid`` for a stream or a REQUEST_MESSAGE ([] if none)."""
        X = self.plant.state
        ms = int(self.t * 1000.0)
        if mid == mavlink.MAVLINK_MSG_ID_HEARTBEAT:
            return [self._heartbeat()]
        if mid == mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            return [tm.autopilot_version(self.cfg.sysid)]
        if mid == mavlink.MAVLINK_MSG_ID_HOME_POSITION:
            return [tm.home_position(self.cfg.home)]
        if mid == mavlink.MAVLINK_MSG_ID_SYS_STATUS:
            return [tm.sys_status(self.load, not self.halted)]
        if mid == mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE:
            return [tm.extended_sys_state(self.plant.on_ground, self.sim.mode == FAILSAFE)]
        if mid == mavlink.MAVLINK_MSG_ID_ACTUATOR_OUTPUT_STATUS:
            return [tm.actuator_outputs(int(self.t * 1e6), self.plant.omega, self.omega_max)]
        if mid in tm.SENSOR_MESSAGES:  # the sensors' newest samples, never the true state: [] under truth
            return tm.sensor_message(mid, self.sim.sensors, self.cfg.home, int(self.t * 1e6))
        if not tm.finite(X):
            return []
        if mid == mavlink.MAVLINK_MSG_ID_ATTITUDE:
            return tm.attitude(X, ms)[:1]
        if mid == mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION:
            return tm.attitude(X, ms)[1:]
        if mid == mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED:
            return [tm.local_position(X, ms)]
        if mid == mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT:
            return [tm.global_position(X, ms, self.cfg.home)]
        return []

    def _housekeeping(self) -> None:
        """Wall-clock duties: GCS commands, heartbeat, streams, flushing files."""
        now = time.monotonic()
        if self.gcs is not None:
            for m, addr in self.gcs.poll():
                self._handle(self.gcs, m, addr)
        if now >= self._next_heartbeat:
            self._next_heartbeat = now + HEARTBEAT_S
            hb = self._heartbeat()
            for ep in self.endpoints:
                ep.send(hb)
            cpu = time.process_time()
            w0, c0 = self._load_at
            self.load = int(1000 * (cpu - c0) / max(now - w0, 1e-6))
            self._load_at = (now, cpu)
        refused = self.rejected.report(now)  # once per second while the receive path refuses anything
        if refused is not None:
            msg = mavlink.MAVLink_statustext_message(mavlink.MAV_SEVERITY_WARNING, refused.encode())
            for ep in self.endpoints:
                ep.send(msg)
        for ep, table in ((self.gcs, self.streams), (self.link, self.ctl_streams)):
            if ep is None or ep.peer is None:
                continue
            for mid, due in table.due.items():
                if now >= due:
                    iv = table[mid]
                    table.due[mid] = due + iv if now - due < iv else now + iv
                    ep.send_many(self._message(mid))
        if self.rows is not None:
            self.rows.flush()
        if self.tlog is not None:
            self.tlog.flush()
        nxt = min([self._next_heartbeat, now + HOUSEKEEPING_S, *self.streams.due.values(),
                   *self.ctl_streams.due.values()])
        self._next_house = max(nxt, now + 0.001)

    # -- receiving ---------------------------------------------------------------------------------
    def _handle(self, ep: Endpoint, m: Any, addr: tuple[str, int]) -> None:
        """A message that passed the frame stage: its sender's authority checked
        (:meth:`_authority`), then checked and acted on by :meth:`_dispatch`.

        The controller link's peer (where ODOMETRY goes, never rate-limited, with a socket of
        its own: Endpoint.prioritise) is the flight's controller: the address of the
        configured controller's message that nothing refused, learned while no flight is on
        (the newest such) or when the flight has none yet (the first), and then held until
        the flight ends: while it is on, the controller's ids from any other address are a
        ``stranger``'s."""
        link = self.link
        if ep is not link:
            self._from_peer = False
            self._dispatch(ep, m, addr)
            return
        known = self._from_peer = addr == link.peer
        why = self._authority(m, known, addr)
        if why is not None:
            self._reject(why)
            if m._type in _COMMANDS:
                self._ack(ep, m, addr, mavlink.MAV_RESULT_DENIED)
            return
        if known:
            self._dispatch(ep, m, addr)
            return
        # the controller's ids from a new address, no flight on (or none with a controller yet):
        # it is the peer while its message is handled (an arm's first state goes to it), and
        # stays so unless the message is refused
        before, refused = link.peer, self.rejected.total
        link.peer = addr
        self._dispatch(ep, m, addr)
        if self.rejected.total != refused:
            link.peer = before
        else:
            link.prioritise(addr)
            if addr != before:  # a new controller hears who it talks to now, not at the next 1 Hz heartbeat
                link.send(self._heartbeat())

    def _authority(self, m: Any, known: bool, addr: tuple[str, int]) -> str | None:
        """Why a message on the controller link is refused for its sender, or None: only the
        configured controller (its sysid and compid) is heard there; with ``controller_from``
        only from that address, else during a flight only from the flight's address
        (docs/design.md, "Authority"). A command for another system is ``target`` whoever sent it."""
        cfg = self.cfg
        kind = m._type
        if kind in _ADDRESSED and addressed_elsewhere(m, cfg.sysid, cfg.compid):
            return "target"
        if not self._from_controller(m):
            return "sender" if kind in _TARGETS else "not_authorised"
        if self._pinned is not None and addr != self._pinned:
            return "stranger"
        if not known and self.link.peer is not None and (self.sim.armed or self.engaged):
            return "stranger"
        return None

    def _controller(self) -> Sender:
        """The flight's controller (configured ids, learned address) as a :class:`Sender`."""
        cfg = self.cfg
        return Sender(cfg.controller_sysid, cfg.controller_compid, self.link.peer or ("?", 0), "controller")

    def _ack(self, ep: Endpoint, m: Any, addr: tuple[str, int], result: int, follow: tuple[Any, ...] = ()) -> None:
        """COMMAND_ACK of ``m`` (and the messages it asked for) to its sender: one datagram,
        within that sender's reply budget."""
        ack = mavlink.MAVLink_command_ack_message(m.command, result, 0, 0, m.get_srcSystem(), m.get_srcComponent())
        ep.reply((ack, *follow), addr)

    def _dispatch(self, ep: Endpoint, m: Any, addr: tuple[str, int]) -> None:
        kind = m._type
        if kind == "HIL_ACTUATOR_CONTROLS" or kind == "SET_ACTUATOR_CONTROL_TARGET":
            self._target(ep, m, kind)
        elif kind == "COMMAND_LONG" or kind == "COMMAND_INT":
            self._command(ep, m, addr)
        elif kind == "TIMESYNC":
            if m.tc1 == 0:  # a request (an answer, tc1 != 0, is for someone else's clock: nothing to do)
                self._request(ep, addr, mavlink.MAVLink_timesync_message(self._clock_ns(), m.ts1))
        elif kind == "PING":  # a request has no target (0, 0); answered as PX4 does, addressed to its sender
            if m.target_system == 0 and m.target_component == 0:
                self._request(ep, addr, mavlink.MAVLink_ping_message(m.time_usec, m.seq, m.get_srcSystem(),
                                                                     m.get_srcComponent()))
        elif kind in _PARAM_MESSAGES:
            self._param_message(ep, m, addr, kind)
        elif kind == "SET_MODE":  # deprecated by DO_SET_MODE, still sent by some ground stations
            if addressed_elsewhere(m, self.cfg.sysid, self.cfg.compid):
                return self._reject("target")
            if not ep.reply_allowed(addr):
                return self._reject("reply_limited")
            by = self._sender(ep, m, addr)
            result = self._set_mode_or_refuse(ep, addr, *requested_custom_mode(m.base_mode, m.custom_mode), by=by)
            ack = mavlink.MAVLink_command_ack_message(mavlink.MAV_CMD_DO_SET_MODE, result, 0, 0, m.get_srcSystem(),
                                                      m.get_srcComponent())
            ep.reply((ack, *self._texts), addr)
            self._texts.clear()
            self._drain_events()
        elif kind == "MISSION_REQUEST_LIST":
            if addressed_elsewhere(m, self.cfg.sysid, self.cfg.compid):
                return self._reject("target")
            self._request(ep, addr, mavlink.MAVLink_mission_count_message(m.get_srcSystem(), m.get_srcComponent(),
                                                                          0, m.mission_type))
        elif kind == "FILE_TRANSFER_PROTOCOL":  # no files: a NAK at once (MAVProxy then fetches parameters)
            if addressed_elsewhere(m, self.cfg.sysid, self.cfg.compid):
                return self._reject("target")
            nak = ftp_nak(bytes(m.payload))
            if nak is not None:
                self._request(ep, addr, mavlink.MAVLink_file_transfer_protocol_message(
                    0, m.get_srcSystem(), m.get_srcComponent(), list(nak)))
        return None

    def _request(self, ep: Endpoint, addr: tuple[str, int], answer: Any) -> None:
        """Answer a request that changes nothing, within its sender's reply budget."""
        if not ep.reply_allowed(addr):
            return self._reject("reply_limited")
        ep.reply((answer,), addr)
        return None

    def _reject(self, why: str) -> None:
        self.rejected.add(why, self._from_peer)

    def _from_controller(self, m: Any) -> bool:
        """Whether ``m`` says it comes from the configured controller (its sysid and compid)."""
        cfg = self.cfg
        return m.get_srcSystem() == cfg.controller_sysid and m.get_srcComponent() == cfg.controller_compid

    def _target(self, ep: Endpoint, m: Any, kind: str) -> None:
        """An actuator target: checked, then held for lockstep or applied at once (realtime)."""
        cfg = self.cfg
        if ep is not self.link or not self._from_controller(m):
            return self._reject("sender")
        now = self._target_wall = time.monotonic()  # the controller streams (whether or not this one is taken)
        if kind == "HIL_ACTUATOR_CONTROLS":
            if not m.mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED:
                return self._no_target(m)
            if self.actuation != "motors":
                return self._reject("message")
        else:
            if self.actuation != "wrench":
                return self._reject("message")
            if m.group_mlx != 0:
                return self._reject("group")
            if addressed_elsewhere(m, cfg.sysid, cfg.compid):
                return self._reject("target")
        offboard = self.sim.armed and self.sim.mode == OFFBOARD
        if self.halted or (not offboard and (self.freerun or not self.engaged)):
            return self._reject("not_offboard")  # lockstep, flight on: VehicleEnd decides when the model delivers
        c = m.controls
        wire = (c[0], c[1], c[2], c[3])
        why = wire_problem(self.actuation, wire)
        if why:
            return self._reject(why)
        key = step_of_usec(m.time_usec, self.rate)
        if not self.freerun:
            if key != self.k or self.pending is not None:
                return self._behind(key)
            self.accepted += 1
            self.pending = (wire, now)
            return None
        if self.applied is not None and key < self.applied[0]:
            return self._reject("reordered")
        if self.sim.command(command_from_wire(self.actuation, wire)):
            self.accepted += 1
            self.applied = (key, wire, now)
        return None

    def _no_target(self, m: Any) -> None:
        """The controller's no-target acknowledgement of a step: HIL_ACTUATOR_CONTROLS with
        SAFETY_ARMED clear in ``mode`` (as PX4's lockstep clocks its simulator while its
        outputs are disarmed). In lockstep, with a flight on, it clocks step k without a
        target (the last one stays in force and the timeout runs); otherwise it means nothing."""
        if self.freerun or self.halted or not self.engaged:
            return None
        key = step_of_usec(m.time_usec, self.rate)
        if key != self.k or self.pending is not None:
            return self._behind(key)
        self.pending = (None, time.monotonic())
        return None

    def _behind(self, key: int) -> None:
        """Lockstep: the controller's answer for a step other than k. For a step whose state was
        resent it is the answer to a copy, its first answer already taken (``answered_again``);
        otherwise a second answer to step k (its state sent once) is ``repeated``, an older one ``stale``, a newer
        one ``future``."""
        if key in self._resent_steps:  # (k itself: both answers to its copies came before it was stepped)
            self.answered_again += 1
            return None
        if key == self.k:
            return self._reject("repeated")
        return self._reject("stale" if key < self.k else "future")

    def _through_link(self, ep: Endpoint, m: Any) -> bool:
        """Whether a command crosses the up-link model: the controller's, on its link, in a lockstep flight."""
        return ep is self.link and self.engaged and not self.freerun and self._from_controller(m)

    def _command(self, ep: Endpoint, m: Any, addr: tuple[str, int]) -> None:
        """COMMAND_LONG / COMMAND_INT from a sender with authority on ``ep``: its numbers
        checked, acted on, answered (COMMAND_ACK and what it asked for, in one datagram) and,
        if it changed the flight, an event naming the sender."""
        cfg = self.cfg
        if addressed_elsewhere(m, cfg.sysid, cfg.compid):
            return self._reject("target")
        if not ep.reply_allowed(addr):
            return self._reject("reply_limited")  # not acted on: its answer could not go
        by = self._sender(ep, m, addr)
        n0 = len(self.sim.events)
        result, follow = self._run_command(ep, m, by)
        self._attribute(n0, by)
        self._ack(ep, m, addr, result, (*follow, *self._texts))
        self._texts.clear()
        self._drain_events()
        return None

    def _sender(self, ep: Endpoint, m: Any, addr: tuple[str, int]) -> Sender:
        return Sender(m.get_srcSystem(), m.get_srcComponent(), addr, "controller" if ep is self.link else "gcs")

    def _attribute(self, n0: int, by: Sender) -> None:
        """Name ``by`` in the events from the ``n0`` th on that say who caused them."""
        for e in self.sim.events[n0:]:
            if e.kind in ATTRIBUTED and " [by " not in e.text:
                e.text += by.tag

    def _run_command(self, ep: Endpoint, m: Any, by: Sender) -> tuple[int, tuple[Any, ...]]:
        """Act on a command whose sender has authority: (MAV_RESULT, the messages it asked for).
        Every parameter used is checked first (:mod:`bridge.mavlink.receive`); a bad one is
        DENIED and counted (``bad_number``), nothing done."""
        cmd = m.command
        denied = (mavlink.MAV_RESULT_DENIED, ())
        if cmd == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            args = arm_disarm_args(m.param1, m.param2)
            if args is None:
                self._reject("bad_number")
                return denied
            if args[0] and self._through_link(ep, m):
                self.vend.receive_arm(self.t)  # acts when the model delivers it, as offline
                return mavlink.MAV_RESULT_IN_PROGRESS, ()
            return self._arm_disarm(m.param1, m.param2, by), ()
        if cmd in (mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAV_CMD_GET_MESSAGE_INTERVAL,
                   mavlink.MAV_CMD_REQUEST_MESSAGE):
            mid = message_id_arg(m.param1)
            interval = interval_arg(m.param2) if cmd == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL else 0.0
            if mid is None or interval is None:
                self._reject("bad_number")
                return denied
            table = self.ctl_streams if ep is self.link else self.streams  # a link's requests change its streams
            if cmd == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
                return self._set_interval(table, mid, interval, by), ()
            if cmd == mavlink.MAV_CMD_GET_MESSAGE_INTERVAL:
                if mid > 0xFFFF:  # MESSAGE_INTERVAL's message_id has 16 bits
                    return mavlink.MAV_RESULT_UNSUPPORTED, ()
                iv = table.get(mid, HEARTBEAT_S if mid == mavlink.MAVLINK_MSG_ID_HEARTBEAT else 0.0)
                return mavlink.MAV_RESULT_ACCEPTED, (
                    mavlink.MAVLink_message_interval_message(mid, int(iv * 1e6) if iv > 0 else -1),)
            follow = tuple(self._message(mid))
            return (mavlink.MAV_RESULT_ACCEPTED if follow else mavlink.MAV_RESULT_UNSUPPORTED), follow
        if cmd == mavlink.MAV_CMD_DO_SET_MODE:
            return self._set_mode_or_refuse(ep, by.addr, *requested_mode(m.param1, m.param2, m.param3), by=by), ()
        if cmd == mavlink.MAV_CMD_NAV_TAKEOFF:
            alt = self._takeoff_altitude(m.param7 if m._type == "COMMAND_LONG" else m.z)  # COMMAND_INT: z, m AMSL
            if isinstance(alt, str):
                return self._refuse(ep, by.addr, alt), ()
            return self._set_mode_or_refuse(ep, by.addr, TAKEOFF, "", by=by, takeoff_alt_m=alt), ()
        if cmd == mavlink.MAV_CMD_NAV_LAND:  # lands where it is (PX4 with NaN lat/lon); a position is not flown to
            return self._set_mode_or_refuse(ep, by.addr, LAND, "", by=by), ()
        if cmd == mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            return mavlink.MAV_RESULT_ACCEPTED, (tm.autopilot_version(self.cfg.sysid),)
        if cmd == mavlink.MAV_CMD_GET_HOME_POSITION:
            return mavlink.MAV_RESULT_ACCEPTED, (tm.home_position(self.cfg.home),)
        return mavlink.MAV_RESULT_UNSUPPORTED, ()

    # -- flight modes (docs/ground-station.md) -------------------------------------------------------
    def _takeoff_altitude(self, param7: float) -> float | str:
        """NAV_TAKEOFF's altitude above home (m) from its param7 (m AMSL, as PX4 reads it; NaN:
        MIS_TAKEOFF_ALT), or why it cannot be flown. MIS_TAKEOFF_ALT is also the least it climbs to: a
        lower altitude (below home too) is raised to it with a STATUSTEXT, as PX4 does; one above the
        plant's envelope (MIS_TAKEOFF_ALT's upper bound) is refused."""
        least = self.sim.takeoff_alt_m
        if math.isnan(param7):
            return least
        hi = BY_NAME["MIS_TAKEOFF_ALT"].hi
        rel = param7 - self.cfg.home.alt
        if not (math.isfinite(param7) and rel <= hi):
            return (f"NAV_TAKEOFF: altitude {param7:g} m AMSL is {rel:g} m above home; "
                    f"must be at most {hi:g} m above (home {self.cfg.home.alt:g} m)")
        if rel < least:
            if rel < least - 0.1:  # PX4 says nothing for less than 10 cm
                self._texts += self._statustext(mavlink.MAV_SEVERITY_WARNING, "Using minimum takeoff altitude: "
                                                f"{self.cfg.home.alt + least:.2f} m")
            return least
        return rel

    def _refuse(self, ep: Endpoint, addr: tuple[str, int], why: str) -> int:
        """DENIED; a STATUSTEXT saying why follows the COMMAND_ACK to the sender (:attr:`_texts`)."""
        self._texts += self._statustext(mavlink.MAV_SEVERITY_WARNING, why)
        self._status(f"refused {why}")
        return mavlink.MAV_RESULT_DENIED

    def _set_mode_or_refuse(self, ep: Endpoint, addr: tuple[str, int], mode: str | None, why: str, *,
                            by: Sender, takeoff_alt_m: float | None = None) -> int:
        """A ground station's (or the controller's) mode change: made at the start of the next
        control period, or DENIED with a STATUSTEXT saying why."""
        if mode is None:
            return self._refuse(ep, addr, why)
        if self.halted:
            return self._refuse(ep, addr, f"mode {mode_name(mode)}: the plant diverged")
        if (mode == OFFBOARD and self.sim.armed and self.sim.mode != OFFBOARD
                and time.monotonic() - self._target_wall > OFFBOARD_STREAM_S):
            # PX4 too: OFFBOARD only while a controller streams targets (its failsafe would act at once)
            return self._refuse(ep, addr, "OFFBOARD: no controller is sending targets")
        n0 = len(self.sim.events)
        was = self.sim.mode
        self.sim.set_mode(mode, takeoff_alt_m)
        self._attribute(n0, by)
        self._clock_after_mode(was)
        return mavlink.MAV_RESULT_ACCEPTED

    def _clock_after_mode(self, was: str) -> None:
        """The step clock after a mode change: a vehicle flown by its own controller (HOLD, LAND,
        TAKEOFF) needs no controller's answers and runs on the wall clock (``speed`` if given);
        OFFBOARD again, armed, returns to lockstep (the state of step k goes out, its answer awaited)."""
        sim, now = self.sim, time.monotonic()
        if self.cfg.clock != "lockstep" or not sim.armed:
            return
        if sim.mode in GROUND_MODES and not self.freerun:
            self._ground_takes_over(now)
        elif sim.mode == OFFBOARD and was != OFFBOARD:
            self._engage_lockstep(now)

    def _ground_takes_over(self, now: float) -> None:
        """Lockstep, a ground station's mode flown by the vehicle's own controller: on the wall clock
        from now; a lockstep flight that was on says so (its record: it left lockstep here)."""
        if self.engaged:
            self.sim.event("lockstep", f"{mode_name(self.sim.mode)} set by a ground station: flown by the "
                                       "vehicle on the wall clock")
        self.pending = None
        self._start_freerun(now)

    def _engage_lockstep(self, now: float) -> None:
        """Lockstep from now: the state of step k goes out and its target is awaited."""
        self.freerun = False
        self.engaged = True
        self.pending = None
        self.pace.restart(now, self.k * self.substeps)
        self._send_odometry(now)

    # -- parameters (docs/ground-station.md) ----------------------------------------------------------
    def _params(self) -> VehicleParams:
        return VehicleParams(self.sim.failsafe, self.sim.takeoff_alt_m, self.cfg.sysid)

    def _param_value(self, index: int, params: VehicleParams | None = None) -> Any:
        spec = PARAMS[index]
        kind = PARAM_TYPES[spec.kind]
        value = read_param(params or self._params(), spec.name)
        return mavlink.MAVLink_param_value_message(spec.name.encode(), param_to_wire(value, kind), kind,
                                                   len(PARAMS), index)

    def _param_message(self, ep: Endpoint, m: Any, addr: tuple[str, int], kind: str) -> None:
        """PARAM_REQUEST_LIST (every PARAM_VALUE, in one datagram), PARAM_REQUEST_READ (by index, or
        by name with index -1), PARAM_SET (checked: made and answered with the new value, or refused,
        answered with the unchanged value and a STATUSTEXT saying why). Within the sender's reply budget."""
        if addressed_elsewhere(m, self.cfg.sysid, self.cfg.compid):
            return self._reject("target")
        if not ep.reply_allowed(addr):
            return self._reject("reply_limited")  # not acted on: its answer could not go
        if kind == "PARAM_REQUEST_LIST":
            params = self._params()
            ep.reply(tuple(self._param_value(i, params) for i in range(len(PARAMS))), addr)
            return None
        name = param_name(m)
        if kind == "PARAM_REQUEST_READ":
            index = m.param_index if m.param_index >= 0 else next(
                (i for i, p in enumerate(PARAMS) if p.name == name), -1)
            if not 0 <= index < len(PARAMS):
                return self._param_unknown(ep, addr, name if m.param_index < 0 else f"index {m.param_index}")
            ep.reply((self._param_value(index),), addr)
            return None
        spec = BY_NAME.get(name)
        if spec is None:
            return self._param_unknown(ep, addr, name)
        index = PARAMS.index(spec)
        want = PARAM_TYPES[spec.kind]
        try:
            if m.param_type != want:
                raise ParamRefused(f"{name}: is {spec.kind}, the set says type {m.param_type}")
            n0 = len(self.sim.events)
            self.sim.change_param(name, param_from_wire(m.param_value, want), self.cfg.sysid)
            self._attribute(n0, self._sender(ep, m, addr))
        except ParamRefused as exc:
            self._reject("param_refused")
            self._status(f"refused {exc}")
            ep.reply((self._param_value(index), *self._statustext(mavlink.MAV_SEVERITY_WARNING, str(exc))), addr)
            return None
        ep.reply((self._param_value(index),), addr)
        self._drain_events()
        return None

    def _param_unknown(self, ep: Endpoint, addr: tuple[str, int], what: str) -> None:
        """No such parameter: no PARAM_VALUE (the protocol's answer), a STATUSTEXT saying so."""
        self._reject("param_unknown")
        ep.reply(tuple(self._statustext(mavlink.MAV_SEVERITY_WARNING, f"param {what}: no such parameter")), addr)

    def _arm_disarm(self, p1: float, p2: float, by: Sender | None = None) -> int:
        """Arm (``p1`` 1) or disarm (0; in the air only with ``p2`` = 21196, forced), checked
        values (:func:`bridge.mavlink.receive.arm_disarm_args`). A new flight armed from a
        ground station learns its controller's address afresh (see :meth:`_handle`)."""
        sim = self.sim
        now = time.monotonic()
        if p1 == 1.0:
            if self.halted:
                return mavlink.MAV_RESULT_DENIED
            was_offboard = sim.armed and sim.mode == OFFBOARD
            from_gcs = by is not None and by.link == "gcs"
            if from_gcs:
                sim.arm_in_mode()  # in the mode it selected (HOLD, LAND, TAKEOFF), else offboard
            else:
                sim.arm()
            if sim.mode in GROUND_MODES:  # the vehicle's own controller flies: no controller's answers
                if self.cfg.clock == "lockstep" and not self.freerun:
                    self._ground_takes_over(now)
                return mavlink.MAV_RESULT_ACCEPTED
            if not was_offboard and from_gcs:
                self.link.forget_peer()  # no controller yet: the flight's is the first to speak
            if not was_offboard:
                self.applied = None  # a new flight: no target of the last one is in force
            if not was_offboard and self.cfg.clock == "lockstep":
                self._engage_lockstep(now)  # back to lockstep
            return mavlink.MAV_RESULT_ACCEPTED
        forced = p2 == FORCE_DISARM
        if sim.armed and not self.plant.on_ground and not forced:
            return mavlink.MAV_RESULT_DENIED  # in the air: only a forced disarm (PX4 does the same)
        sim.disarm("disarmed by command (forced)" if forced else "disarmed by command")
        self.pending = None
        self.engaged = False  # the flight is over: time stands still until armed again
        return mavlink.MAV_RESULT_ACCEPTED

    def _set_interval(self, table: StreamTable, mid: int, interval_us: float, by: Sender) -> int:
        """A checked SET_MESSAGE_INTERVAL on one link's streams; a change is an event."""
        if mid == mavlink.MAVLINK_MSG_ID_HEARTBEAT:
            return mavlink.MAV_RESULT_ACCEPTED if interval_us in (0, HEARTBEAT_S * 1e6) else mavlink.MAV_RESULT_DENIED
        if mid not in table:
            return mavlink.MAV_RESULT_UNSUPPORTED
        iv = table.set(mid, interval_us, time.monotonic())
        if iv is not None:
            name = mavlink.mavlink_map[mid].msgname
            self.sim.event("interval", f"{name} every {iv:g} s on the {by.link} link" if iv > 0
                           else f"{name} off on the {by.link} link")
        return mavlink.MAV_RESULT_ACCEPTED

    def _clock_ns(self) -> int:
        """The vehicle's clock for TIMESYNC: simulation time (ns), as PX4 uses its own clock in
        lockstep; on the wall clock it runs on between physics steps. Never 0: a TIMESYNC with
        tc1 = 0 is a request, not an answer."""
        t = self.pace.time_s(time.monotonic()) if self.freerun else self.t
        return max(int(t * 1e9), 1)


def run_vehicle(flight: Flight, cfg: VehicleConfig, out: str | Path | None = None, overwrite: bool = False) -> int:
    """``bsst vehicle``: serve until SIGTERM or SIGINT; status lines on stdout; exit status 0."""
    path = side_dir(out, ("vehicle.tlog", "vehicle.csv"), overwrite) if out is not None else None
    emit = status_printer()
    v = Vehicle(flight, cfg, path, emit)
    on_stop_signals(v.stop)
    v.run()
    emit("stats " + json.dumps({"accepted": v.accepted, "rejected": v.rejected, "odometry_sent": v.odometry_sent,
                                "received": v.link.received, "overruns": v.pace.rebased, "steps": v.k,
                                "rejected_from_controller": v.rejected.from_peer,
                                "resends": v.resends, "answered_again": v.answered_again,
                                "up": v.vend.up.stats.summary() if cfg.clock == "lockstep" else None}))
    return 0

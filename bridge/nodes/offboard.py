"""The ground-side offboard controller as a MAVLink 2 endpoint: ``bsst controller``.

In:  ODOMETRY from the vehicle (NED position m, FRD body velocity m/s, quaternion FRD to NED, FRD rates
     rad/s; ``time_usec`` us), its HEARTBEAT (armed, system status), COMMAND_ACK, TIMESYNC, STATUSTEXT
Out: one actuator target per state answered, stamped with its ``time_usec``: HIL_ACTUATOR_CONTROLS
     (``motors``: c1..c4 = omega / omega_max, each in [0, 1]) or SET_ACTUATOR_CONTROL_TARGET group 0
     (``wrench``: roll, pitch, yaw in [-1, 1], thrust in [0, 1]), or the no-target acknowledgement;
     ARM_DISARM, HEARTBEAT at 1 Hz (10 Hz until the vehicle's is heard), TIMESYNC every 0.5 s;
     ``controller.tlog``, ``controller.csv`` rows; reports on stdout (:mod:`bridge.nodes.report`); the outcome

It flies a mission against any vehicle that keeps the contract of docs/design.md, "The MAVLink contract": it
sends its own HEARTBEAT, waits for the vehicle's, arms it (COMMAND_LONG ARM_DISARM, until
ACKed), answers each ODOMETRY with the law's actuator target stamped with the state's
time_usec, and at the end of the mission disarms it (forced: it may be in the air) and
returns its outcome: ``completed``, ``failsafe``, ``diverged`` or ``aborted``.

- **lockstep** (default): event-driven. The state of step k (t_k = k / rate_hz, k from
  time_usec) is answered once, at once; a repeated state gets the same answer again
  (the vehicle resends when a datagram is lost). Mission time is counted from the first
  state after arming, in steps, so a fresh vehicle flies exactly the offline loop's times.
  The mission's ``[link]`` model acts here on the states after they cross the socket, in
  simulation time (:class:`bridge.link.ends.ControllerEnd`, the offline loop's end): state k
  enters the ``down`` model at t_k and the guard controls on the newest one delivered.
  Every step is answered, also when the guard sends no command: then with the no-target
  acknowledgement (HIL_ACTUATOR_CONTROLS, SAFETY_ARMED clear in ``mode``), so that the
  vehicle's step clock, and its failsafe timeout, run on as offline.
- **realtime**: a drift-free fixed-rate schedule (tick j at T0 + j / rate_hz, never
  re-based on a late tick), phase-locked just after the first state's arrival; each tick
  controls on the newest state (the link model, if any, is on the wire: ``bsst relay``).
  A tick whose state (k0 + j) is not in yet waits for it at most half a period, as a flight
  stack's rate loop polls for its estimate with a timeout, then controls on what it has
  (counted in ``stale_ticks``). The mission time of tick j is the vehicle's: j / rate_hz
  plus the states' way down (their arrival phase less the vehicle's clock offset from
  TIMESYNC) plus the tick's PHASE_S after the arrival, so the reference is sampled at
  the vehicle's now and each state's age includes its trip, as in lockstep: the guard and
  ``compensation = "predict"`` see the whole delay.
  Each row records the tick's lateness (the period error) and the state-to-command round
  trip estimated with TIMESYNC.

A state is taken only from the vehicle's sysid, finite and in range, and with a stamp that
follows the newest one accepted (:func:`stamp_problem`): not older, and ahead by no more than
the wall time since (at up to twice real time) plus a slack. Anything else is refused and
counted (``stale``; ``stamp_jump`` for a jump of the mission's time either way), so no single
datagram, e.g. one stamped days ahead, can end the mission or make its time jump.

The law runs under a :class:`controller.link_guard.LinkGuard` (the mission's ``[link]``
``stale_ms``, ``stop_ms``, ``compensation`` and ``[failsafe] resume``): stale state freezes
the super-twisting integrators, older state stops the commands, and when the vehicle has
left offboard control (its HEARTBEAT: not armed, or system_status CRITICAL) it sends
nothing but, with ``resume``, asks it to arm again (ARM_DISARM, through the link model in
lockstep) once the state is fresh. A failsafe does not end the flight: the controller keeps
answering steps to the mission's end, whose outcome is then ``failsafe`` unless the vehicle
was back under offboard control. A vehicle that a ground station switches out of OFFBOARD while
armed (its PX4 HEARTBEAT's ``custom_mode``: HOLD, LAND, TAKEOFF, not in its failsafe) is the ground
station's: no more targets are sent, the flight ends ``aborted`` with that reason, and the session
names the ground station from the vehicle's event. Parameter changes scheduled at mission times
(``--param-at``, :class:`bridge.autopilot.params.ParamChange`) go out as PARAM_SET just before the
answer of their step. Each command is sent first, then its row of
``controller.csv`` (:data:`CONTROLLER_COLUMNS`, one ``write`` each, so the file is whole
up to its last row whatever kills the process). A controller killed between the send and
the write leaves one command without its row: the session keeps the steps flown on that
command in ``trace.csv`` with the law's demand unknown (NaN; ``missing_rows``) rather than
guess it.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from bridge.autopilot.params import BY_NAME, ParamChange
from bridge.core.clock import FixedRate
from bridge.core.flight import Flight
from bridge.core.wire import command_to_wire, odometry_to_state, step_of_usec
from bridge.link.ends import ControllerEnd
from bridge.link.model import LinkImpairment
from bridge.mavlink.endpoint import (
    CONTROLLER_COMPID,
    CONTROLLER_SYSID,
    FORCE_DISARM,
    HIL_ACTUATOR_CONTROLS,
    SET_ACTUATOR_CONTROL_TARGET,
    Address,
    Endpoint,
    Tlog,
    wait,
)
from bridge.mavlink.modes import MAIN_OFFBOARD, PARAM_TYPES, main_mode, param_to_wire, shown_name
from bridge.mavlink.receive import Rejections, odometry_problem
from bridge.mavlink.signing import Signing
from bridge.nodes.process import on_stop_signals, report_printer
from bridge.nodes.report import Done, Event, Ready, Report, Stats, StatusText, Warning
from bridge.record.columns import CONTROLLER_COLUMNS
from bridge.record.runlog import LineWriter, side_dir
from controller.link_guard import LinkGuard

OUTCOMES = ("completed", "failsafe", "diverged", "aborted")
PHASE_S = 0.0003  # realtime: tick this long after the state's arrival (its one-way trip and decode)
PHASE_STATES = 5  # realtime: states watched to find the phase of the vehicle's clock
# realtime: a tick whose state is not in yet waits for it at most this share of a period (a
# late wake-up of the vehicle would otherwise cost the step: the law would answer the state
# before, and its target would be two periods old when the next step begins); the rest of
# the period is the target's way back
STATE_WAIT_PERIODS = 0.5
# real time: a way down (state stamp to arrival, by TIMESYNC) outside [-slack, max] means the
# vehicle's stamps and its TIMESYNC clock differ; the ages then count from the arrivals
WAY_DOWN_SLACK_S = 0.005
WAY_DOWN_MAX_S = 2.0
SPIN_BEFORE_TICK_S = 0.0003  # realtime: sleep until this long before a tick, then poll: select wakes late
# a state's stamp may run ahead of the newest accepted state's by one step, plus the wall time
# between their arrivals at up to STAMP_PACE x real time (a vehicle's stamps follow its steps:
# lockstep answers or the wall clock; the factor lets a stream that fell behind catch up),
# plus STAMP_SLACK_S (losses while the controller read late) and, in real time, twice the
# down link's jitter and its bandwidth queue (one state delayed more than the next). Further
# ahead, or further back than the slack, is a jump of the mission's time: stamp_jump
STAMP_PACE = 2.0
STAMP_SLACK_S = 0.5
HOUSEKEEPING_S = 0.05
_ZERO12 = (0.0,) * 12
_ZERO16 = (0.0,) * 16
_NAN4 = (math.nan,) * 4


def stamp_problem(usec: int, newest_usec: int, since_s: float, period_s: float, slack_s: float) -> str | None:
    """Why a state stamped ``usec`` (us) cannot follow the newest state accepted, stamped
    ``newest_usec`` (-1: none yet, nothing to compare with) and received ``since_s`` wall
    seconds ago, or None. Older is ``stale`` (reordered on the way) within ``slack_s`` and a
    jump back beyond; ahead by more than one period ``period_s`` plus :data:`STAMP_PACE` x
    ``since_s`` plus ``slack_s`` is a jump forward. Both are ``stamp_jump``: the state would
    move the mission's time (and a far-future one would end the mission at once)."""
    if newest_usec < 0:
        return None
    ahead_s = (usec - newest_usec) * 1e-6
    if ahead_s < 0.0:
        return "stamp_jump" if -ahead_s > slack_s else "stale"
    return "stamp_jump" if ahead_s > period_s + STAMP_PACE * max(since_s, 0.0) + slack_s else None


def stamp_slack_s(flight: Flight, clock: str) -> float:
    """:data:`STAMP_SLACK_S`, plus in real time what the down link (the relay's, on the wire)
    may take from one state's delay and not the next's: twice its jitter, its bandwidth queue."""
    if clock == "lockstep":  # the down model acts here, after the socket: states cross it in order
        return STAMP_SLACK_S
    d = flight.link.down
    return STAMP_SLACK_S + 2e-3 * d.jitter_ms + (1e-3 * d.queue_ms if d.rate_bps else 0.0)


@dataclass(frozen=True)
class OffboardConfig:
    """Where the vehicle is and how to fly it (see the module docstring)."""

    vehicle: Address
    sysid: int = CONTROLLER_SYSID
    compid: int = CONTROLLER_COMPID
    clock: str = "lockstep"
    target_sysid: int | None = None  # None: the first autopilot that sends a heartbeat
    connect_timeout_s: float = 10.0  # s of wall time to wait for the vehicle's heartbeat
    vehicle_timeout_s: float = 2.0  # s of wall time without any message: the vehicle is lost
    spin_s: float = 0.0002  # as the vehicle's (bridge.nodes.vehicle.VehicleConfig.spin_s)
    timesync_s: float = 0.5
    key: bytes | None = field(default=None, repr=False)  # MAVLink 2 signing key (never shown)
    source_port: int = 0  # local UDP port it sends from (0: any free one; bsst sitl pins it for the vehicle)


class Offboard:
    """One offboard controller flying one mission; :meth:`run` returns the outcome."""

    def __init__(self, flight: Flight, cfg: OffboardConfig, out: Path | None = None,
                 status: Callable[[Report], None] | None = None) -> None:
        self.flight = flight
        self.cfg = cfg
        m = flight.mission
        self.rate = m.rate_hz
        self.steps = m.steps
        self.ctl = flight.make_controller()
        self.guard = LinkGuard(self.ctl, flight.guard)
        # lockstep: the mission's down-link model acts here, on what crossed the socket; real
        # time: the relay applies it on the wire and this end passes the states straight on
        down = flight.link.make()[1] if cfg.clock == "lockstep" else LinkImpairment(direction="down")
        self.cend = ControllerEnd(self.guard, down)
        self._blackouts = flight.blackout_notes()
        self._noted = 0  # guard events already reported
        self._u = self._wire = (0.0, 0.0, 0.0, 0.0)  # the last command sent: demanded, on the wire (as offline)
        self.failsafe_seen = False  # the vehicle reported its failsafe (CRITICAL since we armed it)
        # a scheduled blackout of the real wire (the relay) silences the vehicle: wait that much longer
        self._silence_s = cfg.vehicle_timeout_s + max(
            (d for _, d in flight.link.up.blackouts + flight.link.down.blackouts), default=0.0)
        self._sample = m.trajectory.sample
        self.actuation = flight.profile.actuation
        self._status = status or (lambda report: None)
        self.tlog = Tlog(out / "controller.tlog") if out is not None else None
        self.rejected = Rejections()  # what the receive path refused (bridge.mavlink.receive)
        self.ep = Endpoint(cfg.vehicle, sysid=cfg.sysid, compid=cfg.compid, tlog=self.tlog, name="--vehicle",
                           signing=Signing(cfg.key) if cfg.key is not None else None, rejected=self.rejected,
                           source_port=cfg.source_port)
        self._odo_usec = -1  # time_usec of the newest state accepted: an older one is stale
        self._stamp_slack_s = stamp_slack_s(flight, cfg.clock)  # how far a stamp may jump (stamp_problem)
        self.rows = (LineWriter(out / "controller.csv", ",".join(CONTROLLER_COLUMNS), batch=1)
                     if out is not None else None)
        self.stopping = False
        self._heard = False  # a heartbeat of the vehicle arrived
        self.vsys: int | None = cfg.target_sysid
        self.vcomp = 1
        self.armed_seen = False  # the vehicle's heartbeat showed it armed since we armed it
        self.vehicle_armed = False
        self.vehicle_state = mavlink.MAV_STATE_UNINIT
        self._odo: Any = None  # newest ODOMETRY not yet used
        self._odo_recv = 0.0
        self._acks: dict[int, int] = {}
        now = time.monotonic()
        self._last_rx = now
        self._last_state = now  # wall time of the newest state flown
        self._next_hb = now
        self._next_ts = now
        self._next_house = now
        self._ts_best: tuple[int, int] | None = None  # (rtt ns, offset ns) of the best recent TIMESYNC
        self._ts_age = 0
        self.offset_ns: int | None = None  # vehicle clock - our clock
        self.rtt_ns: int | None = None
        self.stale_ticks = 0
        self.schedule: FixedRate | None = None  # realtime: the tick schedule, once phase-locked
        self.commands = 0
        self.states = 0
        self.t_mission = 0.0
        self.reason = ""
        self.left_lockstep = ""  # the vehicle's STATUSTEXT saying it left lockstep, if it did
        self.taken_over = ""  # the mode a ground station switched the armed vehicle to (PX4 custom_mode), if any
        self.ended_taken_over = False  # the flight ended for it (no more targets sent)
        self._changes = list(flight.param_changes)  # scheduled PARAM_SETs not sent yet, by mission time

    @property
    def overruns(self) -> int:
        """Real-time ticks skipped because the process woke more than a period late."""
        return self.schedule.skipped if self.schedule else 0

    def stop(self) -> None:
        """Ask :meth:`run` to return (safe from a signal handler): outcome ``aborted``."""
        self.stopping = True

    # -- the flight ---------------------------------------------------------------------------
    def run(self) -> str:
        """Connect, arm, fly, disarm; the outcome (one of :data:`OUTCOMES`)."""
        self._status(Ready("controller", vehicle=self.cfg.vehicle.hostport,
                           local=f"{self.ep.local[0]}:{self.ep.local[1]}", clock=self.cfg.clock))
        try:
            if not self._connect() or not self._arm():
                return "aborted"
            outcome = self._fly_lockstep() if self.cfg.clock == "lockstep" else self._fly_realtime()
            if outcome == "completed" and not self._disarm():
                self.reason = "the vehicle did not acknowledge the disarm"
            return outcome
        finally:
            self.close()

    def close(self) -> None:
        if self.rows is not None:
            self.rows.close()
        if self.tlog is not None:
            self.tlog.close()
        self.ep.close()

    def event(self, kind: str, text: str) -> None:
        self._status(Event.at(self.t_mission, kind, text))

    def _connect(self) -> bool:
        deadline = time.monotonic() + self.cfg.connect_timeout_s
        while self.vsys is None or not self._heard:
            if self.stopping:
                return False
            now = time.monotonic()
            if now >= deadline:
                self.reason = (f"no heartbeat from a vehicle at {self.cfg.vehicle} "
                               f"within {self.cfg.connect_timeout_s:g} s")
                self.event("aborted", self.reason)
                return False
            self._serve(min(deadline, self._next_house))
        self.event("connected", f"vehicle sysid {self.vsys} compid {self.vcomp}")
        return True

    def _arm(self) -> bool:
        result = self._command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1.0, 0.0)
        if result != mavlink.MAV_RESULT_ACCEPTED:
            self.reason = "arming not acknowledged" if result is None else f"arming refused (MAV_RESULT {result})"
            self.event("aborted", self.reason)
            return False
        # armed under offboard control from now on: its state of step k0 may come before the heartbeat saying so
        self.vehicle_armed = self.armed_seen = True
        self.vehicle_state = mavlink.MAV_STATE_ACTIVE
        self.event("armed", "vehicle armed, offboard control")
        return True

    def _disarm(self) -> bool:
        result = self._command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0.0, float(FORCE_DISARM))
        ok = result == mavlink.MAV_RESULT_ACCEPTED
        self.event("disarmed" if ok else "disarm", "vehicle disarmed" if ok else "disarm not acknowledged")
        return ok

    def _command(self, cmd: int, p1: float, p2: float, tries: int = 30, every_s: float = 0.1) -> int | None:
        """COMMAND_LONG to the vehicle, repeated (confirmation 0, 1, ...) until ACKed. Every
        0.1 s: an ARM whose ACK was lost has armed the vehicle, whose failsafe takes over
        0.5 s later without a target (ARM_DISARM is idempotent)."""
        self._acks.pop(cmd, None)
        for n in range(tries):
            self.ep.send(mavlink.MAVLink_command_long_message(self.vsys or 0, self.vcomp, cmd, n, p1, p2,
                                                              0, 0, 0, 0, 0))
            deadline = time.monotonic() + every_s
            while time.monotonic() < deadline and not self.stopping:
                self._serve(deadline)
                if cmd in self._acks:
                    return self._acks.pop(cmd)
            if self.stopping:
                return None
        return None

    def _fly_lockstep(self) -> str:
        ep = self.ep
        rate = self.rate
        steps = self.steps
        send = self._answer
        k0 = last_k = None
        last_frame: tuple[int, tuple[float, ...] | None] | None = None
        spin = self.cfg.spin_s
        mono = time.monotonic
        self._last_state = mono()
        while not self.stopping:
            deadline = min(self._next_house, self._last_rx + self.cfg.vehicle_timeout_s)
            for _, m, _addr in wait((ep,), deadline, ep, spin):
                self._on(m)
            odo = self._odo
            if odo is not None:
                self._odo = None
                recv = self._odo_recv
                k = step_of_usec(odo.time_usec, rate)
                if k0 is None:
                    k0 = k
                if last_k is not None and k <= last_k:
                    if k == last_k and last_frame is not None:
                        send(*last_frame)  # the vehicle resent: our answer was lost
                    continue
                if k - k0 >= steps:
                    return self._end_of_mission()
                if self.taken_over:  # its HEARTBEAT came before this state: no answer to it
                    return self._check_vehicle() or "aborted"
                t = (k - k0) / rate
                self._observe(odo, t, recv)
                last_frame = (odo.time_usec, self._decide(t, k, odo.time_usec, recv, math.nan))
                last_k = k
                if mono() < self._next_house:
                    continue
            outcome = self._check_vehicle()
            if outcome:
                return outcome
            if mono() >= self._next_house:
                self._housekeeping()
        return "aborted"

    def _fly_realtime(self) -> str:
        rate = self.rate
        period = 1.0 / rate
        steps = self.steps
        mono = time.monotonic
        # phase-lock to the vehicle: ticks just after its states arrive. The phase is the
        # earliest arrival (recv - k / rate) over a few states, so one state that waited in
        # the socket while we were busy does not shift the schedule.
        self._odo = None
        self._last_state = mono()
        phase: float | None = None
        seen = 0
        while seen < PHASE_STATES and not self.stopping:
            outcome = self._check_vehicle()
            if outcome:
                return outcome
            self._serve(min(self._next_house, self._last_rx + self.cfg.vehicle_timeout_s))
            if self._odo is not None:
                k = step_of_usec(self._odo.time_usec, rate)
                p = self._odo_recv - k * period
                phase = p if phase is None else min(phase, p)
                seen += 1
                self._odo = None
        if self.stopping or phase is None:
            return "aborted"
        k0 = k + 1  # the mission starts with the next state
        self.schedule = clock = FixedRate(phase + k0 * period + PHASE_S, rate)
        last_k = k0 - 1
        usec, recv = 0, math.nan  # the newest state's stamp and arrival
        way_down: float | None = None  # the states' one-way trip (s), once TIMESYNC tells it
        j = 0
        while not self.stopping:
            self._sleep_until(clock.due(j))
            now = mono()
            j = clock.catch_up(j, now)  # missed ticks are skipped, the schedule kept (no drift)
            due = clock.due(j)
            late = now - due
            for m, _addr in self.ep.poll():
                self._on(m)
            self._await_state(k0 + j, due + STATE_WAIT_PERIODS * period)  # at once if it is in
            if way_down is None:
                way_down = self._way_down_s(phase)
            outcome = self._check_vehicle()
            if outcome:
                return outcome
            odo = self._odo
            if odo is None or step_of_usec(odo.time_usec, rate) <= last_k:
                self.stale_ticks += 1
                if last_k < k0:
                    j += 1
                    continue  # no state of the mission yet
            else:
                self._odo = None
                k = step_of_usec(odo.time_usec, rate)
                if last_k < k0 and j:
                    # the first state of the mission came after the first tick (the earlier
                    # ones were lost): the mission starts with it, as the trace does
                    k0, j = k, 0
                    self.schedule = clock = FixedRate(due, rate, clock.skipped)
                if k - k0 >= steps:
                    return self._end_of_mission()
                usec, recv = odo.time_usec, self._odo_recv
                self._observe(odo, (k - k0) / rate, recv)
                last_k = k
            # mission time of this tick on the vehicle's clock: state k0 + j was measured at
            # j / rate, arrived the way down later, and the tick is PHASE_S after its arrival
            t = j / rate + (way_down + PHASE_S if way_down is not None else 0.0)
            j += 1
            self._decide(t, last_k, usec, recv, late)
        return "aborted"

    def _way_down_s(self, phase: float) -> float | None:
        """Real time: the one-way trip of the earliest-arriving states (s, >= 0), from the
        phase of their arrivals and the vehicle's clock offset by TIMESYNC; None until a
        TIMESYNC answer is in. The offset takes the two ways as equal, so an asymmetric link
        (a delay on the way down only) is credited with half of the difference."""
        if self.offset_ns is None:
            return None
        trip = phase + self.offset_ns * 1e-9
        if not -WAY_DOWN_SLACK_S <= trip <= WAY_DOWN_MAX_S:
            # the stamps and TIMESYNC are not on one clock: count ages from the arrivals
            self.event("timesync", f"the states' way down comes out at {trip * 1e3:.1f} ms: "
                                   "not counted in their age (stamps and TIMESYNC on different clocks?)")
            return 0.0
        return max(trip, 0.0)

    def _observe(self, odo: Any, t_state: float, recv: float) -> None:
        """A new state of the vehicle, measured at mission time ``t_state`` (s), crossed the
        socket: into the down-link model with the vehicle's offboard bit (its HEARTBEAT:
        armed and not CRITICAL; sent before the state on every change, so it is this step's)."""
        X = odometry_to_state((odo.x, odo.y, odo.z), odo.q, (odo.vx, odo.vy, odo.vz),
                              (odo.rollspeed, odo.pitchspeed, odo.yawspeed))
        self.cend.receive_state(t_state, X, self.vehicle_armed and self.vehicle_state != mavlink.MAV_STATE_CRITICAL)
        self._last_state = recv

    def _decide(self, t: float, k: int, time_usec: int, recv: float, late: float) -> tuple[float, ...] | None:
        """The control step at mission time t (s): the guard decides on the newest state the
        model delivered; its command (or, in lockstep, the no-target acknowledgement) is sent
        at once, stamped ``time_usec``, then the row (the trace's columns, as offline: the last
        command's u and c, ``state_age_s`` of this step's command, nan without one). Returns
        the wire values sent, None for none."""
        self.t_mission = t
        while self._blackouts and self._blackouts[0][0] <= t:
            self.event("blackout", self._blackouts.pop(0)[1])
        while self._changes and self._changes[0].step(self.rate) <= round(t * self.rate):
            self._send_param(self._changes.pop(0))
        dec = self.cend.step(t, self._sample)
        events = self.guard.events
        while self._noted < len(events):
            _, kind, text = events[self._noted]
            self._noted += 1
            self.event(kind, text)
        if dec.arm:
            self._send_arm()
        cmd = dec.command
        wire = None
        if cmd is not None:
            wire = command_to_wire(self.actuation, cmd.normalised)
            sent = time.monotonic()
            self._send_target(time_usec, wire)
            self._u, self._wire = cmd.demanded, wire
        else:
            sent = time.monotonic()
            if self.cfg.clock == "lockstep":
                self._send_no_target(time_usec)
        s2c = self._state_to_command(time_usec, sent) if cmd is not None and self.cfg.clock == "realtime" else math.nan
        self._row(k, t, self._sample(t), self._u, self._wire, self.ctl.law.desired, recv, sent, s2c, late,
                  dec.state_age_s if cmd is not None else math.nan)
        return wire

    def _end_of_mission(self) -> str:
        """The mission's steps are flown: ``failsafe`` if the vehicle's failsafe took over and
        it is not back under offboard control, else ``completed``. A vehicle its failsafe
        landed and disarmed is disarmed by command too, which ends its lockstep flight."""
        back = self.vehicle_armed and self.vehicle_state != mavlink.MAV_STATE_CRITICAL
        if not self.failsafe_seen or back:
            return "completed"
        self.reason = "the vehicle's failsafe took over (HEARTBEAT system_status CRITICAL)"
        self.event("failsafe", self.reason)
        if not self.vehicle_armed:
            self._disarm()
        return "failsafe"

    def _sleep_until(self, due: float) -> None:
        """Serve the link until ``due``: select until shortly before, then poll to the tick."""
        mono = time.monotonic
        while not self.stopping:
            now = mono()
            if now >= due:
                return
            if now >= self._next_house:
                self._housekeeping()
            if due - now > SPIN_BEFORE_TICK_S:
                for _, m, _addr in wait((self.ep,), min(due - SPIN_BEFORE_TICK_S, self._next_house)):
                    self._on(m)
            else:
                for m, _addr in self.ep.poll():
                    self._on(m)

    def _await_state(self, k: int, deadline: float) -> None:
        """Serve the link until the state of step ``k`` (or a newer one) is in, or ``deadline``."""
        rate = self.rate
        while not self.stopping and (self._odo is None or step_of_usec(self._odo.time_usec, rate) < k):
            if time.monotonic() >= deadline:
                return
            for _, m, _addr in wait((self.ep,), deadline):
                self._on(m)

    def _state_to_command(self, time_usec: int, sent: float) -> float:
        """State-to-command round trip (s) by TIMESYNC: from the state's time, on the vehicle's
        clock mapped onto ours, to our send, plus half a TIMESYNC round trip for the way up."""
        if self.offset_ns is None or self.rtt_ns is None:
            return math.nan
        state_ns = time_usec * 1000 - self.offset_ns
        return (sent * 1e9 - state_ns + 0.5 * self.rtt_ns) * 1e-9

    # -- messages ----------------------------------------------------------------------------------
    def _answer(self, time_usec: int, wire: tuple[float, ...] | None) -> None:
        """Send the answer to the state stamped ``time_usec`` again: its target, or no target."""
        if wire is None:
            self._send_no_target(time_usec)
        else:
            self._send_target(time_usec, wire)

    def _send_no_target(self, time_usec: int) -> None:
        """Lockstep: acknowledge the step of the state stamped ``time_usec`` without a valid
        target (HIL_ACTUATOR_CONTROLS, flags bit 0 lockstep, ``mode`` without SAFETY_ARMED, as
        PX4 clocks its simulator while its outputs are disarmed; for either actuation)."""
        self.ep.send_hot(HIL_ACTUATOR_CONTROLS, (time_usec, 1, *_ZERO16, 0))

    def _send_arm(self) -> None:
        """Ask the vehicle to arm again (the guard's ``resume``); once per step while it asks."""
        self.ep.send(mavlink.MAVLink_command_long_message(self.vsys or 0, self.vcomp,
                                                          mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1.0, 0.0,
                                                          0, 0, 0, 0, 0))

    def _send_param(self, change: ParamChange) -> None:
        """A scheduled parameter change (``--param-at``): PARAM_SET before this step's answer, so
        that in lockstep the vehicle makes it before it flies the step (the same step as offline)."""
        kind = PARAM_TYPES[BY_NAME[change.name].kind]
        self.ep.send(mavlink.MAVLink_param_set_message(self.vsys or 0, self.vcomp, change.name.encode(),
                                                       param_to_wire(change.value, kind), kind))
        self.event("param", f"set {change.name} = {change.value:g}")

    def _send_target(self, time_usec: int, wire: tuple[float, ...]) -> None:
        """The actuator target answering the state stamped ``time_usec`` (hot path)."""
        self.commands += 1
        if self.actuation == "motors":
            flags = 1 if self.cfg.clock == "lockstep" else 0  # bit 0: lockstep
            self.ep.send_hot(HIL_ACTUATOR_CONTROLS, (time_usec, flags, *wire, *_ZERO12,
                                                     mavlink.MAV_MODE_FLAG_SAFETY_ARMED))
        else:  # control group 0
            self.ep.send_hot(SET_ACTUATOR_CONTROL_TARGET, (time_usec, *wire, 0.0, 0.0, 0.0, 0.0, 0,
                                                           self.vsys or 0, self.vcomp))

    def _row(self, k: int, t: float, ref: Any, u: Any, wire: Any, desired: Any, recv: float, sent: float,
             s2c: float, late: float, age: float) -> None:
        if self.rows is not None:
            self.rows.write(",".join(map(repr, (k, t, ref[0][0], ref[1][0], ref[2][0], ref[3][0], *u, *wire,
                                                *desired, recv, sent, s2c, late, age))))

    def _serve(self, deadline: float) -> None:
        for _, m, _addr in wait((self.ep,), deadline):
            self._on(m)
        if time.monotonic() >= self._next_house:
            self._housekeeping()

    def _on(self, m: Any) -> None:
        """Any message from the link (ODOMETRY is kept for the flight loop, newest only)."""
        src = m.get_srcSystem()
        kind = m._type
        if kind == "ODOMETRY":  # checked before the law sees it (bridge.mavlink.receive)
            now = time.monotonic()
            why = ("sender" if src != self.vsys
                   else stamp_problem(m.time_usec, self._odo_usec, now - self._odo_recv, 1.0 / self.rate,
                                      self._stamp_slack_s) or odometry_problem(m))
            if why:
                self.rejected.add(why, True)
                return
            self._odo_usec = m.time_usec
            self.states += 1
            self._odo = m
            self._odo_recv = self._last_rx = now
            return
        if kind == "HEARTBEAT":
            if m.autopilot == mavlink.MAV_AUTOPILOT_INVALID or m.type == mavlink.MAV_TYPE_GCS:
                return
            if self.vsys is None:
                self.vsys, self.vcomp = src, m.get_srcComponent()
            if src != self.vsys:
                return
            self._heard = True
            self._last_rx = time.monotonic()
            self.vehicle_armed = bool(m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
            self.vehicle_state = m.system_status
            if self.vehicle_armed:
                self.armed_seen = True
            if self.armed_seen and m.system_status == mavlink.MAV_STATE_CRITICAL:
                # armed: flying its failsafe; disarmed: landed by it (on a real link the armed
                # CRITICAL heartbeat may have been lost), or halted by divergence
                self.failsafe_seen = True
            elif (self.vehicle_armed and m.autopilot == mavlink.MAV_AUTOPILOT_PX4 and not self.taken_over
                  and main_mode(m.custom_mode) != MAIN_OFFBOARD):
                # armed, not in its failsafe, out of OFFBOARD: a ground station took it (HOLD, LAND, ...)
                self.taken_over = shown_name(m.custom_mode)
            return
        if src != self.vsys:
            return
        self._last_rx = time.monotonic()
        if kind == "COMMAND_ACK":
            if m.target_system in (0, self.cfg.sysid):
                self._acks[m.command] = m.result
        elif kind == "TIMESYNC":
            self._timesync(m)
        elif kind == "STATUSTEXT":
            text = m.text.rstrip("\x00") if isinstance(m.text, str) else m.text.decode(errors="replace")
            self._status(StatusText(m.severity, text))
            if text.startswith("lockstep:") and not self.left_lockstep:  # not a lockstep flight any more
                self.left_lockstep = text

    def _timesync(self, m: Any) -> None:
        now = time.monotonic_ns()
        if m.tc1 == 0:  # a request: answer with our clock
            self.ep.send(mavlink.MAVLink_timesync_message(now, m.ts1))
            return
        rtt = now - m.ts1
        if rtt < 0 or rtt > 1_000_000_000:
            return
        offset = m.tc1 - (m.ts1 + now) // 2
        # keep the sample with the smallest round trip among the last few: its offset is the
        # least disturbed by queueing on either side
        self._ts_age += 1
        if self._ts_best is None or rtt <= self._ts_best[0] or self._ts_age > 8:
            self._ts_best = (rtt, offset)
            self._ts_age = 0
        self.rtt_ns, self.offset_ns = self._ts_best

    def _check_vehicle(self) -> str | None:
        """The outcome if the vehicle is lost to the flight (silent, no more states, disarmed
        other than by its failsafe, taken out of OFFBOARD by a ground station), else None. Its
        failsafe alone does not end the flight."""
        now = time.monotonic()
        timeout = self._silence_s
        if self.taken_over:
            self.reason = f"the vehicle was switched to {self.taken_over}: no more targets sent"
            self.ended_taken_over = True
        elif now - self._last_rx > timeout:
            self.reason = f"vehicle silent for {timeout:g} s"
        elif self.armed_seen and not self.vehicle_armed and not self.failsafe_seen:
            self.reason = "the vehicle was disarmed during the mission"
        elif now - self._last_state > timeout:
            self.reason = f"no new state from the vehicle for {timeout:g} s"
        else:
            return None
        outcome = "failsafe" if self.failsafe_seen else "aborted"
        self.event(outcome, self.reason)
        return outcome

    def _housekeeping(self) -> None:
        now = time.monotonic()
        if now >= self._next_hb:
            # 1 Hz; 10 Hz until the vehicle is heard: one lost to a vehicle still starting costs 0.1 s, not 1 s
            self._next_hb = now + (1.0 if self._heard else 0.1)
            self.ep.send(mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_ONBOARD_CONTROLLER,
                                                           mavlink.MAV_AUTOPILOT_INVALID, 0, 0,
                                                           mavlink.MAV_STATE_ACTIVE, 3))
        if now >= self._next_ts and self.vsys is not None:
            self._next_ts = now + self.cfg.timesync_s
            self.ep.send(mavlink.MAVLink_timesync_message(0, time.monotonic_ns()))
        refused = self.rejected.report(now)
        if refused is not None:
            self._status(Warning(refused))
        if self.tlog is not None:
            self.tlog.flush()
        # no TIMESYNC before a vehicle is known: its due time must not hold the loop awake
        self._next_house = min(self._next_hb, self._next_ts if self.vsys is not None else math.inf,
                               now + HOUSEKEEPING_S)


def run_controller(flight: Flight, cfg: OffboardConfig, out: str | Path | None = None,
                   overwrite: bool = False) -> int:
    """``bsst controller``: fly, then exit 0 if the mission completed (in lockstep: without the vehicle
    leaving it), else 1 (failsafe, diverged, aborted, or lockstep left)."""
    path = side_dir(out, ("controller.tlog", "controller.csv"), overwrite) if out is not None else None
    emit = report_printer()
    node = Offboard(flight, cfg, path, emit)
    on_stop_signals(node.stop)
    outcome = node.run()
    emit(Stats({"commands": node.commands, "states": node.states, "received": node.ep.received,
                "sent": node.ep.sent, "stale_ticks": node.stale_ticks, "overruns": node.overruns,
                "down": node.cend.down.stats.summary() if cfg.clock == "lockstep" else None,
                "rejected": dict(node.rejected), "rejected_from_vehicle": node.rejected.from_peer}))
    left = bool(node.left_lockstep)
    emit(Done(outcome, left, node.reason or None, node.taken_over if node.ended_taken_over else None))
    if outcome != "completed":
        sys.stderr.write(f"bsst controller: {outcome}" + (f": {node.reason}" if node.reason else "") + "\n")
    elif left:
        sys.stderr.write(f"bsst controller: completed, but not in lockstep: the vehicle said {node.left_lockstep!r}\n")
    return 0 if outcome == "completed" and not left else 1

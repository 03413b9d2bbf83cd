"""The offboard controller's flight: connect, arm, fly each step, disarm; its outcome (:mod:`bridge.nodes.offboard`).

In:  the vehicle's states and state of mind through :class:`~bridge.nodes.offboard.link.OffboardLink`; the
     :class:`~bridge.core.flight.Flight` (mission, law, link guard, ``[link]`` down model, parameter changes)
Out: one answer per state (lockstep) or per tick (real time, s on the wall clock); ``controller.bin`` records
     (:data:`~bridge.record.columns.CONTROLLER_COLUMNS`); the outcome (:data:`OUTCOMES`) and why
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from bridge.core.clock import FixedRate, Stalls
from bridge.core.flight import Flight
from bridge.core.wire import command_over_wire, step_of_usec
from bridge.link.ends import ControllerEnd
from bridge.mavlink.endpoint import FORCE_DISARM, Spinner, wait
from bridge.mavlink.eventseq import REQUEST_TIMEOUT_S, REQUEST_TRIES
from bridge.mavlink.modes import MAIN_OFFBOARD, main_mode
from bridge.nodes.offboard.config import (
    OffboardConfig,
)
from bridge.nodes.offboard.endflight import EndFlying
from bridge.nodes.offboard.link import FailsafeSign
from bridge.nodes.offboard.radioturn import down_link
from bridge.nodes.report import Ready, Report
from bridge.record.columns import CONTROLLER_COLUMNS
from bridge.record.halves import HalfWriter
from controller.law import LawFailed
from controller.link_guard import LinkGuard
from missions.references import Prefetched

# crashed, collision, terminated: the vehicle's plant ended the flight, said by its EVENT (before the forty-second
# session such a flight was "failsafe", its HEARTBEAT EMERGENCY taken for one)
OUTCOMES = ("completed", "failsafe", "diverged", "crashed", "collision", "terminated", "aborted", "law_failed")
PARAM_SETTLE_S = 1.0  # s of wall time after the flight for the echoes of the last scheduled PARAM_SETs
END_ASK_S = 1.0  # s of wall time (real time) the vehicle is asked what ended its flight before the controller says
END_EVENT_TRIES = 30  # a HEARTBEAT EMERGENCY's EVENT missed is asked for (every 0.1 s) this many times, not 5


class Offboard(EndFlying):
    """One offboard controller flying one mission; :meth:`run` returns the outcome."""

    def __init__(self, flight: Flight, cfg: OffboardConfig, out: Path | None = None,
                 status: Callable[[Report], None] | None = None, vehicle: tuple[int, int] | None = None) -> None:
        self.flight = flight
        self._known = vehicle  # (sysid, compid) heard on the mission's download link (--await-mission), or None
        m = flight.mission
        self.steps = m.steps
        self.ctl = flight.make_controller()
        self._state_in = flight.wire()[1]  # ODOMETRY's fields to the state (compiled with the law's kernels)
        self.guard = LinkGuard(self.ctl, flight.guard)
        # lockstep: the mission's down-link model acts here, on what crossed the socket (a fleet's one radio: at
        # this controller's turns); real time: the relay applies it on the wire, states pass straight on
        down, self.turns = down_link(flight, cfg, self.event)
        self.cend = ControllerEnd(self.guard, down)
        self._blackouts = flight.blackout_notes()
        self._noted = 0  # guard events already reported
        self._u = self._wire = (0.0, 0.0, 0.0, 0.0)  # the last command sent: demanded, on the wire (as offline)
        # a scheduled blackout of the real wire (the relay) silences the vehicle: wait that much longer
        black = max((d for _, d in flight.link.up.blackouts + flight.link.down.blackouts), default=0.0)
        self._silence_s = cfg.vehicle_timeout_s + black
        self._state_wait_s = (cfg.state_timeout_s or cfg.vehicle_timeout_s) + black  # for a new state, heard
        self._sample = Prefetched(m.trajectory.sample)  # the next step's sampled once its command is out
        super().__init__(flight, cfg, out, status)
        self.spinner = Spinner(self.ep, cfg.spin_s)  # a lockstep state is polled for before sleeping
        self.rows = HalfWriter(out / "controller.bin", CONTROLLER_COLUMNS, batch=1) if out is not None else None
        self._states_rowed = 0  # self.states when the last row was written
        self._last_state = time.monotonic()  # wall time of the newest state flown
        self._started = False  # the mission's third state come (before it: start_timeout_s)
        self.stale_ticks = 0
        self.stalls = Stalls()  # real time: the mission's ticks the machine woke us too late for
        self.stalls_waiting = Stalls()  # real time: those before the mission's first state (not the mission's)
        self.schedule: FixedRate | None = None  # realtime: the tick schedule, once phase-locked
        self.reason = ""
        self.ended_taken_over = False  # the flight ended for a ground station's mode (no more targets sent)
        self.vehicle_silent = False  # the flight ended hearing nothing from the vehicle (Done.silent)
        self._changes = list(flight.param_changes)  # scheduled PARAM_SETs not sent yet, by mission time
        self._way_down: float | None = None  # real time: the states' way down (s), the vehicle's clock ahead of ours
        self.way_down: dict[str, float] | None = None  # real time: that in ms and how far off it may be (stats)
        self._end_usec: int | None = None  # lockstep: the stamp of the state that ended the mission, unanswered
        self._end_height_m = 0.0
        self._mission_zero: float | None = None
        self.disarmed_early: float | None = None  # real time: the mission time its failsafe's disarm ended the flight
        self._mission_end = math.inf
        self.end_unanswered: dict[str, Any] | None = None  # the end action not seen taken (its summary ``end``)
        self._end_ask_until: float | None = None  # real time: until when the vehicle is asked how its flight ended

    @property
    def overruns(self) -> int:
        """Real-time ticks skipped because the process woke more than a period late."""
        return self.schedule.skipped if self.schedule else 0

    def stop(self) -> None:
        """Ask :meth:`run` to return (safe from a signal handler): outcome ``aborted``."""
        self.stopping = True

    def run(self) -> str:
        """Connect, arm, fly, disarm; the outcome (one of :data:`OUTCOMES`)."""
        self._status(Ready("controller", vehicle=self.cfg.vehicle.hostport,
                           local=f"{self.ep.local[0]}:{self.ep.local[1]}", clock=self.cfg.clock))
        try:
            if not self._connect():
                return "aborted"
            if self.cfg.clock == "realtime":  # the machine's stalls from the ARM to the first tick: stalls_waiting
                self.watch_stalls()
            if not self._arm():
                return "aborted"
            try:
                outcome = self._fly_lockstep() if self.cfg.clock == "lockstep" else self._fly_realtime()
            except LawFailed as exc:  # a user's law failed (an exit too): no more targets, said why
                self.reason = f"{exc} at step {round(self.t_mission * self.rate)} (t={self.t_mission:.3f} s)"
                self.event("law_failed", self.reason)
                return "law_failed"
            self.end_t = min(self.end_t, self.vehicle_t())  # the mission's end, or where the flight stopped before it
            self._await_param_echoes()
            self._pending_params.clear()  # given up (said not made): not resent while the vehicle lands
            if outcome == "completed":
                outcome = self._fly_end()
            return outcome
        finally:
            self.close()

    def close(self) -> None:
        if self.rows is not None:
            self.rows.close()
        self.stop_reading()  # what the vehicle sent before now is read: summary.json's link.down, exact
        if self.tlog is not None:
            self.tlog.close()
        self.ep.close()
        if self.turns is not None:
            self.turns.close()

    def _await_param_echoes(self) -> None:
        """The flight is over: serve the link for up to PARAM_SETTLE_S of wall time more while a scheduled PARAM_SET
        is not echoed yet (one sent at the last steps: its echo is on its way; one after the end: not made)."""
        deadline = time.monotonic() + PARAM_SETTLE_S
        while self._pending_params and not self.stopping and time.monotonic() < deadline:
            self._serve(min(deadline, self._next_house))

    def _connect(self) -> bool:
        if self._known is not None:
            # the vehicle the mission came from, heard a moment ago: its arm's ACK says it is still there. On the
            # same source port (bsst sitl pins it) the vehicle sees no new controller, so no HEARTBEAT comes at once
            # (bridge.nodes.vehicle.receiver): waiting for one cost up to its 1 Hz period before every arm
            (self.vsys, self.vcomp), self._heard = self._known, True
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
        """ARM, resent until its ACK, or until the vehicle said otherwise what came of it (:meth:`_arm_settled`). One
        its failsafe took over before its answer came (a slow, lossy link) flies on as any failsafe's: no ARM
        sent again (it would arm the vehicle the failsafe disarmed), the flight's outcome ``failsafe``."""
        self.arming = True
        result = self._command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1.0, 0.0, settled=self._arm_settled)
        self.arming = False
        if result is None and self._arm_settled():
            result = mavlink.MAV_RESULT_ACCEPTED  # its HEARTBEAT or its failsafe said it armed
        if result != mavlink.MAV_RESULT_ACCEPTED:
            entry = mavlink.enums["MAV_RESULT"].get(result) if result is not None else None
            self.reason = ("arming not acknowledged" if result is None
                           else f"arming refused: {entry.name if entry else 'unknown result'} (MAV_RESULT {result})")
            self.event("aborted", self.reason)
            return False
        if self.failsafe_seen or self.plant_end:  # its HEARTBEAT since says what it is now, not the ACK
            self.armed_seen = True
            self.event("armed", "vehicle armed, offboard control; its failsafe took over before the controller had "
                                "the answer: no ARM sent again", answers=("armed",))
            return True
        # armed under offboard control from now on: its state of step k0 may come before the heartbeat saying so
        self.vehicle_armed = self.armed_seen = True
        self.vehicle_state = mavlink.MAV_STATE_ACTIVE
        self.event("armed", "vehicle armed, offboard control", answers=("armed",))
        return True

    def _arm_settled(self) -> bool:
        """While the ARM is resent: the vehicle said what came of it other than by its ACK, so no copy more goes: its
        HEARTBEAT shows it armed under offboard control (or flying its failsafe), or its failsafe took over or its
        plant ended the flight (a late copy would arm again the vehicle its failsafe disarmed)."""
        armed = self.vehicle_armed and (main_mode(self.vehicle_mode) == MAIN_OFFBOARD
                                        or self.vehicle_state == mavlink.MAV_STATE_CRITICAL)
        return armed or bool(self.failsafe_seen) or bool(self.plant_end)

    def _end_lockstep_flight(self) -> None:
        """A vehicle its failsafe disarmed, the mission's steps flown: a disarm by command, which ends its lockstep
        flight (time stands still, as after the end landing's disarm; else, unanswered, it would leave lockstep for
        the wall clock). Not an event when accepted: the vehicle disarmed itself, and said so at its time (until
        the third wave's thirty-ninth session a ``disarmed: vehicle disarmed`` event of the controller's at the
        mission's end said it again, after a geofence Return's disarm long before: offline has none)."""
        result = self._command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0.0, float(FORCE_DISARM))
        if result != mavlink.MAV_RESULT_ACCEPTED:
            self._at_end_now()
            self.event("disarm", "disarm not acknowledged")

    def _fly_lockstep(self) -> str:
        ep = self.ep
        rate = self.rate
        steps = self.steps
        send = self._answer
        k0 = last_k = None
        last_frame: tuple[int, tuple[float, ...] | None] | None = None
        spin = self.spinner
        mono = time.monotonic
        self._last_state = mono()
        while not self.stopping:
            deadline = min(self._next_house, self._last_rx + self.cfg.vehicle_timeout_s)
            for _, m, _addr in wait((ep,), deadline, spin):
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
                    self._end_usec = odo.time_usec  # its answer is the end action's first step
                    return self._end_of_mission((k - k0) / rate, odo)
                if self.taken_over:  # its HEARTBEAT came before this state: no answer to it
                    return self._check_vehicle() or "aborted"
                t = (k - k0) / rate
                if self.turns is None:
                    self._observe(odo, t, recv)
                else:  # a fleet's one radio: the states of step k enter it in the offline order
                    self.turns.enter(k - k0, ep, self._on, lambda o=odo, t=t, r=recv: self._observe(o, t, r))
                last_frame = (odo.time_usec, self._decide(t, k, odo.time_usec, recv, math.nan))
                last_k = k
                self._sample.ahead((k + 1 - k0) / rate)  # the next step's reference, while the vehicle flies
                if mono() < self._next_house:
                    continue
            outcome = self._check_vehicle()
            if outcome:
                return outcome
            if mono() >= self._next_house:
                self._housekeeping()
        return "aborted"

    def _observe(self, odo: Any, t_state: float, recv: float) -> None:
        """A new state of the vehicle, measured at mission time ``t_state`` (s), crossed the socket: into the
        down-link model with the vehicle's offboard bit (its HEARTBEAT: armed and not CRITICAL; sent before the
        state on every change, so it is this step's)."""
        q = odo.q  # odometry_to_state written out, flat (one call: the hot path; tests/test_wire.py)
        X = self._state_in((odo.x, odo.y, odo.z, q[0], q[1], q[2], q[3], odo.vx, odo.vy, odo.vz,
                                        odo.rollspeed, odo.pitchspeed, odo.yawspeed))
        self.cend.receive_state(t_state, X, self.vehicle_armed and self.vehicle_state != mavlink.MAV_STATE_CRITICAL)
        self._last_state, self._started = recv, t_state * self.rate > 1.5

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
            if kind == "link_restored" and self.cfg.clock == "realtime":  # (lockstep's model never loses one)
                self.ask_heartbeat()  # is it still under offboard control? (the HEARTBEAT saying not was lost)
        if dec.arm:
            self._send_arm()
        cmd = dec.command
        wire = None
        if cmd is not None:
            wire = command_over_wire(self.actuation, cmd.normalised)[1]  # float32: the row says what was sent
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

    def _end_of_mission(self, t_end: float, odo: Any, due: tuple[int, float] | None = None) -> str:
        """The mission's steps are flown (the state of mission time ``t_end``, s, came; or, real time, ``due``: its
        step and when it was due to arrive, s of time.monotonic, by the tick schedule, ``odo`` the newest state
        flown): ``failsafe`` if the vehicle's failsafe took over and it is not back under offboard control, else
        ``completed``. A vehicle its failsafe landed (lockstep) waits out its disarm on the step clock
        (:meth:`_clock_disarm`); one it disarmed is disarmed by command too, which ends its lockstep flight."""
        k, arrived = due if due is not None else (step_of_usec(odo.time_usec, self.rate), self._odo_recv)
        # on the vehicle's clock (the session orders both children's events by time): it measured that state
        # the way down before it came
        self.t_mission, self._t_wall = t_end, arrived - (self._way_down or 0.0)  # (its arrival: not when read)
        self._mission_zero, self._mission_end = k / self.rate - t_end, t_end
        self._end_height_m = max(-float(odo.z), 0.0)  # m above the start (NED z): the landing's time
        self._settle_events()
        lost = self._check_vehicle(at_end=True)  # disarmed, taken over, ... in the mission's last steps: not completed
        if lost:
            return lost
        back = self.vehicle_armed and self.vehicle_state != mavlink.MAV_STATE_CRITICAL
        if not self.failsafe_seen or back:
            return "completed"
        self.reason = f"the vehicle's failsafe took over ({self.failsafe_seen.value})"
        # stamped when it took over, its EVENT's time on the flight's clock (that state's step less the mission's
        # time is the first state's), not at the mission's end when it is judged; NaN without one
        took = math.nan if self.failsafe_at is None else self.failsafe_at - (k / self.rate - t_end)
        self.event("failsafe", self.reason, answers=("failsafe",), t=took)
        if self.vehicle_armed and self._resting():
            self._clock_disarm()
        if not self.vehicle_armed:
            self._end_lockstep_flight()
        return "failsafe"

    def _failsafe_disarmed(self) -> bool:
        """Real time, in the mission: whether the vehicle's failsafe has disarmed it (landed, or its ``disarm``
        action) with no ``[failsafe] resume`` to arm it again: nothing is left to fly. (Lockstep clocks the mission's
        steps to its end, as offline: :meth:`_end_of_mission`.)"""
        return (self.cfg.clock == "realtime" and self.armed_seen and not self.vehicle_armed and not self.ending
                and self.failsafe_seen not in (FailsafeSign.NONE, FailsafeSign.EMERGENCY)
                and not self.flight.failsafe.resume)

    def _end_failsafe_disarmed(self) -> str | None:
        """Real time: the vehicle's failsafe disarmed it in the mission (:meth:`_failsafe_disarmed`): the flight ends
        now, ``failsafe`` (not flown as asked, exit 1), said as at the mission's end (:meth:`_end_of_mission`) and
        when (:attr:`disarmed_early`), rather than after the rest of the mission's ticks, each answered with nothing
        (until the third wave's forty-third session ``bsst controller`` alone waited them out: 17 s of a 20 s
        mission its battery failsafe landed at 3 s; ``bsst sitl`` waited for it). None when an EVENT asked for again
        says its plant ended the flight (crashed, terminated: :meth:`_check_vehicle` names it next)."""
        self._settle_events()  # its failsafe's EVENT, missed, asked for again: when it took over
        if self.plant_end:
            return None
        self._at_end_now()
        took = math.nan if self.failsafe_at is None or self._mission_zero is None else \
            self.failsafe_at - self._mission_zero
        self.reason = f"the vehicle's failsafe took over ({self.failsafe_seen.value})"
        self.event("failsafe", self.reason, answers=("failsafe",), t=took)
        self.disarmed_early = self.t_mission
        return "failsafe"

    def _resting(self) -> bool:
        """Lockstep: whether the vehicle's failsafe has landed it (its EVENT LANDED since its latest FAILSAFE's), on
        the step clock still: on the ground, motors off, it only waits out COM_DISARM_LAND (> 0). Not in a fleet (its
        vehicle gated, given ``--state-timeout``): there a failsafe's landing after the mission leaves the shared
        clock, as offline flies it alone, told nothing (docs/swarm.md)."""
        return (self.cfg.clock == "lockstep" and self.cfg.state_timeout_s is None and not self.left_lockstep
                and self.flight.params.land_disarm_s > 0.0 and self.landed_at is not None
                and self.failsafe_at is not None and self.landed_at >= self.failsafe_at)

    def _clock_disarm(self) -> None:
        """A vehicle its failsafe landed before the mission's end waits out COM_DISARM_LAND on the step clock, each
        state answered with the no-target acknowledgement as the end landing's (:meth:`_await_landing`), so that it
        disarms where offline's does without leaving lockstep (until the third wave's thirty-ninth session it left
        lockstep for the wall clock, unanswered, and the run said it was not a lockstep run). The failsafe stays
        the reason the flight ended."""
        reason = self.reason
        self._await_landing()
        self.reason = reason

    def _settle_events(self) -> None:
        """Serve the link while EVENTs the vehicle sent are missed and asked for again (each given up after
        REQUEST_TRIES tries, eventseq): one of them may be a failsafe in the mission's last steps."""
        deadline = time.monotonic() + (REQUEST_TRIES + 1) * REQUEST_TIMEOUT_S
        while self.events_awaited() and not self.stopping and time.monotonic() < deadline:
            self._serve(min(deadline, self._next_house))

    def _word_awaited(self, tries: int = 0) -> bool:
        """Real time, before an end whose cause the controller does not know yet (a HEARTBEAT EMERGENCY without its
        EVENT, a disarm without its failsafe's, no state though the vehicle is heard since its last): whether to wait
        for the vehicle's word, which a lossy link loses. Once, it is asked for its HEARTBEAT, whose datagram carries
        its event sequence (an EVENT missed is then asked for again: bridge.mavlink.eventseq), until one comes or for
        END_ASK_S; ``tries``: each EVENT missed is asked for that many times (more than REQUEST_TRIES). Through
        ``bsst relay --delay 150 --loss 60`` 3 of 8 crashes ended ``aborted`` (``crashed, diverged or was touched``),
        2 ``no new state``, and 3 failsafes ``the vehicle was disarmed during the mission`` without it (docs/sitl.md,
        "An ARM's resends")."""
        if self.cfg.clock != "realtime":
            return False
        now = time.monotonic()
        if self._end_ask_until is None:
            self._end_ask_until = now + END_ASK_S
            self.ask_heartbeat()
        if tries > self.event_seq.tries:  # the flight over for good (EMERGENCY): libevents asks until answered
            self.event_seq.tries = tries
        return now < self._end_ask_until and self._hb_asks > 0  # (none left: its HEARTBEAT came)

    def _row(self, k: int, t: float, ref: Any, u: Any, wire: Any, desired: Any, recv: float, sent: float,
             s2c: float, late: float, age: float) -> None:
        if self.rows is not None:  # odo_arrived: the states taken since the previous row, this one's included
            arrived, self._states_rowed = self.states - self._states_rowed, self.states
            self.rows.write((k, t, ref[0][0], ref[1][0], ref[2][0], ref[3][0], *u, *wire, *desired, recv, sent, s2c,
                             late, age, arrived))

    def _check_vehicle(self, at_end: bool = False) -> str | None:
        """The outcome if the vehicle is lost to the flight (silent, no more states, disarmed
        other than by its failsafe, its flight ended by its plant, taken out of OFFBOARD by a ground
        station; real time, disarmed by its failsafe with no ``resume``: :meth:`_failsafe_disarmed`), else None. Its
        failsafe alone does not end the flight. ``at_end``: the mission's time is flown (None
        is then ``completed``: the vehicle is not asked for its word, :meth:`_word_awaited`, which is for its end)."""
        now = time.monotonic()
        timeout = self._silence_s
        answers: tuple[str, ...] | None = None  # the vehicle's own events this outcome answers
        emergency = self.armed_seen and self.vehicle_state == mavlink.MAV_STATE_EMERGENCY
        if self.taken_over:
            self.reason = f"the vehicle was switched to {self.taken_over}: no more targets sent"
            self.ended_taken_over = True
        elif now - self._last_rx > timeout:
            self.reason, self.vehicle_silent = f"vehicle silent for {timeout:g} s", True
        elif emergency or self.plant_end:
            # at once: its clock halted, so waiting out the state timeout would only delay the end. Its EVENT says how
            # (the outcome: crashed, not the failsafe that may have flown before): one missed is asked for again
            if not self.plant_end and not at_end and (self._word_awaited(END_EVENT_TRIES) | self.events_awaited()):
                return None  # (at the mission's end: ended now, its EVENT or not; waiting, it ended "completed")
            how = {"crashed": "it crashed", "diverged": "it diverged", "collision": "another vehicle touched it",
                   "terminated": "a flight termination"}.get(self.plant_end, "it crashed, diverged or was touched")
            sign = "HEARTBEAT system_status EMERGENCY" if emergency else "its EVENT"  # (a termination: disarmed)
            self.reason = f"the vehicle's flight ended: {how} ({sign})"
            answers = (self.plant_end,) if self.plant_end else ("crashed", "diverged", "collision")
        elif self.armed_seen and not self.vehicle_armed and not self.failsafe_seen:
            if (not at_end and self._word_awaited()) or self.events_awaited():  # a missed EVENT: its failsafe's?
                return None
            self.reason, answers = "the vehicle was disarmed during the mission", ("disarmed",)
        elif not at_end and self._failsafe_disarmed():
            return self._end_failsafe_disarmed()
        elif now - self._last_state > (wait := self._state_wait_s if self._started else
                                       self.cfg.start_timeout_s or self._state_wait_s):
            if not at_end and self.armed_seen and self._last_rx > self._last_state and self._word_awaited():
                return None  # heard, no state: its plant's end (its clock halted), its HEARTBEAT EMERGENCY lost?
            self.reason = f"no new state from the vehicle for {wait:g} s"
        else:
            self._end_ask_until = None  # all well again: a later end may ask the vehicle afresh (_word_awaited)
            return None
        # its plant's end by its EVENT; without one, a failsafe only if one was said (not its HEARTBEAT EMERGENCY)
        flew_failsafe = self.failsafe_seen not in (FailsafeSign.NONE, FailsafeSign.EMERGENCY)
        outcome = self.plant_end or ("failsafe" if flew_failsafe or (self.failsafe_seen and not emergency)
                                     else "aborted")
        self.event(outcome, self.reason, answers)
        return outcome

"""The offboard controller's side of its link to the vehicle: the endpoint, what it knows of the vehicle, what
it sends (:mod:`bridge.nodes.offboard`).

In:  the vehicle's messages: ODOMETRY (checked: sender, stamp, range; kept newest only), HEARTBEAT (armed, system
     status CRITICAL = its failsafe, PX4 ``custom_mode``: a ground station's mode), COMMAND_ACK, TIMESYNC (clock
     offset, its bounds, round trip, ns), EVENT (typed, bridge.mavlink.events: its id FAILSAFE is its failsafe
     too, LOCKSTEP says it left lockstep; each sequence handled once), CURRENT_EVENT_SEQUENCE and
     RESPONSE_EVENT_ERROR (the events missed, bridge.mavlink.eventseq), STATUSTEXT (said, never read to decide)
Out: actuator targets stamped with their state's ``time_usec`` (or the lockstep no-target acknowledgement),
     ARM_DISARM and other COMMAND_LONGs until ACKed, PARAM_SET until the vehicle's PARAM_VALUE echoes it (every
     0.2 s of wall time, until the flight's end), HEARTBEAT, TIMESYNC, REQUEST_EVENT for the EVENTs missed,
     REQUEST_MESSAGE HEARTBEAT when the link is back (:meth:`OffboardLink.ask_heartbeat`); ``controller.tlog``;
     reports (:mod:`bridge.nodes.report`): events at the mission's time, received STATUSTEXTs, refusals
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable
from enum import Enum
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from bridge.autopilot.params import BY_NAME, ParamChange, float32
from bridge.core.flight import Flight
from bridge.core.wire import step_of_usec
from bridge.mavlink.endpoint import HIL_ACTUATOR_CONTROLS, SET_ACTUATOR_CONTROL_TARGET, Endpoint, Tlog, wait
from bridge.mavlink.events import EventId, MAVLink_request_event_message, received_id
from bridge.mavlink.eventseq import EventSequence
from bridge.mavlink.modes import (
    MAIN_AUTO,
    MAIN_OFFBOARD,
    PARAM_TYPES,
    SUB_MISSION,
    custom_mode,
    main_mode,
    param_to_wire,
    shown_name,
)
from bridge.mavlink.receive import Rejections, odometry_problem
from bridge.mavlink.signing import Signing
from bridge.mavlink.telemetry import StatusTextJoiner
from bridge.nodes.offboard.config import (
    HOUSEKEEPING_S,
    SPIN_BEFORE_TICK_S,
    OffboardConfig,
    offset_bounds,
    stamp_problem,
    stamp_slack_s,
)
from bridge.nodes.offboard.paramschedule import PARAM_RETRY_S, ScheduledSet
from bridge.nodes.report import Event, Report, StatusText, Warning

_ZERO12 = (0.0,) * 12
_ZERO16 = (0.0,) * 16
TIMESYNC_WINDOW = 8  # the clock offset is where this many latest TIMESYNC answers' bounds agree (offset_bounds)
TARGETS_TIMED = 256  # the latest targets' sends timed (just before, just after): which left after the vehicle stopped
TIMESYNC_BURST_S = 0.01  # s of wall time between TIMESYNC requests until that many answers are in (then timesync_s)
HEARTBEAT_ASK_S = 0.1  # s of wall time between REQUEST_MESSAGE HEARTBEATs unanswered (ask_heartbeat)
HEARTBEAT_ASKS = 10  # ... and at most this many (the vehicle's own 1 Hz heartbeat comes anyway)


# the vehicle's EVENTs that say its plant ended the flight (its HEARTBEAT then EMERGENCY), by the outcome they give
PLANT_ENDS = {EventId.CRASHED: "crashed", EventId.DIVERGED: "diverged", EventId.COLLISION: "collision",
              EventId.TERMINATED: "terminated"}


class FailsafeSign(Enum):
    """How the vehicle said its failsafe since the controller armed it (its value: the words of the controller's
    record); false for NONE. A HEARTBEAT's word is kept once seen: the EVENT of a failsafe that disarmed in its
    own control period is the only sign of one that never shows CRITICAL."""

    NONE = ""
    EVENT = "its EVENT FAILSAFE"
    CRITICAL = "HEARTBEAT system_status CRITICAL"
    EMERGENCY = "HEARTBEAT system_status EMERGENCY"

    def __bool__(self) -> bool:
        return self is not FailsafeSign.NONE


class OffboardLink:
    """The link side of :class:`~bridge.nodes.offboard.flight.Offboard`: one endpoint to the vehicle, the
    vehicle as its messages tell it, and the messages sent to it."""

    def __init__(self, flight: Flight, cfg: OffboardConfig, out: Path | None,
                 status: Callable[[Report], None] | None) -> None:
        self.cfg = cfg
        self.rate = flight.mission.rate_hz
        self.actuation = flight.profile.actuation
        self._status = status or (lambda report: None)
        self.tlog = Tlog(out / "controller.tlog") if out is not None else None
        self.rejected = Rejections()  # what the receive path refused (bridge.mavlink.receive)
        self._texts = StatusTextJoiner()  # chunked STATUSTEXTs, joined before they are reported
        self.ep = Endpoint(cfg.vehicle, sysid=cfg.sysid, compid=cfg.compid, tlog=self.tlog, name="--vehicle",
                           signing=Signing(cfg.key) if cfg.key is not None else None, rejected=self.rejected,
                           source_port=cfg.source_port)
        self._odo_usec = -1  # time_usec of the newest state accepted: an older one is stale
        self._stamp_slack_s = stamp_slack_s(flight, cfg.clock)  # how far a stamp may jump (stamp_problem)
        self.stopping = False
        self._heard = False  # a heartbeat of the vehicle arrived
        self.vsys: int | None = cfg.target_sysid
        self.vcomp = 1
        self.armed_seen = False  # the vehicle's heartbeat showed it armed since we armed it
        self.vehicle_armed = False
        self.vehicle_state = mavlink.MAV_STATE_UNINIT
        self.vehicle_mode = 0  # its HEARTBEAT's custom_mode (PX4's)
        self.arming = False  # the controller's ARM is being sent: the vehicle's failsafe, crash count from now
        self.plant_end = ""  # how its plant ended the flight, by its EVENT: crashed, diverged, collision, terminated
        self.failsafe_seen = FailsafeSign.NONE  # how the vehicle said its failsafe since we armed it
        self.failsafe_at: float | None = None  # s, the vehicle's clock: its latest EVENT FAILSAFE's time
        self.landed_at: float | None = None  # s, the vehicle's clock: its latest EVENT LANDED's (land detected)
        self.left_lockstep = ""  # how the vehicle said it left lockstep (its LOCKSTEP EVENT), if it did
        self.event_seq = EventSequence()  # the vehicle's EVENTs by sequence: the missed ones asked for again
        self.taken_over = ""  # the mode a ground station switched the armed vehicle to (PX4 custom_mode), if any
        self.ending = False  # the mission's end action handed to the vehicle: its own mode is no takeover
        self._odo: Any = None  # newest ODOMETRY not yet used
        self._odo_recv = 0.0
        self._acks: dict[int, int] = {}
        now = time.monotonic()
        self._last_rx = now
        self._next_hb = now
        self._next_ts = now
        self._next_house = now
        self._hb_asks = 0  # REQUEST_MESSAGE HEARTBEATs still to send while none comes (ask_heartbeat)
        self._next_hb_ask = math.inf
        # the latest answers: (round trip, the least and the greatest clock offset it allows), ns
        self._ts_recent: deque[tuple[int, int, int]] = deque(maxlen=TIMESYNC_WINDOW)
        self.offset_range_ns: tuple[int, int] | None = None  # vehicle clock - our clock: its bounds (_timesync)
        self.offset_ns: int | None = None  # their middle
        self.rtt_ns: int | None = None  # the shortest round trip of the latest answers
        self.commands = 0
        self.targets_left: deque[tuple[float, float]] = deque(maxlen=TARGETS_TIMED)  # the latest, time.monotonic
        self.states = 0
        self.states_refused = 0  # the vehicle's states refused (stamp or numbers)
        self.state_window: list[int] | None = None  # [first, last] step of the vehicle's states read
        self.read_until: float | None = None  # s, time.monotonic: when it stopped reading the vehicle (stop_reading)
        self.t_mission = 0.0  # the mission time the events are reported at (s)
        self._t_wall: float | None = None  # real time: the time.monotonic the vehicle's clock read t_mission at
        self.end_t = flight.mission.steps / self.rate  # the flight's end (s; Offboard.run: where it stopped)
        self.param_sets: list[ScheduledSet] = []  # the scheduled PARAM_SETs sent, in order
        self._pending_params: dict[str, ScheduledSet] = {}  # by name: sent, not echoed by the vehicle yet

    def event(self, kind: str, text: str, answers: tuple[str, ...] | None = None, t: float | None = None,
              result: str | None = None) -> None:
        """Report an event at the mission time (``t``: at that one instead, s; NaN: not known); ``answers``: the
        vehicle's own event kinds it answers, ``result``: its command's answer (:class:`bridge.nodes.report.Event`)."""
        self._status(Event.at(self.t_mission if t is None else t, kind, text, answers=answers, result=result))

    def _command(self, cmd: int, p1: float, p2: float, tries: int = 30, every_s: float = 0.1,
                 p3: float = 0.0, settled: Callable[[], bool] | None = None) -> int | None:
        """COMMAND_LONG to the vehicle, repeated (confirmation 0, 1, ...) until ACKed with a final result
        (IN_PROGRESS is not one), or, ``settled`` true, until the vehicle has said otherwise what came of it
        (None). Every 0.1 s: an ARM whose ACK was lost has armed the vehicle, whose failsafe takes over 0.5 s later
        without a target (the vehicle acts on one arm once, however many of its copies come: a resend is answered
        with its first's result, bridge.nodes.vehicle.armretry)."""
        self._acks.pop(cmd, None)
        for n in range(tries):
            if settled is not None and settled():
                return None
            self.ep.send(mavlink.MAVLink_command_long_message(self.vsys or 0, self.vcomp, cmd, min(n, 255), p1, p2,
                                                              p3, 0, 0, 0, 0))
            deadline = time.monotonic() + every_s
            while time.monotonic() < deadline and not self.stopping:
                self._serve(deadline)
                if cmd in self._acks:
                    return self._acks.pop(cmd)
                if settled is not None and settled():
                    return None
            if self.stopping:
                return None
        return None

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

    def _answer(self, time_usec: int, wire: tuple[float, ...] | None) -> None:
        """Send the answer to the state stamped ``time_usec`` again: its target, or no target."""
        if wire is None:
            self._send_no_target(time_usec)
        else:
            self._send_target(time_usec, wire)

    def stop_reading(self, batches: int = 64) -> None:
        """Before the socket closes: read what already waits on it (its states delivered, not lost), then say when
        reading stopped (:attr:`read_until`, s of ``time.monotonic``, taken before the look that found the socket
        empty: a datagram queued before it was read, one sent after it never was; on one host the vehicle's clock
        too, so ``summary.json`` counts a state it sent after that in flight, docs/sitl.md). Bounded (a flood still
        queued after ``batches`` polls is left); once only."""
        if self.read_until is not None or self.ep.fileno < 0:
            return
        self.read_until = self.ep.drain(lambda m, _addr: self._on(m), batches)

    def _send_no_target(self, time_usec: int) -> None:
        """Lockstep: acknowledge the step of the state stamped ``time_usec`` without a valid
        target (HIL_ACTUATOR_CONTROLS, flags bit 0 lockstep, ``mode`` without SAFETY_ARMED, as
        PX4 clocks its simulator while its outputs are disarmed; for either actuation)."""
        self.ep.send_hot(HIL_ACTUATOR_CONTROLS, (time_usec, 1, *_ZERO16, 0))

    def _send_arm(self) -> None:
        """Ask the vehicle to arm again (the guard's ``resume``, the mission's own ask after a failsafe); once per
        step while it asks, each a command of its own (confirmation 0), as offline's guard asks each step: it
        crosses the link model and draws its fate there, as offline's does (bridge.nodes.vehicle.armretry)."""
        self.ep.send(mavlink.MAVLink_command_long_message(self.vsys or 0, self.vcomp,
                                                          mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1.0, 0.0,
                                                          0, 0, 0, 0, 0))

    def ask_heartbeat(self) -> None:
        """The link is back after an outage (real time): what the vehicle did meanwhile (its failsafe took over, it
        landed) is in its HEARTBEAT, and the one it sent on the change was lost with the outage, its next due up to
        1 s later (the sine re-armed 0.6 s after its link came back: docs/sitl.md, "Failsafe"). Ask for one
        (REQUEST_MESSAGE, as PX4's receiver answers it), again every HEARTBEAT_ASK_S until one comes."""
        self._hb_asks = HEARTBEAT_ASKS
        self._ask_heartbeat(time.monotonic())

    def _ask_heartbeat(self, now: float) -> None:
        self._hb_asks -= 1
        self._next_hb_ask = now + HEARTBEAT_ASK_S if self._hb_asks else math.inf
        self._next_house = min(self._next_house, self._next_hb_ask)
        self.ep.send(mavlink.MAVLink_command_long_message(self.vsys or 0, self.vcomp, mavlink.MAV_CMD_REQUEST_MESSAGE,
                                                          0, float(mavlink.MAVLINK_MSG_ID_HEARTBEAT), 0, 0, 0, 0, 0, 0))

    def _send_param(self, change: ParamChange) -> None:
        """A scheduled parameter change (``--param-at``): PARAM_SET before this step's answer, so
        that in lockstep the vehicle makes it before it flies the step (the same step as offline). It
        is pending until the vehicle's PARAM_VALUE echoes its name and value (:meth:`_on`), sent again
        every PARAM_RETRY_S of wall time until then (:meth:`_resend_params`: a datagram lost on an impaired
        link, in a blackout); a newer change of the same name replaces it. The vehicle makes a set to the
        value in force no change, so a resend never alters a flight."""
        kind = PARAM_TYPES[BY_NAME[change.name].kind]
        wire = float32(param_to_wire(change.value, kind))
        assert wire is not None  # a checked value (its parameter's range) is within float32's
        sent = ScheduledSet(change, wire, kind, self.t_mission)
        self.param_sets.append(sent)
        self._pending_params[change.name] = sent
        # said before it goes: the session reads it with the vehicle's change or before it (bridge.session.eventorder)
        self.event("param", f"PARAM_SET {change.name} = {change.value:g} sent (waiting for the vehicle's echo)")
        self._send_set(sent)

    def _send_set(self, s: ScheduledSet) -> None:
        s.sends += 1
        s.next_send = time.monotonic() + PARAM_RETRY_S
        self.ep.send(mavlink.MAVLink_param_set_message(self.vsys or 0, self.vcomp, s.change.name.encode(),
                                                       s.wire, s.kind))

    def vehicle_t(self) -> float:
        """Now on the vehicle's clock, mission time (s): lockstep, the step it waits at; real time, t_mission and the
        wall time since (a message read between two ticks came after the earlier one's time)."""
        if self._t_wall is None or self.cfg.clock != "realtime":
            return self.t_mission
        return self.t_mission + max(time.monotonic() - self._t_wall, 0.0)

    def _resend_params(self, now: float) -> None:
        """Each scheduled PARAM_SET the vehicle has not echoed yet, again once its PARAM_RETRY_S is up; none at or
        after the flight's end (a real-time blackout that outlasts it; lockstep's waits for the last echoes, its clock
        held at the end): it would change the vehicle's landing, unflown."""
        if self.vehicle_t() >= self.end_t:
            return
        for s in self._pending_params.values():
            if now >= s.next_send:
                self._send_set(s)

    def _param_echo(self, m: Any) -> None:
        """A PARAM_VALUE of the vehicle: the pending scheduled set of that name and value is confirmed, at the echo's
        arrival on the vehicle's clock (at or after its change), or, after the flight's end, not made in flight."""
        name = m.param_id.rstrip("\x00") if isinstance(m.param_id, str) else m.param_id.decode(errors="replace")
        s = self._pending_params.get(name)
        if s is None or float32(m.param_value) != s.wire:
            return
        del self._pending_params[name]
        t, sets = self.vehicle_t(), f"{s.sends} PARAM_SET{'s' if s.sends > 1 else ''}"
        if t > self.end_t + 1e-9:
            s.late_t = t
            self.event("param", f"{name} = {s.change.value:g} echoed by the vehicle only after the flight's end "
                                f"(t={self.end_t:.3f} s; after {sets})", ("param",), t)  # the session judges it
            return
        s.confirmed_t = t
        self.event("param", f"{name} = {s.change.value:g} confirmed by the vehicle (after {sets})", ("param",), t)

    def unconfirmed_params(self) -> list[ScheduledSet]:
        """The scheduled sets the vehicle never echoed in flight (each never echoed said as an event here: not made;
        one echoed after the flight's end was said then)."""
        out = [s for s in self.param_sets if s.confirmed_t is None]
        for s in (s for s in out if s.late_t is None):
            self.event("param", f"{s.change.name} = {s.change.value:g} (due at t={s.change.t_s:g} s) never "
                                f"confirmed by the vehicle after {s.sends} PARAM_SETs: not made")
        return out

    def _send_target(self, time_usec: int, wire: tuple[float, ...]) -> None:
        """The actuator target answering the state stamped ``time_usec`` (hot path)."""
        self.commands += 1
        before = time.monotonic()
        if self.actuation == "motors":
            flags = 1 if self.cfg.clock == "lockstep" else 0  # bit 0: lockstep
            self.ep.send_hot(HIL_ACTUATOR_CONTROLS, (time_usec, flags, *wire, *_ZERO12,
                                                     mavlink.MAV_MODE_FLAG_SAFETY_ARMED))
        else:  # control group 0
            self.ep.send_hot(SET_ACTUATOR_CONTROL_TARGET, (time_usec, *wire, 0.0, 0.0, 0.0, 0.0, 0,
                                                           self.vsys or 0, self.vcomp))
        self.targets_left.append((before, time.monotonic()))

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
            why = ("unheard" if self.vsys is None else "sender" if src != self.vsys  # (its HEARTBEAT not come yet)
                   else stamp_problem(m.time_usec, self._odo_usec, now - self._odo_recv, 1.0 / self.rate,
                                      self._stamp_slack_s) or odometry_problem(m))
            if src == self.vsys:  # the window of steps this side read: what the vehicle sent outside it never came
                k = step_of_usec(m.time_usec, self.rate)
                window = self.state_window
                if window is None:
                    self.state_window = [k, k]
                elif k > window[1]:  # the usual case: the next step (no new list a state)
                    window[1] = k
                elif k < window[0]:
                    window[0] = k
            if why:
                self.rejected.add(why, True)
                self.states_refused += src == self.vsys
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
            self._hb_asks, self._next_hb_ask = 0, math.inf  # (ask_heartbeat: answered)
            self._last_rx = time.monotonic()
            self.vehicle_armed = bool(m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
            self.vehicle_state, self.vehicle_mode = m.system_status, m.custom_mode
            if self.vehicle_armed:
                self.armed_seen = True
            if self.armed_seen and m.system_status in (mavlink.MAV_STATE_CRITICAL, mavlink.MAV_STATE_EMERGENCY):
                # CRITICAL (armed): flying its failsafe. EMERGENCY: its plant ended the flight (crashed, diverged,
                # touched by another vehicle) and its clock halted: no more states will come
                if self.failsafe_seen in (FailsafeSign.NONE, FailsafeSign.EVENT):  # (its EVENT comes first)
                    self.failsafe_seen = (FailsafeSign.CRITICAL if m.system_status == mavlink.MAV_STATE_CRITICAL
                                          else FailsafeSign.EMERGENCY)
            elif (self.vehicle_armed and m.autopilot == mavlink.MAV_AUTOPILOT_PX4 and not self.taken_over
                  and not self.ending and main_mode(m.custom_mode) != MAIN_OFFBOARD
                  and not (self.cfg.await_mission and m.custom_mode == custom_mode(MAIN_AUTO, SUB_MISSION))):
                # armed, not in its failsafe, out of OFFBOARD: a ground station took it (HOLD, LAND, ...)
                self.taken_over = shown_name(m.custom_mode)
            return
        if src != self.vsys:
            return
        self._last_rx = time.monotonic()
        if kind == "COMMAND_ACK":
            # IN_PROGRESS is not an answer (MAVLink's command protocol): only a final result is kept
            if m.target_system in (0, self.cfg.sysid) and m.result != mavlink.MAV_RESULT_IN_PROGRESS:
                self._acks[m.command] = m.result
        elif kind == "PARAM_VALUE":
            if self._pending_params:
                self._param_echo(m)
        elif kind == "TIMESYNC":
            self._timesync(m)
        elif kind == "EVENT":
            if self.event_seq.event(m.sequence, self._last_rx):  # each sequence once (a re-sent one, a duplicate)
                self._event(m)
            self._request_events(self._last_rx)
        elif kind == "CURRENT_EVENT_SEQUENCE":
            self.event_seq.current(m.sequence, m.flags, self._last_rx)
            self._request_events(self._last_rx)
        elif kind == "RESPONSE_EVENT_ERROR":
            if (m.target_system, m.target_component) == (self.cfg.sysid, self.cfg.compid):
                self.event_seq.error(m.sequence, m.sequence_oldest_available)
        elif kind == "STATUSTEXT":  # a chunked one is reported once, joined
            for severity, text in self._texts.add(m, time.monotonic()):
                self._statustext(severity, text)

    def _event(self, m: Any) -> None:
        """A typed EVENT of the vehicle's (bridge.mavlink.events): what the controller decides by, by its id."""
        eid = received_id(m)
        since_armed = self.armed_seen or self.arming  # (its ARM's ACK or HEARTBEAT may come after its failsafe)
        if eid in PLANT_ENDS and since_armed:
            self.plant_end = self.plant_end or PLANT_ENDS[eid]
        if eid is EventId.FAILSAFE and since_armed:
            # when it took over, on the vehicle's clock (an EVENT asked for again keeps its time)
            self.failsafe_at = max(self.failsafe_at or 0.0, m.event_time_boot_ms / 1000.0)
            # a failsafe that disarms the vehicle in its own control period (its disarm action, or on the
            # ground) never shows CRITICAL: disarmed, the failsafe is cleared and HEARTBEAT says STANDBY (PX4)
            if not self.failsafe_seen:
                self.failsafe_seen = FailsafeSign.EVENT
        elif eid is EventId.LANDED and self.armed_seen:  # on the ground, waiting out COM_DISARM_LAND
            self.landed_at = max(self.landed_at or 0.0, m.event_time_boot_ms / 1000.0)
        elif eid is EventId.LOCKSTEP and not self.left_lockstep:  # not a lockstep flight any more
            self.left_lockstep = "its EVENT LOCKSTEP (its STATUSTEXT says why)"

    def _request_events(self, now: float) -> None:
        """REQUEST_EVENT for the vehicle's EVENTs missed and due to be asked for (again) at ``now``
        (bridge.mavlink.eventseq: at once, again after 0.1 s unanswered, 5 times at most)."""
        for first, last in self.event_seq.requests(now):
            self.ep.send(MAVLink_request_event_message(self.vsys or 0, self.vcomp, first, last))

    def events_awaited(self) -> bool:
        """Whether EVENTs the vehicle sent are missed and still asked for: one of them may be its failsafe."""
        return self.event_seq.pending()

    def _statustext(self, severity: int, text: str) -> None:
        self._status(StatusText(severity, text))

    def _timesync(self, m: Any) -> None:
        now = time.monotonic_ns()
        if m.tc1 == 0:  # a request: answer with our clock
            self.ep.send(mavlink.MAVLink_timesync_message(now, m.ts1))
            return
        rtt = now - m.ts1
        if rtt < 0 or rtt > 1_000_000_000:
            return
        # the vehicle read its clock (tc1) between our request (ts1) and its answer's arrival (now): the offset
        # lies within [tc1 - now, tc1 - ts1], the round trip wide, however the trip split between the two ways;
        # a busy machine (either side descheduled) holds up one way of many exchanges, so the offset is taken
        # where the latest answers' bounds agree, not from one exchange (config.offset_bounds)
        self._ts_recent.append((rtt, m.tc1 - now, m.tc1 - m.ts1))
        self.rtt_ns = min(self._ts_recent)[0]
        self.offset_range_ns = offset_bounds(self._ts_recent)
        self.offset_ns = sum(self.offset_range_ns) // 2  # the middle: both ways equal at their fastest

    def _housekeeping(self) -> None:
        now = time.monotonic()
        if now >= self._next_hb:
            # 1 Hz; 10 Hz until the vehicle is heard: one lost to a vehicle still starting costs 0.1 s, not 1 s
            self._next_hb = now + (1.0 if self._heard else 0.1)
            self.ep.send(mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_ONBOARD_CONTROLLER,
                                                           mavlink.MAV_AUTOPILOT_INVALID, 0, 0,
                                                           mavlink.MAV_STATE_ACTIVE, 3))
        if now >= self._next_ts and self.vsys is not None:
            # a burst until the window is full: a real-time flight fixes the states' way down at its
            # first tick (flight.py, _way_down_s), from the best of several answers, not from one
            warm = len(self._ts_recent) >= TIMESYNC_WINDOW
            self._next_ts = now + (self.cfg.timesync_s if warm else TIMESYNC_BURST_S)
            self.ep.send(mavlink.MAVLink_timesync_message(0, time.monotonic_ns()))
        for severity, text in self._texts.expired(now):
            self._statustext(severity, text)
        if self._pending_params:
            self._resend_params(now)
        if self.event_seq.pending():
            self._request_events(now)
        if now >= self._next_hb_ask:
            self._ask_heartbeat(now)
        refused = self.rejected.report(now)
        if refused is not None:
            self._status(Warning(refused))
        if self.tlog is not None:
            self.tlog.flush()
        # no TIMESYNC before a vehicle is known: its due time must not hold the loop awake
        self._next_house = min(self._next_hb, self._next_ts if self.vsys is not None else math.inf,
                               now + HOUSEKEEPING_S, self.event_seq.next_due(), self._next_hb_ask)

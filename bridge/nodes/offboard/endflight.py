"""The offboard controller's end of mission: the vehicle's own end action asked for, and its landing waited out.

In:  the mission's end action (``[end] action``: land, hold), COM_DISARM_LAND (s), the vehicle's answers and events
     through :class:`~bridge.nodes.offboard.link.OffboardLink` (lockstep: its states, each answered with the no-target
     acknowledgement while it lands; real time: the wall clock)
Out: the outcome (``completed``, or ``aborted`` for a stop while the vehicle lands, still armed), the ``end`` events,
     :attr:`EndFlying.reason` and :attr:`EndFlying.end_unanswered` when the vehicle did not take or finish it

:class:`EndFlying` is :class:`~bridge.nodes.offboard.flight.Offboard`'s base, above the real-time clock's
(split out of flight.py, at its 500 lines).
"""

from __future__ import annotations

import time
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from bridge.core.flight import Flight
from bridge.mavlink.endpoint import Spinner, wait
from bridge.mavlink.modes import MAIN_AUTO, SUB_LOITER
from bridge.nodes.offboard.realtime import RealtimeFlying
from bridge.record.ending import end_not_taken_block, end_unanswered


class EndFlying(RealtimeFlying):
    """The end of an offboard controller's mission (module docstring); its flight is :class:`Offboard`'s."""

    flight: Flight
    spinner: Spinner
    ending: bool  # the mission's time is flown: its end action asked for
    reason: str
    end_unanswered: dict[str, Any] | None
    vehicle_silent: bool
    _end_usec: int | None  # lockstep: the stamp of the state that ended the mission, unanswered
    _end_height_m: float
    _mission_zero: float | None  # the vehicle's clock (s) at mission time 0 (real time: from its start; else its end)
    _mission_end: float  # mission time (s) the mission's steps ended

    def _fly_end(self) -> str:
        """The mission's time is flown: the vehicle's own end action (``[end] action``), never a disarm in the
        air. ``land``: NAV_LAND, then wait until it has landed and disarmed itself, in lockstep answering each
        state with the no-target acknowledgement (the landing is clocked as the mission was: offline's to the
        bit); ``hold``: HOLD (DO_SET_MODE AUTO LOITER), the vehicle's until the session ends. What went wrong
        is the :attr:`reason` (the mission itself was completed). The outcome: ``completed``, or ``aborted`` when a
        stop (Ctrl-C, SIGTERM) came while the vehicle was landing, still armed (as ``bsst sim``'s end landing)."""
        self.ending = True
        hold = self.flight.mission.end_action == "hold"
        if hold:
            result = self._command(mavlink.MAV_CMD_DO_SET_MODE, float(mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED),
                                   float(MAIN_AUTO), p3=float(SUB_LOITER))
        else:
            result = self._command(mavlink.MAV_CMD_NAV_LAND, 0.0, 0.0)
        self._at_end_now()
        if result != mavlink.MAV_RESULT_ACCEPTED:
            why = "no answer" if result is None else f"MAV_RESULT {result}"
            self.reason = f"the vehicle did not take the mission's end action ({'HOLD' if hold else 'LAND'}): {why}"
            self.end_unanswered = end_unanswered(self.flight.mission.end_action, why, time.monotonic() - self._last_rx)
            self.event("end", self.reason, result=why)
            return "completed"
        taken_t = self.t_mission  # when its answer came, on the mission's clock
        stays = "stays armed (COM_DISARM_LAND <= 0)" if self.flight.params.land_disarm_s <= 0.0 else "disarms"
        self.event("end", "mission over: the vehicle holds its position" if hold else
                   f"mission over: the vehicle lands where it is and {stays} on the ground", answers=("end",),
                   result="accepted")
        if not hold and not self._await_landing():
            if self.stopping and not self.reason:  # (a stop: _await_landing says no other reason)
                self.reason = "interrupted (Ctrl-C or SIGTERM) in the mission's end landing: the vehicle still armed"
                self.event("end", self.reason)
                return "aborted"
            self.event("end", self.reason)
        elif not hold and self.vehicle_armed:  # landed, COM_DISARM_LAND <= 0: armed on the ground is what was asked
            self.event("end", f"the vehicle landed and stays armed, as asked (COM_DISARM_LAND = "
                              f"{self.flight.params.land_disarm_s:g}: no auto-disarm)")
        self._taken_late(taken_t)
        return "completed"

    def _taken_late(self, taken_t: float) -> None:
        """The end action was answered ACCEPTED at ``taken_t`` (s, mission time), but the vehicle's failsafe had taken
        over after the mission's end and before it (a blackout over the end, the command retried through the link
        back): not flown as asked, as bsst sitl judges it (:func:`bridge.record.ending.end_not_taken`); the failsafe's
        EVENT, missed in the blackout, is asked for first. Until the third wave's forty-second session the controller
        alone said nothing, exit 0."""
        self._settle_events()
        if self.failsafe_at is None or self._mission_zero is None:
            return
        took = self.failsafe_at - self._mission_zero  # on the mission's clock
        if not (self._mission_end - 0.5 / self.rate <= took < taken_t):
            return
        self._at_end_now()
        self.end_unanswered = end_not_taken_block(self.flight.mission.end_action, "accepted", "its EVENT FAILSAFE",
                                                  round(took, 3), round(taken_t, 3),
                                                  None if self.vehicle_armed else round(self.t_mission, 3))

    def _await_landing(self) -> bool:
        """Serve the link until the vehicle has disarmed on the ground (True), or :attr:`reason` says why not:
        silent, or not down within the descent's time at the failsafe's rate, COM_DISARM_LAND and 10 s (vehicle time:
        lockstep counts the steps it clocks, whatever the pace; real time the wall clock). With COM_DISARM_LAND 0 or
        less (no auto-disarm) a vehicle that landed (its EVENT LANDED since) and is still armed then is as asked
        (True): the same time flown, so that its end rows stay offline's."""
        keeps_armed, landed_before = self.flight.params.land_disarm_s <= 0.0, self.landed_at
        lockstep = self.cfg.clock == "lockstep"
        usec, t_end = self._end_usec, self.t_mission
        allowed_s = 10.0 + self.flight.failsafe.time_to_land_s(self._end_height_m) + max(
            self.flight.params.land_disarm_s, 0.0)  # landed, the vehicle disarms after COM_DISARM_LAND
        deadline = time.monotonic() + allowed_s
        last_usec = (usec or 0) + int(allowed_s * 1e6)
        if lockstep and usec is not None:
            self._send_no_target(usec)
        while self.vehicle_armed and not self.stopping:
            now = time.monotonic()
            late = usec is not None and usec > last_usec if lockstep else now > deadline
            if late and keeps_armed and self.landed_at != landed_before:  # on the ground, armed: as asked
                break
            if late or now - self._last_rx > self.cfg.vehicle_timeout_s:
                self.vehicle_silent = not late
                self.reason = "the vehicle did not land and disarm after the mission" if late else \
                    f"vehicle silent for {self.cfg.vehicle_timeout_s:g} s while landing"
                return False
            # (real time polls for nothing: its states come on the wall clock, not as answers)
            for _, m, _addr in wait((self.ep,), min(deadline, self._next_house), self.spinner if lockstep else None):
                self._on(m)
            odo, self._odo = self._odo, None
            if lockstep and odo is not None and self.vehicle_armed and usec is not None and odo.time_usec >= usec:
                usec = odo.time_usec
                self._send_no_target(usec)
            if time.monotonic() >= self._next_house:
                self._housekeeping()
        self._at_end_now()
        if lockstep and usec is not None and self._end_usec is not None:  # at the step it waits at now (a stop's
            self.t_mission = t_end + (usec - self._end_usec) / 1e6  # word was at the mission's end, before the landing)
        return not self.vehicle_armed or (keeps_armed and self.landed_at != landed_before and not self.stopping)

    def _at_end_now(self) -> None:
        """After the mission's steps, events are at the time they happen, not at the last step's: in lockstep
        the vehicle waits at the state that ended the mission, in real time the wall clock has gone on since it
        came (the session orders the two children's events by time: an answer never comes before its cause)."""
        if self._t_wall is not None and self.cfg.clock == "realtime":
            self.t_mission, self._t_wall = self.vehicle_t(), time.monotonic()

"""The controller's answers on its link: actuator targets and the no-target acknowledgement.

In:  HIL_ACTUATOR_CONTROLS (``motors``: c1..c4 = omega / omega_max in [0, 1]; SAFETY_ARMED clear in
     ``mode``: the no-target acknowledgement) or SET_ACTUATOR_CONTROL_TARGET group 0 (``wrench``: roll,
     pitch, yaw in [-1, 1], thrust in [0, 1]), stamped with the ``time_usec`` (us) of the state they
     answer; the current control step k; wall time (s)
Out: in a lockstep flight the answer of step k held by the :class:`~bridge.nodes.vehicle.clock.Clock`
     (:class:`~bridge.nodes.vehicle.clock.Answer`); on the wall clock the target applied to the
     :class:`SimVehicle` at once; refusals counted (``sender``, ``message``, ``group``, ``target``,
     ``not_offboard``, a wire problem, ``reordered``, ``repeated``, ``stale``, ``future``); in lockstep the answers
     that are expected but not flown, counted apart (``answered_again``, ``answered_wall_clock``); the
     controller's targets of the other actuation mode (a ``--profile`` that differs), said in words once
     (:class:`ActuationMismatch`)
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from bridge.autopilot.simvehicle import OFFBOARD, SimVehicle
from bridge.core.wire import command_from_wire, step_of_usec
from bridge.mavlink.receive import wire_problem
from bridge.nodes.vehicle.authority import Authority
from bridge.nodes.vehicle.clock import Answer, Clock, ClockState

Applied = tuple[int, tuple[float, ...], float]  # (the step it answered, wire, wall time received)
MESSAGES = {"motors": "HIL_ACTUATOR_CONTROLS", "wrench": "SET_ACTUATOR_CONTROL_TARGET"}  # each actuation's target


class ActuationMismatch:
    """The controller's targets refused for the other actuation mode (``message``): its profile is not the
    vehicle's. The count says only ``message N``; this says, once, what differs and what to do."""

    def __init__(self, actuation: str, profile: str) -> None:
        self.actuation = actuation
        self.profile = profile
        self.refused = 0
        self.text = ""
        self._said = False

    def note(self, sent: str) -> None:
        """A target of ``sent`` (its message's name) refused for the other actuation mode."""
        self.refused += 1
        if not self.text:
            self.text = (f"actuation: the controller sends {sent}; this vehicle (profile {self.profile}) flies "
                         f"{self.actuation} ({MESSAGES[self.actuation]}): refused; fly both with one --profile")

    def due(self) -> bool:
        """True once, when there is something to say (then said)."""
        if self._said or not self.text:
            return False
        self._said = True
        return True


class Targets:
    """Checks the controller's answers and hands them to the clock (lockstep) or the vehicle (wall clock)."""

    def __init__(self, sim: SimVehicle, clock: Clock, authority: Authority, rate_hz: float, actuation: str,
                 reject: Callable[[str], None], profile: str = "") -> None:
        self.sim = sim
        self.clock = clock
        self.authority = authority
        self.rate = rate_hz
        self.actuation = actuation
        self._reject = reject
        self.mismatch = ActuationMismatch(actuation, profile)
        self.applied: Applied | None = None  # the target in force
        self.accepted = 0
        self.new_steps = 0  # accepted targets of a step newer than any before (vehicle.bin's ``cmd_arrived``)
        self.wall = -math.inf  # wall time of the newest actuator target from the controller (checked)
        # lockstep: the steps whose state was resent (RESEND_S unanswered), and the answers that came for
        # one of them after its first answer had been taken: the controller answers every copy, so a slow
        # answer (not a lost one) comes twice; the second is expected, not a refusal of anyone's datagram
        self.resent_steps: set[int] = set()
        self.answered_again = 0
        # lockstep: the last run of steps whose state went out on the wall clock (a ground station's mode, lockstep
        # lost), first and last; the controller answers those as any state, and one answered once lockstep has
        # engaged again is too late to fly but nobody's fault: counted in answered_wall_clock, not refused as stale
        self.wall_steps = (0, -1)
        self.answered_wall_clock = 0

    def resent(self, k: int) -> None:
        """The state of step k was sent again."""
        self.resent_steps.add(k)
        if len(self.resent_steps) > 256:
            self.resent_steps = {s for s in self.resent_steps if s >= k - 128}

    def sent_on_wall_clock(self, k: int) -> None:
        """The state of step k went out on the wall clock."""
        first, last = self.wall_steps
        self.wall_steps = (first if k == last + 1 else k, k)

    def receive(self, m: Any, kind: str, k: int, on_controller_link: bool) -> None:
        """An actuator target: checked, then held for lockstep or applied at once (realtime)."""
        if not on_controller_link or not self.authority.from_controller(m):
            return self._reject("sender")
        now = self.wall = time.monotonic()  # the controller streams (whether or not this one is taken)
        if kind == "HIL_ACTUATOR_CONTROLS":
            if not m.mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED:
                return self._no_target(m, k)
            if self.actuation != "motors":
                self.mismatch.note(kind)
                return self._reject("message")
        else:
            if self.actuation != "wrench":
                self.mismatch.note(kind)
                return self._reject("message")
            if m.group_mlx != 0:
                return self._reject("group")
            if self.authority.for_others(m):
                return self._reject("target")
        clock = self.clock
        offboard = self.sim.armed and self.sim.mode == OFFBOARD
        if clock.halted or (not offboard and not clock.engaged):
            return self._reject("not_offboard")  # lockstep, flight on: VehicleEnd decides when the model delivers
        c = m.controls
        wire = (c[0], c[1], c[2], c[3])
        why = wire_problem(self.actuation, wire)
        if why:
            return self._reject(why)
        key = step_of_usec(m.time_usec, self.rate)
        if clock.engaged:
            if key != k or clock.state is not ClockState.LOCKSTEP:
                return self._behind(key, k)
            self.accepted += 1
            self.new_steps += 1
            clock.hold(Answer(wire, now))
            return None
        if self.applied is not None and key < self.applied[0]:
            return self._reject("reordered")
        if self.sim.command(command_from_wire(self.actuation, wire)):
            self.accepted += 1
            self.new_steps += self.applied is None or key > self.applied[0]
            if self.applied is None:  # a flight's first target: its stamp is the mission's time 0 (real time)
                self.sim.start_mission_clock(key / self.rate)
            self.applied = (key, wire, now)
        return None

    def _no_target(self, m: Any, k: int) -> None:
        """The controller's no-target acknowledgement of a step: HIL_ACTUATOR_CONTROLS with
        SAFETY_ARMED clear in ``mode`` (as PX4's lockstep clocks its simulator while its
        outputs are disarmed). In lockstep, with a flight on, it clocks step k without a
        target (the last one stays in force and the timeout runs); otherwise it means nothing."""
        clock = self.clock
        if not clock.engaged:
            return None
        key = step_of_usec(m.time_usec, self.rate)
        if key != k or clock.state is not ClockState.LOCKSTEP:
            return self._behind(key, k)
        clock.hold(Answer(None, time.monotonic()))
        return None

    def _behind(self, key: int, k: int) -> None:
        """Lockstep: the controller's answer for a step other than k. For a step whose state was
        resent it is the answer to a copy, its first answer already taken (``answered_again``);
        for a step whose state went out on the wall clock before lockstep engaged again it is a late answer to
        that (``answered_wall_clock``); otherwise a second answer to step k (its state sent once) is ``repeated``,
        an older one ``stale``, a newer one ``future``."""
        if key in self.resent_steps:  # (k itself: both answers to its copies came before it was stepped)
            self.answered_again += 1
            return None
        if self.wall_steps[0] <= key <= self.wall_steps[1] < k:  # (until the third wave's 39th session: stale)
            self.answered_wall_clock += 1
            return None
        if key == k:
            return self._reject("repeated")
        return self._reject("stale" if key < k else "future")

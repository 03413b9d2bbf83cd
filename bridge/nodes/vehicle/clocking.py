"""Which clock a vehicle's flight runs on as its modes, its controller and its end change (the commander's side).

In:  a mode change made (the mode it was), an arm, the mission's end action handed over (LAND or HOLD), a control
     period flown, the controller silent (wall time, s, ``time.monotonic``), another vehicle's touch, the plant's
     verdict; the current control step k (``step``) and the physics substeps a step
Out: the step clock's transitions (:class:`~bridge.nodes.vehicle.clock.Clock`: engage, run free, fire a
     :class:`~bridge.nodes.vehicle.clock.Trigger`), the state of step k sent when lockstep engages (``state_out``),
     the events saying the flight left lockstep, and :attr:`Clocking.end_landing` (the mission's end landing, clocked
     as the mission)

Split out of :class:`~bridge.nodes.vehicle.commander.Commander` (which arms, sets modes and runs commands, and calls
these after each change): in lockstep a vehicle flown by its own controller (HOLD, LAND, TAKEOFF, RTL) needs no
controller's answers and runs on the wall clock; OFFBOARD again, armed, engages lockstep; a disarm, the plant's
verdict or a touch ends the flight's clock (docs/design.md, "Clocks").
"""

from __future__ import annotations

import time
from collections.abc import Callable

from bridge.autopilot.simvehicle import GROUND_MODES, HOLD, LAND, OFFBOARD, SimVehicle
from bridge.mavlink.modes import mode_name
from bridge.nodes.vehicle.clock import Clock, Trigger
from bridge.nodes.vehicle.config import VehicleConfig


class Clocking:
    """The step clock of one vehicle's flight, as the commander's changes move it."""

    def __init__(self, sim: SimVehicle, clock: Clock, cfg: VehicleConfig, substeps: int, step: Callable[[], int],
                 state_out: Callable[[float], None]) -> None:
        self.sim = sim
        self.clock = clock
        self.cfg = cfg
        self.lockstep = cfg.clock == "lockstep"
        self.substeps = substeps
        self.step = step  # the current control step k
        self.state_out = state_out  # send step k's state at wall time now (s): lockstep awaits its answer
        self.end_landing = False  # lockstep: the mission's end landing is flown (its failsafe's too), clocked as it

    def after_mode(self, was: str) -> None:
        """The step clock after a mode change: a vehicle flown by its own controller (HOLD, LAND,
        TAKEOFF) needs no controller's answers and runs on the wall clock (``speed`` if given);
        OFFBOARD again, armed, returns to lockstep (the state of step k goes out, its answer awaited)."""
        sim, now = self.sim, time.monotonic()
        if not self.lockstep or not sim.armed:
            return
        if sim.mode in GROUND_MODES and not self.clock.free_running:
            self.ground_takes_over(now)
        elif sim.mode == OFFBOARD and was != OFFBOARD:
            self.engage(now)

    def ground_takes_over(self, now: float, how: str = "flown by the vehicle") -> None:
        """Lockstep, a ground station's mode flown by the vehicle's own controller: on the wall clock
        from now; a lockstep flight that was on, or a session's vehicle awaiting its controller (a ground
        station's arm in HOLD before the controller's), says so (its record: it left lockstep here)."""
        if self.clock.engaged or self.cfg.controller_from is not None:
            self.sim.event("lockstep", f"{mode_name(self.sim.mode)} set by a ground station: {how} on the wall "
                                       "clock")
        self.clock.run_free(Trigger.GROUND, now, self.step() * self.substeps)
        self.end_landing = False

    def off_step_clock(self) -> None:
        """Lockstep: a flight termination leaves the step clock; the vehicle falls on the wall clock."""
        if self.lockstep and not (self.clock.free_running or self.clock.halted):
            self.ground_takes_over(time.monotonic(), "the vehicle falls")

    def engage(self, now: float) -> None:
        """Lockstep from now: the state of step k goes out and its target is awaited. Only ever at a control
        period's start: on the wall clock the vehicle holds what may lead here
        (:func:`~bridge.nodes.vehicle.commander.engages_lockstep`) until then."""
        self.clock.engage(now, self.step() * self.substeps)
        self.end_landing = False
        self.state_out(now)

    def end_mission(self, mode: str) -> None:
        """The mission's end action handed over (LAND or HOLD): lockstep, the controller clocks the landing with its
        no-target acknowledgements, and a hold is the end of the lockstep flight (time stands still)."""
        self.end_landing = self.lockstep and mode == LAND
        if self.lockstep and mode == HOLD and self.clock.engaged:
            self.clock.fire(Trigger.DISARM)  # the lockstep flight is over: time stands still

    def landed(self) -> None:
        """After a control period: a lockstep flight whose vehicle disarmed itself on the ground (the end
        action's landing) is over; time stands still until it is armed again, as after a disarm by command."""
        if self.clock.engaged and not self.sim.armed and self.end_landing:  # (a ground station's LAND runs free)
            self.clock.fire(Trigger.DISARM)
            self.end_landing = False

    # -- what ends a flight --------------------------------------------------------------------------
    def controller_lost(self, now: float) -> None:
        """Lockstep, the controller silent for ``lost_after_s``: on the wall clock from ``now``, where the
        vehicle's timeout and failsafe take over."""
        self.sim.event("lockstep", f"controller silent for {self.cfg.lost_after_s:g} s of wall time: "
                                   "leaving lockstep, running on the wall clock")
        self.clock.run_free(Trigger.LOSE, now, self.step() * self.substeps)

    def collided(self, why: str) -> None:
        """A fleet's shared clock: another vehicle touched this one (``why``); the flight ends there, disarmed,
        the clock halted, as offline (``collision``)."""
        self.sim.event("collision", why)
        self.sim.disarm(f"collision: {why}")
        self.clock.fire(Trigger.COLLIDE)

    def diverged(self) -> bool:
        """After a control period: whether the plant ended the flight (diverged, or crashed while armed:
        :meth:`SimVehicle.plant_verdict`, as offline); then disarmed, and the clock halted for good."""
        verdict = self.sim.plant_verdict()
        if verdict is None:
            return False
        self.sim.disarm(f"{verdict}: {self.sim.events[-1].text}")
        self.clock.fire(Trigger.DIVERGE)
        return True

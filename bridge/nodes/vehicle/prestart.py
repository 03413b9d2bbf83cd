"""Before an awaited mission's flight (``--await-mission``): a ground station's arm in HOLD on the ground, and
PX4's pre-takeoff timeout (COM_DISARM_PRFLT), which also ends a ground station's arm in HOLD on the ground of a
vehicle awaiting no mission.

In:  the simulated vehicle (armed, mode, on the ground, its events, ``preflight_disarm_s``), the mission manager
     (a start requested, a mission flying or completed), wall time (s, ``time.monotonic``)
Out: the vehicle's mode before its first arm (HOLD); whether it is armed in HOLD before the mission's flight
     (:meth:`PreStart.held`) and awaits its start (:meth:`PreStart.awaits`); the events of such an arm, and of a
     disarm before the start, marked ``pre_start`` (part of the start, not a change to a flight: summary.json's
     interventions and ended_by skip them); the vehicle's own disarm once COM_DISARM_PRFLT has passed with no start
     (:meth:`PreStart.tick`: the clock's DISARM)

As PX4 without RC sticks, the vehicle awaiting a mission waits in HOLD; a ground station's arm arms it there and
nothing flies until the start (in lockstep time stands still), which the controller's arm takes from HOLD to
OFFBOARD (docs/missions.md).
"""

from __future__ import annotations

from bridge.autopilot.simvehicle import HOLD, SimVehicle
from bridge.nodes.vehicle.clock import Clock, Trigger
from bridge.nodes.vehicle.mission import MissionManager


class PreStart:
    """A ground station's arm awaiting an awaited mission's start, for one vehicle."""

    def __init__(self, sim: SimVehicle, clock: Clock, missions: MissionManager | None, await_mission: bool) -> None:
        self.sim = sim
        self.clock = clock
        self.missions = missions if await_mission else None
        self.at: float | None = None  # wall time (s) of the arm whose timeout runs (None: none runs)
        self.armed_at: float | None = None  # wall time (s) of the vehicle's latest arm from disarmed, any link's
        if self.missions is not None:
            sim.mode = HOLD  # as PX4 without RC sticks waits in Hold: a ground station's arm arms there

    def starting(self) -> bool:
        """A ground station started the mission; the controller's arm, once it has it, is still to come."""
        return self.missions is not None and self.missions.start_requested

    def held(self) -> bool:
        """Armed in HOLD on the ground before the mission's flight (nothing flown yet)."""
        m, sim = self.missions, self.sim
        return (m is not None and m.watch is None and not m.completed and sim.armed and sim.mode == HOLD
                and sim.plant.on_ground)

    def awaits(self) -> bool:
        """Held with no start yet: the pre-takeoff timeout runs."""
        return self.held() and not self.starting()

    def times_out(self) -> bool:
        """Whether the pre-takeoff timeout runs now: awaiting the mission's start (:meth:`awaits`), or, with no
        mission awaited, armed in HOLD on the ground (a ground station's arm: nothing takes off from there)."""
        if self.missions is not None:
            return self.awaits()
        sim = self.sim
        return sim.armed and sim.mode == HOLD and sim.plant.on_ground and not sim.took_off

    def arm_taken(self, now: float, was_armed: bool) -> None:
        """An arm command took (any link's: a ground station's, a controller's offboard arm) at wall time ``now``
        (s); from disarmed, PX4's pre-takeoff timeout runs from it, whatever mode is selected on the ground later."""
        if not was_armed:
            self.armed_at = now

    def ground_armed(self, now: float) -> None:
        """With no mission awaited: a ground station's arm left the vehicle armed in HOLD on the ground at wall time
        ``now`` (s): PX4's pre-takeoff timeout runs from it (the events are not the start's: none is awaited). HOLD
        selected later on the ground, never off it since the arm, starts it at :meth:`tick`; after a flight
        (``took_off``) a landed HOLD disarms after COM_DISARM_LAND instead (bridge/autopilot/failsafe.LandedHold)."""
        if self.missions is None and self.at is None and self.times_out():  # (an arm again: the timeout runs on)
            self.at = now

    def armed(self, now: float, n0: int) -> None:
        """A ground station's arm left the vehicle held (its events from ``n0``): the first one starts the timeout
        and is the start's; one again, or after the start, changes nothing."""
        if self.at is None and not self.starting():
            self.at = now
            self.mark(n0)

    def mark(self, n0: int) -> None:
        """The vehicle's events from ``n0`` on are the start's (``pre_start``)."""
        for e in self.sim.events[n0:]:
            e.pre_start = True

    def tick(self, now: float) -> None:
        """Wall-clock duty: held and not started (or, no mission awaited, armed in HOLD on the ground) for
        COM_DISARM_PRFLT (> 0) since the arm, the vehicle disarms itself, as PX4's pre-takeoff timeout does."""
        at = self.at
        if at is None:
            if self.missions is None and self.times_out():  # HOLD selected on the ground, never off it since the
                # arm (a TAKEOFF that had not lifted, a controller's offboard arm): from the arm, as PX4's commander
                # counts it (landed since arming), whatever the mode it was armed in. Until the forty-fifth session
                # from the HOLD: a HOLD 8 s after the arm disarmed 10 s later, 18 s after it, not at 10 s
                self.at = now if self.armed_at is None else min(now, self.armed_at)
            return
        if not self.times_out():
            self.at = None  # disarmed, another mode, taken off, or started
            return
        limit = self.sim.preflight_disarm_s
        if limit > 0.0 and now - at >= limit:
            self.at = None
            n0 = len(self.sim.events)
            what = "no mission started" if self.missions is not None else "no takeoff"
            self.sim.disarm(f"disarmed: {what} within COM_DISARM_PRFLT = {limit:g} s of arming")
            if self.missions is not None:
                self.mark(n0)
            self.clock.fire(Trigger.DISARM)

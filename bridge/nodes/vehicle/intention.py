"""The mode a session's vehicle takes once it disarms: PX4's user mode intention with AUTO.MISSION.

In:  the simulated vehicle's mode and arming after each command and each control period (HOLD, TAKEOFF, OFFBOARD,
     LAND, RTL, the failsafe's), and whether it shows AUTO.MISSION (an awaited mission selected, started or flying)
Out: disarmed in LAND or RTL, or in its failsafe, the vehicle takes the last mode it was put in that PX4 arms in,
     a ``mode`` event saying so (:class:`bridge.autopilot.intention.UserModeIntention`, which the offline loop uses
     too); AUTO.MISSION among them here; a ground station's arm then arms in that mode, as on PX4

PX4 (src/modules/commander/UserModeIntention.cpp, 1.14 and 1.15; the rest in :mod:`bridge.autopilot.intention`):
after a LAND or a Return has landed and auto-disarmed (COM_DISARM_LAND), PX4 is back in the mode before them (Hold
after a takeoff, Offboard after an offboard flight, Mission after a mission), where an arm is allowed; a mission's own
landing stays in Mission. Here the offboard controller's mission end LAND is such a change too (as a companion's
NAV_LAND is on PX4): after its landing the vehicle is back in OFFBOARD (AUTO.MISSION for an awaited mission, which
PX4 flies as Mission throughout). The failsafe's modes (shown HOLD, LAND, RTL) are no user's: not remembered; its
disarm clears it and takes the same mode (PX4's failsafe selects no action while disarmed), STANDBY.
"""

from __future__ import annotations

from bridge.autopilot.intention import UserModeIntention
from bridge.autopilot.simvehicle import OFFBOARD, SimVehicle
from bridge.mavlink.modes import MISSION
from bridge.nodes.vehicle.mission import MissionManager


class ModeIntention(UserModeIntention):
    """The mode to take after disarming, for one vehicle, AUTO.MISSION included."""

    def __init__(self, sim: SimVehicle, missions: MissionManager | None) -> None:
        super().__init__(sim)
        self.missions = missions

    def note(self) -> None:
        """After a command or a control period: the mode the vehicle is in, if PX4 arms in it, is the one to take
        after disarming (AUTO.MISSION while it shows)."""
        sim, missions = self.sim, self.missions
        if missions is not None and missions.shows_mission(sim.armed, sim.mode == OFFBOARD):
            self.after = MISSION
        else:
            super().note()

    def take(self, mode: str) -> tuple[str, str]:
        """AUTO.MISSION is taken as a ground station's selection of it is (an arm then starts the held mission, from
        its first item; the vehicle flies it in OFFBOARD, the event's typed ``mode`` says MISSION, as its text);
        if it cannot be (no mission held, an upload on), OFFBOARD."""
        if mode == MISSION and (self.missions is None or self.missions.select(False) is not None):
            mode = OFFBOARD
        return mode, OFFBOARD if mode == MISSION else mode

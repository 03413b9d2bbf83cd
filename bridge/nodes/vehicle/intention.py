"""The mode the vehicle is in once it disarms: PX4's user mode intention, as its commander keeps it.

In:  the simulated vehicle's mode and arming after each command and each control period (HOLD, TAKEOFF, OFFBOARD,
     LAND, RTL), and whether it shows AUTO.MISSION (an awaited mission selected, started or flying)
Out: disarmed in LAND or RTL (its landing's auto-disarm, or a disarm by command), the vehicle takes the last mode it
     was put in that PX4 arms in (:meth:`ModeIntention.after`), a ``mode`` event saying so; a ground station's arm
     then arms in that mode, as on PX4

PX4 (src/modules/commander/UserModeIntention.cpp, 1.14 and 1.15): every mode change the user (or the navigator: the
takeoff's end to Hold) makes is remembered as the mode to take after disarming, unless the mode prevents arming
(``mode_req_prevent_arming``, ModeUtil/mode_requirements.cpp: AUTO.LAND, AUTO.RTL, Descend, Termination ...);
``Commander::disarm`` then calls ``UserModeIntention::onDisarm``, which takes it (it boots with Hold). So after a
LAND or a Return has landed and auto-disarmed (COM_DISARM_LAND), PX4 is back in the mode before them (Hold after a
takeoff, Offboard after an offboard flight, Mission after a mission), where an arm is allowed; a mission's own
landing stays in Mission. Here the offboard controller's mission end LAND is such a change too (as a companion's
NAV_LAND is on PX4): after its landing the vehicle is back in OFFBOARD (AUTO.MISSION for an awaited mission, which
PX4 flies as Mission throughout). The failsafe's modes (shown HOLD, LAND, RTL) are no user's: not remembered, and
not left here after its disarm (that vehicle shows LAND, CRITICAL, until armed again).
"""

from __future__ import annotations

from bridge.autopilot.simvehicle import HOLD, LAND, OFFBOARD, RTL, TAKEOFF, SimVehicle
from bridge.mavlink.modes import MISSION, mode_name
from bridge.nodes.vehicle.mission import MissionManager

ARMABLE = (HOLD, TAKEOFF, OFFBOARD)  # the modes the vehicle flies that PX4 arms in (and AUTO.MISSION)
NOT_ARMABLE = {LAND: "Land", RTL: "Return"}  # PX4's prevent-arming modes the vehicle flies, by PX4's name


class ModeIntention:
    """The mode to take after disarming, for one vehicle."""

    def __init__(self, sim: SimVehicle, missions: MissionManager | None) -> None:
        self.sim = sim
        self.missions = missions
        self.after = sim.mode if sim.mode in ARMABLE else HOLD  # PX4 boots with Hold

    def note(self) -> None:
        """After a command or a control period: the mode the vehicle is in, if PX4 arms in it, is the one to take
        after disarming (AUTO.MISSION while it shows)."""
        sim, missions = self.sim, self.missions
        if missions is not None and missions.shows_mission(sim.armed, sim.mode == OFFBOARD):
            self.after = MISSION
        elif sim.mode in ARMABLE:
            self.after = sim.mode

    def fall_back(self) -> bool:
        """Disarmed in LAND or RTL: take :attr:`after` (a ``mode`` event, the vehicle's); True if it did. AUTO.MISSION
        is taken as a ground station's selection of it is (an arm then starts the held mission, from its first
        item); if it cannot be (no mission held, an upload on), OFFBOARD."""
        sim = self.sim
        if sim.armed or sim.mode not in NOT_ARMABLE:
            return False
        was, mode = sim.mode, self.after
        if mode == MISSION and (self.missions is None or self.missions.select(False) is not None):
            mode = OFFBOARD
        sim.mode = OFFBOARD if mode == MISSION else mode
        sim.event("mode", f"{mode_name(mode)} (disarmed after {mode_name(was)}: PX4 takes the last mode it arms "
                          f"in; armed in it next)", mode=sim.mode, armed=False)
        return True

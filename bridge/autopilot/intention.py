"""The mode the vehicle takes once it disarms: PX4's user mode intention, and its failsafe cleared on disarm.

In:  the simulated vehicle's mode and arming after each control period (and, in a session, each command): OFFBOARD,
     HOLD, TAKEOFF, LAND, RTL, and the failsafe's (FAILSAFE flying, LANDED the period it disarmed the vehicle in)
Out: disarmed in LAND or RTL, or in its failsafe (its landing's auto-disarm, its ``disarm`` action, a disarm by
     command), the vehicle takes the last mode it was put in that PX4 arms in (:attr:`UserModeIntention.after`),
     with a ``mode`` event of its own saying which and why (:meth:`UserModeIntention.fall_back`); the next arm is
     in that mode, as on PX4. The same in every clock: the offline loop (``bridge/loop.py``) and a session's vehicle
     (``bridge/nodes/vehicle/intention.py``, which adds AUTO.MISSION) call it after each control period.

PX4 (src/modules/commander/UserModeIntention.cpp, 1.14 and 1.15): every mode change the user (or the navigator: the
takeoff's end to Hold) makes is remembered as the mode to take after disarming, unless the mode prevents arming
(``mode_req_prevent_arming``, ModeUtil/mode_requirements.cpp: AUTO.LAND, AUTO.RTL, Descend, Termination ...);
``Commander::disarm`` then calls ``UserModeIntention::onDisarm``, which takes it (it boots with Hold). The failsafe's
modes are no user's: they never change the intention. And the failsafe is cleared on disarm
(failsafe/framework.cpp, the same in the framework's first version, 2022, and today's: ``FailsafeBase::update``
removes on a disarm the actions that clear ``OnDisarm`` and ``OnModeChangeOrDisarm``, and ``getSelectedAction``
selects no action at all while disarmed, except a Terminate), so the commander sets ``nav_state`` to
``modeFromAction(None, user intended mode)``, the user's mode, and ``vehicle_status.failsafe`` false;
mavlink/streams/HEARTBEAT.hpp says STANDBY for any disarmed vehicle.
So after a failsafe has landed (or stopped) and disarmed the vehicle, PX4 shows the mode before the failsafe
(OFFBOARD after an offboard flight, HOLD after a ground station's takeoff), STANDBY, and arms in it again.
"""

from __future__ import annotations

from bridge.autopilot.simvehicle import FAILSAFE, HOLD, LAND, LANDED, OFFBOARD, RTL, TAKEOFF, SimVehicle

ARMABLE = (HOLD, TAKEOFF, OFFBOARD)  # the modes the vehicle flies that PX4 arms in
NOT_ARMABLE = {LAND: "Land", RTL: "Return"}  # PX4's prevent-arming modes the vehicle flies, by PX4's name
FAILSAFE_MODES = (FAILSAFE, LANDED)  # the failsafe's: flying its action, and the period it disarmed the vehicle in


class UserModeIntention:
    """The mode to take after disarming, for one vehicle."""

    def __init__(self, sim: SimVehicle) -> None:
        self.sim = sim
        self.after = sim.mode if sim.mode in ARMABLE else HOLD  # PX4 boots with Hold

    def note(self) -> None:
        """After a command or a control period: the mode the vehicle is in, if PX4 arms in it, is the one to take
        after disarming."""
        if self.sim.mode in ARMABLE:
            self.after = self.sim.mode

    def fall_back(self) -> bool:
        """Disarmed in LAND or RTL, or in its failsafe: take :attr:`after` (a ``mode`` event, the vehicle's saying
        which and why); True if it did."""
        sim = self.sim
        if sim.armed or (sim.mode not in NOT_ARMABLE and sim.mode not in FAILSAFE_MODES):
            return False
        was = sim.mode
        shown, sim.mode = self.take(self.after)
        why = ("its failsafe: PX4 clears the failsafe on disarm and takes" if was in FAILSAFE_MODES
               else f"{was.upper()}: PX4 takes")
        sim.event("mode", f"{shown.upper()} (disarmed after {why} the last mode it arms in; armed in it next)",
                  mode=shown, armed=False)
        return True

    def after_period(self) -> str:
        """After a control period (or a command): :meth:`note`, then :meth:`fall_back`; the mode the vehicle was in
        before them (the period's)."""
        flown = self.sim.mode
        self.note()
        self.fall_back()
        return flown

    def take(self, mode: str) -> tuple[str, str]:
        """The mode taken for :attr:`after` = ``mode``: (the mode a ground station sees, the event's typed ``mode``;
        the vehicle's mode)."""
        return mode, mode

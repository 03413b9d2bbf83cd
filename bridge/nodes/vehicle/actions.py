"""Commands MAVSDK's Action and Failure plugins send besides arming and modes, as PX4 takes them: failure injection,
speed, termination, protocol version; and a ground station's DO_SET_MISSION_CURRENT (:mod:`.setcurrent`).

In:  MAV_CMD_INJECT_FAILURE (:mod:`.injection`), MAV_CMD_DO_CHANGE_SPEED (param1 speed type, param2 m/s: > 0 sets,
     else the default), MAV_CMD_DO_FLIGHTTERMINATION (param1: > 0.5 terminate, else DENIED),
     MAV_CMD_REQUEST_PROTOCOL_VERSION, MAV_CMD_DO_SET_MISSION_CURRENT (:mod:`.setcurrent`), from a sender with
     authority (:class:`~bridge.autopilot.vehicleevents.Sender`); the simulated vehicle and its step clock
Out: the MAV_RESULT and why a command was refused (the commander's STATUSTEXT); an injection's events scheduled
     (:meth:`~bridge.autopilot.simvehicle.SimVehicle.schedule`); a ``speed`` event, the vehicle's own
     controller's horizontal speed (:meth:`~bridge.autopilot.onboard.OnboardController.cruise`); a ``terminated``
     event, the motors off (disarmed), mode TERMINATION (latched: :meth:`Actions.refusal`); PROTOCOL_VERSION (msg 300);
     MISSION_CURRENT (:mod:`.setcurrent`)

**INJECT_FAILURE.** DENIED unless SYS_FAILURE_EN = 1 (PX4's receiver does the same), and DENIED once the plant ended
the flight (crashed, diverged, collided: its clock halted, nothing would act on it); else its events are acted on at
the start of the next control period, naming the sender, or it is refused saying why (:mod:`.injection`).

**DO_CHANGE_SPEED.** PX4's navigator (navigator_main.cpp) sets its cruising speed to param2 if positive, else back to
the default, whatever param1's speed type (a multicopter: "not differentiating ground and airspeed yet"), and always
answers ACCEPTED; each navigator mode (Hold, Return, Mission, Land) resets it to the default when it begins. Here the
speed is the vehicle's own controller's horizontal speed limit for the target it flies now (HOLD's flight to a
DO_REPOSITION point, Return's way home), at most its 2 m/s, until its next target (a mode, the takeoff's end, the
failsafe); in OFFBOARD (the offboard controller's targets, an awaited mission's trajectory) it changes nothing, as on
PX4, and the event says so.

**DO_FLIGHTTERMINATION.** PX4's commander (Commander.cpp, ``VEHICLE_CMD_DO_FLIGHTTERMINATION``): param1 > 0.5
of an armed vehicle forces its outputs to their failsafe values (the motors off) and triggers a parachute; the vehicle
falls; its mode is Termination from then on (UserModeIntention.cpp: it never changes out of it, not after a disarm
either), HEARTBEAT's ``system_status`` FLIGHT_TERMINATION (streams/HEARTBEAT.hpp); ACCEPTED. A vehicle not armed:
DENIED; param1 0 (no cancel in PX4 main): DENIED. Here the motors stop in the same control
period (the vehicle is disarmed, where PX4 keeps it armed with its outputs forced off: the same thrust, none), the
vehicle falls on its own (a lockstep flight leaves the step clock: the vehicle's time runs on the wall clock), every
later arm and mode change is DENIED, and the flight's outcome is ``terminated`` (exit 1; summary.json's ``ended_by``
names who terminated it and how it came down). Any param1 over 0.5 terminates, 2 (PX4's ``commander lockdown on``)
too: PX4 main's commander has no lockdown test over 1.5 any more (UNSUPPORTED here until the third wave's
thirty-eighth session). Not modelled: the parachute. Until 2026-12-06 a termination of a vehicle on the ground,
disarmed, was ACCEPTED and latched (it could not be armed again), and a cancel with nothing to cancel ACCEPTED, as
PX4 before its UserModeIntention.

**REQUEST_PROTOCOL_VERSION.** PX4's MAVLink receiver answers with PROTOCOL_VERSION: version 200, min 100, max 200
(MAVLink 2), the hashes of its MAVLink library; here zero hashes. pymavlink's dialect has no PROTOCOL_VERSION, so its
frame is built here (:data:`PROTOCOL_VERSION`: id 300, CRC extra 217).
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from bridge.autopilot.modes import TERMINATION
from bridge.autopilot.simvehicle import OFFBOARD, SimVehicle
from bridge.autopilot.vehicleevents import Sender
from bridge.core.weather import event_problem
from bridge.mavlink.modes import mode_name
from bridge.nodes.vehicle.authority import attribute
from bridge.nodes.vehicle.clock import Clock
from bridge.nodes.vehicle.injection import injection
from bridge.nodes.vehicle.mission import MissionManager
from bridge.nodes.vehicle.setcurrent import set_current

Result = tuple[int, str | None]  # (MAV_RESULT, why it was refused: a STATUSTEXT; None: not refused)


class ProtocolVersion(mavlink.MAVLink_message):
    """PROTOCOL_VERSION (MAVLink message 300, not in pymavlink's dialect): version, min and max (MAVLink 1.0 = 100),
    the spec's and library's hashes (8 bytes each)."""

    id = 300
    msgname = "PROTOCOL_VERSION"
    fieldnames = ["version", "min_version", "max_version", "spec_version_hash", "library_version_hash"]
    crc_extra = 217
    unpacker = struct.Struct("<HHH8s8s")

    def __init__(self, version: int, min_version: int, max_version: int, spec: bytes = bytes(8),
                 library: bytes = bytes(8)) -> None:
        mavlink.MAVLink_message.__init__(self, ProtocolVersion.id, ProtocolVersion.msgname)
        self._fieldnames = ProtocolVersion.fieldnames
        self.version, self.min_version, self.max_version = version, min_version, max_version
        self.spec_version_hash, self.library_version_hash = spec, library

    def pack(self, mav: Any, force_mavlink1: bool = False) -> bytes:
        return self._pack(mav, self.crc_extra, self.unpacker.pack(
            self.version, self.min_version, self.max_version, self.spec_version_hash, self.library_version_hash),
            force_mavlink1=force_mavlink1)


PROTOCOL_VERSION = (200, 100, 200)  # PX4's answer: MAVLink 2, and it speaks 1.0 to 2.0


class Actions:
    """INJECT_FAILURE, DO_CHANGE_SPEED, DO_FLIGHTTERMINATION, REQUEST_PROTOCOL_VERSION and DO_SET_MISSION_CURRENT
    (with a mission manager) for one vehicle."""

    def __init__(self, sim: SimVehicle, clock: Clock, reject: Callable[[str], None],
                 run_free: Callable[[], None], missions: MissionManager | None = None) -> None:
        self.missions = missions
        self.sim = sim
        self.clock = clock
        self.reject = reject  # count a refusal (bad_number)
        self.run_free = run_free  # lockstep: the vehicle's time on the wall clock from now (it falls by itself)

    def run(self, m: Any, by: Sender) -> tuple[Result, tuple[Any, ...]] | None:
        """Command ``m`` if it is one of these: ((MAV_RESULT, why refused), the messages it asked for); else None."""
        cmd = m.command
        if cmd == mavlink.MAV_CMD_INJECT_FAILURE:
            return self.inject_failure(m, by), ()
        if cmd == mavlink.MAV_CMD_DO_CHANGE_SPEED:
            return self.change_speed(m.param2, by), ()
        if cmd == mavlink.MAV_CMD_DO_FLIGHTTERMINATION:
            return self.terminate(m.param1, by), ()
        if cmd == mavlink.MAV_CMD_REQUEST_PROTOCOL_VERSION:
            return (mavlink.MAV_RESULT_ACCEPTED, None), (ProtocolVersion(*PROTOCOL_VERSION),)
        if cmd == mavlink.MAV_CMD_DO_SET_MISSION_CURRENT and self.missions is not None:
            return set_current(self.missions, m, by, self.reject)
        return None

    @property
    def terminated(self) -> bool:
        return self.sim.mode == TERMINATION

    def refusal(self, what: str) -> str | None:
        """Why ``what`` (an arm, a mode) is refused after a flight termination, or None (not terminated)."""
        if not self.terminated:
            return None
        return f"{what}: the flight was terminated (PX4 leaves TERMINATION only by a reboot)"

    def inject_failure(self, m: Any, by: Sender) -> Result:
        """MAV_CMD_INJECT_FAILURE (module docstring)."""
        sim = self.sim
        if not sim.failure_injection:
            return mavlink.MAV_RESULT_DENIED, "INJECT_FAILURE: disabled, SYS_FAILURE_EN is 0"
        if self.clock.halted:  # its plant is stepped no more: an accepted fault would never act nor be logged
            return mavlink.MAV_RESULT_DENIED, "INJECT_FAILURE: the plant ended the flight"
        sensors = sim.sensors.config if sim.sensors is not None else None
        got = injection(m.param1, m.param2, m.param3, sim.t,
                        lambda kind: event_problem(kind, sim.plant.profile, sensors,
                                                   getattr(sim.estimator, "kind", "truth"),
                                                   sim.plant.battery is not None))
        if got.why is not None:
            if got.result == mavlink.MAV_RESULT_DENIED:
                self.reject("bad_number")
            return got.result, got.why
        for e in got.events:
            sim.schedule(e, by)
        return mavlink.MAV_RESULT_ACCEPTED, None

    def change_speed(self, speed: float, by: Sender) -> Result:
        """DO_CHANGE_SPEED's param2 (m/s): the vehicle's own controller flies its target at it (module docstring)."""
        if speed == math.inf:
            self.reject("bad_number")
            return mavlink.MAV_RESULT_DENIED, "DO_CHANGE_SPEED: param2 (speed) must be finite"
        sim = self.sim
        asked = speed if speed > 0.0 else None  # (NaN, 0 and below: the default, as PX4)
        flying = sim.armed and sim.mode not in (OFFBOARD, TERMINATION) and sim.onboard.target is not None
        n0 = len(sim.events)
        if not flying:
            sim.onboard.g = sim.onboard.gains
            what = "default" if asked is None else f"{asked:g} m/s"
            sim.event("speed", f"{what}: nothing flown by the vehicle's own controller now ({mode_name(sim.mode)}"
                               f"{'' if sim.armed else ', disarmed'}): no change (PX4 resets it as each mode begins)")
        else:
            top = sim.onboard.cruise(asked)
            sim.event("speed", f"{mode_name(sim.mode)} flies at most {top:g} m/s across" + (
                "" if asked is None or top == asked else f" (asked {asked:g}: the vehicle's own controller's limit)"))
        attribute(sim.events, n0, by)
        return mavlink.MAV_RESULT_ACCEPTED, None

    def terminate(self, p1: float, by: Sender) -> Result:
        """DO_FLIGHTTERMINATION (module docstring)."""
        if not math.isfinite(p1):
            self.reject("bad_number")
            return mavlink.MAV_RESULT_DENIED, "DO_FLIGHTTERMINATION: param1 must be 0 (cancel) or 1 (terminate)"
        if p1 <= 0.5:  # PX4 main has no cancel: DENIED (and, over 0.5, no lockdown test: every value terminates)
            return mavlink.MAV_RESULT_DENIED, ("DO_FLIGHTTERMINATION: the flight was terminated; it is not undone "
                                               "(PX4 leaves TERMINATION only by a reboot)" if self.terminated else
                                               "DO_FLIGHTTERMINATION: param1 0: nothing to cancel (PX4 cancels none)")
        if self.clock.halted:
            return mavlink.MAV_RESULT_DENIED, "DO_FLIGHTTERMINATION: the flight is over (the plant ended it)"
        if self.terminated:
            return mavlink.MAV_RESULT_ACCEPTED, None
        sim = self.sim
        if not sim.armed:  # PX4 main's commander: `if (!isArmed())` DENIED
            return mavlink.MAV_RESULT_DENIED, "DO_FLIGHTTERMINATION: not armed (PX4 terminates only an armed vehicle)"
        X = sim.published()
        n0 = len(sim.events)
        sim.event("terminated", f"flight termination: motors off at x={X[0]:.3f} y={X[2]:.3f} z={X[4]:.3f} m, "
                                f"{X[5]:+.2f} m/s up, {mode_name(sim.mode)}"
                                f"{'' if sim.plant.on_ground else ': it falls'}")
        sim.disarm("terminated: motors off")
        sim.mode = TERMINATION
        attribute(sim.events, n0, by)
        self.run_free()
        return mavlink.MAV_RESULT_ACCEPTED, None

"""The vehicle's commander: arming, flight modes, commands, and the triggers that end a flight.

In:  COMMAND_LONG / COMMAND_INT (COMPONENT_ARM_DISARM, DO_SET_MODE, NAV_TAKEOFF m AMSL, NAV_LAND, NAV_RETURN_TO_LAUNCH,
     MISSION_START (with ``await_mission``: :mod:`.mission`), DO_REPOSITION, INJECT_FAILURE, DO_CHANGE_SPEED,
     DO_FLIGHTTERMINATION, REQUEST_PROTOCOL_VERSION, DO_SET_MISSION_CURRENT (:mod:`.actions`), the requests for
     messages and their rates (:mod:`.requests`)) and SET_MODE from a sender with authority
     (:class:`~bridge.autopilot.vehicleevents.Sender`); the plant's divergence and the controller's silence (wall
     time, s)
Out: COMMAND_ACK (with what a command asked for, and a STATUSTEXT saying why it was refused) in one
     datagram; the flight's changes (arm, disarm, mode) on the :class:`SimVehicle` as events naming their
     sender; the step clock's transitions (:class:`~bridge.nodes.vehicle.clock.Clock`); why a command was
     refused (a :class:`~bridge.nodes.report.Refused` report)

Flight modes (OFFBOARD, HOLD, LAND, TAKEOFF, RTL, in PX4's encoding: :mod:`bridge.mavlink.modes`) and what a
ground station can do with them: docs/ground-station.md; the mode taken after a disarm in LAND, RTL or the
failsafe: :mod:`.intention`. Every command's numbers are checked before use (:mod:`bridge.mavlink.receive`): a bad
one is DENIED and counted (``bad_number``), nothing done.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from bridge.autopilot.failsafe import PositionHold
from bridge.autopilot.fencewatch import reposition_refusal
from bridge.autopilot.flightstart import flight_begun
from bridge.autopilot.intention import NOT_ARMABLE
from bridge.autopilot.params import BY_NAME
from bridge.autopilot.positionloss import taken_without_position
from bridge.autopilot.simvehicle import GROUND_MODES, HOLD, LAND, OFFBOARD, RTL, TAKEOFF, SimVehicle
from bridge.autopilot.vehicleevents import Sender
from bridge.mavlink.endpoint import Endpoint
from bridge.mavlink.modes import MISSION, mode_name, requested_custom_mode, requested_mode
from bridge.mavlink.receive import FORCE_DISARM, arm_disarm_args
from bridge.nodes.vehicle.actions import Actions
from bridge.nodes.vehicle.armretry import Arm, ArmRetries
from bridge.nodes.vehicle.authority import Authority, attribute
from bridge.nodes.vehicle.clock import Clock, Trigger
from bridge.nodes.vehicle.clocking import Clocking
from bridge.nodes.vehicle.intention import ModeIntention
from bridge.nodes.vehicle.mission import START_ARM, START_ARMED, START_COMMAND, MissionManager, in_air_refusal
from bridge.nodes.vehicle.prestart import PreStart
from bridge.nodes.vehicle.reposition import reposition
from bridge.nodes.vehicle.requests import MessageRequests, Result
from bridge.nodes.vehicle.streams import StatusTexts, StreamTable
from bridge.nodes.vehicle.takeoff import takeoff_altitude
from bridge.record.metrics import plant_blocks

OFFBOARD_STREAM_S = 1.0  # s of wall time: a ground station's OFFBOARD needs a target from the controller this recent


@dataclass(frozen=True)
class CommanderPorts:
    """What the commander asks of the vehicle that wires it."""

    step: Callable[[], int]  # the current control step k
    state_out: Callable[[float], None]  # send step k's state at wall time now (s): lockstep awaits its answer
    new_flight: Callable[[bool], None]  # a new flight is armed (True: by a ground station)
    # the controller's arm enters the up-link model now (lockstep); the callables: when it has been acted on, and
    # whether it is still to be when the model delivers it
    arm_through_link: Callable[[Callable[[], None], Callable[[], bool]], None]
    target_wall: Callable[[], float]  # wall time (s) of the newest actuator target from the controller
    controller_heard: Callable[[], bool]  # whether a controller has spoken on the controller link
    message: Callable[[int, bool], list[Any]]  # the message(s) of an id as a stream sends them (own: a GCS's frame)
    reject: Callable[[str], None]  # count a refusal (bridge.mavlink.receive.Rejections)
    refused: Callable[[str], None]  # a command refused, and why (its report to the session)
    # the events a command made said on stdout now, before its COMMAND_ACK, so that whoever the answer reaches
    # (the controller, and what it reports) never speaks of it before the vehicle did
    announce: Callable[[], None] = lambda: None
    missions: MissionManager | None = None  # a ground station's mission start and AUTO.MISSION (await_mission)


class FinalAck:
    """The final COMMAND_ACK of a controller's arm answered IN_PROGRESS (lockstep: it crossed the up-link model),
    sent to its sender once the vehicle has acted on it, as MAVLink's command protocol asks after IN_PROGRESS:
    ACCEPTED if it is armed in OFFBOARD then, TEMPORARILY_REJECTED if its pre-arm check denied it, else FAILED.
    An arm the model loses gets none, as a command lost on a real link does."""

    def __init__(self, m: Any, ep: Endpoint, addr: tuple[str, int], sim: SimVehicle, arm: Arm) -> None:
        self.command, self.sysid, self.compid = m.command, m.get_srcSystem(), m.get_srcComponent()
        self.ep, self.addr, self.sim, self.arm = ep, addr, sim, arm

    def wanted(self) -> bool:
        """Whether this copy, delivered by the model, is still to be acted on: not if a copy of the same arm was
        (a resend on its way while the first armed the vehicle, whose failsafe may have disarmed it since)."""
        return self.arm.result is None

    def __call__(self) -> None:
        sim, result = self.sim, self.arm.result
        if result is None:  # this copy was acted on: its result answers the later ones
            result = (mavlink.MAV_RESULT_ACCEPTED if sim.armed and sim.mode == OFFBOARD
                      else mavlink.MAV_RESULT_TEMPORARILY_REJECTED if sim.arming_refused
                      else mavlink.MAV_RESULT_FAILED)
            ArmRetries.acted(self.arm, result)
        self.ep.send(mavlink.MAVLink_command_ack_message(self.command, result, 0, 0, self.sysid, self.compid),
                     self.addr)


class Commander:
    """Arms, disarms, sets modes and runs commands for one vehicle."""

    def __init__(self, sim: SimVehicle, clock: Clock, authority: Authority, texts: StatusTexts,
                 streams: dict[str, StreamTable], substeps: int, ports: CommanderPorts) -> None:
        self.sim = sim
        self.clock = clock
        self.authority = authority
        self.cfg = authority.cfg
        self._statustext = texts
        self.ports = ports
        self.texts: list[Any] = []  # STATUSTEXTs saying why a command was refused: sent after its COMMAND_ACK
        self.plant_at_end: dict[str, Any] | None = None  # the plant's summary blocks when the mission ended
        # which clock the flight runs on as its modes and its end change (lockstep, the wall clock, none)
        self.clocking = Clocking(sim, clock, self.cfg, substeps, ports.step, ports.state_out)
        # a ground station's arm in HOLD on the ground awaiting a mission's start (--await-mission)
        self.pre_start = PreStart(sim, clock, ports.missions, self.cfg.await_mission)
        self.intention = ModeIntention(sim, ports.missions)  # the mode a disarm in LAND, RTL or failsafe leaves
        self.actions = Actions(sim, clock, ports.reject, self.clocking.off_step_clock, ports.missions)
        # link (controller, gcs) -> its stream table: a link's requests change its own
        self.requests = MessageRequests(sim, streams, self.cfg.sysid, ports.message, ports.reject)
        self.arm_copies = ArmRetries()  # each sender's arm: acted on once, however many copies come

    # -- the messages ---------------------------------------------------------------------------------
    def command(self, ep: Endpoint, m: Any, addr: tuple[str, int], link: str) -> bool:
        """COMMAND_LONG / COMMAND_INT from a sender with authority on ``ep``: its numbers checked, acted
        on, answered (COMMAND_ACK and what it asked for, in one datagram) and, if it changed the flight,
        an event naming the sender. False when refused unanswered (``target``, ``reply_limited``)."""
        if self.authority.for_others(m):
            self.ports.reject("target")
            return False
        if not ep.reply_allowed(addr):
            self.ports.reject("reply_limited")  # not acted on: its answer could not go
            return False
        by = self.authority.sender(m, addr, link)
        n0 = len(self.sim.events)
        result, follow = self._run_command(m, by, ep, addr)
        attribute(self.sim.events, n0, by)
        self._after_change()
        self.ports.announce()
        ack = mavlink.MAVLink_command_ack_message(m.command, result, 0, 0, m.get_srcSystem(), m.get_srcComponent())
        ep.reply((ack, *follow, *self.texts), addr)
        self.texts.clear()
        return True

    def set_mode_message(self, ep: Endpoint, m: Any, addr: tuple[str, int], link: str) -> bool:
        """SET_MODE (deprecated by DO_SET_MODE, still sent by some ground stations), answered as a
        DO_SET_MODE. False when refused unanswered."""
        if self.authority.for_others(m):
            self.ports.reject("target")
            return False
        if not ep.reply_allowed(addr):
            self.ports.reject("reply_limited")
            return False
        by = self.authority.sender(m, addr, link)
        result = self._set_mode_or_refuse(*requested_custom_mode(m.base_mode, m.custom_mode), by=by)
        self._after_change()
        self.ports.announce()
        ack = mavlink.MAVLink_command_ack_message(mavlink.MAV_CMD_DO_SET_MODE, result, 0, 0, m.get_srcSystem(),
                                                  m.get_srcComponent())
        ep.reply((ack, *self.texts), addr)
        self.texts.clear()
        return True

    def _run_command(self, m: Any, by: Sender, ep: Endpoint, addr: tuple[str, int]) -> Result:
        """Act on a command whose sender has authority (``ep``, ``addr``: where its answers go): (MAV_RESULT, the
        messages it asked for)."""
        cmd = m.command
        if cmd == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            args = arm_disarm_args(m.param1, m.param2)
            if args is None:
                self.ports.reject("bad_number")
                return mavlink.MAV_RESULT_DENIED, ()
            if not args[0]:  # its own disarm ends its arm: an ARM it resends after is another arm's
                self.arm_copies.forget((m.get_srcSystem(), m.get_srcComponent(), addr))
                return self.arm_disarm(m.param1, m.param2, by), ()
            return self._arm_copy(m, by, ep, addr), ()
        asked = self.requests.run(m, by)  # SET/GET_MESSAGE_INTERVAL, REQUEST_MESSAGE, CAPABILITIES, HOME_POSITION
        if asked is not None:
            return asked
        if cmd == mavlink.MAV_CMD_DO_SET_MODE:
            return self._set_mode_or_refuse(*requested_mode(m.param1, m.param2, m.param3), by=by), ()
        if cmd == mavlink.MAV_CMD_NAV_TAKEOFF:
            got = takeoff_altitude(m.param7 if m._type == "COMMAND_LONG" else m.z,  # COMMAND_INT: z, m AMSL
                                   self.sim.takeoff_alt_m, BY_NAME["MIS_TAKEOFF_ALT"].hi, self.cfg.home.alt)
            if got.alt_m is None:
                return self._refuse(got.why or "NAV_TAKEOFF"), ()
            if got.warning is not None:
                self.texts += self._statustext(mavlink.MAV_SEVERITY_WARNING, got.warning)
            return self._set_mode_or_refuse(TAKEOFF, "", by=by, takeoff_alt_m=got.alt_m), ()
        if cmd == mavlink.MAV_CMD_NAV_LAND:  # lands where it is (PX4 with NaN lat/lon); a position is not flown to
            return self._set_mode_or_refuse(LAND, "", by=by), ()
        if cmd == mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH:  # Return mode, as PX4's commander takes it
            return self._set_mode_or_refuse(RTL, "", by=by), ()
        if cmd == mavlink.MAV_CMD_DO_REPOSITION:  # MAVSDK's goto_location, QGroundControl's "Go to location"
            return self._reposition(m, by), ()
        if cmd == mavlink.MAV_CMD_MISSION_START and self.cfg.await_mission:
            return self._start_mission(by, m.param1), ()
        acted = self.actions.run(m, by)  # INJECT_FAILURE, DO_CHANGE_SPEED, TERMINATION, PROTOCOL_VERSION, SET_CURRENT
        if acted is None:
            return mavlink.MAV_RESULT_UNSUPPORTED, ()
        (result, why), follow = acted
        return (result if why is None else self._refuse(why, result)), follow

    def _reposition(self, m: Any, by: Sender) -> int:
        """DO_REPOSITION, as PX4: HOLD (AUTO.LOITER); armed in the air, HOLD flies to the point given and holds
        it (:mod:`.reposition`); disarmed, only the mode is taken (PX4's navigator keeps no point for a vehicle
        not armed); armed on the ground, DENIED (take off first). A point not flown is refused saying why; one
        outside the geofence (GF_ACTION 2-5: :func:`~bridge.autopilot.fencewatch.reposition_refusal`) as PX4 does:
        ACCEPTED (HOLD), a CRITICAL STATUSTEXT, and the vehicle holds where it is (in HOLD: where it held). In a
        failsafe, as any mode a ground station selects, HOLD takes over (PX4's user takeover)."""
        sim = self.sim
        got = reposition(m, self.cfg.home, sim.published())
        if not sim.armed and got.result != mavlink.MAV_RESULT_UNSUPPORTED:  # no point kept, so none checked
            return self._set_mode_or_refuse(HOLD, "", by=by)
        if got.to is None:
            return self._refuse(got.why or "DO_REPOSITION", got.result)
        if sim.plant.on_ground:
            return self._refuse("DO_REPOSITION: on the ground: take off first (NAV_TAKEOFF)")
        outside = reposition_refusal(got.to, sim.t, sim.home, sim.max_hor_m, sim.max_ver_m, sim.fence,
                                     sim.fence_action)
        if outside is None:
            return self._set_mode_or_refuse(HOLD, "", by=by, hold_at=PositionHold(*got.to, psi=got.psi,
                                                                                   speed=got.speed))
        # PX4's commander takes AUTO.LOITER (ACCEPTED), and its navigator does not fly the point: HOLD holds
        x, y, z = got.to
        why = f"Reposition is outside geofence: to x={x:.3f} y={y:.3f} z={z:.3f} m: {outside}: not flown, holding"
        self.texts += self._statustext(mavlink.MAV_SEVERITY_CRITICAL, why)
        self.ports.refused(why)
        return mavlink.MAV_RESULT_ACCEPTED if sim.mode == HOLD else self._set_mode_or_refuse(HOLD, "", by=by)

    def _through_link(self, m: Any, by: Sender) -> bool:
        """Whether a command crosses the up-link model: the controller's, on its link, in a lockstep flight."""
        return by.link == "controller" and self.clock.engaged and self.authority.from_controller(m)

    # -- flight modes (docs/ground-station.md) -------------------------------------------------------
    def _mission_selected(self) -> bool:
        return self.ports.missions is not None and self.ports.missions.selected

    def _start_mission(self, by: Sender, first: float, how: str = START_COMMAND) -> int:
        """MISSION_START, or a ground station's arm with AUTO.MISSION selected: the held mission is started
        for the offboard controller to download and fly (it arms the vehicle), or DENIED saying why. PX4 arms
        at once; here the arm is the controller's, once it has the mission."""
        if self.clock.halted:
            return self._refuse("MISSION_START: the plant ended the flight")
        if self.sim.armed and not self.pre_start.awaits():
            return self._refuse(self._armed_start_refusal())
        missions = self.ports.missions
        why = "MISSION_START: no mission manager" if missions is None else missions.start(by, first, how)
        if why:
            return self._refuse(why)
        self.pre_start.at = None  # started: no pre-takeoff timeout while the controller downloads it
        return mavlink.MAV_RESULT_ACCEPTED

    def _armed_start_refusal(self) -> str:
        """Why MISSION_START is refused armed (but in HOLD on the ground awaiting the start): in the air,
        :func:`~bridge.nodes.vehicle.mission.in_air_refusal`."""
        flying = self.ports.missions is not None and self.ports.missions.flown() is not None
        if not self.sim.plant.on_ground:  # (its own mission in flight: said so, not told to land and start it)
            return ("MISSION_START: the mission is flying (it flies whole, once, from its start)" if flying
                    else in_air_refusal("MISSION_START", self.sim.mode))
        return "MISSION_START: only on the ground, disarmed or armed in HOLD (the controller flies it from its start)"

    def _refuse(self, why: str, result: int = mavlink.MAV_RESULT_DENIED) -> int:
        """``result`` (DENIED, or UNSUPPORTED); a STATUSTEXT saying why follows the COMMAND_ACK to the sender
        (:attr:`texts`)."""
        self.texts += self._statustext(mavlink.MAV_SEVERITY_WARNING, why)
        self.ports.refused(why)
        return result

    def _set_mode_or_refuse(self, mode: str | None, why: str, *, by: Sender,
                            takeoff_alt_m: float | None = None, hold_at: PositionHold | None = None) -> int:
        """A ground station's (or the controller's) mode change: made at the start of the next
        control period, or refused with a STATUSTEXT saying why: DENIED for a mode that is none of ours or a
        flight that is over for good (the plant ended it, or a termination), else TEMPORARILY_REJECTED, PX4's
        answer to a mode that cannot run now (Commander.cpp, DO_SET_MODE and the mode commands). No mode asked
        (``mode`` None, no ``why``: a base mode PX4 picks none for) is ACCEPTED and changes nothing, as PX4's."""
        if mode is None:
            return self._refuse(why) if why else mavlink.MAV_RESULT_ACCEPTED
        if self.clock.halted:
            return self._refuse(f"mode {mode_name(mode)}: the plant ended the flight")
        terminated = self.actions.refusal(f"mode {mode_name(mode)}")
        if terminated:
            return self._refuse(terminated)
        refused = self._mode_refusal(mode, by, hold_at)
        if refused is not None:
            return refused
        n0 = len(self.sim.events)
        was = self.sim.mode
        self.sim.set_mode(mode, takeoff_alt_m, hold_at)
        attribute(self.sim.events, n0, by)
        self.clocking.after_mode(was)
        self._ground_flight(engaged=True)
        return mavlink.MAV_RESULT_ACCEPTED

    def _ground_flight(self, engaged: bool = False) -> None:
        """After a command or a control period: a flight flown by the vehicle's own controller (a ground station's
        modes) has begun (:func:`~bridge.autopilot.flightstart.flight_begun`: a takeoff, or up; ``engaged``: a mode
        just given, sent up; not an arm that leaves it on the ground): with no target yet (real time) the mission's
        clock starts now (its timeline, gusts and disturbance: docs/weather.md), unless the flight of record is a
        controller's (one pinned, ``--controller-from``, as bsst sitl's; a mission awaited): its first target's
        state stays time 0, as the session's trace's."""
        cfg = self.cfg
        if (self.sim.mission_t0 is None and not cfg.await_mission and cfg.controller_from is None
                and flight_begun(self.sim, engaged)):
            self.sim.start_mission_clock_now()

    def _not_now(self, why: str) -> int:
        """A mode that cannot run now: TEMPORARILY_REJECTED (PX4's answer), a STATUSTEXT saying why."""
        return self._refuse(why, mavlink.MAV_RESULT_TEMPORARILY_REJECTED)

    def _mode_refusal(self, mode: str, by: Sender, hold_at: PositionHold | None) -> int | None:
        """The answer to a mode change that is not made as asked (:meth:`_set_mode_or_refuse`): taken
        otherwise (LAND without a position, the mission's start or end), or refused; None: to be made."""
        if self.sim.armed and not self.sim.position.valid:  # PX4 (UserModeIntention::change): armed, a mode must run
            return self._without_position(mode, by)
        if mode == MISSION:
            if self.pre_start.awaits():  # armed in HOLD on the ground: AUTO.MISSION starts the mission
                return self._start_mission(by, 0.0, START_ARMED)
            missions = self.ports.missions
            refused = "mode MISSION: not flown here" if missions is None else missions.select(self.sim.armed)
            if refused and not self.cfg.await_mission:  # never flown by this vehicle: as a mode none of ours
                return self._refuse(refused)
            return self._not_now(refused) if refused else mavlink.MAV_RESULT_ACCEPTED
        sim = self.sim
        if mode in NOT_ARMABLE and not sim.armed:
            return self._not_now(f"mode {mode_name(mode)}: only armed (PX4 does not arm in {NOT_ARMABLE[mode]} mode)")
        if self.ports.missions is not None and (not sim.armed or self.pre_start.starting()):
            # AUTO.MISSION no longer selected, or the mission starting
            refused = self.ports.missions.select_other(mode_name(mode))
            if refused:
                return self._not_now(refused)
        if (mode == OFFBOARD and sim.armed and sim.mode != OFFBOARD
                and time.monotonic() - self.ports.target_wall() > OFFBOARD_STREAM_S):
            # PX4 too: OFFBOARD only while a controller streams targets (its failsafe would act at once)
            return self._not_now("OFFBOARD: no controller is sending targets")
        if (mode == OFFBOARD and not sim.armed and self.cfg.controller_from is None
                and not self.ports.controller_heard()):
            # disarmed, for the next arm: refused while no controller is there to fly it (armed, its failsafe would
            # disarm it at once); a session's controller, pinned, is on its way
            return self._not_now("OFFBOARD: no controller has spoken on the controller link")
        if by.link == "controller" and mode in (LAND, HOLD) and hold_at is None and sim.armed and sim.mode == OFFBOARD:
            return self._end_mission(mode)
        return None

    def _without_position(self, mode: str, by: Sender) -> int:
        """A mode asked for armed while the horizontal position is invalid, as PX4's commander answers it
        (:func:`~bridge.autopilot.positionloss.taken_without_position`): LAND is taken (a ``mode`` event naming the
        sender; the failsafe's descent flies on, LAND once the position is valid), any other is TEMPORARILY_REJECTED
        (PX4's answer to a mode that cannot run) with a STATUSTEXT saying why."""
        sim = self.sim
        if not taken_without_position(mode, sim.position):
            return self._refuse(f"mode {mode_name(mode)}: no valid horizontal position estimate (it needs one)",
                                mavlink.MAV_RESULT_TEMPORARILY_REJECTED)
        n0 = len(sim.events)
        sim.event("mode", "LAND without a valid horizontal position estimate: descending without horizontal control "
                  "until it is valid again, then LAND from there (PX4 always takes LAND)", mode=LAND, armed=True)
        attribute(sim.events, n0, by)
        return mavlink.MAV_RESULT_ACCEPTED

    def _end_mission(self, mode: str) -> int:
        """The flight's controller hands the vehicle the mission's end action (LAND or HOLD,
        :meth:`SimVehicle.end_mission`): flown by the vehicle's own controller and no ground station's
        takeover, so the step clock stays the flight's: lockstep, the controller clocks the landing with its
        no-target acknowledgements (offline's landing to the bit) and the touchdown ends the flight
        (:meth:`flight_over`); a hold stands still, holding, until the session ends."""
        # summary.json's plant blocks are the mission's, as offline (taken before the end action flies)
        self.plant_at_end = plant_blocks(self.sim.plant)
        self.sim.end_mission("land" if mode == LAND else "hold")
        self.clocking.end_mission(mode)
        return mavlink.MAV_RESULT_ACCEPTED

    def flight_over(self) -> None:
        """After a control period: a lockstep flight whose vehicle disarmed itself on the ground (the end
        action's landing) is over; time stands still until it is armed again, as after a disarm by command. Then
        the mode a disarm in LAND, RTL or the failsafe leaves (:meth:`_after_change`)."""
        self.clocking.landed()
        self._after_change()

    def _after_change(self) -> None:
        """After a command or a control period: the mode to take after disarming noted, and, disarmed in LAND, RTL or
        the failsafe, taken (:mod:`.intention`: PX4's user mode intention, its failsafe cleared on disarm); a flight
        of the vehicle's own begun, the mission's clock started (:meth:`_ground_flight`)."""
        self._ground_flight()
        self.intention.after_period()

    # -- arming ----------------------------------------------------------------------------------------
    def _arm_copy(self, m: Any, by: Sender, ep: Endpoint, addr: tuple[str, int]) -> int:
        """An ARM (checked): acted on once per arm, however many of its copies come (:mod:`.armretry`); a resend of
        an arm acted on already is answered with its result, nothing done (PX4's commander: a duplicate)."""
        confirmation = getattr(m, "confirmation", 0)  # (COMMAND_INT has none)
        arm = self.arm_copies.copy((m.get_srcSystem(), m.get_srcComponent(), addr), confirmation, time.monotonic())
        if arm.result is not None:
            return self._resend_answered(arm.result, confirmation)
        if by.link == "gcs" and not self.sim.armed and self._mission_selected():
            if self.sim.arming_denied():  # PX4 arms at once, so checks first: the mission does not start
                result = mavlink.MAV_RESULT_TEMPORARILY_REJECTED
            else:
                result = self._start_mission(by, 0.0, START_ARM)  # AUTO.MISSION, then arm: the mission starts
        elif self._through_link(m, by):
            if confirmation > 0 and self.sim.armed and self.sim.mode == OFFBOARD:
                # the controller's ARM again, its first ACCEPTED late on a loaded machine: armed already.
                # Through the link model it would take a packet's fate offline never drew (and its
                # IN_PROGRESS overtook the ACCEPTED: "arming refused (MAV_RESULT 5)")
                return mavlink.MAV_RESULT_ACCEPTED
            # acts when the model delivers it, as offline (unless a copy of the same arm acted first); then its
            # final answer
            final = FinalAck(m, ep, addr, self.sim, arm)
            self.ports.arm_through_link(final, final.wanted)
            return mavlink.MAV_RESULT_IN_PROGRESS
        else:
            result = self.arm_disarm(m.param1, m.param2, by)
        ArmRetries.acted(arm, result)
        return result

    def _resend_answered(self, result: int, confirmation: int) -> int:
        """A resend (``confirmation``) of an arm acted on: its result again; said when the vehicle is no longer
        armed (its failsafe disarmed it since: the flight that arm began is over, a resend begins none)."""
        if not self.sim.armed:
            self.texts += self._statustext(
                mavlink.MAV_SEVERITY_WARNING, f"ARM resend (confirmation {confirmation}) of an arm acted on "
                                              "already: not armed again")
        return result

    def arm_disarm(self, p1: float, p2: float, by: Sender | None = None) -> int:
        """Arm (``p1`` 1) or disarm (0; in the air only with ``p2`` = 21196, forced), checked
        values (:func:`bridge.mavlink.receive.arm_disarm_args`). A new flight armed from a
        ground station learns its controller's address afresh (``new_flight``). An arm PX4's pre-arm check
        denies (:meth:`SimVehicle.arming_denied`) is TEMPORARILY_REJECTED, as PX4's commander answers it."""
        sim = self.sim
        now = time.monotonic()
        if p1 == 1.0:
            if self.clock.halted:
                return mavlink.MAV_RESULT_DENIED
            terminated = self.actions.refusal("arming denied")
            if terminated:
                return self._refuse(terminated)
            was_armed, was_offboard = sim.armed, sim.armed and sim.mode == OFFBOARD
            from_gcs = by is not None and by.link == "gcs"
            n0 = len(sim.events)
            if from_gcs:
                sim.arm_in_mode()  # in the mode it selected (HOLD, LAND, TAKEOFF), else offboard
            else:  # the controller's: a started mission's arm takes the vehicle armed in HOLD on the ground
                sim.arm(from_hold=self.pre_start.starting() and sim.mode == HOLD)
            if not sim.armed:  # PX4's pre-arm check denied it: its preflight event says why, on every link
                return mavlink.MAV_RESULT_TEMPORARILY_REJECTED
            self.pre_start.arm_taken(now, was_armed)  # PX4's pre-takeoff timeout runs from here (landed since)
            if from_gcs and self.pre_start.held():
                # nothing flies until the mission's start: in lockstep time stands still, as disarmed
                self.pre_start.armed(now, n0)
                return mavlink.MAV_RESULT_ACCEPTED
            if sim.mode in GROUND_MODES:  # the vehicle's own controller flies: no controller's answers
                if self.clocking.lockstep and not self.clock.free_running:
                    self.clocking.ground_takes_over(now)
                if from_gcs:
                    self.pre_start.ground_armed(now)  # in HOLD on the ground: PX4's pre-takeoff timeout
                return mavlink.MAV_RESULT_ACCEPTED
            if not was_offboard:
                self.ports.new_flight(from_gcs)  # no target of the last flight is in force
                if self.clocking.lockstep:
                    self.clocking.engage(now)  # back to lockstep
            return mavlink.MAV_RESULT_ACCEPTED
        forced = p2 == FORCE_DISARM
        if sim.armed and not sim.plant.on_ground and not forced:  # in the air: only a forced disarm, as PX4's
            return self._refuse("Disarming denied: not landed", mavlink.MAV_RESULT_TEMPORARILY_REJECTED)
        held, n0 = self.pre_start.held(), len(sim.events)
        sim.disarm("disarmed by command (forced)" if forced else "disarmed by command")
        if held:  # armed in HOLD before the mission's flight: nothing flew, nothing ends
            self.pre_start.mark(n0)
        self.clock.fire(Trigger.DISARM)  # a lockstep flight is over: time stands still until armed again
        return mavlink.MAV_RESULT_ACCEPTED



def engages_lockstep(m: Any) -> bool:
    """Whether ``m`` may engage lockstep (:meth:`~bridge.nodes.vehicle.clocking.Clocking.engage`), from either link:
    an arm (COMPONENT_ARM_DISARM param1 1), or OFFBOARD asked for (DO_SET_MODE, SET_MODE)."""
    kind = m.get_type()
    if kind == "SET_MODE":
        return requested_custom_mode(m.base_mode, m.custom_mode)[0] == OFFBOARD
    if kind not in ("COMMAND_LONG", "COMMAND_INT"):
        return False
    if m.command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
        return m.param1 == 1.0
    return m.command == mavlink.MAV_CMD_DO_SET_MODE and requested_mode(m.param1, m.param2, m.param3)[0] == OFFBOARD

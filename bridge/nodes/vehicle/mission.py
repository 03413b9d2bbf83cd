"""The vehicle's mission manager: the MAVLink mission protocol as PX4's ``MavlinkMissionManager`` runs it
(src/modules/mavlink/mavlink_mission.cpp), and the mission it holds (docs/ground-station.md, "Missions").

In:  MISSION_COUNT, MISSION_ITEM_INT / MISSION_ITEM, MISSION_REQUEST_LIST, MISSION_REQUEST_INT /
     MISSION_REQUEST, MISSION_ACK, MISSION_CLEAR_ALL, MISSION_SET_CURRENT from a sender with authority (the
     receive path checked it), with the link they came in on; wall time (s, ``time.monotonic``) at each
     :meth:`MissionManager.tick`; ``reached(seq)`` from the flight
Out: MISSION_REQUEST_INT / MISSION_REQUEST, MISSION_COUNT, MISSION_ITEM_INT / MISSION_ITEM, MISSION_ACK
     (MAV_MISSION_RESULT), MISSION_CURRENT, MISSION_ITEM_REACHED, STATUSTEXT (PX4's texts); the accepted
     mission as typed items (:class:`Mission` of :class:`~bridge.mavlink.missionitems.MissionItem`); a
     ``mission`` event naming its sender for each accepted upload, clear, set-current and start; ``refused ...``
     and ``mission ...`` status lines; at a started mission's arm (or the first flight's), a ``fence`` or ``rally``
     event when the fence or rally points held are not those the run's mission.toml holds (the controller's
     download of them, or the mission's own); such a fence the vehicle then watches for the record even with
     GF_ACTION 0 (``SimVehicle.fence_recorded``)

With ``await_mission`` (``bsst sitl --await-mission``) a ground station starts the held mission
(:meth:`MissionManager.start`: MAV_CMD_MISSION_START, or AUTO.MISSION selected and then an arm): the vehicle
shows AUTO.MISSION and MISSION_CURRENT says ACTIVE, the offboard controller (which asks for MISSION_CURRENT while
AUTO.MISSION shows) downloads the mission over its link, arms the vehicle and flies it (AUTO.MISSION selected alone
starts nothing); each control step :meth:`MissionManager.flight_step` watches the items (:mod:`.missionwatch`):
MISSION_ITEM_REACHED as each is reached, MISSION_CURRENT following.

The protocol's transfers run per link, as PX4 runs one ``MavlinkMissionManager`` per MAVLink instance
(:mod:`.missiontransfer`: a ground station's download does not hold up the controller's; one upload at a time
across the links); this manager holds what they share: the mission, the one upload's turn, the start.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from bridge.autopilot.simvehicle import LAND, OFFBOARD, TAKEOFF, SimVehicle
from bridge.autopilot.vehicleevents import ITSELF, Sender
from bridge.core.flight import Flight
from bridge.mavlink import telemetry as tm
from bridge.mavlink.endpoint import Endpoint
from bridge.mavlink.fenceitems import FENCE, RALLY
from bridge.mavlink.modes import mode_name
from bridge.nodes.vehicle.authority import Authority, attribute
from bridge.nodes.vehicle.missiontransfer import LinkTransfer, Mission, Partner, State
from bridge.nodes.vehicle.missionwatch import Goal, ItemWatch
from bridge.nodes.vehicle.startcheck import WAIT_S, Held, StartCheck
from bridge.nodes.vehicle.streams import StatusTexts
from bridge.nodes.vehicle.zones import HeldZones

REACHED_REPEATS = 10  # PX4 sends MISSION_ITEM_REACHED once more at each of its next 10 1 Hz ticks
REACHED_S = 1.0
MISSIONPLANNER = mavlink.MAV_COMP_ID_MISSIONPLANNER  # PX4 also takes mission messages addressed to it
MESSAGES = frozenset({"MISSION_COUNT", "MISSION_ITEM", "MISSION_ITEM_INT", "MISSION_REQUEST_LIST", "MISSION_REQUEST",
                      "MISSION_REQUEST_INT", "MISSION_ACK", "MISSION_CLEAR_ALL", "MISSION_SET_CURRENT"})
START_COMMAND = "MISSION_START"  # how a ground station started the mission (summary.json mission_transfer)
START_ARM = "AUTO.MISSION, then arm"
# the event kind of what a ground station uploaded or cleared, by its mission type: read by kind, never by text
EVENT_OF = {mavlink.MAV_MISSION_TYPE_MISSION: "mission", mavlink.MAV_MISSION_TYPE_FENCE: "fence",
            mavlink.MAV_MISSION_TYPE_RALLY: "rally"}
# a fence's and rally points' words when those flown are not the record's (MissionManager.flight_armed)
UNRECORDED = {FENCE: ("a fence", "the one"), RALLY: ("rally points", "the ones")}
START_ARMED = "arm, then AUTO.MISSION"  # armed in HOLD on the ground first (MAVSDK's arm(), then start_mission())
# what each start is called in its refusal: the command or mode the ground station sent
_ASKED = {START_COMMAND: "MISSION_START", START_ARM: "arm (mode MISSION)", START_ARMED: "mode MISSION (armed in HOLD)"}


def in_air_refusal(what: str, mode: str) -> str:
    """Why ``what`` (MISSION_START, AUTO.MISSION) does not start the mission armed in the air, in ``mode``. PX4 takes
    it (Commander::arm is NOT_CHANGED armed; its navigator flies the mission on from its current item, or from
    MISSION_START's param1); here the controller flies a mission whole from its takeoff on the ground, and is gone
    once that flight is over."""
    return (f"{what}: armed in the air ({mode_name(mode)}): PX4 would fly the mission on from there; here the "
            "controller flies a mission whole from its takeoff: land and disarm, then start it")


class MissionManager:
    """Answers the mission protocol for one vehicle and holds its mission (:attr:`mission`)."""

    def __init__(self, sim: SimVehicle, authority: Authority, texts: StatusTexts,
                 broadcast: Callable[[list[Any]], None], refused: Callable[[str], None], flight: Flight) -> None:
        self.sim = sim
        self.flight = flight  # the settings a ground station's mission is flown with (its start check's)
        self.authority = authority
        self.sysid = authority.cfg.sysid
        self.texts = texts
        self._broadcast = broadcast  # messages to every ground station (the GCS link)
        self.refused = refused  # a message or an upload refused, and why (its report to the session)
        self.mission = Mission()
        self.upload_link: str | None = None  # the link an upload is on: one at a time (PX4's _transfer_in_progress)
        self.transfers: dict[str, LinkTransfer] = {}  # each link's transfers (.missiontransfer), made as it speaks
        self.last_reached = -1
        self._reached_left = 0
        self._reached_at = 0.0
        self.selected = False  # AUTO.MISSION selected (or started) by a ground station, not flown yet
        self.started: dict[str, str] | None = None  # the last start: how (``command``) and by whom (``by``)
        self.started_n0 = 0  # the vehicle's events from the last start on (its ``mission`` event's index)
        self.chosen = 0  # the current item a ground station chose (MISSION_SET_CURRENT, an upload's current item)
        self.start_requested = False  # started: the controller is to download the mission and fly it
        self.watch: ItemWatch | None = None  # the mission in flight (None: none)
        self.completed = False  # the last started mission's items were all reached
        self._goals: tuple[Goal, ...] = ()  # the started mission's items, where and how each is reached
        self.home = (authority.cfg.home.lat, authority.cfg.home.lon, authority.cfg.home.alt)
        self.zones = HeldZones(sim, self.home)  # an uploaded fence and rally points, and those the record holds
        self._first_flight = True
        self._check: StartCheck | None = None  # the last check begun (.startcheck): one runs at a time

    # -- a ground station's start (await_mission) --------------------------------------------------------
    def select(self, armed: bool) -> str | None:
        """AUTO.MISSION asked for (DO_SET_MODE, SET_MODE): selected, disarmed, with a mission (None), or why
        not. Armed and flying the mission already: nothing to do; armed otherwise, why not (in the air:
        :func:`in_air_refusal`)."""
        if not self.authority.cfg.await_mission:
            return ("mode MISSION: not flown here; OFFBOARD, HOLD, LAND, TAKEOFF, RTL are flown here (and MISSION "
                    "with --await-mission)")
        if armed:
            if self.flown() is not None:
                return None  # flying the mission already: nothing to do
            if not self.sim.plant.on_ground:  # its flight over (HOLD after the end, say): not flown again
                return in_air_refusal("mode MISSION", self.sim.mode)
            return "mode MISSION: only selected on the ground, disarmed"
        why = self._startable("mode MISSION")
        if why is None:
            self.selected = True
        return why

    def select_other(self, mode: str) -> str | None:
        """Another mode (``mode``, its name) asked for while disarmed: AUTO.MISSION is no longer selected (the
        latest selection wins, as on PX4: an arm then arms in that mode), or why not: a started mission's arm is
        the controller's and is on its way."""
        if self.start_requested:
            return (f"mode {mode}: the mission is starting (the controller arms the vehicle once it has it); "
                    "switch modes once it flies")
        self.selected = False
        return None

    def start(self, by: Sender, first: float, how: str = START_COMMAND) -> str | None:
        """A ground station starts the mission (``how``: :data:`START_COMMAND`, MAV_CMD_MISSION_START with its
        first item ``first``, :data:`START_ARM`, an arm with AUTO.MISSION selected, or :data:`START_ARMED`): a
        ``mission`` event, the vehicle shows AUTO.MISSION, and the controller is to fly it from item 0 (None), or
        why not, naming what was asked (the mission is checked as the controller will fly it: :mod:`.startcheck`).
        :attr:`started` says how and by whom (summary.json)."""
        if first not in (0.0, -1.0):  # PX4's commander: DENIED unless finite, -1 or more, and an item
            return f"MISSION_START: only from item 0 (the whole mission; -1: the current one), got first item {first:g}"
        why = self._startable(_ASKED[how])
        if why is not None:
            return why
        goals = self._goals_checked()
        assert goals is not None  # (_startable said it is done)
        self.watch = None
        self._goals = goals
        self.selected = self.start_requested = True
        n0 = len(self.sim.events)
        self.sim.event("mission", f"start requested by {how}: {len(self.mission.items)} items, for the controller "
                                  "to fly")
        attribute(self.sim.events, n0, by)
        self.started, self.started_n0 = {"command": how, "by": str(by)}, n0
        return None

    def _startable(self, what: str) -> str | None:
        if not self.mission.items:
            return f"{what}: no mission uploaded"
        if self.chosen != 0:  # PX4 would start there; the controller flies the whole trajectory, from item 0
            return (f"{what}: the current item is {self.chosen} (a ground station's MISSION_SET_CURRENT): a mission "
                    "is flown here whole, from item 0; set item 0 current first")
        # an upload is about to change the mission; a download changes nothing, and the controller's own
        # download begins the moment AUTO.MISSION shows (MAVSDK's arm then comes during it, as a loaded CI showed)
        if self.upload_link is not None:
            return f"{what}: a mission upload is on"
        if not self.authority.cfg.await_mission:
            return None  # (never started here: MISSION_START is UNSUPPORTED, AUTO.MISSION refused before)
        got = self._goals_checked(WAIT_S)
        if got is None:
            assert self._check is not None
            return (f"{what}: the mission ({len(self.mission.items)} items) is still being checked as the controller "
                    f"will fly it ({time.monotonic() - self._check.began:.0f} s so far): ask again once it is done")
        if isinstance(got, str):  # PX4: mission_result.valid false, MISSION_START and Mission mode refused
            return f"{what}: the mission cannot be flown: {got}"
        return None

    def _goals_checked(self, wait_s: float = 0.0) -> tuple[Goal, ...] | str | None:
        """The held mission's check (:mod:`.startcheck`): its goals, why it cannot be flown, or None while it
        runs (waited for ``wait_s`` at most)."""
        deadline = time.monotonic() + wait_s
        held = self._held()
        if self._check is not None and not self._check.of(held):
            self._check.wait(wait_s)  # an earlier mission's check holds the thread: this one's begins after it
        self.check_held()
        check = self._check
        if check is None or not check.of(held):
            return None
        return check.result(max(0.0, deadline - time.monotonic()))

    def check_held(self) -> None:
        """Begin the held mission's check (with the fence and rally points held) unless it has begun or another
        runs (then at a later tick): the one thread it takes stays on the newest (an upload while one is checked
        waits for it)."""
        check = self._check
        if not self.authority.cfg.await_mission or not self.mission.items or self.flown() is not None:
            return  # (flying it: no start to check, and a plan's timing takes the step loop's core; a later tick)
        held = self._held()
        if check is not None and (check.of(held) or check.running()):
            return
        self._check = StartCheck(held, self.home, self.flight, self.authority.cfg.trace_cap)

    def _held(self) -> Held:
        """The items the controller downloads at a start: the mission's, the fence's, the rally points'."""
        zones = self.zones.items
        return self.mission.items, zones[FENCE].items, zones[RALLY].items

    def shows_mission(self, armed: bool, offboard: bool) -> bool:
        """Whether the vehicle shows AUTO.MISSION: selected or started and disarmed, started armed in HOLD on the
        ground (the controller's arm to come), or flying the mission."""
        return (self.selected and (not armed or self.start_requested)) or (self.watch is not None and armed
                                                                          and offboard)

    def flight_armed(self) -> None:
        """The controller armed a new flight: the started mission is flown from now (item 0 current). A started
        mission's arm (or the first flight's, without --await-mission) with a fence or rally points the run's record
        does not hold (uploaded after the controller's download, or before that first arm) says so: a ``fence`` or
        ``rally`` event, after the arm, so that the run judges that fence by the vehicle's watch, as one uploaded in
        flight (bridge.record.policies), and a Return's rally point is not read as mission.toml's."""
        if self._first_flight or self.start_requested:  # (a record begins: the controller's mission.toml)
            self._first_flight = False
            when = "after the controller's download" if self.authority.cfg.await_mission else "before the arm"
            for mtype, (noun, which) in UNRECORDED.items():
                held = self.zones.items[mtype]
                if held is not self.zones.recorded[mtype]:
                    said = self.sim.event(EVENT_OF[mtype], f"flown with {noun} of {len(held.items)} items uploaded "
                                                           f"or cleared {when}, not {which} mission.toml holds")
                    said.by = ITSELF  # (the vehicle's word, not the arm's sender's)
        if not self.start_requested:
            return
        self.start_requested = self.selected = self.completed = False
        self.watch = ItemWatch(self._goals)
        self.set_current(self.watch.current)

    def flight_step(self, t: float, X: tuple[float, ...], armed: bool) -> None:
        """After a control step of the mission's flight (``t`` s, the plant's state ``X``): each item reached
        is said (MISSION_ITEM_REACHED) and the next made current; disarmed, the mission's flight is over (and once a
        ground station changed the mission of a flight that is over: :meth:`_flight_over`)."""
        watch = self.watch
        if watch is None:
            return
        for seq in watch.step(t, X):
            self.reached(seq)
            self.set_current(watch.current)
            self.completed = watch.done
            self._broadcast(self.current_message())  # the change at once, as PX4 does, not at the next 1 Hz tick
        if not armed:
            self.watch = None

    def flown(self) -> str | None:
        """Why the mission and its current item cannot be changed now (None: they can): started, or armed in
        OFFBOARD flying it, the controller flies its whole trajectory, planned from item 0, which neither a new
        mission, a clear nor a new current item can change (PX4's navigator takes each at once). Once the flight
        left OFFBOARD (the mission's end action HOLD or LAND, a ground station's mode, a failsafe) the controller
        flies it no more: they can, as on PX4, armed or not."""
        if self.start_requested or (self.watch is not None and self.sim.armed and self.sim.mode == OFFBOARD):
            return "flying the mission (planned whole, from item 0): change it once it has ended"
        return None

    # -- the flight's side ----------------------------------------------------------------------------
    def reached(self, seq: int) -> None:
        """Item ``seq`` reached (its acceptance radius): MISSION_ITEM_REACHED to the ground stations now
        and at the next :data:`REACHED_REPEATS` 1 Hz ticks, as PX4 repeats it."""
        if not 0 <= seq < len(self.mission.items):
            raise ValueError(f"mission item {seq} reached: the mission has {len(self.mission.items)} items")
        self.last_reached = seq
        self._reached_left = REACHED_REPEATS
        self._reached_at = time.monotonic() + REACHED_S
        self._broadcast([mavlink.MAVLink_mission_item_reached_message(seq)])

    def set_current(self, seq: int) -> None:
        """The flight goes on to item ``seq`` (MISSION_CURRENT says so at its next send)."""
        if not 0 <= seq < len(self.mission.items):
            raise ValueError(f"mission item {seq}: the mission has {len(self.mission.items)} items")
        self.mission = Mission(self.mission.items, seq)

    def current_message(self) -> list[Any]:
        """MISSION_CURRENT (:meth:`current_fields`)."""
        return tm.mission_current(*self.current_fields())

    def current_fields(self) -> tuple[int, int, int, int]:
        """MISSION_CURRENT's seq, total (0: no mission), mission_state and mission_mode."""
        return self.mission.current, len(self.mission.items), self.mission_state, self.mission_mode

    @property
    def mission_state(self) -> int:
        """MISSION_STATE: NO_MISSION without one; ACTIVE once a ground station started the mission (the controller's
        cue to fly it: AUTO.MISSION selected alone is NOT_STARTED, and the vehicle stays on the ground) and while it
        flies; PAUSED once its flight left the modes that fly items (:attr:`mission_mode`) after reaching one, as
        PX4's (a ground station's HOLD; a failsafe's or a ground station's LAND stays ACTIVE); COMPLETE once its
        last item was reached. PX4 main says ACTIVE from the mode alone, even disarmed on the ground:
        docs/ground-station.md."""
        if not self.mission.items:
            return mavlink.MISSION_STATE_NO_MISSION
        watch = self.watch
        if self.start_requested or (watch is not None and not watch.done):
            if watch is not None and watch.i > 0 and self.mission_mode == tm.MISSION_MODE_SUSPENDED:
                return mavlink.MISSION_STATE_PAUSED
            return mavlink.MISSION_STATE_ACTIVE
        return mavlink.MISSION_STATE_COMPLETE if self.completed else mavlink.MISSION_STATE_NOT_STARTED

    @property
    def mission_mode(self) -> int:
        """MISSION_CURRENT's mission_mode as PX4 sets it: in mission (AUTO.MISSION shown, or TAKEOFF or LAND:
        PX4's AUTO_TAKEOFF and AUTO_LAND also fly mission items), else suspended."""
        sim = self.sim
        if self.shows_mission(sim.armed, sim.mode == OFFBOARD) or sim.mode in (TAKEOFF, LAND):
            return tm.MISSION_MODE_IN_MISSION
        return tm.MISSION_MODE_SUSPENDED

    # -- the wall clock ---------------------------------------------------------------------------------
    def tick(self, now: float) -> None:
        """Each link's transfers (items requested again, silent ones ended); MISSION_ITEM_REACHED repeated."""
        for transfer in self.transfers.values():
            transfer.tick(now)
        self.check_held()
        if self._reached_left > 0 and now >= self._reached_at:
            self._reached_left -= 1
            self._reached_at = now + REACHED_S
            self._broadcast([mavlink.MAVLink_mission_item_reached_message(self.last_reached)])

    # -- the messages -----------------------------------------------------------------------------------
    def handle(self, ep: Endpoint, m: Any, addr: tuple[str, int], link: str, reject: Callable[[str], None]) -> bool:
        """A mission message from a sender with authority on ``ep`` (``link``: ``controller`` or ``gcs``),
        answered within its reply budget; True when it changed the mission (its event is to be announced)."""
        if m.target_system != self.sysid or m.target_component != MISSIONPLANNER:  # PX4 also takes 190
            if self.authority.for_others(m):
                reject("target")
                return False
        if not ep.reply_allowed(addr):
            reject("reply_limited")  # not acted on: its answer could not go
            return False
        transfer = self.transfers.get(link)
        if transfer is None:
            transfer = self.transfers[link] = LinkTransfer(link, self)
        changed = transfer.handle(Partner(self.authority.sender(m, addr, link), ep), m, time.monotonic())
        # the controller asked for the fence or the rally points: what its download sends (begun, or begun again) is
        # what its mission.toml holds, the record's
        if (link == "controller" and m._type == "MISSION_REQUEST_LIST" and m.mission_type in self.zones.recorded
                and transfer.state is State.SENDLIST and transfer.mtype in self.zones.recorded):
            self.zones.downloaded(transfer.mtype, transfer.sending)
        return changed

    # -- what the links' transfers share (.missiontransfer.TransferHost) ------------------------------------
    def held(self, mission_type: int) -> Mission:
        """The items held of ``mission_type``: the mission, the fence or the rally points (:mod:`.zones`)."""
        return self.mission if mission_type == mavlink.MAV_MISSION_TYPE_MISSION else self.zones.items[mission_type]

    def accept(self, who: Partner, mission: Mission, what: str,
               mission_type: int = mavlink.MAV_MISSION_TYPE_MISSION) -> str | None:
        """What the ground station made of ``mission_type``: held, and an event of its kind (:data:`EVENT_OF`:
        ``mission``, ``fence``, ``rally``) saying it; or why a fence
        or rally points cannot be read (nothing held, nothing said here: the transfer refuses the upload)."""
        if mission_type == mavlink.MAV_MISSION_TYPE_MISSION:
            self._flight_over(new_items=mission.items is not self.mission.items)
            self.mission = mission
            self.chosen = mission.current
        else:
            why = self.zones.accept(mission, mission_type)
            if why is not None:
                return why
        self.check_held()  # as PX4's navigator checks a mission once it is stored (here its fence and rally points too)
        n0 = len(self.sim.events)
        self.sim.event(EVENT_OF[mission_type], what)
        attribute(self.sim.events, n0, who.who)
        return None

    def choose(self, by: Sender, seq: int, reset: bool, what: str) -> None:
        """A ground station's DO_SET_MISSION_CURRENT (:mod:`.setcurrent`): item ``seq`` current, as a chosen one
        (MISSION_START then starts only from item 0); ``reset``: a COMPLETE mission is NOT_STARTED again."""
        self._flight_over(new_items=reset)
        self.mission = Mission(self.mission.items, seq)
        self.chosen = seq
        n0 = len(self.sim.events)
        self.sim.event("mission", f"current item {seq} ({what}{', mission reset' if reset else ''})")
        attribute(self.sim.events, n0, by)

    def _flight_over(self, new_items: bool) -> None:
        """A ground station changes the mission of a flight that is over (:meth:`flown` is None; it may still be
        armed: HOLD after the end): its watch is let go (nothing of the new mission is reached by it); a new
        mission (or a reset) is NOT_STARTED, no more COMPLETE (PX4: a new mission is not finished)."""
        self.watch = None
        if new_items:
            self.completed = False

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
     and ``mission ...`` status lines

With ``await_mission`` (``bsst sitl --await-mission``) a ground station starts the held mission
(:meth:`MissionManager.start`: MAV_CMD_MISSION_START, or AUTO.MISSION selected and then an arm): the vehicle
shows AUTO.MISSION and MISSION_CURRENT says ACTIVE, the offboard controller (which asks for MISSION_CURRENT while
AUTO.MISSION shows) downloads the mission over its link, arms the vehicle and flies it (AUTO.MISSION selected alone
starts nothing); each control step :meth:`MissionManager.flight_step` watches the items (:mod:`.missionwatch`):
MISSION_ITEM_REACHED as each is reached, MISSION_CURRENT following.

PX4's state machine: IDLE, GETLIST (an upload: the vehicle requests item after item), SENDLIST (a
download: the ground station requests them). One transfer at a time, with one partner (sysid, compid,
address and link): anyone else who starts or joins one is answered ``MAV_MISSION_ERROR`` with PX4's
"Busy" STATUSTEXT (PX4 sends that ACK to its partner, which then abandons its own transfer; here it goes
to the one who asked). An upload is staged and swapped in at its last item, so a failed, refused or
abandoned upload leaves the mission as it was, and the vehicle never holds a mission shorter than the one
it acknowledged. While it waits for an item the vehicle requests it again every :data:`RETRY_S`; a transfer
nobody spoke in for :data:`PROTOCOL_TIMEOUT_S` ends ("Operation timeout"). Only ``MAV_MISSION_TYPE_MISSION``:
fence and rally are answered ``MAV_MISSION_UNSUPPORTED``. The items' checks: :mod:`bridge.mavlink.missionitems`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from bridge.autopilot.simvehicle import Sender, SimVehicle
from bridge.mavlink import telemetry as tm
from bridge.mavlink.endpoint import Endpoint
from bridge.mavlink.missionitems import ItemRefused, MissionItem, TransferStats, item_message, parse_item
from bridge.nodes.vehicle.authority import Authority, attribute
from bridge.nodes.vehicle.missionwatch import Goal, ItemWatch, goals_of
from bridge.nodes.vehicle.streams import StatusTexts
from params import ConfigError

RETRY_S = 0.25  # PX4's MAVLINK_MISSION_RETRY_TIMEOUT_DEFAULT: an item not here this long is requested again
PROTOCOL_TIMEOUT_S = 5.0  # PX4's MAVLINK_MISSION_PROTOCOL_TIMEOUT_DEFAULT: a silent transfer ends
MAX_ITEMS = 65534  # PX4 SITL's NUM_MISSIONS_SUPPORTED (UINT16_MAX - 1): a larger count is MAV_MISSION_NO_SPACE
REACHED_REPEATS = 10  # PX4 sends MISSION_ITEM_REACHED once more at each of its next 10 1 Hz ticks
REACHED_S = 1.0
MISSIONPLANNER = mavlink.MAV_COMP_ID_MISSIONPLANNER  # PX4 also takes mission messages addressed to it
MISSION = mavlink.MAV_MISSION_TYPE_MISSION
MESSAGES = frozenset({"MISSION_COUNT", "MISSION_ITEM", "MISSION_ITEM_INT", "MISSION_REQUEST_LIST", "MISSION_REQUEST",
                      "MISSION_REQUEST_INT", "MISSION_ACK", "MISSION_CLEAR_ALL", "MISSION_SET_CURRENT"})
BUSY = "WPM: REJ. CMD: Busy"
START_COMMAND = "MISSION_START"  # how a ground station started the mission (summary.json mission_transfer)
START_ARM = "AUTO.MISSION, then arm"


class State(Enum):
    """PX4's MAVLINK_WPM_STATES."""

    IDLE = "idle"
    SENDLIST = "sendlist"  # a download: items go out on request
    GETLIST = "getlist"  # an upload: items come in on request


@dataclass(frozen=True)
class Mission:
    """The mission the vehicle holds: its items (seq 0..n-1) and the current one."""

    items: tuple[MissionItem, ...] = ()
    current: int = 0


@dataclass(frozen=True)
class Partner:
    """The other end of a transfer: who (:class:`Sender`) and the endpoint its answers go out on."""

    who: Sender
    ep: Endpoint


class MissionManager:
    """Answers the mission protocol for one vehicle and holds its mission (:attr:`mission`)."""

    def __init__(self, sim: SimVehicle, authority: Authority, texts: StatusTexts,
                 broadcast: Callable[[list[Any]], None], refused: Callable[[str], None]) -> None:
        self.sim = sim
        self.authority = authority
        self.sysid = authority.cfg.sysid
        self._texts = texts
        self._broadcast = broadcast  # messages to every ground station (the GCS link)
        self._refused = refused  # a message or an upload refused, and why (its report to the session)
        self.mission = Mission()
        self.state = State.IDLE
        self.partner: Partner | None = None
        self.int_mode = True  # MISSION_REQUEST_INT / ITEM_INT (else the legacy float ones), as the partner speaks
        self.seq = 0  # the transfer's next item (PX4's _transfer_seq); kept when idle, to spot a repeated last item
        self.count = 0  # the transfer's items
        self.staged: list[MissionItem] = []  # an upload's items so far
        self.sent: set[int] = set()  # a download's items sent so far
        self.staged_current = 0
        self.sending: Mission = self.mission  # a download's mission, as it was when it began
        self.last_recv = self.last_sent = self.started = 0.0
        self.upload = TransferStats()
        self.last_reached = -1
        self._reached_left = 0
        self._reached_at = 0.0
        self.selected = False  # AUTO.MISSION selected (or started) by a ground station, not flown yet
        self.started: dict[str, str] | None = None  # the last start: how (``command``) and by whom (``by``)
        self.start_requested = False  # started: the controller is to download the mission and fly it
        self.watch: ItemWatch | None = None  # the mission in flight (None: none)
        self.completed = False  # the last started mission's items were all reached
        self._goals: tuple[Goal, ...] = ()  # the started mission's items, where and how each is reached
        self._flying: tuple[MissionItem, ...] = ()  # the items of the mission in flight
        self.home = (authority.cfg.home.lat, authority.cfg.home.lon, authority.cfg.home.alt)

    # -- a ground station's start (await_mission) --------------------------------------------------------
    def select(self, armed: bool) -> str | None:
        """AUTO.MISSION asked for (DO_SET_MODE, SET_MODE): selected, disarmed, with a mission (None), or why
        not. Armed and flying the mission already: nothing to do."""
        if not self.authority.cfg.await_mission:
            return ("mode MISSION: not flown here; OFFBOARD, HOLD, LAND, TAKEOFF, RTL are (and MISSION with "
                    "--await-mission)")
        if armed:
            return None if self.watch is not None else "mode MISSION: only selected on the ground, disarmed"
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
        first item ``first``, or :data:`START_ARM`, an arm with AUTO.MISSION selected): a ``mission`` event, the
        vehicle shows AUTO.MISSION, and the controller is to fly it from item 0 (None), or why not (the mission
        is checked as the controller will fly it). :attr:`started` says how and by whom (summary.json)."""
        if not (math.isnan(first) or first in (0.0, -1.0)):
            return f"MISSION_START: only from item 0 (the whole mission), got first item {first:g}"
        why = self._startable("MISSION_START")
        if why is not None:
            return why
        try:
            goals = goals_of(self.mission.items, self.home)
        except ConfigError as exc:
            return f"MISSION_START: the mission cannot be flown: {exc}"[:200]
        self.watch = None
        self._goals = goals
        self.selected = self.start_requested = True
        n0 = len(self.sim.events)
        self.sim.event("mission", f"start requested by {how}: {len(self.mission.items)} items, for the controller "
                                  "to fly")
        attribute(self.sim.events, n0, by)
        self.started = {"command": how, "by": str(by)}
        return None

    def _startable(self, what: str) -> str | None:
        if not self.mission.items:
            return f"{what}: no mission uploaded"
        # an upload is about to change the mission; a download changes nothing, and the controller's own
        # download begins the moment AUTO.MISSION shows (MAVSDK's arm then comes during it, as a loaded CI showed)
        if self.state is State.GETLIST:
            return f"{what}: a mission upload is on"
        return None

    def shows_mission(self, armed: bool, offboard: bool) -> bool:
        """Whether the vehicle shows AUTO.MISSION: selected or started and disarmed, or flying the mission."""
        return (self.selected and not armed) or (self.watch is not None and armed and offboard)

    def flight_armed(self) -> None:
        """The controller armed a new flight: the started mission is flown from now (item 0 current)."""
        if not self.start_requested:
            return
        self.start_requested = self.selected = self.completed = False
        self.watch = ItemWatch(self._goals)
        self._flying = self.mission.items
        self.set_current(self.watch.current)

    def flight_step(self, t: float, X: tuple[float, ...], armed: bool) -> None:
        """After a control step of the mission's flight (``t`` s, the plant's state ``X``): each item reached
        is said (MISSION_ITEM_REACHED) and the next made current; disarmed, the mission's flight is over."""
        watch = self.watch
        if watch is None:
            return
        if self.mission.items is not self._flying:  # a ground station replaced or cleared it meanwhile
            self.watch = None
            self.sim.event("mission", "the mission flown was replaced by an upload: its items are no more watched "
                                      "(the controller flies the one it downloaded)")
            return
        for seq in watch.step(t, X):
            self.reached(seq)
            self.set_current(watch.current)
            self.completed = watch.done
            self._broadcast(self.current_message())  # the change at once, as PX4 does, not at the next 1 Hz tick
        if not armed:
            self.watch = None

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
        """MISSION_CURRENT ([] without a mission: PX4 does not broadcast one then)."""
        return tm.mission_current(self.mission.current, len(self.mission.items), self.mission_state)

    @property
    def mission_state(self) -> int:
        """MISSION_STATE: ACTIVE once a ground station started the mission (the controller's cue to fly it: AUTO.MISSION
        selected alone is NOT_STARTED, and the vehicle stays on the ground, as PX4's does) and while it flies,
        COMPLETE once its last item was reached."""
        if self.start_requested or (self.watch is not None and not self.watch.done):
            return mavlink.MISSION_STATE_ACTIVE
        return mavlink.MISSION_STATE_COMPLETE if self.completed else mavlink.MISSION_STATE_NOT_STARTED

    # -- the wall clock ---------------------------------------------------------------------------------
    def tick(self, now: float) -> None:
        """Request the awaited item again after :data:`RETRY_S`; end a transfer silent for
        :data:`PROTOCOL_TIMEOUT_S`; repeat MISSION_ITEM_REACHED."""
        p = self.partner
        if self.state is State.GETLIST and p is not None and now - self.last_sent > RETRY_S:
            self.upload.re_requests += 1
            self._send_request(p, now)
        elif self.state is not State.IDLE and p is not None and now - self.last_recv > PROTOCOL_TIMEOUT_S:
            if self.state is State.GETLIST:
                self._end_upload(now, "timeout")
            self._idle()
            p.ep.send_many(self._texts(mavlink.MAV_SEVERITY_CRITICAL, "Operation timeout"), p.who.addr)
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
        now = time.monotonic()
        who = Partner(self.authority.sender(m, addr, link), ep)
        kind = m._type
        if kind in ("MISSION_ITEM_INT", "MISSION_ITEM", "MISSION_REQUEST_INT", "MISSION_REQUEST") and (
                self.state is State.IDLE or self._is_partner(who)):  # the form the partner speaks (not another's)
            self.int_mode = kind.endswith("_INT")
        if kind in ("MISSION_ITEM_INT", "MISSION_ITEM"):
            return self._item(who, m, now)
        if kind in ("MISSION_REQUEST_INT", "MISSION_REQUEST"):
            self._request(who, m, now)
            return False
        if kind == "MISSION_ACK":
            self._ack(who, m, now)
            return False
        if kind != "MISSION_SET_CURRENT" and m.mission_type != MISSION and not (
                kind == "MISSION_CLEAR_ALL" and m.mission_type == mavlink.MAV_MISSION_TYPE_ALL):
            self._answer(who, mavlink.MAV_MISSION_UNSUPPORTED, m.mission_type)  # no fence, no rally points
            return False
        self._idle_if_sent()
        if kind == "MISSION_COUNT":
            return self._count(who, m, now)
        if kind == "MISSION_REQUEST_LIST":
            self._request_list(who, m, now)
            return False
        if self.state is not State.IDLE:
            self._busy(who, m.mission_type if kind == "MISSION_CLEAR_ALL" else MISSION)
            return False
        if kind == "MISSION_CLEAR_ALL":
            if self.mission.items:  # clearing no mission changes nothing: answered, not said as a change
                self._accept(who, Mission(), "cleared")
            self._answer(who, mavlink.MAV_MISSION_ACCEPTED, m.mission_type)
            return True
        return self._set_current(who, m)

    # -- upload -----------------------------------------------------------------------------------------
    def _count(self, who: Partner, m: Any, now: float) -> bool:
        """MISSION_COUNT: an upload begins (0 items: the mission is cleared at once)."""
        if self.state is State.GETLIST and self._is_partner(who) and self.seq == 0:
            self.last_recv = now  # our first request was lost: ask again
            self._send_request(who, now)
            return False
        if self.state is not State.IDLE:
            self._busy(who, MISSION)
            return False
        if m.count > MAX_ITEMS:
            self._answer(who, mavlink.MAV_MISSION_NO_SPACE)
            return False
        if m.count == 0:
            self._accept(who, Mission(), "cleared (an upload of 0 items)")
            self._answer(who, mavlink.MAV_MISSION_ACCEPTED)
            return True
        self.state, self.partner = State.GETLIST, who
        self.seq, self.count, self.staged, self.staged_current = 0, m.count, [], 0
        self.last_recv = self.started = now
        self.upload = TransferStats(items=m.count)
        self._send_request(who, now)
        return False

    def _item(self, who: Partner, m: Any, now: float) -> bool:
        """MISSION_ITEM(_INT): the awaited item staged and the next requested, or the upload done; a bad
        item ends the upload with PX4's result; one out of sequence is ignored (it is requested again)."""
        if self.state is State.IDLE:
            if self._is_partner(who) and self.count > 0 and self.seq == m.seq + 1 == self.count:
                self._answer(who, mavlink.MAV_MISSION_ACCEPTED)  # the last item again: our ACK was lost
            else:
                self._answer(who, mavlink.MAV_MISSION_ERROR, text="IGN MISSION_ITEM: No transfer")
            return False
        if self.state is State.SENDLIST or not self._is_partner(who):
            self._busy(who, MISSION)
            return False
        if m.mission_type != MISSION:
            self._answer(who, mavlink.MAV_MISSION_ERROR)  # PX4: answered, the upload goes on
            return False
        self.last_recv = now
        if m.seq != self.seq:
            return False
        try:
            item = parse_item(m, self.int_mode)
        except ItemRefused as exc:
            self._refused(f"mission item {m.seq} (command {m.command}, frame {m.frame}): {exc}")
            self._end_upload(now, f"refused item {m.seq}")
            self._idle()
            self._answer(who, exc.result, text=f"IGN MISSION_ITEM: Invalid item {m.seq}: {exc}")
            return False
        self.staged.append(item)
        if m.current:
            self.staged_current = m.seq
        self.seq += 1
        if self.seq < self.count:
            self._send_request(who, now)
            return False
        self._end_upload(now, "accepted")
        self._idle()
        up = self.upload
        self._accept(who, Mission(tuple(self.staged), self.staged_current),
                     f"uploaded {up.items} items in {up.duration_s:.2f} s, {up.re_requests} requested again")
        self._answer(who, mavlink.MAV_MISSION_ACCEPTED)
        return True

    def _send_request(self, p: Partner, now: float) -> None:
        """MISSION_REQUEST_INT (or MISSION_REQUEST, as the partner speaks) for the awaited item."""
        self.last_sent = now
        self.upload.requests += 1
        target = (p.who.sysid, p.who.compid)
        msg = (mavlink.MAVLink_mission_request_int_message(*target, self.seq, MISSION) if self.int_mode
               else mavlink.MAVLink_mission_request_message(*target, self.seq, MISSION))
        p.ep.send(msg, p.who.addr)

    def _end_upload(self, now: float, result: str) -> None:
        self.upload.duration_s = now - self.started
        self.upload.result = result
        if result != "accepted":  # an accepted one is its mission event
            self._refused(f"mission upload {result}: {self.upload}")

    # -- download ---------------------------------------------------------------------------------------
    def _request_list(self, who: Partner, m: Any, now: float) -> None:
        """MISSION_REQUEST_LIST: a download begins (again, for its partner)."""
        if not (self.state is State.IDLE or (self.state is State.SENDLIST and self._is_partner(who))):
            self._busy(who, MISSION, "Mission download request ignored, already active")
            return
        self.state, self.partner, self.sending = State.SENDLIST, who, self.mission
        self.seq, self.count, self.sent = 0, len(self.mission.items), set()
        self.last_recv = self.last_sent = now
        who.ep.reply((mavlink.MAVLink_mission_count_message(who.who.sysid, who.who.compid, self.count, MISSION),),
                     who.who.addr)

    def _request(self, who: Partner, m: Any, now: float) -> None:
        """MISSION_REQUEST(_INT): the item asked for, to the download's partner, in whatever order it asks;
        one past the mission ends the download (``MAV_MISSION_ERROR``). PX4 also ends it on a request other
        than the next item or the last again; ArduPilot answers any, as here: MAVProxy asks for five items
        at once and each lost one again 2 s later, so over a lossy link PX4's rule ends every download
        whose requests were not all delivered in order (docs/ground-station.md, "Missions")."""
        if not self._is_partner(who):
            if self.state is not State.IDLE:
                self._busy(who, MISSION)
            return  # no transfer: ignored, as PX4 does (some on-screen displays ask anyway)
        if self.state is State.GETLIST:
            who.ep.reply(tuple(self._texts(mavlink.MAV_SEVERITY_CRITICAL, BUSY)), who.who.addr)
            return
        if self.state is not State.SENDLIST or m.mission_type != MISSION:
            return
        self.last_recv = now
        if not 0 <= m.seq < self.count:
            self._idle()
            self._answer(who, mavlink.MAV_MISSION_ERROR, text="WPM: REJ. CMD: Req. WP was unexpected")
            return
        self.seq = max(self.seq, m.seq + 1)
        self.sent.add(m.seq)
        sending = self.sending
        item = sending.items[m.seq]
        self.last_sent = now
        who.ep.reply((item_message(item, (who.who.sysid, who.who.compid), m.seq == sending.current, self.int_mode),),
                     who.who.addr)

    def _ack(self, who: Partner, m: Any, now: float) -> None:
        """MISSION_ACK from the partner: a download ends; an upload is cancelled
        (MAV_MISSION_OPERATION_CANCELLED) or its requests switch between _INT and float (UNSUPPORTED)."""
        if not self._is_partner(who) or m.mission_type != MISSION:
            return
        if self.state is State.SENDLIST:
            self.last_recv = now
            self._idle()
        elif self.state is State.GETLIST:
            if m.type == mavlink.MAV_MISSION_OPERATION_CANCELLED:
                self._end_upload(now, "cancelled")
                self._idle()
            elif m.type == mavlink.MAV_MISSION_UNSUPPORTED:
                self.int_mode = not self.int_mode
                self._send_request(who, now)

    # -- set current ------------------------------------------------------------------------------------
    def _set_current(self, who: Partner, m: Any) -> bool:
        """MISSION_SET_CURRENT: the current item, answered with MISSION_CURRENT (PX4 publishes it at once)."""
        if not 0 <= m.seq < len(self.mission.items):
            who.ep.reply(tuple(self._texts(mavlink.MAV_SEVERITY_CRITICAL, "WPM: WP CURR CMD: Not in list")),
                         who.who.addr)
            return False
        self._accept(who, Mission(self.mission.items, m.seq), f"current item {m.seq}")
        who.ep.reply(tuple(self.current_message()), who.who.addr)
        return True

    # -- helpers ----------------------------------------------------------------------------------------
    def _is_partner(self, who: Partner) -> bool:
        p = self.partner
        return p is not None and p.who == who.who

    def _idle_if_sent(self) -> None:
        """A download whose every item went out ends here (its final ACK lost, or never sent), as PX4 ends it
        on a new MISSION_REQUEST_LIST, so that it holds up no new transfer (no download holds up a start)."""
        if self.state is State.SENDLIST and len(self.sent) == self.count:
            self._idle()

    def _idle(self) -> None:
        """Back to IDLE: a staged upload is dropped (the mission stays as it was)."""
        if self.state is State.GETLIST and self.seq < self.count:
            self.staged = []
        self.state = State.IDLE

    def _accept(self, who: Partner, mission: Mission, what: str) -> None:
        """The mission the ground station made: held, and a ``mission`` event naming it."""
        self.mission = mission
        n0 = len(self.sim.events)
        self.sim.event("mission", what)
        attribute(self.sim.events, n0, who.who)

    def _answer(self, who: Partner, result: int, mission_type: int = MISSION, text: str | None = None) -> None:
        """MISSION_ACK with ``result`` to ``who`` (and a STATUSTEXT saying why, in the same datagram)."""
        ack = mavlink.MAVLink_mission_ack_message(who.who.sysid, who.who.compid, result, mission_type)
        texts = self._texts(mavlink.MAV_SEVERITY_CRITICAL, text) if text is not None else []
        who.ep.reply((ack, *texts), who.who.addr)

    def _busy(self, who: Partner, mission_type: int, text: str = BUSY) -> None:
        """Another transfer is on: ``MAV_MISSION_ERROR`` and PX4's STATUSTEXT, to the one who asked."""
        self._refused(f"mission message from {who.who}: busy ({self.state.value})")
        self._answer(who, mavlink.MAV_MISSION_ERROR, mission_type, text)

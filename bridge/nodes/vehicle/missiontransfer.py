"""One link's mission transfers: PX4's ``MavlinkMissionManager`` state machine, of which PX4 runs one per MAVLink
instance (src/modules/mavlink/mavlink_mission.cpp).

In:  a mission message already checked for authority and target, its sender and the endpoint its answers go out
     on (:class:`Partner`), wall time (s, ``time.monotonic``); the vehicle's mission from its host
     (:class:`TransferHost`: :class:`bridge.nodes.vehicle.mission.MissionManager`)
Out: MISSION_REQUEST_INT / MISSION_REQUEST, MISSION_COUNT, MISSION_ITEM_INT / MISSION_ITEM, MISSION_ACK
     (MAV_MISSION_RESULT), STATUSTEXT (PX4's texts) to the partner; to the host, an accepted upload, a clear or
     a new current item (``accept``) and what was refused and why (``refused``)

PX4's states: IDLE, GETLIST (an upload: the vehicle requests item after item), SENDLIST (a download: the ground
station requests them). One transfer at a time on a link, with one partner (sysid, compid, address): anyone else
who starts or joins one there is answered as PX4 main answers (:meth:`LinkTransfer._busy`: an upload
``MAV_MISSION_ERROR`` and "Busy", the rest PX4's text alone). Each link has its
own (the offboard controller's and the ground stations'), as each PX4 MAVLink instance has its own: a ground
station's download does not hold up the controller's. Uploads are one at a time across the links (PX4's static
``_transfer_in_progress``): the host's ``upload_link``. An upload is staged and swapped in at its last item, so a
failed, refused or abandoned upload leaves the mission as it was, and the vehicle never holds a mission shorter
than the one it acknowledged; a download sends the mission as it was when it began. While it waits for an item
the vehicle requests it again every :data:`RETRY_S`; a transfer nobody spoke in for :data:`PROTOCOL_TIMEOUT_S`
ends ("Operation timeout"). Three mission types, each held apart, as PX4 holds them: the mission, the fence and
the rally points (a transfer is of one type; MISSION_CLEAR_ALL of MAV_MISSION_TYPE_ALL clears the three). A type
PX4 does not know (any other) is answered as PX4 answers it, its MAX_COUNT and _count read as 0 for it: MISSION_COUNT
of one item or more MAV_MISSION_NO_SPACE, of none ACCEPTED; MISSION_REQUEST_LIST a MISSION_COUNT of 0;
MISSION_CLEAR_ALL ACCEPTED; nothing held changes (it was MAV_MISSION_UNSUPPORTED until 2026-12-06). The
items' checks: :mod:`bridge.mavlink.missionitems` (a mission's), :mod:`bridge.mavlink.fenceitems` (a fence's and
rally points').
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum
from typing import Any, Protocol

from pymavlink.dialects.v20 import common as mavlink

from bridge.autopilot.vehicleevents import Sender
from bridge.mavlink.endpoint import Endpoint
from bridge.mavlink.fenceitems import parse_zone_item
from bridge.mavlink.missionitems import ItemRefused, MissionItem, TransferStats, item_message, parse_item

RETRY_S = 0.25  # PX4's MAVLINK_MISSION_RETRY_TIMEOUT_DEFAULT: an item not here this long is requested again
PROTOCOL_TIMEOUT_S = 5.0  # PX4's MAVLINK_MISSION_PROTOCOL_TIMEOUT_DEFAULT: a silent transfer ends
MAX_ITEMS = 65534  # PX4 SITL's NUM_MISSIONS_SUPPORTED (UINT16_MAX - 1): a larger count is MAV_MISSION_NO_SPACE
MISSION = mavlink.MAV_MISSION_TYPE_MISSION
TYPES = (MISSION, mavlink.MAV_MISSION_TYPE_FENCE, mavlink.MAV_MISSION_TYPE_RALLY)
# the most items of an upload of each type, PX4's MavlinkMissionManager::MAX_COUNT (mavlink_mission.h): its SITL's
# missions, DM_KEY_FENCE_POINTS_MAX and DM_KEY_SAFE_POINTS_MAX (src/lib/dataman/dataman.h); more is NO_SPACE
MAX_FENCE_ITEMS, MAX_RALLY_POINTS = 64, 32
MAX_COUNT = {MISSION: MAX_ITEMS, mavlink.MAV_MISSION_TYPE_FENCE: MAX_FENCE_ITEMS,
             mavlink.MAV_MISSION_TYPE_RALLY: MAX_RALLY_POINTS}
BUSY = "WPM: REJ. CMD: Busy"
_NOUN = {MISSION: "mission", mavlink.MAV_MISSION_TYPE_FENCE: "fence", mavlink.MAV_MISSION_TYPE_RALLY: "rally point"}


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


class TransferHost(Protocol):
    """What a link's transfers share with the others: the vehicle's mission, fence and rally points (each a
    :class:`Mission` of its type), and the one upload at a time."""

    mission: Mission
    upload_link: str | None  # the link an upload is on (None: none)

    def held(self, mission_type: int) -> Mission: ...

    def flown(self) -> str | None: ...

    def accept(self, who: Partner, mission: Mission, what: str, mission_type: int = MISSION) -> str | None: ...

    def refused(self, text: str) -> None: ...

    def texts(self, severity: int, text: str) -> list[Any]: ...

    def current_message(self) -> list[Any]: ...


class LinkTransfer:
    """The mission protocol on one link (``link``: ``controller`` or ``gcs``)."""

    def __init__(self, link: str, host: TransferHost) -> None:
        self.link = link
        self.host = host
        self.state = State.IDLE
        self.partner: Partner | None = None
        self.int_mode = True  # MISSION_REQUEST_INT / ITEM_INT (else the legacy float ones), as the partner speaks
        self.seq = 0  # the transfer's next item (PX4's _transfer_seq); kept when idle, to spot a repeated last item
        self.count = 0  # the transfer's items
        self.staged: list[MissionItem] = []  # an upload's items so far
        self.staged_current = 0
        self.sent: set[int] = set()  # a download's items sent so far
        self.sending = Mission()  # a download's mission, as it was when it began
        self.last_recv = self.last_sent = self.started = 0.0
        self.upload = TransferStats()
        self.mtype = MISSION  # the transfer's mission type (kept when idle, as seq is)

    def handle(self, who: Partner, m: Any, now: float) -> bool:
        """One mission message (its target and the sender's authority checked); True when it changed the
        mission (its event is to be announced)."""
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
        mtype = MISSION if kind == "MISSION_SET_CURRENT" else m.mission_type
        if kind == "MISSION_COUNT":
            return self._count(who, m, now)
        if kind == "MISSION_REQUEST_LIST":
            self._idle_if_sent()
            self._request_list(who, mtype, now)
            return False
        if self.state is not State.IDLE:  # this link's transfer only, as PX4's instance checks its own; PX4
            # answers a clear or a new current item then with its text alone, no ACK
            self._busy(who, mtype, "WPM: IGN CLEAR CMD: Busy" if kind == "MISSION_CLEAR_ALL"
                       else "WPM: IGN WP CURR CMD: Busy", ack=False)
            return False
        if kind == "MISSION_CLEAR_ALL":
            if self._flown(who, mtype, "IGN CLEAR CMD"):
                return False
            # (a type PX4 does not know: nothing to clear, ACCEPTED as PX4 answers it)
            types = TYPES if mtype == mavlink.MAV_MISSION_TYPE_ALL else (mtype,) if mtype in TYPES else ()
            held = [t for t in types if self.host.held(t).items]
            for t in held:  # clearing nothing changes nothing: answered, not said as a change
                self.host.accept(who, Mission(), "cleared", t)
            self._answer(who, mavlink.MAV_MISSION_ACCEPTED, mtype)
            return bool(held)
        return self._set_current(who, m)

    def tick(self, now: float) -> None:
        """Request the awaited item again after :data:`RETRY_S`; end a transfer silent for
        :data:`PROTOCOL_TIMEOUT_S`."""
        p = self.partner
        if self.state is State.GETLIST and p is not None and now - self.last_sent > RETRY_S:
            self.upload.re_requests += 1
            self._send_request(p, now)
        elif self.state is not State.IDLE and p is not None and now - self.last_recv > PROTOCOL_TIMEOUT_S:
            if self.state is State.GETLIST:
                self._end_upload(now, "timeout")
            self._idle()
            p.ep.send_many(self.host.texts(mavlink.MAV_SEVERITY_CRITICAL, "Operation timeout"), p.who.addr)

    # -- upload -----------------------------------------------------------------------------------------
    def _count(self, who: Partner, m: Any, now: float) -> bool:
        """MISSION_COUNT: an upload begins (0 items: the mission is cleared at once)."""
        if self.state is State.GETLIST and self._is_partner(who) and self.seq == 0:
            self.last_recv = now  # our first request was lost: ask again
            self._send_request(who, now)
            return False
        mtype = m.mission_type
        if self.state is not State.IDLE or self.host.upload_link is not None:
            self._busy(who, mtype, "WPM: IGN MISSION_COUNT: Busy" if self.state is State.SENDLIST else BUSY)
            return False
        if m.count > MAX_COUNT.get(mtype, 0):  # a type PX4 does not know: room for none
            self._answer(who, mavlink.MAV_MISSION_NO_SPACE, mtype)
            return False
        if mtype not in TYPES:  # and none of it to clear: ACCEPTED, nothing held changes
            self._answer(who, mavlink.MAV_MISSION_ACCEPTED, mtype)
            return False
        if self._flown(who, mtype, "IGN MISSION_COUNT"):
            return False
        self.mtype = mtype
        if m.count == 0:  # a clear (of nothing: answered, not said as a change)
            held = bool(self.host.held(mtype).items)
            if held:
                self.host.accept(who, Mission(), "cleared (an upload of 0 items)", mtype)
            self._answer(who, mavlink.MAV_MISSION_ACCEPTED)
            return held
        self.state, self.partner, self.host.upload_link = State.GETLIST, who, self.link
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
        if not self._is_partner(who):  # PX4: its text alone (an ERROR would end the stranger's own transfer)
            self._busy(who, self.mtype, "REJ. MIS ITEM: partner id mismatch", ack=False)
            return False
        if self.state is State.SENDLIST:
            self._busy(who, self.mtype, "IGN MISSION_ITEM: Busy")
            return False
        if m.mission_type != self.mtype:
            self._answer(who, mavlink.MAV_MISSION_ERROR)  # PX4: of the transfer's type; the upload goes on
            return False
        self.last_recv = now
        if m.seq != self.seq:
            return False
        try:
            item = parse_item(m, self.int_mode) if self.mtype == MISSION else parse_zone_item(m, self.int_mode,
                                                                                               self.mtype)
        except ItemRefused as exc:
            self.host.refused(f"{_NOUN[self.mtype]} item {m.seq} (command {m.command}, frame {m.frame}): {exc}")
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
        up = self.upload
        up.duration_s = now - self.started
        why = self.host.accept(who, Mission(tuple(self.staged), self.staged_current),
                               f"uploaded {up.items} items in {up.duration_s:.2f} s, {up.re_requests} requested again",
                               self.mtype)
        self._end_upload(now, "accepted" if why is None else f"refused: {why}")
        self._idle()
        if why is not None:  # the whole fence or rally points cannot be read: PX4's navigator would ignore them
            self._answer(who, mavlink.MAV_MISSION_ERROR, text=f"WPM: {why}")
            return False
        self._answer(who, mavlink.MAV_MISSION_ACCEPTED)
        return True

    def _send_request(self, p: Partner, now: float) -> None:
        """MISSION_REQUEST_INT (or MISSION_REQUEST, as the partner speaks) for the awaited item."""
        self.last_sent = now
        self.upload.requests += 1
        target = (p.who.sysid, p.who.compid)
        msg = (mavlink.MAVLink_mission_request_int_message(*target, self.seq, self.mtype) if self.int_mode
               else mavlink.MAVLink_mission_request_message(*target, self.seq, self.mtype))
        p.ep.send(msg, p.who.addr)

    def _end_upload(self, now: float, result: str) -> None:
        self.upload.duration_s = now - self.started
        self.upload.result = result
        if result != "accepted":  # an accepted one is its mission event
            self.host.refused(f"mission upload {result}: {self.upload}")

    # -- download ---------------------------------------------------------------------------------------
    def _request_list(self, who: Partner, mtype: int, now: float) -> None:
        """MISSION_REQUEST_LIST: a download of ``mtype``'s items begins (again, for its partner)."""
        if not (self.state is State.IDLE or (self.state is State.SENDLIST and self._is_partner(who)
                                             and mtype == self.mtype)):
            self._busy(who, mtype, "Mission download request ignored, already active", ack=False,
                       severity=mavlink.MAV_SEVERITY_INFO)  # PX4's text alone, as information
            return
        mission = self.host.held(mtype) if mtype in TYPES else Mission()  # a type PX4 does not know: no items
        self.state, self.partner, self.sending, self.mtype = State.SENDLIST, who, mission, mtype
        self.seq, self.count, self.sent = 0, len(mission.items), set()
        self.last_recv = self.last_sent = now
        who.ep.reply((mavlink.MAVLink_mission_count_message(who.who.sysid, who.who.compid, self.count, mtype),),
                     who.who.addr)

    def _request(self, who: Partner, m: Any, now: float) -> None:
        """MISSION_REQUEST(_INT): the item asked for, to the download's partner, in whatever order it asks;
        one past the mission ends the download (``MAV_MISSION_ERROR``). PX4 also ends it on a request other
        than the next item or the last again; ArduPilot answers any, as here: MAVProxy asks for five items
        at once and each lost one again 2 s later, so over a lossy link PX4's rule ends every download
        whose requests were not all delivered in order (docs/ground-station.md, "Missions")."""
        if not self._is_partner(who):
            if self.state is not State.IDLE:  # PX4: its text alone
                self._busy(who, m.mission_type, "WPM: REJ. CMD: partner id mismatch", ack=False)
            return  # no transfer: ignored, as PX4 does (some on-screen displays ask anyway)
        if self.state is State.GETLIST:
            self._say(who, BUSY)
            return
        if self.state is not State.SENDLIST or m.mission_type != self.mtype:
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
        current = self.mtype == MISSION and m.seq == sending.current  # (a fence's or rally points': none current)
        who.ep.reply((item_message(item, (who.who.sysid, who.who.compid), current, self.int_mode, self.mtype),),
                     who.who.addr)

    def _ack(self, who: Partner, m: Any, now: float) -> None:
        """MISSION_ACK from the partner: a download ends; an upload is cancelled
        (MAV_MISSION_OPERATION_CANCELLED) or its requests switch between _INT and float (UNSUPPORTED)."""
        if not self._is_partner(who) or m.mission_type != self.mtype:
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
        mission = self.host.mission
        if self._flown(who, MISSION, "WP CURR CMD", ack=False):  # PX4 answers MISSION_SET_CURRENT with no ACK
            return False
        if not 0 <= m.seq < len(mission.items):
            self._say(who, "WPM: WP CURR CMD: Not in list")
            return False
        self.host.accept(who, Mission(mission.items, m.seq), f"current item {m.seq}")
        who.ep.reply(tuple(self.host.current_message()), who.who.addr)
        return True

    def _flown(self, who: Partner, mtype: int, what: str, ack: bool = True) -> bool:
        """Whether the mission (``mtype`` MISSION or ALL) is being flown and cannot change (the host's
        ``flown``): then ``MAV_MISSION_ERROR`` ("not accepting mission commands right now", unless not ``ack``)
        and a STATUSTEXT saying why, to ``who``. PX4 takes the change in flight; here the controller's trajectory
        is planned whole (docs/ground-station.md, "Missions")."""
        why = self.host.flown() if mtype in (MISSION, mavlink.MAV_MISSION_TYPE_ALL) else None
        if why is None:
            return False
        self.host.refused(f"mission message from {who.who}: {what}: {why}")
        if ack:
            self._answer(who, mavlink.MAV_MISSION_ERROR, mtype, f"WPM: {what}: {why}")
        else:
            self._say(who, f"WPM: {what}: {why}")
        return True

    # -- helpers ----------------------------------------------------------------------------------------
    def _is_partner(self, who: Partner) -> bool:
        p = self.partner
        return p is not None and p.who == who.who

    def _idle_if_sent(self) -> None:
        """A download whose every item went out (its final ACK lost, or never sent) ends here, on a new
        MISSION_REQUEST_LIST, as PX4's ``maybe_completed`` ends it (on nothing else: until the 5 s timeout an
        upload, a clear and a new current item on its link are "Busy", as on PX4)."""
        if self.state is State.SENDLIST and len(self.sent) == self.count:
            self._idle()

    def _idle(self) -> None:
        """Back to IDLE: a staged upload is dropped (the mission stays as it was), and the upload's turn goes."""
        if self.state is State.GETLIST:
            if self.seq < self.count:
                self.staged = []
            self.host.upload_link = None
        self.state = State.IDLE

    def _answer(self, who: Partner, result: int, mission_type: int | None = None, text: str | None = None) -> None:
        """MISSION_ACK with ``result`` to ``who`` (and a STATUSTEXT saying why, in the same datagram), of
        ``mission_type`` (None: the transfer's)."""
        ack = mavlink.MAVLink_mission_ack_message(who.who.sysid, who.who.compid, result,
                                                  self.mtype if mission_type is None else mission_type)
        texts = self.host.texts(mavlink.MAV_SEVERITY_CRITICAL, text) if text is not None else []
        who.ep.reply((ack, *texts), who.who.addr)

    def _busy(self, who: Partner, mission_type: int, text: str = BUSY, ack: bool = True,
              severity: int = mavlink.MAV_SEVERITY_CRITICAL) -> None:
        """Another transfer is on: PX4's STATUSTEXT to the one who asked, with ``MAV_MISSION_ERROR`` where PX4
        sends one (``ack``: an upload's MISSION_COUNT, an item from the partner of a download); a request list,
        a clear, a new current item or a stranger's request or item get the text alone, as on PX4."""
        why = self.state.value if self.state is not State.IDLE else f"an upload on the {self.host.upload_link} link"
        self.host.refused(f"mission message from {who.who}: busy ({why})")
        if ack:
            self._answer(who, mavlink.MAV_MISSION_ERROR, mission_type, text)
        else:
            self._say(who, text, severity)

    def _say(self, who: Partner, text: str, severity: int = mavlink.MAV_SEVERITY_CRITICAL) -> None:
        """PX4's STATUSTEXT alone (no ACK) to ``who``."""
        who.ep.reply(tuple(self.host.texts(severity, text)), who.who.addr)

"""The offboard controller's wait for a ground station's mission: ``bsst controller --await-mission``.

In:  the vehicle's messages before the flight: HEARTBEAT (``custom_mode`` AUTO.MISSION, disarmed; ``system_status``
     EMERGENCY or FLIGHT_TERMINATION: its flight over for good, no mission to wait for) and
     MISSION_CURRENT (``mission_state`` ACTIVE: a ground station started the held mission; asked for with
     REQUEST_MESSAGE while AUTO.MISSION shows), MISSION_COUNT,
     MISSION_ITEM_INT, MISSION_ACK, HOME_POSITION (degE7,
     mm AMSL); the settings' :class:`~bridge.core.flight.Flight` (profile, law, rates, ``[link]``, ...)
Out: REQUEST_MESSAGE (MISSION_CURRENT), MISSION_REQUEST_LIST, MISSION_REQUEST_INT (again after
     :data:`~bridge.nodes.vehicle.mission.RETRY_S` unanswered), the final MISSION_ACK, GET_HOME_POSITION; the
     mission's :class:`~bridge.core.flight.Flight` (the settings flying the plan's smooth trajectory); in the
     controller's directory ``mission.plan`` (the items, fence and rally points as a QGroundControl plan) and
     ``mission.toml`` (the mission as flown, resolved: ``kind = "smooth"``, its ``[geofence]`` and ``[rally]``
     those the vehicle held at the start); each download's
     :class:`~bridge.mavlink.missionitems.TransferStats` (items, requests, requests again, wall time s, result):
     the mission's, and the fence's and the rally points' under ``fence`` and ``rally``; the vehicle's (sysid,
     compid) it came from, which the flight arms without waiting for another HEARTBEAT

The download is a ground station's (the vehicle is PX4's server, :mod:`bridge.nodes.vehicle.mission`: it sends
nothing unasked): MISSION_REQUEST_LIST until MISSION_COUNT comes, then MISSION_REQUEST_INT for each item in
turn, each sent again after PX4's retry time while its item does not come; a transfer the vehicle is silent in
for PX4's protocol timeout fails. Each item is checked by the vehicle's own parser
(:func:`~bridge.mavlink.missionitems.parse_item`) and the mission by the plan files' rules
(:func:`~bridge.mavlink.missionitems.plan_of`), about the vehicle's home (its HOME_POSITION). Then the fence and
the rally points (MAV_MISSION_TYPE_FENCE, _RALLY), as a ground station downloads them, through the vehicle's
parser of each (:mod:`bridge.mavlink.fenceitems`); all three are built and checked as the vehicle checked them at
its start (:func:`~bridge.nodes.uploaded.uploaded_flight`), the fence and rally points read as a plan's
``geoFence`` and ``rallyPoints``: the mission as flown holds them, so replaying it flies the same flight and the
run's ``geofence`` policy judges the trace against that fence (one uploaded in flight is the vehicle's event, not
this record's).

The link model: in lockstep the mission's ``[link]`` acts on the transfer here, both directions (up: what the
controller sends, down: what the vehicle sends), on the transfer's own clock (s of wall time from its first
request); in real time an impaired link is ``bsst relay``'s, on the wire. Either way the flight's own models
start fresh with the flight, so the flight is the same whatever the transfer met.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from bridge.core.flight import Flight
from bridge.link.model import LinkImpairment
from bridge.mavlink.fenceitems import FENCE, RALLY, parse_zone_item
from bridge.mavlink.missionitems import ItemRefused, MissionItem, TransferStats, parse_item
from bridge.mavlink.modes import MAIN_AUTO, SUB_MISSION, custom_mode
from bridge.nodes.offboard.config import OffboardConfig
from bridge.nodes.offboard.link import OffboardLink
from bridge.nodes.process import on_stop_signals
from bridge.nodes.report import Done, MissionLoaded, Ready, Report, Stats
from bridge.nodes.uploaded import uploaded_flight
from bridge.nodes.vehicle.missiontransfer import PROTOCOL_TIMEOUT_S, RETRY_S
from bridge.record.runlog import write_text_atomic
from missions.planfiles import plan_text
from params import ConfigError, dump_toml

MISSION_MODE = custom_mode(MAIN_AUTO, SUB_MISSION)
MISSION = mavlink.MAV_MISSION_TYPE_MISSION
TRANSFER_BYTES = 60  # a mission message's MAVLink 2 frame, about (the link model's bandwidth only)
MISSION_CURRENT_S = 0.1  # s: how often the waiting controller asks for the vehicle's MISSION_CURRENT (the start's cue)
_WANTED = ("MISSION_COUNT", "MISSION_ITEM_INT", "MISSION_ACK")
# the vehicle's HEARTBEAT system_status of a flight over for good, before any mission's start (a ground station's own
# flight ended so): no mission can fly after it, so the wait ends (its words: the controller's reason)
OVER = {mavlink.MAV_STATE_EMERGENCY: "its plant ended the flight: it crashed, diverged or was touched "
                                     "(HEARTBEAT system_status EMERGENCY)",
        mavlink.MAV_STATE_FLIGHT_TERMINATION: "a ground station terminated the flight (HEARTBEAT system_status "
                                              "FLIGHT_TERMINATION: PX4 leaves it only by a reboot)"}
PLANT_ENDS = ("crashed", "diverged", "collision", "terminated")  # the vehicle's events a flight over for good follows


@dataclass(frozen=True)
class Fetched:
    """What the wait gave: the mission's flight (None: none, ``why`` says why) and the download's figures."""

    flight: Flight | None
    transfer: TransferStats
    why: str = ""
    states: dict[str, Any] = field(default_factory=dict)  # the vehicle's states read while waiting (Stats' keys)
    zone_figures: dict[str, TransferStats] = field(default_factory=dict)  # the fence's and rally points' (begun)
    vehicle: tuple[int, int] | None = None  # the vehicle's (sysid, compid) heard on this link: the flight arms it

    def figures(self) -> dict[str, Any]:
        """The downloads' figures as the controller says them (summary.json ``mission_transfer``,
        bridge.record.transfers): the mission's, with the fence's and the rally points' under their keys."""
        return {**self.transfer.as_dict(), **{k: st.as_dict() for k, st in self.zone_figures.items()}}


class MissionLink(OffboardLink):
    """The controller's link before the flight: it waits for the start, downloads the mission, asks the home."""

    def __init__(self, flight: Flight, cfg: OffboardConfig, status: Callable[[Report], None]) -> None:
        super().__init__(flight, cfg, None, status)
        self.vehicle_mode: int | None = None  # the vehicle's HEARTBEAT custom_mode
        self.mission_state: int | None = None  # its MISSION_CURRENT's: ACTIVE once a ground station started it
        self.home: tuple[float, float, float] | None = None
        self.over = ""  # why no mission can fly: the vehicle's flight over for good before its start (:data:`OVER`)
        self._inbox: list[Any] = []  # mission messages from the vehicle, not through the down model yet
        model = cfg.clock == "lockstep" and flight.link.impaired
        self._models: tuple[LinkImpairment, LinkImpairment] | None = flight.link.make() if model else None
        self._t0 = 0.0

    def stop(self) -> None:
        self.stopping = True

    def _on(self, m: Any) -> None:
        src = m.get_srcSystem()
        kind = m._type
        if kind == "HEARTBEAT" and (self.vsys is None or src == self.vsys) and m.type != mavlink.MAV_TYPE_GCS \
                and m.autopilot != mavlink.MAV_AUTOPILOT_INVALID:
            self.vehicle_mode = m.custom_mode
        elif src == self.vsys and kind in _WANTED and m.target_system == self.cfg.sysid:
            self._inbox.append(m)
        elif src == self.vsys and kind == "HOME_POSITION":
            self.home = (m.latitude / 1e7, m.longitude / 1e7, m.altitude / 1000.0)
        elif src == self.vsys and kind == "MISSION_CURRENT":
            self.mission_state = m.mission_state
        super()._on(m)

    # -- the transfer, through the link model in lockstep ---------------------------------------------
    def _t(self) -> float:
        return time.monotonic() - self._t0

    def _up(self, msg: Any) -> None:
        if self._models is None:
            self.ep.send(msg)
        else:
            self._models[0].send(self._t(), TRANSFER_BYTES, msg)

    def _pump(self) -> list[Any]:
        """What reached the controller: the vehicle's mission messages (through the down model in lockstep);
        what the up model delivers by now goes out."""
        got, self._inbox = self._inbox, []
        if self._models is None:
            return got
        up, down = self._models
        t = self._t()
        for d in up.deliver(t):
            self.ep.send(d.payload)
        for m in got:
            down.send(t, TRANSFER_BYTES, m)
        return [d.payload for d in down.deliver(t)]

    def _flush(self) -> None:
        """The final MISSION_ACK: what the up model has not lost goes out now (nothing waits for it)."""
        if self._models is not None:
            for d in self._models[0].drain():
                self.ep.send(d.payload)

    def _next_due(self) -> float:
        if self._models is None:
            return float("inf")
        due = [d for d in (self._models[0].next_due(), self._models[1].next_due()) if d is not None]
        return self._t0 + min(due) if due else float("inf")

    def download(self, mission_type: int = MISSION) -> tuple[list[MissionItem], TransferStats]:
        """The vehicle's items of ``mission_type`` (the mission, its fence or its rally points), item by item
        (see the module docstring), each read by the vehicle's own parser of that type, and the transfer's
        figures."""
        st = TransferStats()
        start = time.monotonic()
        self._t0 = self._t0 or start  # the link models' clock: from the first transfer's first request
        target = (self.vsys or 0, self.vcomp)
        items: list[MissionItem] = []
        count: int | None = None

        def ask() -> Any:
            st.requests += 1
            if count is None:
                return mavlink.MAVLink_mission_request_list_message(*target, mission_type)
            return mavlink.MAVLink_mission_request_int_message(*target, len(items), mission_type)

        self._up(ask())
        sent = heard = time.monotonic()
        while not self.stopping:
            self._serve(min(sent + RETRY_S, self._next_due(), self._next_house))
            now = time.monotonic()
            for m in self._pump():
                heard = now
                if m._type == "MISSION_ACK":
                    st.result = f"the vehicle ended it: MAV_MISSION_RESULT {m.type}"
                elif m.mission_type != mission_type:
                    continue
                elif count is None and m._type == "MISSION_COUNT":
                    count = st.items = m.count
                    st.result = "" if count or mission_type != MISSION else "the vehicle holds no mission"
                elif count is not None and m._type == "MISSION_ITEM_INT" and m.seq == len(items):
                    try:
                        items.append(parse_item(m, True) if mission_type == MISSION
                                     else parse_zone_item(m, True, mission_type))
                    except ItemRefused as exc:
                        st.result = f"item {m.seq} refused: {exc}"
                else:
                    continue
                if st.result:
                    break
                if len(items) == count:  # (a fence or rally points of none: ended as a ground station ends it)
                    self._up(mavlink.MAVLink_mission_ack_message(*target, mavlink.MAV_MISSION_ACCEPTED,
                                                                 mission_type))
                    self._flush()
                    st.result = "accepted"
                    break
                self._up(ask())
                sent = now
            if st.result:
                break
            if now - heard > PROTOCOL_TIMEOUT_S:
                st.result = f"timeout: the vehicle silent for {PROTOCOL_TIMEOUT_S:g} s"
                break
            if now - sent >= RETRY_S:
                st.re_requests += 1
                self._up(ask())
                sent = now
        st.duration_s = round(time.monotonic() - start, 6)
        if self.stopping and not st.result:
            st.result = "stopped"
        return items, st

    def await_start(self) -> bool:
        """Serve the link until a ground station has started the mission (True): the vehicle shows AUTO.MISSION,
        disarmed, and its MISSION_CURRENT says ACTIVE (asked for with REQUEST_MESSAGE every
        :data:`MISSION_CURRENT_S` while AUTO.MISSION shows). AUTO.MISSION selected alone is not a start: PX4 stays
        on the ground until it is armed or sent MISSION_START. False: the controller was stopped, or the vehicle's
        flight is over for good before the start (:attr:`over` says why: a ground station's own flight crashed,
        diverged or was terminated; the vehicle refuses every later arm and start)."""
        said = False
        while not self.stopping:
            if self._heard and self.vehicle_state in OVER:
                self.over = f"no mission can fly: {OVER[self.vehicle_state]}"
                self.event("aborted", self.over, PLANT_ENDS)
                return False
            if self._heard and self.vehicle_mode == MISSION_MODE:  # (armed: armed in HOLD, then AUTO.MISSION)
                if self.mission_state == mavlink.MISSION_STATE_ACTIVE:
                    return True
                if self.mission_state is not None and not said:
                    said = True
                    self.event("mission", "AUTO.MISSION selected, not started: waiting for its start (an arm, or "
                                          "MISSION_START)")
                self.mission_state = None  # the answer to this request decides
                self._command(mavlink.MAV_CMD_REQUEST_MESSAGE, float(mavlink.MAVLINK_MSG_ID_MISSION_CURRENT), 0.0,
                              tries=1, every_s=MISSION_CURRENT_S)
                if self.mission_state == mavlink.MISSION_STATE_ACTIVE:
                    continue
                self._serve(min(time.monotonic() + MISSION_CURRENT_S, self._next_house))
            else:
                self._serve(self._next_house)
        return False

    def ask_home(self) -> bool:
        """The vehicle's home (GET_HOME_POSITION, answered with HOME_POSITION)."""
        self._command(mavlink.MAV_CMD_GET_HOME_POSITION, 0.0, 0.0)
        return self.home is not None


def fetch_mission(flight: Flight, cfg: OffboardConfig, out: Path | None, status: Callable[[Report], None]) -> Fetched:
    """Wait for a ground station's start, download the mission, build its flight on ``flight``'s settings and
    write it as flown into ``out`` (``mission.plan``, ``mission.toml``); each step an event."""
    link = MissionLink(flight, cfg, status)
    on_stop_signals(link.stop)  # the flight's handler replaces this one after
    # ready now (the session waits for it, not for a ground station): the flight says ready again when it starts
    status(Ready("controller", vehicle=cfg.vehicle.hostport, local=f"{link.ep.local[0]}:{link.ep.local[1]}",
                 clock=cfg.clock))
    empty = TransferStats()
    got = _fetch(link, flight, out, empty)
    # the states the vehicle sent while it waited crossed the link: read, not lost (summary.json link.down)
    return replace(got, states={"states": link.states, "states_refused": link.states_refused,
                                "state_window": link.state_window, "read_until": link.read_until,
                                "kernel_drops": link.ep.kernel_drops()})


def _fetch(link: MissionLink, flight: Flight, out: Path | None, empty: TransferStats) -> Fetched:
    """:func:`fetch_mission`'s wait, download and build on ``link`` (closed after)."""
    try:
        link.event("mission", "waiting for a ground station to upload a mission and start it")
        if not link.await_start():
            return Fetched(None, empty, link.over or "stopped before a mission was started")
        items, st = link.download()
        if st.result != "accepted":
            return Fetched(None, st, f"mission download failed: {st.result}")
        zones: dict[int, list[MissionItem]] = {}
        figures: dict[str, TransferStats] = {}  # each download's, by its key in summary.json's mission_transfer
        # held as flown from the start, as PX4's navigator holds them with the mission (a GCS reads all three)
        for mtype, key, noun in ((FENCE, "fence", "fence"), (RALLY, "rally", "rally points")):
            zones[mtype], figures[key] = link.download(mtype)
            if figures[key].result != "accepted":
                return Fetched(None, st, f"{noun} download failed: {figures[key].result}", zone_figures=figures)
        if not link.ask_home():
            return Fetched(None, st, "the vehicle did not say its home (GET_HOME_POSITION)", zone_figures=figures)
        assert link.home is not None
        try:  # the check the vehicle's start made (bsst sitl's step cap aside: the vehicle's, bsst vehicle --trace-cap)
            plan, new = uploaded_flight(flight, items, link.home, fence=zones[FENCE], rally=zones[RALLY])
        except (ConfigError, ValueError) as exc:  # (a refusal, as the vehicle's start check takes either)
            return Fetched(None, st, f"the mission cannot be flown: {exc}", zone_figures=figures)
        if out is not None:
            write_text_atomic(out / "mission.plan", plan_text(plan))
            write_text_atomic(out / "mission.toml", dump_toml(new.mission.to_dict()))
        link.event("mission", f"downloaded {st.items} items in {st.duration_s:.2f} s ({st.requests} requests, "
                              f"{st.re_requests} again), a fence of {len(zones[FENCE])} items and "
                              f"{len(zones[RALLY])} rally points: {new.mission.duration_s:.2f} s to fly")
        assert link.vsys is not None  # (await_start returns once the vehicle's HEARTBEAT is heard)
        return Fetched(new, st, zone_figures=figures, vehicle=(link.vsys, link.vcomp))
    finally:
        link.stop_reading()  # the states already on the socket are read (delivered); the time it stopped said
        link.ep.close()



def mission_flight(flight: Flight, cfg: OffboardConfig, out: Path | None,
                   emit: Callable[[Report], None]) -> tuple[Flight | None, dict[str, Any], tuple[int, int] | None]:
    """``bsst controller --await-mission`` before its flight: the mission's flight (its ``mission`` report
    said), the download's figures and the vehicle's (sysid, compid) it came from; None when there is none to fly
    (its ``stats`` and ``done`` said, why on stderr: the controller then exits 1)."""
    got = fetch_mission(flight, cfg, out, emit)
    transfer = got.figures()
    if got.flight is None:
        emit(Stats({"mission_transfer": transfer, **got.states}))
        emit(Done("aborted", False, got.why))
        sys.stderr.write(f"bsst controller: aborted: {got.why}\n")
        return None, transfer, None
    emit(MissionLoaded(got.flight.mission.name, got.transfer.items, transfer))
    return got.flight, transfer, got.vehicle

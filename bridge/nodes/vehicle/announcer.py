"""The vehicle's events said out loud: each new event of the simulated vehicle as a status line to the session,
a STATUSTEXT (for people: ground stations show it) and a typed EVENT (for programs: its id says the kind,
:mod:`bridge.mavlink.events`) on every link, with a HEARTBEAT at once; a parameter changed, with its new
PARAM_VALUE on every link too (but to the peer that changed it: it has had its answer).

In:  the simulated vehicle's event list (appended by its parts); the controller link's peer (who armed); a
     REQUEST_EVENT (its sender's ids, the sequence range)
Out: Event reports (:mod:`bridge.nodes.report`); one datagram per link of STATUSTEXT(s), EVENT(s), the PARAM_VALUE
     of each parameter changed, and a HEARTBEAT,
     to a would-be controller within its trial's credit (:meth:`~bridge.nodes.vehicle.receiver.Receiver.charged`);
     at 1 Hz the HEARTBEAT with CURRENT_EVENT_SEQUENCE (:meth:`Announcer.beat`); the EVENTs asked for again
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager, nullcontext
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from bridge.autopilot.simvehicle import SimVehicle
from bridge.autopilot.vehicleevents import Sender
from bridge.mavlink.endpoint import Endpoint
from bridge.mavlink.events import EventRing
from bridge.nodes.report import Event, Report
from bridge.nodes.vehicle.authority import Authority, claim
from bridge.nodes.vehicle.streams import StatusTexts

# events sent as CRITICAL STATUSTEXT, and as EVENTs of log level critical (else info)
CRITICAL_KINDS = ("failsafe", "diverged", "lockstep", "preflight", "battery", "terminated")
MAX_TEXT_MESSAGES = 12  # STATUSTEXTs in one datagram of events (the newest texts, whole)
MAX_EVENT_MESSAGES = 24  # EVENTs in one datagram (65 bytes each); more go in datagrams of their own before it


class Announcer:
    """Says each new event once as a status line (:meth:`report_events`) and once on the links (:meth:`drain`)."""

    def __init__(self, sim: SimVehicle, authority: Authority, link: Endpoint, endpoints: list[Endpoint],
                 report: Callable[[Report], None], statustext: StatusTexts, heartbeat: Callable[[], Any],
                 param_value: Callable[[str], Any]) -> None:
        self.sim = sim
        self.authority = authority
        self.link = link
        self.endpoints = endpoints
        self.report = report
        self.statustext = statustext
        self.heartbeat = heartbeat
        self.param_value = param_value  # a parameter's PARAM_VALUE now, by name (ParamService.value_of)
        # the receive path's trial scope (Receiver.charged), wired once the receiver exists
        self.charged: Callable[[], AbstractContextManager[None]] = nullcontext
        self.sent = 0  # events said on the links
        self.reported = 0  # events said as status lines (a command's before its answer: report_events)
        self.ring = EventRing()  # the EVENTs sent: numbered, the last few kept for REQUEST_EVENT

    def report_events(self) -> None:
        """Each new event as a status line, at once: a command's before its COMMAND_ACK (Commander.command), so
        that the controller, which reports what the answer tells it, never speaks of it first."""
        events = self.sim.events
        while self.reported < len(events):
            e = events[self.reported]
            self.reported += 1
            # not caused by a command handled here: an arm the up-link model delivered (the
            # flight's controller sent it), or the vehicle's own disarm (landed, diverged)
            peer = self.link.peer
            claim(e, self.authority.controller(peer) if e.kind == "armed" and peer is not None else None)
            self.report(Event.of(e))

    def drain(self) -> None:
        """Each new event as a status line (:meth:`report_events`) and a STATUSTEXT; a parameter changed, with its
        PARAM_VALUE, so that every ground station's copy follows a change another one (or the controller) made, as
        PX4's ``MavlinkParametersManager::send_untransmitted`` sends each changed parameter on every link (not to
        a link's peer that made the change: it has had its answer, which PX4 sends twice); then a HEARTBEAT at
        once, so that a ground station sees an arm, disarm or failsafe without waiting up to 1 s."""
        events = self.sim.events
        if self.sent == len(events):
            return
        self.report_events()
        texts: list[list[Any]] = []
        typed: list[Any] = []
        values: list[tuple[Any, Sender | None]] = []  # PARAM_VALUEs of the parameters changed, and by whom
        while self.sent < len(events):
            e = events[self.sent]
            self.sent += 1
            sev = mavlink.MAV_SEVERITY_CRITICAL if e.kind in CRITICAL_KINDS else mavlink.MAV_SEVERITY_INFO
            texts.append(self.statustext(sev, f"{e.kind}: {e.shown}"))
            typed.append(self.ring.add(e.kind, e.t, sev))
            if e.param is not None:
                values.append((self.param_value(e.param.name), e.by))
        msgs: list[Any] = []
        for chunks in reversed(texts):  # the newest texts, whole, if many came at once
            if len(msgs) + len(chunks) > MAX_TEXT_MESSAGES:
                break
            msgs[:0] = chunks
        while len(typed) > MAX_EVENT_MESSAGES:  # every EVENT goes out (a program acts on them), the oldest first
            self.to_links(typed[:MAX_EVENT_MESSAGES])
            typed = typed[MAX_EVENT_MESSAGES:]
        msgs += typed
        msgs.append(self.heartbeat())
        self.to_links(msgs, values)

    def beat(self) -> None:
        """The 1 Hz HEARTBEAT on every link, with CURRENT_EVENT_SEQUENCE (a receiver sees an EVENT it missed;
        PX4 sends it every 3 s, mavlink_events.h: here it rides the heartbeat's datagram)."""
        self.to_links([self.heartbeat(), self.ring.current()])

    def resend(self, m: Any) -> list[Any]:
        """The answer to a REQUEST_EVENT ``m``: the EVENTs asked for, or RESPONSE_EVENT_ERRORs (EventRing.resend)."""
        return self.ring.resend(m.first_sequence, m.last_sequence, m.get_srcSystem(), m.get_srcComponent())

    def to_links(self, msgs: list[Any], values: Sequence[tuple[Any, Sender | None]] = ()) -> None:
        """``msgs``, one datagram per link (to a would-be controller within its trial's credit), after ``values``
        (:meth:`drain`'s PARAM_VALUEs, each with its change's sender): each but to the link's peer that made it."""
        with self.charged():
            for ep in self.endpoints:
                told = [v for v, by in values if by is None or (by.host, by.port) != ep.peer]
                ep.send_many([*told, *msgs] if told else msgs)

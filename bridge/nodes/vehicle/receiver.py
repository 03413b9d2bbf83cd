"""The vehicle's receive path: each message that passed the frame stage, its sender's authority checked,
handed to the part that acts on it.

In:  a message (pymavlink), the :class:`Endpoint` it came in on and its source address (host, port)
Out: calls into the parts (:class:`Targets`, :class:`Commander`, :class:`ParamService`,
     :class:`MissionManager`); answers to the requests that change nothing (TIMESYNC with the vehicle's clock
     in ns, PING, MAVLink FTP's replies (the component metadata files, read-only: :mod:`bridge.mavlink.ftp`),
     REQUEST_EVENT's EVENTs again); the controller link's peer learned; refusals
     counted, with whether the flight's controller sent them (:class:`Refusals`)

Before a flight, a vehicle not told its controller's address (no ``controller_from``) cannot know its
controller: whoever claims the controller's ids on the controller link is on trial, and every reply to
the would-be controllers (their peer included) is charged, to each one's reply budget and to one credit
they share: all together get back at most the bytes they sent, plus one frame
(:class:`~bridge.mavlink.receive.ReplyCredit`;
docs/hostile-input.md, "Load shedding"). A flight on, its controller is known and answered freely.
"""

from __future__ import annotations

from collections.abc import Callable
from contextlib import AbstractContextManager
from dataclasses import dataclass
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from bridge.autopilot.vehicleevents import CONTROLLER_LINK
from bridge.mavlink.compmeta import FILES as METADATA_FILES
from bridge.mavlink.endpoint import Endpoint
from bridge.mavlink.ftp import FtpServer
from bridge.mavlink.receive import Rejections, ReplyCredit
from bridge.nodes.vehicle.authority import COMMANDS, TARGETS, Authority
from bridge.nodes.vehicle.commander import Commander
from bridge.nodes.vehicle.mission import MESSAGES as MISSION_MESSAGES
from bridge.nodes.vehicle.mission import MissionManager
from bridge.nodes.vehicle.paramservice import MESSAGES as PARAM_MESSAGES
from bridge.nodes.vehicle.paramservice import ParamService
from bridge.nodes.vehicle.targets import Targets


class Refusals:
    """Counts a refusal in ``rejected``, marked as the flight's controller's while :attr:`from_peer`."""

    def __init__(self, rejected: Rejections) -> None:
        self.rejected = rejected
        self.from_peer = False  # the message being handled came from the controller's address

    def __call__(self, why: str) -> None:
        self.rejected.add(why, self.from_peer)


@dataclass(frozen=True)
class ReceiverPorts:
    """What the receive path asks of the vehicle that wires it."""

    step: Callable[[], int]  # the current control step k
    flight_on: Callable[[], bool]  # armed, or a lockstep flight on
    announce: Callable[[], None]  # the new events out now (status lines, STATUSTEXT, HEARTBEAT)
    heartbeat: Callable[[], Any]  # the HEARTBEAT now
    clock_ns: Callable[[], int]  # the vehicle's clock for TIMESYNC (ns, never 0)
    events: Callable[[Any], list[Any]]  # the answer to a REQUEST_EVENT: its EVENTs again (or their errors)


class Charged(AbstractContextManager[None]):
    """:meth:`Receiver.charged`'s context: a class, not ``contextlib.contextmanager`` (whose generator costs
    ~3 us a use, at every housekeeping of a lockstep flight)."""

    __slots__ = ("receiver", "before")

    def __init__(self, receiver: Receiver) -> None:
        self.receiver = receiver
        self.before: ReplyCredit | None = None

    def __enter__(self) -> None:
        r = self.receiver
        link = r.link
        self.before = link.trial
        if r.on_trial():
            link.trial = r.trial

    def __exit__(self, *exc: object) -> None:
        self.receiver.link.trial = self.before


class Receiver:
    """Routes the messages of the controller link (``link``) and the GCS link to the vehicle's parts."""

    def __init__(self, link: Endpoint, authority: Authority, refuse: Refusals, targets: Targets,
                 commander: Commander, params: ParamService, mission: MissionManager, ports: ReceiverPorts) -> None:
        self.link = link
        self.authority = authority
        self.refuse = refuse
        self.targets = targets
        self.commander = commander
        self.params = params
        self.mission = mission
        self.ports = ports
        self.ftp = FtpServer(METADATA_FILES)  # the component metadata files, to every link's senders
        self.trial = ReplyCredit()  # what the would-be controllers may get back (the module docstring)
        self._flown: tuple[str, int] | None = None  # the address that flew the last flight (:meth:`on_trial`)

    def handle(self, ep: Endpoint, m: Any, addr: tuple[str, int]) -> None:
        """A message that passed the frame stage: its sender's authority checked
        (:meth:`Authority.controller_refusal`), then checked and acted on by :meth:`dispatch`.

        The controller link's peer (where ODOMETRY goes, never rate-limited, with a socket of
        its own: Endpoint.prioritise) is the flight's controller: the address of the
        configured controller's message that nothing refused, learned while no flight is on
        (the newest such) or when the flight has none yet (the first), and then held until
        the flight ends: while it is on, the controller's ids from any other address are a
        ``stranger``'s."""
        link = self.link
        if ep is not link:
            self.refuse.from_peer = False
            self.dispatch(ep, m, addr)
            return
        known = self.refuse.from_peer = addr == link.peer
        flight_on = self.ports.flight_on()
        why = self.authority.controller_refusal(m, known, addr, link.peer, flight_on)
        if why is not None:
            self.refuse(why)
            if m._type in COMMANDS:
                ep.reply((mavlink.MAVLink_command_ack_message(m.command, mavlink.MAV_RESULT_DENIED, 0, 0,
                                                              m.get_srcSystem(), m.get_srcComponent()),), addr)
            return
        if known and flight_on:  # the flight's controller (the lockstep's hot path)
            self.dispatch(link, m, addr)
            return
        if flight_on or self.authority.pinned is not None:
            self._from_controller(m, addr, known)
            return
        if known and addr == self._flown:  # the last flight's controller: trusted until another claims its ids
            self._from_controller(m, addr, known)
            return
        self.trial.earn(len(m.get_msgbuf()))  # no controller known yet: on trial (the module docstring)
        link.trial = self.trial
        try:
            self._from_controller(m, addr, known)
        finally:
            link.trial = None

    def _from_controller(self, m: Any, addr: tuple[str, int], known: bool) -> None:
        """A message of the configured controller's that nothing refused: to its part; from a new address
        (no flight on, or none with a controller yet) its address is learned as the peer."""
        link = self.link
        if known:
            self._dispatch_on_trial(m, addr)
            return
        # the controller's ids from a new address, no flight on (or none with a controller yet):
        # it is the peer while its message is handled (an arm's first state goes to it), and
        # stays so unless the message is refused
        rejected = self.refuse.rejected
        before, refused = link.peer, rejected.total
        link.peer = addr
        self._dispatch_on_trial(m, addr)
        if rejected.total != refused:
            link.peer = before
        else:
            link.prioritise(addr)
            if addr != before:  # a new controller hears who it talks to now, not at the next 1 Hz heartbeat
                link.reply((self.ports.heartbeat(),), addr)  # on trial: within its credit (else at 1 Hz)

    def _dispatch_on_trial(self, m: Any, addr: tuple[str, int]) -> None:
        """:meth:`dispatch` on the controller link; an answer that did not fit the trial's credit was not
        sent, and is counted ``reply_limited`` (a request whose answer is that long is not served)."""
        cut = self.trial.cut
        self.dispatch(self.link, m, addr)
        if self.trial.cut != cut:
            self.refuse("reply_limited")

    def dispatch(self, ep: Endpoint, m: Any, addr: tuple[str, int]) -> None:
        """A message whose sender may send it, to the part that acts on it."""
        kind = m._type
        if kind in TARGETS:
            self.targets.receive(m, kind, self.ports.step(), ep is self.link)
        elif kind in COMMANDS:
            if self.commander.command(ep, m, addr, self._link_name(ep)):
                self.ports.announce()
        elif kind == "TIMESYNC":
            if m.tc1 == 0:  # a request (an answer, tc1 != 0, is for someone else's clock: nothing to do)
                self._request(ep, addr, mavlink.MAVLink_timesync_message(self.ports.clock_ns(), m.ts1))
        elif kind == "PING":  # a request has no target (0, 0); answered as PX4 does, addressed to its sender
            if m.target_system == 0 and m.target_component == 0:
                self._request(ep, addr, mavlink.MAVLink_ping_message(m.time_usec, m.seq, m.get_srcSystem(),
                                                                     m.get_srcComponent()))
        elif kind in PARAM_MESSAGES:
            if self.params.handle(ep, m, addr, self._link_name(ep)):
                self.ports.announce()
        elif kind == "SET_MODE":
            if self.commander.set_mode_message(ep, m, addr, self._link_name(ep)):
                self.ports.announce()
        elif kind in MISSION_MESSAGES:
            if self.mission.handle(ep, m, addr, self._link_name(ep), self.refuse):
                self.ports.announce()
        elif kind == "REQUEST_EVENT":  # an EVENT missed (its sequence skipped): sent again to the asker
            if self.authority.for_others(m):
                return self.refuse("target")
            if not ep.reply_allowed(addr):
                return self.refuse("reply_limited")
            ep.reply(tuple(self.ports.events(m)), addr)
        elif kind == "FILE_TRANSFER_PROTOCOL":  # the metadata files; anything else NAKed at once (MAVProxy's
            if self.authority.for_others(m):  # parameter file too: it then fetches them by the parameter protocol)
                return self.refuse("target")
            if not ep.reply_allowed(addr):
                return self.refuse("reply_limited")
            replies = self.ftp.handle(bytes(m.payload), addr)
            ep.reply(tuple(mavlink.MAVLink_file_transfer_protocol_message(0, m.get_srcSystem(), m.get_srcComponent(),
                                                                           list(p)) for p in replies), addr)
        return None

    def on_trial(self) -> bool:
        """Whether the controller link's peer is a would-be controller: no controller pinned, no flight on, and
        not the address that flew the last flight (trusted until another address claims the controller's ids)."""
        if self.authority.pinned is not None:
            return False
        if self.ports.flight_on():
            self._flown = self.link.peer
            return False
        return self.link.peer != self._flown

    def charged(self) -> Charged:
        """While on trial, every datagram the controller link sends its peer is charged to the trial's credit
        (Endpoint.trial; the module docstring): ``with receiver.charged(): ...``."""
        return Charged(self)

    def _link_name(self, ep: Endpoint) -> str:
        return CONTROLLER_LINK if ep is self.link else "gcs"

    def _request(self, ep: Endpoint, addr: tuple[str, int], answer: Any) -> None:
        """Answer a request that changes nothing, within its sender's reply budget."""
        if not ep.reply_allowed(addr):
            return self.refuse("reply_limited")
        ep.reply((answer,), addr)
        return None

"""Who may command what on which link (docs/design.md, "Authority"), and who caused an event.

In:  a message that passed the frame stage (pymavlink), the address it came from (host, port) and
     its link (``controller`` or ``gcs``); the flight's controller address (learned, or None) and
     whether a flight is on
Out: why the message is refused for its sender (a :class:`~bridge.mavlink.receive.Rejections` reason)
     or None; the :class:`Sender` of a command; the `` [by ...]`` suffix of the events it caused

Only the configured controller (its sysid and compid) is heard on the controller link: with
``controller_from`` only from that address, else during a flight only from the flight's address. A
ground station may command on the GCS link (its commands still pass :mod:`bridge.mavlink.receive`'s
checks). A command for another system is refused as ``target`` whoever sent it.
"""

from __future__ import annotations

import socket
from dataclasses import dataclass
from typing import Any

from bridge.autopilot.simvehicle import Event
from bridge.mavlink.receive import addressed_elsewhere
from bridge.nodes.vehicle.config import VehicleConfig

TARGETS = frozenset({"HIL_ACTUATOR_CONTROLS", "SET_ACTUATOR_CONTROL_TARGET"})
ADDRESSED = frozenset({"COMMAND_LONG", "COMMAND_INT", "MISSION_REQUEST_LIST", "PARAM_REQUEST_LIST",
                       "PARAM_REQUEST_READ", "PARAM_SET", "SET_MODE"})  # target fields checked first
COMMANDS = frozenset({"COMMAND_LONG", "COMMAND_INT"})
ATTRIBUTED = ("armed", "disarmed", "mode", "interval", "param")  # the events that say who caused them
BY_VEHICLE = " [by vehicle]"  # the suffix of an arm or disarm the vehicle made itself (failsafe landing, divergence)


@dataclass(frozen=True)
class Sender:
    """Who sent a command: its sysid and compid, its address, and the link it came in on
    (``controller`` or ``gcs``)."""

    sysid: int
    compid: int
    addr: tuple[str, int]
    link: str

    @property
    def tag(self) -> str:
        """The suffix of the events it caused (:func:`sender_suffix`)."""
        return sender_suffix(self)


def sender_suffix(by: Sender | None) -> str:
    """The suffix of an event's text naming who caused it: `` [by SYSID:COMPID HOST:PORT LINK]``, or
    `` [by vehicle]`` (None: the vehicle itself). docs/design.md, "Authority": a policy checker parses it
    from events.log."""
    if by is None:
        return BY_VEHICLE
    return f" [by {by.sysid}:{by.compid} {by.addr[0]}:{by.addr[1]} {by.link}]"


def claim(event: Event, by: Sender | None) -> None:
    """Name ``by`` in ``event`` if it is one that says who caused it and names nobody yet."""
    if event.kind in ATTRIBUTED and " [by " not in event.text and event.by is None:  # by: named, typed
        event.text += sender_suffix(by)


def attribute(events: list[Event], n0: int, by: Sender) -> None:
    """Name ``by`` in the events from the ``n0`` th on that say who caused them."""
    for e in events[n0:]:
        claim(e, by)


class Authority:
    """The vehicle's rules of who is heard (its ids, the controller's ids, the pinned address)."""

    def __init__(self, cfg: VehicleConfig) -> None:
        self.cfg = cfg
        pin = cfg.controller_from  # numeric, as recvfrom gives addresses (a name would never match)
        self.pinned = (socket.gethostbyname(pin[0]), pin[1]) if pin is not None else None

    def from_controller(self, m: Any) -> bool:
        """Whether ``m`` says it comes from the configured controller (its sysid and compid)."""
        cfg = self.cfg
        return m.get_srcSystem() == cfg.controller_sysid and m.get_srcComponent() == cfg.controller_compid

    def for_others(self, m: Any) -> bool:
        """Whether ``m`` is addressed to another system or component than this vehicle."""
        return addressed_elsewhere(m, self.cfg.sysid, self.cfg.compid)

    def controller_refusal(self, m: Any, known: bool, addr: tuple[str, int], peer: tuple[str, int] | None,
                           flight_on: bool) -> str | None:
        """Why a message on the controller link is refused for its sender, or None. ``known``: it came
        from the flight's controller address ``peer``; ``flight_on``: armed, or a lockstep flight on."""
        kind = m._type
        if kind in ADDRESSED and self.for_others(m):
            return "target"
        if not self.from_controller(m):
            return "sender" if kind in TARGETS else "not_authorised"
        if self.pinned is not None and addr != self.pinned:
            return "stranger"
        if not known and peer is not None and flight_on:
            return "stranger"
        return None

    @staticmethod
    def sender(m: Any, addr: tuple[str, int], link: str) -> Sender:
        """The sender of ``m``, from ``addr`` on ``link``."""
        return Sender(m.get_srcSystem(), m.get_srcComponent(), addr, link)

    def controller(self, peer: tuple[str, int] | None) -> Sender:
        """The flight's controller (configured ids, learned address ``peer``) as a :class:`Sender`."""
        cfg = self.cfg
        return Sender(cfg.controller_sysid, cfg.controller_compid, peer or ("?", 0), "controller")

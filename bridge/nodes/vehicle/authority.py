"""Who may command what on which link (docs/design.md, "Authority"), and who caused an event.

In:  a message that passed the frame stage (pymavlink), the address it came from (host, port) and
     its link (``controller`` or ``gcs``); the flight's controller address (learned, or None) and
     whether a flight is on
Out: why the message is refused for its sender (a :class:`~bridge.mavlink.receive.Rejections` reason)
     or None; the :class:`~bridge.autopilot.vehicleevents.Sender` of a command, set as the ``by`` field of
     the events it caused (:data:`~bridge.autopilot.vehicleevents.ITSELF`: the vehicle's own)

Only the configured controller (its sysid and compid) is heard on the controller link: with
``controller_from`` only from that address, else during a flight only from the flight's address. A
ground station may command on the GCS link (its commands still pass :mod:`bridge.mavlink.receive`'s
checks). A command for another system is refused as ``target`` whoever sent it. The mission is the ground
station's: the controller may download it (:data:`MISSION_READS`), not change it (:data:`MISSION_WRITES`:
``not_authorised`` on the controller link).
"""

from __future__ import annotations

import socket
from typing import Any

from bridge.autopilot.vehicleevents import CONTROLLER_LINK, ITSELF, Event, Sender
from bridge.mavlink.receive import addressed_elsewhere
from bridge.nodes.vehicle.config import VehicleConfig

TARGETS = frozenset({"HIL_ACTUATOR_CONTROLS", "SET_ACTUATOR_CONTROL_TARGET"})
# the mission protocol's messages that change the mission: a ground station's, never the controller's
MISSION_WRITES = frozenset({"MISSION_COUNT", "MISSION_ITEM", "MISSION_ITEM_INT", "MISSION_CLEAR_ALL",
                            "MISSION_SET_CURRENT"})
MISSION_READS = frozenset({"MISSION_REQUEST_LIST", "MISSION_REQUEST", "MISSION_REQUEST_INT", "MISSION_ACK"})
ADDRESSED = frozenset({"COMMAND_LONG", "COMMAND_INT", "PARAM_REQUEST_LIST", "PARAM_REQUEST_READ", "PARAM_SET",
                       "SET_MODE", *MISSION_WRITES, *MISSION_READS})  # target fields checked first
COMMANDS = frozenset({"COMMAND_LONG", "COMMAND_INT"})
# the events that say who caused them (``preflight``: whose arm was denied)
ATTRIBUTED = ("armed", "disarmed", "mode", "interval", "param", "mission", "fence", "rally", "preflight", "speed",
              "terminated")


def claim(event: Event, by: Sender | None) -> None:
    """Name ``by`` (None: the vehicle itself, :data:`ITSELF`) as the cause of ``event`` if it is one that
    says who caused it and names nobody yet."""
    if event.kind in ATTRIBUTED and event.by is None:
        event.by = by if by is not None else ITSELF


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
        if kind in MISSION_WRITES:
            return "not_authorised"
        if self.pinned is not None and addr != self.pinned:
            return "stranger"
        if not known and peer is not None and flight_on:
            return "stranger"
        return None

    @staticmethod
    def sender(m: Any, addr: tuple[str, int], link: str) -> Sender:
        """The sender of ``m``, from ``addr`` on ``link``."""
        return Sender(m.get_srcSystem(), m.get_srcComponent(), addr[0], addr[1], link)

    def controller(self, peer: tuple[str, int] | None) -> Sender:
        """The flight's controller (configured ids, learned address ``peer``) as a :class:`Sender`."""
        cfg = self.cfg
        host, port = peer or ("?", 0)
        return Sender(cfg.controller_sysid, cfg.controller_compid, host, port, CONTROLLER_LINK)

"""The controller's down-link model, and in a lockstep fleet on one radio its turns on it (:mod:`bridge.link.turns`).

In:  the flight, the controller's settings (its clock; a lockstep fleet's radio file and this controller's user,
     ``OffboardConfig.radio``); then the mission step k (control periods) of each state it receives, and a
     handler for what its link brings while it waits (s of wall time, ``time.monotonic``)
Out: :func:`down_link`: the down-link model the controller's end puts states through (lockstep: the mission's;
     real time: none, the relay's acts on the wire) and the :class:`DownTurns`, or None; :meth:`DownTurns.wait`
     returns once this controller's turn of step k has come (or, after :data:`TURN_WAIT_S` of wall time, late:
     counted and said); :meth:`DownTurns.stats`

A controller whose turn has not come sleeps in ``select`` on its own link and on a wake socket of its own (a UDP
port of 127.0.0.1 it writes into the radio's file), serving its link meanwhile; a controller that took its turn
sends one datagram to every other controller's wake port, and the file says whether the turn has come. A wake-up
that is lost costs at most :data:`LOOK_S`.
"""

from __future__ import annotations

import select
import socket
import time
from collections.abc import Callable
from typing import Any

from bridge.core.flight import Flight
from bridge.link.model import LinkImpairment
from bridge.link.turns import WAKE, TurnRadio
from bridge.mavlink.endpoint import Endpoint
from bridge.nodes.offboard.config import OffboardConfig

LOOK_S = 0.002  # s: the longest sleep before looking at the turns again without a wake-up
TURN_WAIT_S = 30.0  # s of wall time waited for a turn before the state enters out of turn (a stuck fleet)


class DownTurns:
    """One controller's turns on its fleet's one radio (the module's docstring)."""

    def __init__(self, radio: TurnRadio, event: Callable[[str, str], None]) -> None:
        self.radio = radio
        self.event = event
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.setblocking(False)
        radio.wake_on(self.sock.getsockname()[1])
        self._wake: list[int] = []  # the other controllers' wake ports, once every one has written its own
        self.waits = 0  # states whose turn had not come when they arrived
        self.late: list[int] = []  # steps whose state entered out of turn (waited TURN_WAIT_S)

    def enter(self, k: int, ep: Endpoint, handle: Callable[[Any], None], observe: Callable[[], None]) -> None:
        """The state of step k: at this controller's turn (:meth:`wait`), ``observe`` puts it through the model;
        then the turn is over, and the other controllers are woken up to look."""
        radio = self.radio
        if not radio.ordered:  # (no rate: the order changes nothing, nobody waits)
            observe()
            return
        self.wait(k, ep, handle)
        observe()
        radio.took(k)
        ports = self._wake or [row[WAKE] for i, row in enumerate(radio.rows()) if i != radio.user]
        if all(ports):  # (until every controller has started, the file is read again at each turn)
            self._wake = ports
        for port in ports:
            if port:
                try:
                    self.sock.sendto(b"T", ("127.0.0.1", port))
                except OSError:
                    pass  # (a controller gone: nothing waits on it)

    def wait(self, k: int, ep: Endpoint, handle: Callable[[Any], None]) -> None:
        """Return when this controller's turn of step k has come, ``handle`` taking each message its link ``ep``
        brings meanwhile; after :data:`TURN_WAIT_S`, at once (late, said as an event)."""
        waiting = self.radio.blocking(k)
        if not waiting:
            return
        self.waits += 1
        now = time.monotonic()
        give_up = now + TURN_WAIT_S
        while waiting:
            if now >= give_up:
                self.late.append(k)
                self.event("radio", f"state of step {k} entered the fleet's radio out of turn: users "
                                    f"{', '.join(map(str, waiting))} took no turn for {TURN_WAIT_S:g} s")
                return
            try:
                select.select([self.sock, ep.wake_socket], [], [], min(LOOK_S, give_up - now))
            except InterruptedError:
                pass
            self._drain()
            for m, _addr in ep.poll():
                handle(m)
            now = time.monotonic()
            waiting = self.radio.blocking(k)

    def _drain(self) -> None:
        """Read the wake-ups (their content says nothing: the file does)."""
        while True:
            try:
                self.sock.recv(16)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                continue

    def stats(self) -> dict[str, Any]:
        """This controller's part of the radio (its ``radio`` stats), with its waits and late turns."""
        return {**self.radio.part(), "turn_waits": self.waits, "late_turns": self.late}

    def close(self) -> None:
        self.sock.close()
        self.radio.close()


def down_link(flight: Flight, cfg: OffboardConfig,
              event: Callable[[str, str], None]) -> tuple[LinkImpairment, DownTurns | None]:
    """The controller's down-link model and its turns on a lockstep fleet's one radio (None: a radio of its own)."""
    if cfg.clock != "lockstep":
        return LinkImpairment(direction="down"), None
    if cfg.radio is None:
        return flight.link.make()[1], None
    d = flight.link.down
    radio = TurnRadio(cfg.radio[0], "down", d.rate_bps, d.queue_ms / 1000.0, cfg.radio[1])
    return flight.link.make((None, radio), cfg.radio[1])[1], DownTurns(radio, event)

"""The controller's down-link model, and in a lockstep fleet on one radio its turns on it (:mod:`bridge.link.turns`).

In:  the flight, the controller's settings (its clock; a lockstep fleet's radio file and this controller's user,
     ``OffboardConfig.radio``); then the mission step k (control periods) of each state it receives, and a
     handler for what its link brings while it waits (s of wall time, ``time.monotonic``)
Out: :func:`down_link`: the down-link model the controller's end puts states through (lockstep: the mission's;
     real time: none, the relay's acts on the wire) and the :class:`DownTurns`, or None; :meth:`DownTurns.wait`
     returns once this controller's turn of step k has come (or, after :data:`TURN_WAIT_S` of wall time, late:
     counted and said); :meth:`DownTurns.stats`

The controllers of a fleet have no socket among them: a controller whose turn has not come looks at the radio's
file again after a short sleep in ``select`` on its own link (serving it meanwhile), the sleep doubling from
:data:`LOOK_FIRST_S` to :data:`LOOK_MOST_S`. Its predecessors' states of the step are in their sockets when its
own is (each vehicle sends its state after the same gate), so the wait is short.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from bridge.core.flight import Flight
from bridge.link.model import LinkImpairment
from bridge.link.turns import TurnRadio
from bridge.mavlink.endpoint import Endpoint, wait
from bridge.nodes.offboard.config import OffboardConfig

LOOK_FIRST_S = 0.0001  # s: the first sleep before looking at the turns again
LOOK_MOST_S = 0.002  # s: the longest
TURN_WAIT_S = 30.0  # s of wall time waited for a turn before the state enters out of turn (a stuck fleet)


class DownTurns:
    """One controller's turns on its fleet's one radio (the module's docstring)."""

    def __init__(self, radio: TurnRadio, event: Callable[[str, str], None]) -> None:
        self.radio = radio
        self.event = event
        self.waits = 0  # states whose turn had not come when they arrived
        self.late: list[int] = []  # steps whose state entered out of turn (waited TURN_WAIT_S)

    def wait(self, k: int, ep: Endpoint, handle: Callable[[Any], None]) -> None:
        """Return when this controller's turn of step k has come, ``handle`` taking each message its link ``ep``
        brings meanwhile; after :data:`TURN_WAIT_S`, at once (late, said as an event)."""
        waiting = self.radio.blocking(k)
        if not waiting:
            return
        self.waits += 1
        now = time.monotonic()
        give_up = now + TURN_WAIT_S
        look = LOOK_FIRST_S
        while waiting:
            if now >= give_up:
                self.late.append(k)
                self.event("radio", f"state of step {k} entered the fleet's radio out of turn: users "
                                    f"{', '.join(map(str, waiting))} took no turn for {TURN_WAIT_S:g} s")
                return
            for _, m, _addr in wait((ep,), min(now + look, give_up)):
                handle(m)
            look = min(2.0 * look, LOOK_MOST_S)
            now = time.monotonic()
            waiting = self.radio.blocking(k)

    def enter(self, k: int, ep: Endpoint, handle: Callable[[Any], None], observe: Callable[[], None]) -> None:
        """The state of step k: at this controller's turn (:meth:`wait`), ``observe`` puts it through the model;
        then the turn is over."""
        self.wait(k, ep, handle)
        observe()
        self.radio.took(k)

    def stats(self) -> dict[str, Any]:
        """This controller's part of the radio (its ``radio`` stats), with its waits and late turns."""
        return {**self.radio.part(), "turn_waits": self.waits, "late_turns": self.late}

    def close(self) -> None:
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

"""A fleet's one radio in lockstep: every user's packets of a step admitted in the offline loop's turn order.

In:  the fleet's radio file (:func:`bridge.link.radio.make_radio_file`), this process's user (its vehicle's place
     in the fleet, from 0) and direction (``up``: the vehicles, who receive the commands; ``down``: the
     controllers, who receive the states); the mission step k (control periods since the mission's start) of its
     packets; the step a vehicle leaves the fleet's turns from
Out: :meth:`TurnRadio.blocking`: the users whose turn at step k comes first and has not been taken (empty: this
     user's turn); packets admitted at mission time (s) behind every other user's, as
     :class:`~bridge.link.radio.Radio` admits them; :meth:`TurnRadio.part`, this user's share for
     ``summary.json``

Offline (:mod:`bridge.swarm`) each control step every vehicle flies its step in turn, the first one rotating
(:func:`turn_order`), so on one radio the packets sent at the same instant queue in that order. In lockstep
each vehicle and each controller is a process of its own; a shared radio is the same arithmetic on one state,
the radio's free time in the file, taken in the same order: before its packets of step k (the states a
controller receives, the commands and arm requests a vehicle receives) a user waits until every user before it
in step k's order has taken its turn of step k, and every user after it its turn of step k - 1; a user with no
packet in a step still takes its turn (:meth:`TurnRadio.took`). A vehicle that leaves (its flight over: a
verdict, a contact, the mission's end, the clock left lockstep) says from which step (:meth:`TurnRadio.leave`),
before it tells the other vehicles' gates: step k's order is over the users that had not left before it, as the
offline loop's. So every process knows, before its step k, who flies step k, and every packet meets the queue
the offline loop's meets.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from bridge.link.radio import DIRECTIONS, Radio, RadioFile, waits_ms

LEFT, WAKE = 2, 3  # a radio file's turns columns: the step a user leaves from; its controller's wake port
TURNS = ("each control step every vehicle flies its step in turn, the first one rotating (step k: the (k mod N)-th "
         "of the N still flying, by id): on one radio, whose packets sent at the same instant queue first")


def turn_order(live: Sequence[int], k: int) -> list[int]:
    """The users of step k (``live``, in id order) in the order they take their turns: the first rotating (the
    (k mod N)-th of the N), as the offline fleet flies them (:data:`TURNS`)."""
    turn = k % len(live)
    return [*live[turn:], *live[:turn]]


def blocking(user: int, k: int, direction: int, turns: Sequence[tuple[int, ...]]) -> list[int]:
    """The users ``user`` waits for before its turn of step k in ``direction`` (0 up, 1 down), given every user's
    (last turn up, last turn down, left from step): the users of step k (not left before it) before it in
    :func:`turn_order` that have not taken step k's turn, and those after it that have not taken step k - 1's. A
    user that left from step s takes no turn from s on, so it is waited for up to its turn of step s - 1 only
    (step s's order still has its slot, as the offline loop's, where it ends). Empty for a ``user`` not in step
    k's order (it left before k)."""
    live = [i for i, row in enumerate(turns) if row[LEFT] >= k]
    if user not in live:
        return []
    order = turn_order(live, k)
    pos = order.index(user)
    waits = [i for i in order[:pos] if turns[i][direction] < k and turns[i][LEFT] > k]
    waits += [i for i in order[pos + 1:] if turns[i][direction] < k - 1 and turns[i][LEFT] > k - 1]
    return sorted(waits)


class TurnRadio(Radio):
    """One direction of a fleet's radio in lockstep, as its user ``user`` (the module's docstring): times are
    mission time (s). Call :meth:`blocking` until it is empty, then admit the step's packets, then :meth:`took`."""

    __slots__ = ("user", "direction", "file", "last_end_s")

    def __init__(self, path: str | Path, direction: str, rate_bps: float, queue_s: float, user: int,
                 flag: str = "--radio") -> None:
        self.file = RadioFile(path, user, flag)
        super().__init__(rate_bps, queue_s, self.file.users)
        self.user = user
        self.direction = DIRECTIONS.index(direction)
        self.last_end_s: float | None = None  # the end of this user's last transmission (mission time, s)

    @property
    def ordered(self) -> bool:
        """Whether the order of the packets matters: a radio with a rate. Without one nobody waits for anybody
        (each packet is sent at once and only counted), so no turns are taken."""
        return self.rate > 0.0

    def blocking(self, k: int) -> list[int]:
        """The users this one waits for before its packets of step k (empty: its turn; :func:`blocking`)."""
        return blocking(self.user, k, self.direction, self.rows()) if self.rate > 0.0 else []

    def rows(self) -> list[tuple[int, ...]]:
        """Every user's row of the file (:meth:`bridge.link.radio.RadioFile.turns`)."""
        f = self.file
        f.lock()
        try:
            return f.turns()
        finally:
            f.unlock()

    def admit(self, t: float, size: int, user: int = 0) -> float | None:
        """As :meth:`Radio.admit`, behind every packet admitted before it in turn order (its turn taken)."""
        f = self.file
        f.lock()
        try:
            self.free_at = f.free_at(self.direction)
            end = super().admit(t, size, user)
            f.set_free_at(self.direction, self.free_at)
        finally:
            f.unlock()
        if end is not None:
            self.last_end_s = end
        return end

    def took(self, k: int) -> None:
        """This user's turn of step k is over (its packets of step k admitted, or none)."""
        if self.rate > 0.0:
            self._write(self.direction, k)

    def leave(self, k: int) -> None:
        """This user's vehicle takes no turn from step k on (both directions: the file's row is the vehicle's)."""
        self._write(LEFT, k)

    def wake_on(self, port: int) -> None:
        """This user's controller is woken up on UDP port ``port`` of 127.0.0.1 when another takes a turn."""
        self._write(WAKE, port)

    def _write(self, column: int, value: int) -> None:
        f = self.file
        f.lock()
        try:
            f.set_turn(column, value)
        finally:
            f.unlock()

    def part(self) -> dict[str, Any]:
        """This user's share of the radio for ``summary.json`` (:func:`bridge.link.radio.occupancy_of_parts` puts
        the parts together): bytes, queue drops, waits (ms), and when it first sent (the mission's start, 0 s: the
        offline span's) and last finished sending (mission time, s; None: nothing sent)."""
        u = self.user
        return {"user": u, "bytes": self.bytes[u], "lost_queue": self.dropped[u],
                "queue_wait_ms": waits_ms(self.waits[u]), "first_s": 0.0, "last_end_s": self.last_end_s}

    def close(self) -> None:
        self.file.close()

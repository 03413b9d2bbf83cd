"""A radio's bandwidth budget and queue: the link model's bandwidth cap, for one link or several behind one radio.

In:  the cap ``rate_bps`` (bytes/s; 0: none) and the longest wait ``queue_s`` (s) of one direction, the number
     of links (users) behind it; then packets: send time (s, non-decreasing across all users), size (bytes),
     the user (0..users-1)
Out: each packet's end of transmission (s) or None (tail-dropped); per user the bytes put on the air, the
     packets dropped and each packet's wait in the queue (s); :meth:`Radio.occupancy` for ``summary.json``

A radio shared by processes (real time: one ``bsst relay`` per vehicle, :class:`ProcessRadio`) keeps its one
number of state, when it is free again (s on ``CLOCK_MONOTONIC``, the clock ``time.perf_counter`` reads on
Linux, one for every process of the machine), in a small file every user maps (:func:`make_radio_file`: a
magic, the number of users, one slot per direction); each packet reads and moves it under an exclusive
``flock``. Each process counts its own user's bytes, drops and waits (:meth:`ProcessRadio.part`), and the fleet
puts the parts together (:func:`occupancy_of_parts`).

The model (docs/design.md, "Link model", step 3; docs/swarm.md, "One radio"): packets queue at the sender
in the order they are sent, first in first out, each occupying the radio for size / rate; a packet that would
wait longer than ``queue_s`` is dropped (tail drop). A link of its own has a radio of its own
(:class:`~bridge.link.impairment.LinkImpairment` makes one); a fleet on one radio hands every vehicle's link of
a direction the same :class:`Radio`, each vehicle a user, so their packets wait behind each other's. As the
transmissions never overlap and none starts before time 0, the bytes put on the air over a span reaching the
end of the last transmission, divided by that span, are together at most the rate.
"""

from __future__ import annotations

import fcntl
import math
import mmap
import os
import struct
from array import array
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from params import ConfigError

DIRECTIONS = ("up", "down")  # a radio file's slots, in this order
_HEADER = struct.Struct("<4sI")  # magic, users
# when the direction's radio is free again (s: CLOCK_MONOTONIC in real time, mission time in lockstep; -inf: never)
_SLOT = struct.Struct("<d")
# lockstep (bridge.link.turns), one row a user: the last step it took its turn in, up and down, the step it left the
# fleet's turns from (NEVER: still flying), and the UDP port on 127.0.0.1 its controller is woken up on when another
# takes a turn (0: none yet); real time leaves them as made
_TURNS = struct.Struct("<qqqq")
_MAGIC = b"BSSR"
NOT_YET = -1  # a user's last turn before its first
NEVER = 2**63 - 1  # the step a user still flying leaves from


def radio_file_bytes(users: int) -> int:
    """The size of a radio file of ``users`` users (bytes)."""
    return _HEADER.size + _SLOT.size * len(DIRECTIONS) + _TURNS.size * users


class Radio:
    """One direction's bandwidth budget and FIFO queue, shared by ``users`` links (see the module docstring)."""

    __slots__ = ("rate", "queue_s", "free_at", "bytes", "dropped", "waits")

    def __init__(self, rate_bps: float, queue_s: float, users: int = 1) -> None:
        self.rate = rate_bps
        self.queue_s = queue_s
        self.free_at = -math.inf  # when the radio is free again (s)
        self.bytes = [0] * users  # put on the air, by user
        self.dropped = [0] * users  # tail-dropped, by user
        self.waits = [array("d") for _ in range(users)]  # each admitted packet's wait in the queue (s), by user

    def admit(self, t: float, size: int, user: int = 0) -> float | None:
        """A packet of ``size`` bytes sent at time ``t`` (s): when its transmission ends (s), or None when it
        would wait longer than the queue allows (dropped). Without a rate: ``t`` (the bytes counted, no wait)."""
        if self.rate <= 0.0:
            self.bytes[user] += size
            return t
        start = self.free_at if self.free_at > t else t
        if start - t > self.queue_s:
            self.dropped[user] += 1
            return None
        self.free_at = end = start + size / self.rate
        self.bytes[user] += size
        self.waits[user].append(start - t)
        return end

    def occupancy(self, ids: list[int], until_s: float) -> dict[str, Any]:
        """``summary.json["radio"]["up" | "down"]``: the radio's rate, and each user's share of it over the span
        from 0 to ``until_s`` (s) or the end of the last transmission, whichever is later (so the shares
        together are never more than the rate): bytes, bytes/s, fraction of the rate, queue drops, and its
        packets' waits in the queue (ms: mean, p50, p95, max)."""
        span = max(until_s, self.free_at if math.isfinite(self.free_at) else 0.0)
        return occupancy_block(self.rate, self.queue_s, span, ids, self.bytes, self.dropped,
                               [waits_ms(w) for w in self.waits])


def occupancy_block(rate: float, queue_s: float, span: float, ids: Sequence[int], sent: Sequence[int],
                    dropped: Sequence[int], waits_ms: Sequence[Mapping[str, float | None]]) -> dict[str, Any]:
    """One direction's ``summary.json["radio"]`` block: the rate (bytes/s), the queue (ms), the span (s) and, per
    user (``ids`` in order), its bytes, its share of the rate over the span (bytes/s and fraction), its queue drops
    and its waits (ms); the same totals for the radio."""
    users = []
    for i, uid in enumerate(ids):
        bps = sent[i] / span if span > 0.0 else 0.0
        users.append({"id": uid, "bytes": sent[i], "share_bps": bps, "share": bps / rate if rate > 0.0 else None,
                      "lost_queue": dropped[i], "queue_wait_ms": dict(waits_ms[i])})
    total = sum(sent) / span if span > 0.0 else 0.0
    return {"rate_bps": rate or None, "queue_ms": queue_s * 1000.0 if rate > 0.0 else None,
            "span_s": span, "share_bps": total, "occupancy": total / rate if rate > 0.0 else None,
            "lost_queue": sum(dropped), "vehicles": users}


def make_radio_file(path: str | Path, users: int) -> None:
    """Create the file of a radio that ``users`` processes share (the module's docstring): never used yet."""
    Path(path).write_bytes(_HEADER.pack(_MAGIC, users) + _SLOT.pack(-math.inf) * len(DIRECTIONS)
                           + _TURNS.pack(NOT_YET, NOT_YET, NEVER, 0) * users)


class RadioFile:
    """A radio file mapped (:func:`make_radio_file`), as its user ``user``: each direction's free time and every
    user's turns, read and written under an exclusive ``flock`` (:meth:`locked`). A bad file, or a user it does
    not have, is a ConfigError naming ``flag`` and the file."""

    def __init__(self, path: str | Path, user: int, flag: str = "--radio") -> None:
        try:
            fd = os.open(path, os.O_RDWR)
        except OSError as exc:
            raise ConfigError.at(f"{flag} {path}", None, f"cannot open ({exc.strerror or exc})") from None
        try:
            size = os.fstat(fd).st_size
            head = os.pread(fd, _HEADER.size, 0)
            magic, users = _HEADER.unpack(head) if len(head) == _HEADER.size else (b"", 0)
            if magic != _MAGIC or size != radio_file_bytes(users):
                raise ConfigError.at(f"{flag} {path}", None, "not a radio file (its magic or size is wrong)")
            if not 0 <= user < users:
                raise ConfigError.at(f"{flag} {path}", None, f"no user {user} in it (users 0-{users - 1})")
            self.map = mmap.mmap(fd, size)
        except BaseException:
            os.close(fd)
            raise
        self.fd = fd
        self.users = users
        self.user = user

    def lock(self) -> None:
        fcntl.flock(self.fd, fcntl.LOCK_EX)

    def unlock(self) -> None:
        fcntl.flock(self.fd, fcntl.LOCK_UN)

    def free_at(self, direction: int) -> float:
        """When the direction's radio is free again (s; hold the lock)."""
        return _SLOT.unpack_from(self.map, _HEADER.size + _SLOT.size * direction)[0]

    def set_free_at(self, direction: int, t: float) -> None:
        _SLOT.pack_into(self.map, _HEADER.size + _SLOT.size * direction, t)

    def turns(self) -> list[tuple[int, ...]]:
        """Every user's (last turn up, last turn down, left from step, controller's wake port) (hold the lock)."""
        at = _HEADER.size + _SLOT.size * len(DIRECTIONS)
        return [_TURNS.unpack_from(self.map, at + _TURNS.size * i) for i in range(self.users)]

    def set_turn(self, column: int, value: int) -> None:
        """This user's last turn of a direction (column 0 up, 1 down), (2) the step it left from, (3) its
        controller's wake port."""
        at = _HEADER.size + _SLOT.size * len(DIRECTIONS) + _TURNS.size * self.user + 8 * column
        struct.pack_into("<q", self.map, at, value)

    def close(self) -> None:
        if self.fd >= 0:
            self.map.close()
            os.close(self.fd)
            self.fd = -1


class ProcessRadio(Radio):
    """One direction of a radio shared by processes on this machine, on the wall clock (the module's
    docstring), as its user ``user``: times given to :meth:`admit` are s since ``offset`` (s on the monotonic
    clock), the queue's state is the file's. A bad file, or a user it does not have, is a ConfigError naming it."""

    __slots__ = ("offset", "user", "first_s", "last_end_s", "_file", "_dir")

    def __init__(self, path: str | Path, direction: str, rate_bps: float, queue_s: float, user: int,
                 offset: float = 0.0) -> None:
        self._file = RadioFile(path, user)
        super().__init__(rate_bps, queue_s, self._file.users)
        self._dir = DIRECTIONS.index(direction)
        self.offset = offset
        self.user = user
        self.first_s: float | None = None  # the first packet's send time (s, monotonic clock)
        self.last_end_s: float | None = None  # the end of this user's last transmission (s, monotonic clock)

    def admit(self, t: float, size: int, user: int = 0) -> float | None:
        """As :meth:`Radio.admit`, behind every other process's packets: the file's state read and moved under an
        exclusive lock. The send times of several processes come in the order they take the lock (first come,
        first served), each a few microseconds apart at most from when it arrived."""
        if self.first_s is None:
            self.first_s = t + self.offset
        if self.rate <= 0.0:
            end: float | None = super().admit(t, size, user)
        else:
            f = self._file
            f.lock()
            try:
                self.free_at = f.free_at(self._dir) - self.offset
                end = super().admit(t, size, user)
                f.set_free_at(self._dir, self.free_at + self.offset)
            finally:
                f.unlock()
        if end is not None:
            self.last_end_s = end + self.offset
        return end

    def part(self) -> dict[str, Any]:
        """A copy of this user's share of the radio (cheap: no percentiles, for a serving loop): bytes, queue
        drops, each packet's wait (s, ``waits``), and when it first sent and last finished sending (s, monotonic
        clock; None: nothing yet). :func:`finished_part` makes it ``summary.json``'s."""
        u = self.user
        return {"user": u, "bytes": self.bytes[u], "lost_queue": self.dropped[u], "waits": array("d", self.waits[u]),
                "first_s": self.first_s, "last_end_s": self.last_end_s}

    def close(self) -> None:
        self._file.close()


def finished_part(part: Mapping[str, Any]) -> dict[str, Any]:
    """A :meth:`ProcessRadio.part` as JSON: its waits as ms (mean, p50, p95, max: ``queue_wait_ms``)."""
    out = {k: v for k, v in part.items() if k != "waits"}
    out["queue_wait_ms"] = waits_ms(part["waits"])
    return out


def occupancy_of_parts(parts: Sequence[Mapping[str, Any] | None], ids: Sequence[int], rate: float,
                       queue_s: float, until_s: float | None = None) -> dict[str, Any]:
    """One direction of a radio shared by processes, from each user's :func:`finished_part` (in the order of
    ``ids``; None: a user that left none, counted as nothing sent): :func:`occupancy_block` over the span from
    the first packet any user sent to the end of the last transmission, or to ``until_s`` if later (lockstep:
    the steps flown, as :meth:`Radio.occupancy`). Every transmission lies within it and none overlaps another,
    so the shares together are never more than the rate."""
    got = [p for p in parts if p is not None]
    firsts = [p["first_s"] for p in got if p["first_s"] is not None]
    ends = [p["last_end_s"] for p in got if p["last_end_s"] is not None]
    span = max(ends) - min(firsts) if firsts and ends else 0.0
    if until_s is not None:
        span = max(span, until_s - min(firsts, default=0.0))
    none = {"mean": None, "p50": None, "p95": None, "max": None}
    return occupancy_block(rate, queue_s, max(span, 0.0), ids, [p["bytes"] if p else 0 for p in parts],
                           [p["lost_queue"] if p else 0 for p in parts],
                           [p["queue_wait_ms"] if p else none for p in parts])


def waits_ms(waits: array) -> dict[str, float | None]:
    """Mean, p50, p95 and max of a user's queue waits, in ms (None without packets)."""
    if not waits:
        return {"mean": None, "p50": None, "p95": None, "max": None}
    import numpy as np  # lazy: the relay loads no numpy while it relays

    w = np.frombuffer(waits, dtype=float) * 1000.0
    p50, p95 = np.percentile(w, (50.0, 95.0))
    return {"mean": float(w.mean()), "p50": float(p50), "p95": float(p95), "max": float(w.max())}

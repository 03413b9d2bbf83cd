"""A radio's bandwidth budget and queue: the link model's bandwidth cap, for one link or several behind one radio.

In:  the cap ``rate_bps`` (bytes/s; 0: none) and the longest wait ``queue_s`` (s) of one direction, the number
     of links (users) behind it; then packets: send time (s, non-decreasing across all users), size (bytes),
     the user (0..users-1)
Out: each packet's end of transmission (s) or None (tail-dropped); per user the bytes put on the air, the
     packets dropped and each packet's wait in the queue (s); :meth:`Radio.occupancy` for ``summary.json``

The model (docs/design.md, "Link model", step 3; docs/swarm.md, "One radio"): packets queue at the sender
in the order they are sent, first in first out, each occupying the radio for size / rate; a packet that would
wait longer than ``queue_s`` is dropped (tail drop). A link of its own has a radio of its own
(:class:`~bridge.link.impairment.LinkImpairment` makes one); a fleet on one radio hands every vehicle's link of
a direction the same :class:`Radio`, each vehicle a user, so their packets wait behind each other's. As the
transmissions never overlap and none starts before time 0, the bytes put on the air over a span reaching the
end of the last transmission, divided by that span, are together at most the rate.
"""

from __future__ import annotations

import math
from array import array
from typing import Any


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
        users = []
        for i, uid in enumerate(ids):
            bps = self.bytes[i] / span if span > 0.0 else 0.0
            users.append({"id": uid, "bytes": self.bytes[i], "share_bps": bps,
                          "share": bps / self.rate if self.rate > 0.0 else None,
                          "lost_queue": self.dropped[i], "queue_wait_ms": _waits_ms(self.waits[i])})
        total = sum(self.bytes) / span if span > 0.0 else 0.0
        return {"rate_bps": self.rate or None, "queue_ms": self.queue_s * 1000.0 if self.rate > 0.0 else None,
                "span_s": span, "share_bps": total, "occupancy": total / self.rate if self.rate > 0.0 else None,
                "lost_queue": sum(self.dropped), "vehicles": users}


def _waits_ms(waits: array) -> dict[str, float | None]:
    """Mean, p50, p95 and max of a user's queue waits, in ms (None without packets)."""
    if not waits:
        return {"mean": None, "p50": None, "p95": None, "max": None}
    import numpy as np  # lazy: the relay loads no numpy while it relays

    w = np.frombuffer(waits, dtype=float) * 1000.0
    p50, p95 = np.percentile(w, (50.0, 95.0))
    return {"mean": float(w.mean()), "p50": float(p50), "p95": float(p95), "max": float(w.max())}

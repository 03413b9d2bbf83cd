"""The one receive path of both MAVLink endpoints: what is refused, and how it is counted.

In:  each datagram's sender and arrival time (s, for the rate limits in datagrams/s), and the fields
     of decoded messages: actuator targets (normalised, [-1, 1] / [0, 1]), ODOMETRY (position m,
     quaternion), target ids
Out: accept, or a refusal reason of :data:`REASONS` counted in :class:`Rejections` (``summary.json``
     ``link.rejected``), and a STATUSTEXT line on them (at most 50 characters) at most once a second

Every datagram the vehicle or the controller receives takes the same path before anything
of it reaches the plant or the law:

1. **Read** (:meth:`bridge.mavlink.endpoint.Endpoint.poll`): at most ``batch`` datagrams per call,
   so a flood never holds a loop past its deadline. A datagram from the link's own peer
   (the configured controller, once it has spoken; the vehicle, for the controller) is
   always taken; one from anyone else is first charged to its source's token bucket and to
   the bucket of all others together (:class:`RateLimiter`), and dropped unparsed when
   either is empty: excess from others is shed first, the peer never.
2. **Frame** (:func:`bridge.mavlink.endpoint.parse_datagram`): MAVLink 2 frames only, whole, known
   message id, good CRC, payload no longer than the message, and, with a key
   (:mod:`bridge.mavlink.signing`), correctly signed and newer than the last frame of its stream.
   Only frames that pass are decoded (the per-step messages, ODOMETRY and the two actuator
   targets, by the hot codec; the rest by pymavlink) and written to the tlog. The first bad frame ends its datagram.
3. **Message** (the owner's handler, with the validators below): the right sender and
   target, finite values in range, the right state (armed, the step awaited).

A refused datagram or message raises nothing, blocks nothing, changes no state: it is
counted in a :class:`Rejections` by its reason (:data:`REASONS`), which ends up in
``summary.json`` as ``link.rejected.<reason>``, and the vehicle says what it refused in a
STATUSTEXT once per second while refusals go on (:meth:`Rejections.report`).
"""

from __future__ import annotations

import math
import time
from typing import Any

MAX_DATAGRAM = 2048  # bytes: a MAVLink 2 frame is at most 280; a few may share a datagram
BATCH = 64  # datagrams read per poll at most
SOURCE_RATE_HZ = 1000.0  # datagrams/s one source other than the peer may send (and burst)
OTHERS_RATE_HZ = 50000.0  # datagrams/s all sources other than the peer together may send (and burst)
MAX_POSITION_M = 10_000.0
QUATERNION_TOL = 1e-3  # | |q|^2 - 1 | allowed: a float32 unit quaternion is within ~1e-7
REPORT_S = 1.0  # s of wall time between two STATUSTEXT reports of refusals
STATUSTEXT_CHARS = 50
REASONS: dict[str, str] = {
    # read
    "rate_limited": "from a source other than the peer, over its own or all others' rate: dropped unparsed",
    "sender": "from an address other than the peer of a sending link, or a target or state from another "
              "system or component than the configured one",
    # frame
    "truncated": "empty datagram, or one that ends inside a frame",
    "oversized": f"datagram over {MAX_DATAGRAM} bytes, or a payload longer than its message",
    "no_frame": "bytes that do not start a MAVLink frame",
    "mavlink1": "a MAVLink 1 frame (the links speak MAVLink 2 only)",
    "bad_flags": "unknown incompatibility flags",
    "unknown_id": "a message id not in the common dialect",
    "bad_crc": "checksum wrong",
    "malformed": "a frame pymavlink cannot decode",
    "unsigned": "with a key: no signature",
    "bad_signature": "with a key: not signed with our key (forged or corrupted)",
    "replayed": "with a key: timestamp not newer than the last of its stream",
    # message
    "target": "addressed to another system or component",
    "message": "actuator message of the other actuation mode",
    "group": "SET_ACTUATOR_CONTROL_TARGET of a control group other than 0",
    "not_finite": "NaN or infinite value",
    "out_of_range": "motors outside [0, 1], roll/pitch/yaw outside [-1, 1], thrust outside [0, 1], "
                    "|position| > 10 km or a quaternion not of unit norm",
    "not_offboard": "actuator target while disarmed or not under offboard control",
    "stale": "time_usec older than the step awaited (lockstep), or than the newest state (controller)",
    "future": "lockstep: target for a step not reached yet",
    "reordered": "realtime: target older than the one in force",
}


class Rejections(dict[str, int]):
    """Refusals by reason (a plain dict of counts, so it serialises as one), plus how many
    came from the link's own peer (``from_peer``: the controller's, at the vehicle) and the
    state of the once-per-second report."""

    def __init__(self) -> None:
        super().__init__()
        self.from_peer = 0
        self.total = 0  # all refusals (kept as counts are set: read on every message, so O(1))
        self._reported: dict[str, int] = {}
        self._next_report = 0.0

    def __setitem__(self, reason: str, count: int) -> None:
        self.total += count - self.get(reason, 0)
        super().__setitem__(reason, count)

    def add(self, reason: str, from_peer: bool = False) -> None:
        self[reason] = self.get(reason, 0) + 1
        if from_peer:
            self.from_peer += 1

    def report(self, now: float | None = None) -> str | None:
        """A line on the refusals since the last report (most frequent first, at most
        :data:`STATUSTEXT_CHARS` characters), at most once per :data:`REPORT_S` of wall
        time; None when there is nothing new or it is too soon."""
        now = time.monotonic() if now is None else now
        if now < self._next_report or self.total == sum(self._reported.values()):
            return None
        new = {r: c - self._reported.get(r, 0) for r, c in self.items() if c > self._reported.get(r, 0)}
        self._reported = dict(self)
        self._next_report = now + REPORT_S
        text = f"rejected {sum(new.values())}: " + ", ".join(
            f"{r} {c}" for r, c in sorted(new.items(), key=lambda rc: -rc[1]))
        return text if len(text) <= STATUSTEXT_CHARS else text[:STATUSTEXT_CHARS - 3] + "..."


class RateLimiter:
    """Token buckets (datagrams/s, full bucket = one second's worth): one per source address
    and one for all sources together. The peer of a link is never charged (see the module
    docstring). At most ``max_sources`` buckets are kept; beyond that the full ones (idle
    sources) are forgotten, and if none is, all are."""

    def __init__(self, source_hz: float = SOURCE_RATE_HZ, others_hz: float = OTHERS_RATE_HZ,
                 max_sources: int = 4096) -> None:
        self.source_hz = source_hz
        self.others_hz = others_hz
        self.max_sources = max_sources
        self._src: dict[Any, list[float]] = {}  # address -> [tokens, time of last refill]
        self._all = [others_hz, time.monotonic()]

    def allow(self, addr: Any, now: float) -> bool:
        """Charge one datagram from ``addr`` at wall time ``now`` (s); False: drop it."""
        b = self._src.get(addr)
        if b is None:
            if len(self._src) >= self.max_sources:
                self._forget(now)
            b = self._src[addr] = [self.source_hz, now]
        else:
            b[0] = min(self.source_hz, b[0] + (now - b[1]) * self.source_hz)
            b[1] = now
        a = self._all
        a[0] = min(self.others_hz, a[0] + (now - a[1]) * self.others_hz)
        a[1] = now
        if b[0] < 1.0 or a[0] < 1.0:
            return False
        b[0] -= 1.0
        a[0] -= 1.0
        return True

    def _forget(self, now: float) -> None:
        hz = self.source_hz
        idle = [k for k, (tokens, t) in self._src.items() if tokens + (now - t) * hz >= hz]
        for k in idle or list(self._src):
            del self._src[k]


# -- message stage: stateless checks of what a message carries ---------------------------------
def wire_problem(actuation: str, wire: tuple[float, ...]) -> str | None:
    """The reason an actuator target's four values are refused, or None: finite, and in
    [0, 1] for ``motors`` (c1..c4), [-1, 1] for roll, pitch, yaw and [0, 1] for thrust
    (SET_ACTUATOR_CONTROL_TARGET group 0, ``wrench``; docs/design.md, "Frames and units")."""
    a, b, c, d = wire
    if actuation == "wrench":
        if -1.0 <= a <= 1.0 and -1.0 <= b <= 1.0 and -1.0 <= c <= 1.0 and 0.0 <= d <= 1.0:
            return None
    elif 0.0 <= a <= 1.0 and 0.0 <= b <= 1.0 and 0.0 <= c <= 1.0 and 0.0 <= d <= 1.0:
        return None
    return "out_of_range" if all(map(math.isfinite, wire)) else "not_finite"


def odometry_problem(m: Any) -> str | None:
    """The reason an ODOMETRY is refused, or None: every value the law uses finite, the
    position within :data:`MAX_POSITION_M` of the origin, the quaternion of unit norm."""
    q = m.q
    vals = (m.x, m.y, m.z, q[0], q[1], q[2], q[3], m.vx, m.vy, m.vz, m.rollspeed, m.pitchspeed, m.yawspeed)
    try:  # the sum is finite when every value is (one call for all); if not, look value by value
        if not math.isfinite(sum(vals)) and not all(map(math.isfinite, vals)):
            return "not_finite"
    except TypeError:  # not numbers at all
        return "malformed"
    if m.x * m.x + m.y * m.y + m.z * m.z > MAX_POSITION_M * MAX_POSITION_M:
        return "out_of_range"
    if abs(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3] - 1.0) > QUATERNION_TOL:
        return "out_of_range"
    return None


def addressed_elsewhere(m: Any, sysid: int, compid: int) -> bool:
    """Whether a message with target fields is for another system or component (0 = all)."""
    return m.target_system not in (0, sysid) or getattr(m, "target_component", 0) not in (0, compid)

"""The one receive path of both MAVLink endpoints: what is refused, and how it is counted.

In:  each datagram's sender, size (bytes) and arrival time (s, for the budgets in datagrams/s, frames/s
     and bytes/s), and the fields of decoded messages: actuator targets (normalised, [-1, 1] / [0, 1]),
     ODOMETRY (position m, quaternion), command parameters (message ids, intervals in us), target ids
Out: accept, or a refusal reason of :data:`REASONS` counted in :class:`Rejections` (``summary.json``
     ``link.rejected``), and a STATUSTEXT line on them (at most 50 characters) at most once a second;
     whether a reply to a source is within its budget (:class:`ReplyBudget`), and to the sources on trial
     together within the bytes they sent (:class:`ReplyCredit`)

Every datagram the vehicle or the controller receives takes the same path before anything
of it reaches the plant or the law:

1. **Read** (:meth:`bridge.mavlink.endpoint.Endpoint.poll`): at most ``batch`` datagrams per call,
   so a flood never holds a loop past its deadline. A datagram from the link's own peer
   (the vehicle's flight's controller, once it has spoken; the vehicle, for the controller)
   is always taken; one from anyone else is first charged (one datagram, its bytes) to its
   source's budget and to the budget of all others together (:class:`RateLimiter`), and
   dropped unparsed when either is spent: excess from others is shed first, the peer never.
2. **Frame** (:func:`bridge.mavlink.frames.parse_datagram`): MAVLink 2 frames only, whole, known
   message id, good CRC, payload no longer than the message, and, with a key
   (:mod:`bridge.mavlink.signing`), correctly signed and newer than the last frame of its stream.
   Each frame of a datagram from anyone but the peer is charged to the same budgets in
   frames, so that packing many frames into a datagram buys nothing.
   Only frames that pass are decoded (the per-step messages, ODOMETRY and the two actuator
   targets, by the hot codec; the rest by pymavlink) and written to the tlog. The first bad frame ends its datagram.
3. **Message** (the owner's handler, with the validators below): the right sender (its
   authority on that link: docs/design.md, "Authority") and target, every number it uses
   finite, whole where a whole number is due, and in range, the right state (armed, the
   step awaited). What is sent back to a source is at most one datagram per frame it sent
   and within its reply budget (:class:`ReplyBudget`): a flood cannot be amplified.

A refused datagram or message raises nothing, blocks nothing, changes no state: it is
counted in a :class:`Rejections` by its reason (:data:`REASONS`), which ends up in
``summary.json`` as ``link.rejected.<reason>``, and the vehicle says what it refused in a
STATUSTEXT once per second while refusals go on (:meth:`Rejections.report`).
"""

from __future__ import annotations

import bisect
import math
import time
from collections import deque
from typing import Any

MAX_DATAGRAM = 2048  # bytes: a MAVLink 2 frame is at most 280; a few may share a datagram
BATCH = 64  # datagrams read per poll at most
SOURCE_RATE_HZ = 1000.0  # datagrams/s one source other than the peer may send (and burst); frames/s alike
OTHERS_RATE_HZ = 50000.0  # datagrams/s all sources other than the peer together may send (and burst); frames/s alike
MAX_FRAME = 280  # bytes: the longest MAVLink 2 frame (255-byte payload, signed)
SOURCE_BYTES_S = SOURCE_RATE_HZ * MAX_FRAME  # bytes/s of one source: its frame budget of the longest frames
OTHERS_BYTES_S = OTHERS_RATE_HZ * MAX_FRAME  # bytes/s of all others together
REPLY_RATE_HZ = 100.0  # reply datagrams/s to one source (and burst): COMMAND_ACK, TIMESYNC, requested messages
REPLY_BYTES_S = 16_384.0  # reply bytes/s to one source (and burst)
MESSAGE_ID_MAX = 2**24 - 1  # MAVLink 2 message ids have 24 bits
MAX_INTERVAL_US = 3.6e9  # SET_MESSAGE_INTERVAL: at most one an hour
FORCE_DISARM = 21196  # param2 of ARM_DISARM that disarms in the air (MAVLink's magic number)
MAX_POSITION_M = 10_000.0
QUATERNION_TOL = 1e-3  # | |q|^2 - 1 | allowed: a float32 unit quaternion is within ~1e-7
REPORT_S = 1.0  # s of wall time between two STATUSTEXT reports of refusals
STATUSTEXT_CHARS = 50
REASONS: dict[str, str] = {
    # read
    "rate_limited": "from a source other than the peer, over its own or all others' budget of datagrams, "
                    "frames or bytes per second: the datagram (or the rest of it) dropped unparsed",
    "sender": "from an address other than the peer of a sending link, or a target or state from another "
              "system or component than the configured one",
    "unheard": "the controller: a state before the vehicle's HEARTBEAT named its system (no --target-sysid): the "
               "controller flies no vehicle it has not heard",
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
    "not_authorised": "a command, request or other message on a link where its sender has no authority (the "
                      "controller link obeys only the configured controller's sysid and compid)",
    "stranger": "the configured controller's ids from an address other than the one its flight is on",
    "bad_number": "a command parameter NaN, infinite, not a whole number where one is due, or out of range",
    "reply_limited": "a request from a source whose reply budget is spent: not acted on, not answered",
    "message": "actuator message of the other actuation mode",
    "group": "SET_ACTUATOR_CONTROL_TARGET of a control group other than 0",
    "not_finite": "NaN or infinite value",
    "out_of_range": "motors outside [0, 1], roll/pitch/yaw outside [-1, 1], thrust outside [0, 1], "
                    "|position| > 10 km or a quaternion not of unit norm",
    "not_offboard": "actuator target while disarmed or not under offboard control",
    "stale": "time_usec older than the step awaited (lockstep; an answer to a state sent on the wall clock before "
             "lockstep engaged again is counted in timing.answered_wall_clock, not here), or than the newest state "
             "(controller)",
    "future": "lockstep: target for a step not reached yet",
    "repeated": "lockstep: a second answer to the step awaited, whose state was sent once (an answer to a "
                "resent state's copy is expected: counted in timing.answered_again, not here)",
    "reordered": "realtime: target older than the one in force",
    "param_refused": "PARAM_SET of a value out of its range, of the wrong type, or of a parameter that acts "
                     "at start only: answered with the unchanged value and a STATUSTEXT",
    "param_unknown": "PARAM_REQUEST_READ or PARAM_SET of a parameter the vehicle does not have",
}


# refusals counted but never said in the STATUSTEXT report: a ground station's port carries a fleet's traffic for
# every vehicle, so a message for another system is routine there (PX4 drops it without a word)
UNREPORTED = frozenset({"target"})


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
        time; None when there is nothing new or it is too soon. :data:`UNREPORTED` reasons are left out."""
        now = time.monotonic() if now is None else now
        if now < self._next_report or self.total == sum(self._reported.values()):
            return None
        new = {r: c - self._reported.get(r, 0) for r, c in self.items()
               if c > self._reported.get(r, 0) and r not in UNREPORTED}
        self._reported = dict(self)
        if not new:
            return None
        self._next_report = now + REPORT_S
        text = f"rejected {sum(new.values())}: " + ", ".join(
            f"{r} {c}" for r, c in sorted(new.items(), key=lambda rc: -rc[1]))
        return text if len(text) <= STATUSTEXT_CHARS else text[:STATUSTEXT_CHARS - 3] + "..."


def _refill(b: list[float], rates: tuple[float, float, float], now: float) -> None:
    """Refill a bucket ``[datagrams, frames, bytes, time]`` to ``now`` at ``rates`` (per s,
    each also the bucket's size: one second's worth)."""
    dt = now - b[3]
    if dt > 0.0:  # (conditionals, not min(): this runs for every datagram from others)
        d, f, n = rates
        v = b[0] + dt * d
        b[0] = v if v < d else d
        v = b[1] + dt * f
        b[1] = v if v < f else f
        v = b[2] + dt * n
        b[2] = v if v < n else n
        b[3] = now


class RateLimiter:
    """Token buckets of datagrams, frames and bytes per second (full bucket = one second's
    worth): one per source address and one for all sources together. :meth:`admit` charges a
    datagram and its bytes before it is parsed, :meth:`frame` each of its frames before it is
    decoded. The peer of a link is never charged (see the module docstring). At most
    ``max_sources`` buckets are kept; beyond that the full ones (idle sources) are forgotten,
    and if none is, all are."""

    def __init__(self, source_hz: float = SOURCE_RATE_HZ, others_hz: float = OTHERS_RATE_HZ,
                 max_sources: int = 4096, source_bytes_s: float = SOURCE_BYTES_S,
                 others_bytes_s: float = OTHERS_BYTES_S) -> None:
        self.source = (source_hz, source_hz, source_bytes_s)
        self.others = (others_hz, others_hz, others_bytes_s)
        self.max_sources = max_sources
        self._src: dict[Any, list[float]] = {}  # address -> [datagrams, frames, bytes, time of last refill]
        self._all = [*self.others, time.monotonic()]
        self._last: list[float] = self._all  # the bucket of the datagram admitted last (for frame())

    def admit(self, addr: Any, now: float, nbytes: int) -> bool:
        """Charge one datagram of ``nbytes`` from ``addr`` at wall time ``now`` (s); False: drop it."""
        b = self._src.get(addr)
        if b is None:
            if len(self._src) >= self.max_sources:
                self._forget(now)
            b = self._src[addr] = [*self.source, now]
        elif now > b[3]:
            _refill(b, self.source, now)
        a = self._all
        if now > a[3]:
            _refill(a, self.others, now)
        if b[0] < 1.0 or a[0] < 1.0 or b[2] < nbytes or a[2] < nbytes:
            return False
        b[0] -= 1.0
        a[0] -= 1.0
        b[2] -= nbytes
        a[2] -= nbytes
        self._last = b
        return True

    def frame(self) -> bool:
        """Charge one frame of the datagram admitted last (to its source and to all others);
        False: the budget is spent, the rest of the datagram is dropped."""
        b, a = self._last, self._all
        if b[1] < 1.0 or a[1] < 1.0:
            return False
        b[1] -= 1.0
        a[1] -= 1.0
        return True

    def _forget(self, now: float) -> None:
        full = self.source
        for b in self._src.values():
            _refill(b, full, now)
        idle = [k for k, b in self._src.items() if (b[0], b[1], b[2]) == full]
        for k in idle or list(self._src):
            del self._src[k]


class ReplyBudget:
    """What one endpoint may send back to each source: token buckets of reply datagrams and
    bytes per second (full bucket = one second's worth), per destination address. With at
    most one reply datagram per frame received, no source gets more back than it sent, and
    none more than :data:`REPLY_RATE_HZ` datagrams or :data:`REPLY_BYTES_S` bytes a second
    however much it sends. Kept for at most ``max_sources`` addresses, as :class:`RateLimiter`."""

    def __init__(self, rate_hz: float = REPLY_RATE_HZ, bytes_s: float = REPLY_BYTES_S,
                 max_sources: int = 4096) -> None:
        self.rates = (rate_hz, rate_hz, bytes_s)  # (the frames entry of the bucket is not used)
        self.max_sources = max_sources
        self._to: dict[Any, list[float]] = {}  # address -> [datagrams, -, bytes, time of last refill]

    def _bucket(self, addr: Any, now: float) -> list[float]:
        b = self._to.get(addr)
        if b is None:
            if len(self._to) >= self.max_sources:
                self._to.clear()
            b = self._to[addr] = [*self.rates, now]
        else:
            _refill(b, self.rates, now)
        return b

    def allows(self, addr: Any, now: float) -> bool:
        """Whether a reply to ``addr`` may go now: a datagram and the bytes of the longest reply
        (a COMMAND_ACK and one message, two frames) left."""
        b = self._bucket(addr, now)
        return b[0] >= 1.0 and b[2] >= 2 * MAX_FRAME

    def charge(self, addr: Any, now: float, nbytes: int) -> bool:
        """Take one reply datagram of ``nbytes`` to ``addr``; False (and nothing taken) when it
        does not fit."""
        b = self._bucket(addr, now)
        if b[0] < 1.0 or b[2] < nbytes:
            return False
        b[0] -= 1.0
        b[2] -= nbytes
        return True


class ReplyCredit:
    """What the sources on trial (a vehicle's would-be controllers, before a flight makes one its
    controller) may be sent back, all together: the bytes they sent (:meth:`earn`), kept up to ``cap``
    bytes, plus one frame's worth from the start (``start``: an answer may be a little longer than its
    request, as a PING's is). Bytes out never exceed bytes in plus ``start``, however many addresses
    share the work."""

    def __init__(self, cap: float = REPLY_BYTES_S, start: float = MAX_FRAME) -> None:
        self.cap = cap
        self.bytes = float(start)
        self.cut = 0  # replies that did not fit (not sent)

    def earn(self, nbytes: int) -> None:
        """A frame of ``nbytes`` from a source on trial: that much more may go back."""
        self.bytes = min(self.cap, self.bytes + nbytes)

    def charge(self, nbytes: int) -> bool:
        """Take a reply of ``nbytes``; False (and nothing taken) when it does not fit."""
        if nbytes > self.bytes:
            self.cut += 1
            return False
        self.bytes -= nbytes
        return True


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


def whole(value: float, lo: int, hi: int) -> int | None:
    """``value`` (a float parameter) as an int if it is a whole number in [lo, hi], else None
    (NaN, +-inf, a fraction or out of range: never a ValueError or OverflowError)."""
    if not (lo <= value <= hi) or value != int(value):  # NaN fails the first test, inf is out of range
        return None
    return int(value)


def arm_disarm_args(p1: float, p2: float) -> tuple[bool, bool] | None:
    """MAV_CMD_COMPONENT_ARM_DISARM's (arm, forced), or None when refused (``bad_number``):
    param1 exactly 0 (disarm) or 1 (arm); param2 exactly 21196 forces, anything else does
    not, NaN included (MAVLink's "unused" value: MAVSDK arms with param2 NaN)."""
    if p1 != 0.0 and p1 != 1.0:  # NaN is neither
        return None
    return p1 == 1.0, p2 == FORCE_DISARM


def message_id_arg(p1: float) -> int | None:
    """A message id given as a command's param1 (REQUEST_MESSAGE, GET/SET_MESSAGE_INTERVAL):
    a whole number in [0, 2^24 - 1], else None (``bad_number``)."""
    return whole(p1, 0, MESSAGE_ID_MAX)


def interval_arg(p2: float) -> float | None:
    """SET_MESSAGE_INTERVAL's param2 (us): -1 (off), 0 (the default), or in (0, 3.6e9]
    (at most one an hour); None for anything else (``bad_number``)."""
    if p2 == -1.0 or p2 == 0.0 or 0.0 < p2 <= MAX_INTERVAL_US:
        return p2
    return None


def addressed_elsewhere(m: Any, sysid: int, compid: int) -> bool:
    """Whether a message with target fields is for another system or component (0 = all)."""
    return m.target_system not in (0, sysid) or getattr(m, "target_component", 0) not in (0, compid)


class StepRanges:
    """The control steps a stream of per-step messages carried, as inclusive ``[first, last]`` ranges of
    consecutive steps (a JSON list of pairs, one pair on a link that skipped none; at most :data:`MAX_RANGES`,
    later steps then extend the last range): what a sender's statistics say it sent, so that a reader can
    tell which of them reached the receiver's window (``link.*.in_flight`` of a session's summary)."""

    MAX_RANGES = 4096

    def __init__(self) -> None:
        self.ranges: list[list[int]] = []

    def add(self, k: int) -> None:
        r = self.ranges
        if r and r[-1][0] <= k <= r[-1][1] + 1:
            r[-1][1] = max(r[-1][1], k)
        elif len(r) < self.MAX_RANGES and (not r or k > r[-1][1]):
            r.append([k, k])
        else:  # out of order, or out of room: the last range covers it
            r[-1][0], r[-1][1] = min(r[-1][0], k), max(r[-1][1], k)

    def holds(self, k: int) -> bool:
        """Whether step ``k`` lies in a range (was sent, or lies in one a later step was folded into)."""
        r = self.ranges
        i = bisect.bisect_right(r, k, key=lambda pair: pair[0]) - 1
        return i >= 0 and r[i][0] <= k <= r[i][1]


class StepSends:
    """Every send of a per-step message, counted per send: the steps (:class:`StepRanges`, each once), how many
    times each step sent again went again (``again``: {step: sends after its first}, at most :data:`MAX_AGAIN`
    steps; more in ``again_unlisted``), and when the latest :data:`MAX_TIMED` of those resends left (step, and
    ``time.monotonic`` just before and just after the send: on one host the receiver's clock too). A step's first
    send goes before any later step's, so only a resend can leave after the receiver stopped reading steps it had
    read: the summary tells those apart from a loss (:func:`bridge.record.linkblock.sends_outside`). Bounded: a long
    flight keeps its ranges, its resent steps and the last resends' times, not one entry a send."""

    MAX_AGAIN = 4096
    MAX_TIMED = 128

    def __init__(self) -> None:
        self.steps = StepRanges()
        self.again: dict[int, int] = {}
        self.again_unlisted = 0
        self.timed: deque[tuple[int, float, float]] = deque(maxlen=self.MAX_TIMED)
        self._newest = -1

    def add(self, k: int, before: float, after: float) -> None:
        """One send of step ``k`` that left between ``before`` and ``after`` (s, ``time.monotonic``)."""
        if not (k == self._newest or (k < self._newest and self.steps.holds(k))):  # its first send
            self.steps.add(k)
            self._newest = max(self._newest, k)
            return
        self.timed.append((k, before, after))
        if k in self.again or len(self.again) < self.MAX_AGAIN:
            self.again[k] = self.again.get(k, 0) + 1
        else:
            self.again_unlisted += 1

    @property
    def resends(self) -> int:
        """Sends of a step after its first."""
        return sum(self.again.values()) + self.again_unlisted

    def stats(self) -> dict[str, Any]:
        """The sender's ``stats`` keys: ``odometry_steps`` (ranges), ``odometry_again`` ([step, sends again]
        pairs), ``odometry_again_unlisted``, ``odometry_resent`` ([step, before, after] of the latest resends)."""
        return {"odometry_steps": self.steps.ranges, "odometry_again": [[k, n] for k, n in self.again.items()],
                "odometry_again_unlisted": self.again_unlisted,
                "odometry_resent": [[k, a, b] for k, a, b in self.timed]}

"""The receive side of MAVLink's events protocol: which of a sender's EVENTs came, which were missed, what to
ask for again (REQUEST_EVENT), as a ground station follows a PX4 vehicle's events (libevents'
``libs/cpp/protocol/receive.h``, ``ReceiveProtocol``, which QGroundControl runs per vehicle component).

In:  a received EVENT's ``sequence``, CURRENT_EVENT_SEQUENCE's ``sequence`` and ``flags`` (RESET), a
     RESPONSE_EVENT_ERROR's ``sequence`` and ``sequence_oldest_available`` (all uint16, wrapping), the wall time
     ``now`` (s, ``time.monotonic``) at each
Out: whether an EVENT is new (handle it) or a duplicate (drop it); the REQUEST_EVENT ranges due now
     (first, last, inclusive, wrapping); whether events are still awaited; counts (:class:`SequenceCounts`)

As libevents: the next expected sequence is tracked; the first EVENT or CURRENT_EVENT_SEQUENCE heard sets it
(events sent before are not asked for); a sequence ahead of it (an EVENT's, or CURRENT_EVENT_SEQUENCE newer than
the last received) shows a gap, asked for at once; an unanswered request is sent again after
:data:`REQUEST_TIMEOUT_S` (libevents' 100 ms timer); a RESPONSE_EVENT_ERROR gives up what the sender no longer
keeps; the RESET flag starts over. Unlike libevents, an EVENT after a gap is handled at once (not dropped to be
asked for again in order: a decision must not wait), each missed sequence is handled once when it comes, and a
gap is asked for :data:`REQUEST_TRIES` times at most (libevents asks until answered), then counted lost.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

from bridge.mavlink.events import RING, SEQUENCE_RESET

REQUEST_TIMEOUT_S = 0.1  # s of wall time before an unanswered REQUEST_EVENT is sent again (libevents: 100 ms)
REQUEST_TRIES = 5  # REQUEST_EVENTs per missed sequence at most; then it is counted lost
MAX_MISSING = RING  # missed sequences awaited at most (the newest): the sender keeps no more to send again
_HALF = 0x8000


def ahead(seq: int, ref: int) -> int:
    """How far uint16 ``seq`` is ahead of ``ref`` (wrapping): 0 equal, > 0 newer, < 0 older."""
    d = (seq - ref) & 0xFFFF
    return d - 0x10000 if d >= _HALF else d


@dataclass
class SequenceCounts:
    """What following one sender's sequence took: REQUEST_EVENTs sent, missed events that came when asked for
    (``recovered``), missed events given up (``lost``: the sender had them no more, or no answer came), EVENTs
    received again and dropped (``duplicates``)."""

    requests: int = 0
    recovered: int = 0
    lost: int = 0
    duplicates: int = 0

    def as_dict(self) -> dict[str, Any]:
        """Its JSON form (the controller's ``stats["events"]``)."""
        return asdict(self)


@dataclass
class _Missing:
    tries: int = 0  # REQUEST_EVENTs sent for it
    due: float = 0.0  # wall time (s) its next request is due


class EventSequence:
    """One sender's (a vehicle component's) events, followed by sequence: :meth:`event`, :meth:`current` and
    :meth:`error` take what came, :meth:`requests` says what to ask for now."""

    def __init__(self, timeout_s: float = REQUEST_TIMEOUT_S, tries: int = REQUEST_TRIES) -> None:
        self.timeout_s = timeout_s
        self.tries = tries
        self.next: int | None = None  # the next sequence expected (None: nothing heard yet)
        self.missing: dict[int, _Missing] = {}  # missed sequences awaited, oldest first
        self.counts = SequenceCounts()

    def event(self, seq: int, now: float) -> bool:
        """An EVENT of sequence ``seq`` came at ``now``: True if it is new (handle it), False if it was handled
        before (a duplicate: the link's, or a request's second answer)."""
        seq &= 0xFFFF
        if self.next is None:
            self.next = seq
        d = ahead(seq, self.next)
        if d < 0:
            if self.missing.pop(seq, None) is None:
                self.counts.duplicates += 1
                return False
            self.counts.recovered += 1
            return True
        self._skip_to(seq, now)
        self.next = (seq + 1) & 0xFFFF
        return True

    def current(self, seq: int, flags: int, now: float) -> None:
        """CURRENT_EVENT_SEQUENCE at ``now``: the sender's newest sequence ``seq``; RESET in ``flags`` starts
        over (nothing sent yet, or the sender restarted): what was awaited is forgotten."""
        seq &= 0xFFFF
        if flags & SEQUENCE_RESET:
            self.next = None
            self.missing.clear()
        if self.next is None:
            self.next = (seq + 1) & 0xFFFF
        elif ahead(seq, self.next) >= 0:
            self._skip_to((seq + 1) & 0xFFFF, now)
            self.next = (seq + 1) & 0xFFFF

    def error(self, seq: int, oldest: int) -> None:
        """RESPONSE_EVENT_ERROR (to us): the sender no longer keeps ``seq``, its oldest kept after it is
        ``oldest``: every awaited sequence from ``seq`` up to before ``oldest`` is given up (libevents:
        ``handleEventError``). One not awaited (already come, or given up) changes nothing."""
        seq &= 0xFFFF
        if seq not in self.missing:
            return
        span = ahead(oldest & 0xFFFF, seq)
        if span <= 0:  # it keeps nothing after it: this one alone
            span = 1
        for s in [s for s in self.missing if 0 <= ahead(s, seq) < span]:
            del self.missing[s]
            self.counts.lost += 1

    def requests(self, now: float) -> list[tuple[int, int]]:
        """The REQUEST_EVENT ranges (first, last; inclusive, wrapping) due at ``now``: each awaited sequence
        whose last request is :attr:`timeout_s` old (or that was never asked for), neighbours joined; one asked
        for :attr:`tries` times already is given up instead."""
        due: list[int] = []
        for s, m in list(self.missing.items()):
            if m.due > now:
                continue
            if m.tries >= self.tries:
                del self.missing[s]
                self.counts.lost += 1
                continue
            m.tries += 1
            m.due = now + self.timeout_s
            due.append(s)
        ranges: list[tuple[int, int]] = []
        for s in due:
            if ranges and (ranges[-1][1] + 1) & 0xFFFF == s:
                ranges[-1] = (ranges[-1][0], s)
            else:
                ranges.append((s, s))
        self.counts.requests += len(ranges)
        return ranges

    def pending(self) -> bool:
        """Whether missed events are still awaited (asked for, not come, not given up)."""
        return bool(self.missing)

    def next_due(self) -> float:
        """The wall time (s) the next request or give-up is due (inf: none awaited)."""
        return min((m.due for m in self.missing.values()), default=float("inf"))

    def _skip_to(self, seq: int, now: float) -> None:
        """Await every sequence from the expected one up to before ``seq`` (the newest :data:`MAX_MISSING`
        awaited in all; older ones are counted lost: the sender keeps no more)."""
        first = seq if self.next is None else self.next
        gap = ahead(seq, first)
        for i in range(max(0, gap - MAX_MISSING), gap):
            self.missing[(first + i) & 0xFFFF] = _Missing(due=now)
        self.counts.lost += max(0, gap - MAX_MISSING)
        while len(self.missing) > MAX_MISSING:
            del self.missing[next(iter(self.missing))]
            self.counts.lost += 1

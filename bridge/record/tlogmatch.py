"""The frames of tlogs and the per-packet one-way delays of one link's sources, matched between its two ends
(what :mod:`bridge.record.linkextract` builds a link's trace from; docs/links.md).

In:  tlog bytes or files (8-byte big-endian Unix time in us + one MAVLink 1 or 2 frame, repeated: what
     MAVProxy and our nodes write); the frames of the two ends' tlogs
Out: :class:`Frame` per frame (stamp s); :func:`sender_ends`, which end sent each source; :func:`direction_records`, one
     source's :class:`DirectionRecords` (send time s, one-way delay s or None for lost);
     :func:`timesync_offset`, the two ends' clock offset (s) from TIMESYNC exchanges

How: each end's tlog holds the frames it sent and those it received. A source (system,
component) belongs to the end that logged more of its frames (the sender logs every one; the
receiver only what arrived; ties: the end that logged it first). A received frame is the sent frame
with the same bytes (nearest in time), so its delay is the difference of the two stamps; duplicates
count once. Losses come from the sequence numbers: between two delivered frames of a source, the
frames the sender logged that continue its sequence (seq + 1, + 2, ...) are lost; where that chain
does not close (frames of the same source on another link), the gap in sequence numbers is counted
instead, at times spaced evenly between the two. Only frames between a source's first and last
delivered one count: what was sent before the receiver listened or after it stopped is no loss.
"""

from __future__ import annotations

import bisect
import itertools
import math
import struct
from collections import defaultdict
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from params import ConfigError, read_regular_file

MAX_TLOG_BYTES = 4 << 30
TIMESYNC = 111
STAMP_SLACK_S = 0.002  # a frame may look received up to this much before it was sent (stamp resolution)

Source = tuple[int, int]


@dataclass(frozen=True, slots=True)
class Frame:
    """One frame of a tlog: its stamp (s, the logger's clock), source, message id, sequence, bytes."""

    t: float
    src: Source
    msgid: int
    seq: int
    raw: bytes
    payload: bytes


@dataclass
class DirectionRecords:
    """One direction: (send time s, delay s or None) per packet, and what was counted."""

    records: list[tuple[float, float | None]] = field(default_factory=list)
    duplicates: int = 0
    unmatched: int = 0  # received frames the sender never logged, while it logged
    outside: int = 0  # received frames stamped before the sender's log of their source starts or after it ends
    gaps_counted: int = 0  # losses from a sequence gap, their send time spread evenly
    reordered: int | None = None  # received after one sent later (first copies; None: not counted, as by gaps)

    @property
    def sent(self) -> int:
        return len(self.records)

    @property
    def lost(self) -> int:
        return sum(1 for _, d in self.records if d is None)

    def figures(self) -> dict[str, Any]:
        """sent, delivered, lost, loss %, delay percentiles (ms), duplicates: what ``bsst link extract`` prints."""
        import numpy as np  # lazy: only to report

        d = np.array([x for _, x in self.records if x is not None]) * 1000.0
        pct = dict(zip(("p50", "p95", "p99"), map(float, np.percentile(d, (50, 95, 99))), strict=True)) | {
            "max": float(d.max())} if len(d) else {"p50": None, "p95": None, "p99": None, "max": None}
        return {"sent": self.sent, "delivered": self.sent - self.lost, "lost": self.lost,
                "loss_pct": 100.0 * self.lost / self.sent if self.sent else None, "delay_ms": pct,
                "duplicates": self.duplicates, "unmatched": self.unmatched, "outside": self.outside,
                "gaps_counted": self.gaps_counted}


# -- reading tlogs -----------------------------------------------------------------------------------
def read_tlog(path: str | Path) -> list[Frame]:
    """Every frame of a tlog (``ConfigError`` naming the file and the byte where it stops being one)."""
    return parse_tlog(read_regular_file(path, "a tlog", MAX_TLOG_BYTES), str(path))


def parse_tlog(data: bytes, name: str) -> list[Frame]:
    """The frames of a tlog's bytes; a truncated last frame (a writer killed mid-write) is left out."""
    frames: list[Frame] = []
    i, n = 0, len(data)
    while n - i > 8:
        stamp = int.from_bytes(data[i:i + 8], "big")
        j = i + 8
        magic = data[j]
        if magic == 0xFD and n - j >= 10:
            ln, incompat, seq, sysid, comp = data[j + 1], data[j + 2], data[j + 4], data[j + 5], data[j + 6]
            msgid = data[j + 7] | data[j + 8] << 8 | data[j + 9] << 16
            head, size = 10, 12 + data[j + 1] + (13 if incompat & 1 else 0)
        elif magic == 0xFE and n - j >= 6:
            ln, seq, sysid, comp, msgid = data[j + 1], data[j + 2], data[j + 3], data[j + 4], data[j + 5]
            head, size = 6, 8 + ln
        elif magic in (0xFD, 0xFE):
            break  # a header cut short at the end
        else:
            raise ConfigError(f"{name}: byte {j}: 0x{magic:02x} is not the start of a MAVLink frame (after the "
                              f"time stamp at byte {i}): not a tlog of 8-byte stamps and frames")
        if j + size > n:
            break
        frames.append(Frame(stamp / 1e6, (sysid, comp), msgid, seq, data[j:j + size], data[j + head:j + head + ln]))
        i = j + size
    if not frames:
        raise ConfigError(f"{name}: no MAVLink frame in it (an empty or cut tlog)")
    return frames


def u64(payload: bytes) -> int:
    return struct.unpack_from("<Q", payload.ljust(8, b"\0"))[0]


def _timesync(payload: bytes) -> tuple[int, int]:
    return struct.unpack_from("<qq", payload.ljust(16, b"\0"))


# -- matching the two ends ------------------------------------------------------------------------------
def sender_ends(a: Sequence[Frame], b: Sequence[Frame]) -> dict[Source, str]:
    """For each source in both logs, the end ("a" or "b") that sent it (module docstring). The frames counted are
    those between the source's first and last frame seen at both ends, in each log: a log cut short (a truncated
    tlog, a logger started late) lacks what the other end logged past its cut, which is no sign of who sent it.
    Ties (a link that lost nothing): the end that stamped most of the frames seen at both ends first."""
    by_a, by_b = by_source(a), by_source(b)
    out = {}
    for s in by_a.keys() & by_b.keys():
        fa, fb = by_a[s], by_b[s]
        ta: dict[bytes, float] = {}
        tb: dict[bytes, float] = {}
        for f in fa:
            ta.setdefault(f.raw, f.t)
        for f in fb:
            tb.setdefault(f.raw, f.t)
        common = ta.keys() & tb.keys()
        na, nb = (_span_count(fa, common), _span_count(fb, common)) if common else (len(fa), len(fb))
        if na != nb:
            out[s] = "a" if na > nb else "b"
            continue
        votes = sum(1 if ta[r] <= tb[r] else -1 for r in common) if common else 0
        out[s] = ("a" if votes > 0 else "b") if votes else ("a" if fa[0].t <= fb[0].t else "b")
    return out


def by_source(frames: Sequence[Frame]) -> dict[Source, list[Frame]]:
    """The frames of each source, in the log's order."""
    out: dict[Source, list[Frame]] = defaultdict(list)
    for f in frames:
        out[f.src].append(f)
    return out


def _span_count(frames: Sequence[Frame], common: set[bytes]) -> int:
    """How many of ``frames`` lie between the first and the last of them whose bytes are in ``common``."""
    idx = [i for i, f in enumerate(frames) if f.raw in common]
    return idx[-1] - idx[0] + 1


class _Copies:
    """The frames a sender logged with one set of bytes (their indices, in order), and which a receiver has
    matched yet. :meth:`take`: the last one not yet matched sent by a time, else the first one not yet matched,
    in amortised constant time (path-compressed pointers), so n repeats of a frame cost O(n), not O(n^2)."""

    __slots__ = ("first", "free_before", "idx", "latest", "taken")

    def __init__(self, idx: list[int], sent_t: Sequence[float]) -> None:
        self.idx = idx
        self.latest = list(itertools.accumulate((sent_t[i] for i in idx), max))  # bisectable if stamps step back
        self.free_before = list(range(len(idx)))  # itself while free; once taken, a copy before it (-1: none)
        self.taken = [False] * len(idx)
        self.first = 0

    def _free_at_or_before(self, p: int) -> int:
        root = p
        while root >= 0 and self.taken[root]:
            root = self.free_before[root]
        while p > root and self.taken[p]:  # compress the path walked
            nxt = self.free_before[p]
            self.free_before[p] = root
            p = nxt
        return root

    def take(self, by_t: float) -> int | None:
        """The sent index of the copy a frame received at ``by_t`` (s, the sender's clock, slack included) is."""
        q = self._free_at_or_before(bisect.bisect_right(self.latest, by_t) - 1)
        if q < 0:
            while self.first < len(self.idx) and self.taken[self.first]:
                self.first += 1
            if self.first == len(self.idx):
                return None
            q = self.first
        self.taken[q] = True
        self.free_before[q] = q - 1
        return self.idx[q]


def direction_records(sent: Sequence[Frame], recv: Sequence[Frame], shift_recv_s: float) -> DirectionRecords:
    """One source's frames as sent and as received (stamps + ``shift_recv_s`` on the sender's clock)."""
    out = DirectionRecords()
    by_bytes: dict[bytes, list[int]] = defaultdict(list)
    for i, f in enumerate(sent):
        by_bytes[f.raw].append(i)
    sent_t = [f.t for f in sent]
    lo, hi = min(sent_t, default=math.inf), max(sent_t, default=-math.inf)
    copies: dict[bytes, _Copies] = {}
    arrival: dict[int, float] = {}
    for r in recv:
        cands = by_bytes.get(r.raw)
        if not cands:
            t = r.t + shift_recv_s  # past the sender's log (one cut short): no sign of another link
            if t < lo or t > hi:
                out.outside += 1
            else:
                out.unmatched += 1
            continue
        pool = copies.get(r.raw)
        if pool is None:
            pool = copies[r.raw] = _Copies(cands, sent_t)
        t = r.t + shift_recv_s
        i = pool.take(t + STAMP_SLACK_S)
        if i is None:
            out.duplicates += 1
            continue
        arrival[i] = t
    if not arrival:
        return out
    matched = sorted(arrival)
    rows: list[tuple[float, float | None]] = [(sent_t[i], arrival[i] - sent_t[i]) for i in matched]
    for a, b in zip(matched, matched[1:], strict=False):
        want = (sent[a].seq + 1) & 0xFF
        chain = []
        for j in range(a + 1, b):
            if sent[j].seq == want and j not in arrival:
                chain.append(j)
                want = (want + 1) & 0xFF
        if want == sent[b].seq:
            rows += [(sent_t[j], None) for j in chain]
            continue
        gap = (sent[b].seq - sent[a].seq - 1) & 0xFF  # the chain does not close: count the sequence gap
        out.gaps_counted += gap
        rows += [(sent_t[a] + (sent_t[b] - sent_t[a]) * (k + 1) / (gap + 1), None) for k in range(gap)]
    out.records = sorted(rows, key=lambda r: r[0])
    return out


def merge_directions(parts: Iterable[DirectionRecords]) -> DirectionRecords:
    """The sources' records of one direction as one, in send-time order; ``reordered`` the sum of each source's own
    (a source's packets against each other), None if a source's is not counted (a part of a sum is not the count)."""
    out = DirectionRecords()
    parts = list(parts)
    for p in parts:
        out.records += p.records
        out.duplicates += p.duplicates
        out.unmatched += p.unmatched
        out.outside += p.outside
        out.gaps_counted += p.gaps_counted
    counted = [p.reordered for p in parts]
    out.reordered = sum(counted) if counted and None not in counted else None  # type: ignore[arg-type]
    out.records.sort(key=lambda r: r[0])
    return out


def timesync_offset(vehicle: Sequence[Frame], controller: Sequence[Frame],
                    ends: dict[Source, str]) -> tuple[float, float] | None:
    """(vehicle clock - controller clock, round trip) in s from the TIMESYNC exchange with the lowest
    round trip (either end asking; equal one-way delays assumed), or None without a complete exchange."""
    logs = {"a": vehicle, "b": controller}
    best: tuple[float, float] | None = None
    for asker, answerer in (("b", "a"), ("a", "b")):
        mine, theirs = logs[asker], logs[answerer]
        srcs_ask = {s for s, e in ends.items() if e == asker}
        srcs_ans = {s for s, e in ends.items() if e == answerer}
        got = {f.raw: f.t for f in theirs if f.msgid == TIMESYNC and f.src in srcs_ask}
        asked = {}
        for f in mine:
            if f.msgid == TIMESYNC and f.src in srcs_ask and f.raw in got:
                tc1, ts1 = _timesync(f.payload)
                if tc1 == 0:
                    asked[ts1] = (f.t, got[f.raw])  # a1 (asker's clock), b1 (answerer's)
        heard = {f.raw: f.t for f in mine if f.msgid == TIMESYNC and f.src in srcs_ans}
        for f in theirs:
            if f.msgid != TIMESYNC or f.src not in srcs_ans or f.raw not in heard:
                continue
            tc1, ts1 = _timesync(f.payload)
            if tc1 == 0 or ts1 not in asked:
                continue
            a1, b1 = asked[ts1]
            b2, a2 = f.t, heard[f.raw]
            rtt = (a2 - a1) - (b2 - b1)
            off = ((b1 - a1) + (b2 - a2)) / 2.0  # answerer - asker
            off_vc = off if answerer == "a" else -off
            if rtt >= 0.0 and (best is None or rtt < best[1]):
                best = (off_vc, rtt)
    return best

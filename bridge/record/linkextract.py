"""A link as it was: per-packet one-way delays and losses of both directions, from a run directory of ours
or two tlogs recorded at the two ends of any MAVLink link (``bsst link extract``; docs/links.md).

In:  a real-time run directory (``vehicle.tlog`` and ``controller.tlog``; without them ``vehicle.csv``
     and ``controller.csv``), or a vehicle-end and a controller-end tlog (8-byte big-endian Unix time
     in us + one MAVLink 1 or 2 frame, repeated: what MAVProxy and our nodes write); which clock the two
     ends' stamps are on (``same``, or ``timesync``: the offset estimated from TIMESYNC exchanges)
Out: :class:`Extraction`: per direction the records (send time s from the trace's start, one-way delay
     s or None for lost) and its counts, the clock offset used, notes; :func:`extraction_text`, the
     trace file (``t_s, delay_ms, direction``) that ``[link] trace`` replays

How (tlogs): each end's tlog holds the frames it sent and those it received. A source (system,
component) belongs to the end that logged more of its frames (the sender logs every one; the
receiver only what arrived; ties: the end that logged it first). A received frame is the sent frame
with the same bytes (nearest in time), so its delay is the difference of the two stamps; duplicates
count once. Losses come from the sequence numbers: between two delivered frames of a source, the
frames the sender logged that continue its sequence (seq + 1, + 2, ...) are lost; where that chain
does not close (frames of the same source on another link), the gap in sequence numbers is counted
instead, at times spaced evenly between the two. Only frames between a source's first and last
delivered one count: what was sent before the receiver listened or after it stopped is no loss.
A run directory's trace starts (``t_s`` = 0) at the flight's time 0 (the state the first actuator
target answers left the vehicle), a pair of tlogs' at the first frame.
"""

from __future__ import annotations

import bisect
import csv
import itertools
import json
import math
import struct
from collections import Counter, defaultdict
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bridge.link.trace import trace_text
from params import ConfigError, read_regular_file

MAX_TLOG_BYTES = 4 << 30
CLOCKS = ("same", "timesync")
_TIMESYNC, _ODOMETRY = 111, 331
_TARGETS = (93, 139)  # HIL_ACTUATOR_CONTROLS, SET_ACTUATOR_CONTROL_TARGET: both open with time_usec
_STAMP_SLACK_S = 0.002  # a frame may look received up to this much before it was sent (stamp resolution)

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
    unmatched: int = 0  # received frames the sender never logged
    gaps_counted: int = 0  # losses from a sequence gap, their send time spread evenly

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
                "duplicates": self.duplicates, "unmatched": self.unmatched, "gaps_counted": self.gaps_counted}


@dataclass
class Extraction:
    up: DirectionRecords
    down: DirectionRecords
    origin: str  # what t_s = 0 is
    clock: str
    offset_s: float = 0.0  # vehicle clock - controller clock, as used
    timesync: tuple[float, float] | None = None  # (offset s, round trip s) TIMESYNC gives, when it can
    inputs: tuple[str, ...] = ()
    notes: list[str] = field(default_factory=list)


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


def _u64(payload: bytes) -> int:
    return struct.unpack_from("<Q", payload.ljust(8, b"\0"))[0]


def _timesync(payload: bytes) -> tuple[int, int]:
    return struct.unpack_from("<qq", payload.ljust(16, b"\0"))


# -- matching the two ends ------------------------------------------------------------------------------
def _ends(a: Sequence[Frame], b: Sequence[Frame]) -> dict[Source, str]:
    """For each source in both logs, the end ("a" or "b") that sent it (module docstring)."""
    ca, cb = Counter(f.src for f in a), Counter(f.src for f in b)
    first_a: dict[Source, float] = {}
    first_b: dict[Source, float] = {}
    for f in a:
        first_a.setdefault(f.src, f.t)
    for f in b:
        first_b.setdefault(f.src, f.t)
    out = {}
    for s in set(ca) & set(cb):
        out[s] = ("a" if ca[s] > cb[s] else "b") if ca[s] != cb[s] else ("a" if first_a[s] <= first_b[s] else "b")
    return out


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


def _direction(sent: Sequence[Frame], recv: Sequence[Frame], shift_recv_s: float) -> DirectionRecords:
    """One source's frames as sent and as received (stamps + ``shift_recv_s`` on the sender's clock)."""
    out = DirectionRecords()
    by_bytes: dict[bytes, list[int]] = defaultdict(list)
    for i, f in enumerate(sent):
        by_bytes[f.raw].append(i)
    sent_t = [f.t for f in sent]
    copies: dict[bytes, _Copies] = {}
    arrival: dict[int, float] = {}
    for r in recv:
        cands = by_bytes.get(r.raw)
        if not cands:
            out.unmatched += 1
            continue
        pool = copies.get(r.raw)
        if pool is None:
            pool = copies[r.raw] = _Copies(cands, sent_t)
        t = r.t + shift_recv_s
        i = pool.take(t + _STAMP_SLACK_S)
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


def _merge(parts: Iterable[DirectionRecords]) -> DirectionRecords:
    out = DirectionRecords()
    for p in parts:
        out.records += p.records
        out.duplicates += p.duplicates
        out.unmatched += p.unmatched
        out.gaps_counted += p.gaps_counted
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
        got = {f.raw: f.t for f in theirs if f.msgid == _TIMESYNC and f.src in srcs_ask}
        asked = {}
        for f in mine:
            if f.msgid == _TIMESYNC and f.src in srcs_ask and f.raw in got:
                tc1, ts1 = _timesync(f.payload)
                if tc1 == 0:
                    asked[ts1] = (f.t, got[f.raw])  # a1 (asker's clock), b1 (answerer's)
        heard = {f.raw: f.t for f in mine if f.msgid == _TIMESYNC and f.src in srcs_ans}
        for f in theirs:
            if f.msgid != _TIMESYNC or f.src not in srcs_ans or f.raw not in heard:
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


def _flight_origin(vehicle: Sequence[Frame], controller: Sequence[Frame], ends: dict[Source, str],
                   shift_c: float) -> float | None:
    """The vehicle-clock time (s) the state answered by the first actuator target left the vehicle."""
    first = next((f for f in controller if f.msgid in _TARGETS and ends.get(f.src) == "b"), None)
    if first is None:
        return None
    usec = _u64(first.payload)
    for f in vehicle:
        if f.msgid == _ODOMETRY and ends.get(f.src) == "a" and _u64(f.payload) == usec:
            return f.t
    return first.t + shift_c


def extract_tlogs(vehicle: Sequence[Frame], controller: Sequence[Frame], clock: str = "same",
                  run_dir: bool = False, inputs: tuple[str, ...] = ()) -> Extraction:
    """Both directions of the link between the two ends whose tlogs these are (module docstring).
    ``run_dir``: the trace starts at the flight's time 0, else at the first frame. Two tlogs that are not
    the two ends of one link (one tlog twice, clocks that never overlap, no frame of one in the other, frames
    received before they were sent) are a ``ConfigError``: their figures would be nonsense."""
    if clock not in CLOCKS:
        raise ConfigError(f"--clock must be one of {', '.join(CLOCKS)}, got {clock!r}")
    names = " and ".join(inputs) or "the tlogs"
    if len(vehicle) == len(controller) and all(a.t == b.t and a.raw == b.raw for a, b in zip(vehicle, controller)):
        raise ConfigError(f"{names}: the same frames at the same times: one tlog given as both ends (give the "
                          f"vehicle's tlog and the controller's)")
    ends = _ends(vehicle, controller)
    if not ends:
        raise ConfigError(f"{names}: no MAVLink source appears in both, so no frame crossed between them: not the "
                          f"two ends of one link")
    ts = timesync_offset(vehicle, controller, ends)
    notes = []
    if clock == "timesync":
        if ts is None:
            raise ConfigError(f"--clock timesync: {names} hold no complete TIMESYNC exchange (a request and its "
                              f"answer, each seen at both ends)")
        shift_c = ts[0]  # controller stamps + shift = vehicle clock
    else:
        shift_c = 0.0
        if ts is not None and abs(ts[0]) > max(0.005, ts[1]):
            notes.append(f"TIMESYNC puts the vehicle's clock {ts[0] * 1e3:+.1f} ms from the controller's (round trip "
                         f"{ts[1] * 1e3:.1f} ms): if the two ends' clocks differ, use --clock timesync")
    _check_overlap(vehicle, controller, shift_c, names)
    v_by, c_by = _by_source(vehicle), _by_source(controller)
    per: dict[str, list[DirectionRecords]] = {"up": [], "down": []}
    for src, end in sorted(ends.items()):
        if end == "a":  # the vehicle's: down
            per["down"].append(_direction(v_by[src], c_by[src], shift_c))
        else:  # the controller's, on its clock shifted to the vehicle's: up
            sent = [Frame(f.t + shift_c, f.src, f.msgid, f.seq, f.raw, f.payload) for f in c_by[src]]
            per["up"].append(_direction(sent, v_by[src], 0.0))
    up, down = _merge(per["up"]), _merge(per["down"])
    _check_matched(up, down, names)
    negative = [x for d in (up, down) for _, x in d.records if x is not None and x < -_STAMP_SLACK_S]
    if negative and clock == "same":
        raise ConfigError(f"{names}: {len(negative)} frames arrived before they were sent by the stamps (by up to "
                          f"{-min(negative):.6g} s): the two ends' clocks differ (use --clock timesync) or these are "
                          f"not the two ends of one link")
    if negative:
        notes.append(f"{len(negative)} frames arrived before they were sent by the stamps (by up to "
                     f"{-min(negative) * 1e3:.1f} ms): the TIMESYNC offset is off by at least that much")
    origin = _flight_origin(vehicle, controller, ends, shift_c) if run_dir else None
    what = "the flight's time 0 (the state the first actuator target answers left the vehicle)"
    if origin is None:
        origin, what = min(r[0][0] for r in (up.records, down.records) if r), "the first frame sent either way"
    for d in (up, down):
        d.records = [(t - origin, x) for t, x in d.records if t >= origin]
    return Extraction(up, down, what, clock, shift_c, ts, inputs, notes)


def _by_source(frames: Sequence[Frame]) -> dict[Source, list[Frame]]:
    out: dict[Source, list[Frame]] = defaultdict(list)
    for f in frames:
        out[f.src].append(f)
    return out


def _check_overlap(vehicle: Sequence[Frame], controller: Sequence[Frame], shift_c: float, names: str) -> None:
    """Refuse two tlogs whose stamps (the controller's shifted by ``shift_c`` s) never overlap in time."""
    v0, v1 = min(f.t for f in vehicle), max(f.t for f in vehicle)
    c0, c1 = min(f.t for f in controller) + shift_c, max(f.t for f in controller) + shift_c
    if v1 < c0 or c1 < v0:
        raise ConfigError(f"{names}: the vehicle's tlog spans {v0:.3f}..{v1:.3f} s, the controller's {c0:.3f}.."
                          f"{c1:.3f} s (Unix time{', TIMESYNC offset applied' if shift_c else ''}): they never "
                          f"overlap, so these are not the two ends of one link (or their clocks differ: "
                          f"--clock timesync)")


def _check_matched(up: DirectionRecords, down: DirectionRecords, names: str) -> None:
    """Refuse two tlogs where no frame, or in either direction fewer than half the frames received, match a
    frame the other end sent."""
    if not any(d.sent - d.lost for d in (up, down)):
        raise ConfigError(f"{names}: no frame was delivered either way (no frame one end received is one the "
                          f"other sent): not the two ends of one link")
    for name, d in (("up", up), ("down", down)):
        delivered = d.sent - d.lost
        if d.unmatched > delivered:
            raise ConfigError(f"{names}: {name}: {d.unmatched} of the {d.unmatched + delivered} frames received "
                              f"from the other end's sources are not in the other end's tlog: not the two ends of "
                              f"one link")


# -- a run directory -----------------------------------------------------------------------------------
def run_clock(path: Path) -> str | None:
    """The clock a run was flown on, from its summary.json (None: no readable summary)."""
    try:
        return json.loads((path / "summary.json").read_text()).get("clock")
    except (OSError, ValueError, AttributeError):
        return None


def extract_run_dir(path: str | Path, clock: str = "same") -> Extraction:
    """Both directions of a real-time run's link: from its tlogs, else from vehicle.csv and controller.csv."""
    p = Path(path)
    if not p.is_dir():
        raise ConfigError(f"{p}: not a run directory (or give a vehicle tlog and a controller tlog)")
    flown = run_clock(p)
    if flown in ("lockstep", "offline"):
        raise ConfigError(f"{p}: flown {'in lockstep' if flown == 'lockstep' else 'offline'}: its link model acted in "
                          f"simulation time{' after the sockets' if flown == 'lockstep' else ''}, so no file holds the "
                          f"link as packets met it (its [link] table is in mission.toml); extract a real-time run")
    v, c = p / "vehicle.tlog", p / "controller.tlog"
    if v.is_file() and c.is_file():
        return extract_tlogs(read_tlog(v), read_tlog(c), clock, run_dir=True, inputs=(str(v), str(c)))
    vc, cc = p / "vehicle.csv", p / "controller.csv"
    if vc.is_file() and cc.is_file():
        if clock != "same":
            raise ConfigError(f"--clock {clock}: {p} has no tlogs; its CSVs are on one host's monotonic clock")
        return extract_csvs(vc, cc)
    raise ConfigError(f"{p}: neither vehicle.tlog and controller.tlog nor vehicle.csv and controller.csv: "
                      f"no record of a link to extract")


def _csv_rows(path: Path, names: Sequence[str]) -> list[dict[str, float]]:
    text = read_regular_file(path, "a CSV").decode("utf-8", errors="replace")
    reader = csv.reader(text.splitlines())
    head = next(reader, None)
    if head is None:
        raise ConfigError(f"{path}: empty")
    missing = [n for n in names if n not in head]
    if missing:
        raise ConfigError(f"{path}: no column {missing[0]!r} in its header")
    pos = [head.index(n) for n in names]
    out = []
    for row in reader:
        if len(row) != len(head):
            continue  # a row cut by a kill: the last one
        try:
            out.append({n: float(row[i]) if row[i] != "" else math.nan for n, i in zip(names, pos, strict=True)})
        except ValueError:
            continue
    return out


def extract_csvs(vehicle_csv: Path, controller_csv: Path) -> Extraction:
    """Both directions from each side's half of the trace (one host's monotonic clock). Approximate:
    a state or command is known by its step k, so a command superseded within one control period
    counts as lost, and a tick that reuses a state sends a command with the same k (the first counts)."""
    v = _csv_rows(vehicle_csv, ("k", "odo_sent_wall", "cmd_k", "cmd_recv_wall"))
    c = _csv_rows(controller_csv, ("k", "odo_recv_wall", "cmd_sent_wall"))
    if not v or not c:
        raise ConfigError(f"{vehicle_csv if not v else controller_csv}: no rows")
    state_sent = {int(r["k"]): r["odo_sent_wall"] for r in v}
    state_recv: dict[int, float] = {}
    cmd_sent: dict[int, float] = {}
    for r in c:
        state_recv.setdefault(int(r["k"]), r["odo_recv_wall"])
        cmd_sent.setdefault(int(r["k"]), r["cmd_sent_wall"])
    cmd_recv: dict[int, float] = {}
    for r in v:
        if r["cmd_k"] >= 0:
            cmd_recv.setdefault(int(r["cmd_k"]), r["cmd_recv_wall"])
    k0, k1 = min(state_recv), max(state_recv)
    down = DirectionRecords([(state_sent[k], state_recv[k] - state_sent[k] if k in state_recv else None)
                             for k in sorted(state_sent) if k0 <= k <= k1])
    delivered = [k for k in cmd_sent if k in cmd_recv]
    last = max(delivered) if delivered else k0
    up = DirectionRecords([(cmd_sent[k], cmd_recv[k] - cmd_sent[k] if k in cmd_recv else None)
                           for k in sorted(cmd_sent) if k <= last and math.isfinite(cmd_sent[k])])
    origin = state_sent.get(k0, min(t for t, _ in down.records))
    for d in (up, down):
        d.records = [(t - origin, x) for t, x in d.records if t >= origin and math.isfinite(t)]
    note = ("from vehicle.csv and controller.csv (no tlogs): approximate, by step number; a command superseded "
            "within one control period counts as lost")
    return Extraction(up, down, "the flight's time 0 (the first state the controller answered left the vehicle)",
                      "same", 0.0, None, (str(vehicle_csv), str(controller_csv)), [note])


# -- the trace file -------------------------------------------------------------------------------------
def extraction_rows(ex: Extraction) -> list[tuple[float, float | None, str]]:
    """(t_s, delay_ms or None, direction) rows, in time order, t_s rounded to us and strictly increasing
    per direction (two frames stamped alike are 1 us apart), delays to us."""
    rows = []
    for d, part in (("up", ex.up), ("down", ex.down)):
        last = -math.inf
        for t, x in part.records:
            t = round(max(t, last + 1e-6), 6)
            last = t
            rows.append((t, None if x is None else round(x * 1000.0, 3), d))
    rows.sort(key=lambda r: (r[0], r[2]))
    return rows


def extraction_text(ex: Extraction) -> str:
    """The trace file of an extraction, with where it came from as comments."""
    comments = [f"bsst link extract {' '.join(ex.inputs)}",
                f"t_s = 0 at {ex.origin}; clock {ex.clock}"
                + (f" (controller stamps {ex.offset_s * 1e3:+.3f} ms)" if ex.clock == "timesync" else ""),
                "one row per frame: delay_ms = one-way delay, empty = lost; up = controller -> vehicle"]
    comments += ex.notes
    return trace_text(extraction_rows(ex), comments)

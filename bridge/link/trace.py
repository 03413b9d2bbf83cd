"""Measured link traces: per-packet one-way delays and losses, replayed by the link model
(docs/links.md, "Link traces").

In:  a trace file (CSV, UTF-8: a header naming ``t_s`` (s from the trace's start), ``delay_ms``
     (one-way, ms; empty: lost) and optionally ``direction`` (``up`` | ``down``); ``#`` lines are
     comments), a packet's send time (s of mission time)
Out: :class:`TraceFile` (each direction's :class:`Records`, validated: a bad row is a ``ConfigError``
     naming the file and the line), the delay (s) or the loss of a packet sent at time t
     (:class:`Replay`), a trace's own figures (:func:`own_figures`: records, loss %, delay
     percentiles ms), and trace text to write (:func:`trace_text`)

A packet sent at time t takes the record with the largest ``t_s`` <= t of its direction (the
first record before the trace's first ``t_s``); with a ``direction`` column each direction has its
own rows, without one the rows serve both. A trace lasts its last ``t_s`` plus its median record
spacing (:attr:`Records.length_s`); past its end it is refused for a longer mission
(bridge.link.model), or looped: t is taken modulo that length.

Pure: the file's bytes come from :func:`params.read_regular_file`, which refuses what is not a
regular file; this module only reads text, ~1000 rows at a time: a chunk of plain good rows at once (numpy,
~1 µs a row), any other line by line, which names every bad row (docs/figures.md, the third wave's fortieth session).
"""

from __future__ import annotations

import bisect
import csv
import io
import math
from array import array
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from params import ConfigError, read_regular_file, utf8_text
from params.text import number

COLUMNS = ("t_s", "delay_ms", "direction")
REQUIRED = ("t_s", "delay_ms")
DIRECTIONS = ("up", "down")
DELAY_RANGE_MS = (0.0, 60_000.0)  # the one-way delay a record may give, as the [link] delay_ms key
T_RANGE_S = (0.0, 1e7)  # a record's time from the trace's start
MAX_TRACE_BYTES = 512 << 20  # about 2.5e7 records: anything bigger is not a link trace of a flight
LENGTH_SLACK_S = 1e-6  # a trace "as long as" the mission may fall short of it by rounding
MIN_TRACE_RECORDS = 2  # per direction replayed: one record has no spacing, so no length (bridge.link.model refuses it)
MAX_ROW_CHARS = 1000  # a record is two numbers and a direction: a longer line is not one


@dataclass(frozen=True, eq=False)
class Records:
    """One direction's records: send times (s, strictly increasing) and one-way delays (s, nan: lost), as
    arrays of doubles (8 bytes a number: a trace of 10^7 records is 160 MB, not a Python object per row)."""

    t_s: array[float]
    delay_s: array[float]
    length_s: float  # last t_s + the median spacing: how long the trace lasts (its loop period)

    @property
    def n(self) -> int:
        return len(self.t_s)

    @property
    def lost(self) -> int:
        return int(np.count_nonzero(np.isnan(np.frombuffer(self.delay_s, dtype=float)))) if self.n else 0


def make_records(t_s: Iterable[float], delay_s: Iterable[float]) -> Records:
    """:class:`Records` from times (s, strictly increasing) and delays (s, nan lost); length computed."""
    t = t_s if isinstance(t_s, array) and t_s.typecode == "d" else array("d", t_s)
    d = delay_s if isinstance(delay_s, array) and delay_s.typecode == "d" else array("d", delay_s)
    # the median of the spacings, as statistics.median gives it (the middle one, or the mean of the two)
    spacing = float(np.median(np.diff(np.frombuffer(t, dtype=float)))) if len(t) > 1 else 0.0
    return Records(t, d, (t[-1] + spacing) if t else 0.0)


@dataclass(frozen=True)
class TraceFile:
    """A validated trace: its path and its records, for both directions or each apart."""

    path: str
    both: Records | None = None  # no direction column: these rows serve both directions
    up: Records | None = None
    down: Records | None = None

    def records(self, direction: str) -> Records | None:
        """The records ``direction`` replays (None: the file has no rows for it)."""
        return self.both if self.both is not None else (self.up if direction == "up" else self.down)


@dataclass(frozen=True)
class DirectionTrace:
    """What one direction of the link model replays: the file, its records, whether it loops."""

    path: str
    records: Records
    loop: bool = False

    def describe(self) -> str:
        r = self.records
        return f"trace {Path(self.path).name} ({r.n} records, {r.length_s:g} s{', looped' if self.loop else ''})"


class Replay:
    """The delay (s) or loss (nan) of a packet sent at time t (s from the trace's start)."""

    def __init__(self, trace: DirectionTrace) -> None:
        self.t = trace.records.t_s
        self.d = trace.records.delay_s
        self.length = trace.records.length_s
        self.loop = trace.loop and self.length > 0.0

    def delay_at(self, t: float) -> float:
        """Delay in s (nan: lost) of the record with the largest ``t_s`` <= t (the first before it)."""
        if not t > 0.0:  # before the trace's start (or -inf: a mission clock not started yet)
            return self.d[0]
        if self.loop and t >= self.length:
            t = math.fmod(t, self.length)
        i = bisect.bisect_right(self.t, t) - 1
        return self.d[i if i > 0 else 0]


# -- reading -----------------------------------------------------------------------------------
def read_trace(path: str | Path) -> TraceFile:
    """Read and validate a trace file (every problem a ``ConfigError`` naming the file, and the line)."""
    data = read_regular_file(path, "a link trace (CSV)", MAX_TRACE_BYTES)
    return parse_trace(data, str(path))


FIRST_CHUNK_BYTES = 256  # the header's chunk: read line by line (anything may come before the header)
CHUNK_BYTES = 1 << 15  # ~1000 rows a chunk: its Python objects stay ~200 kB (a trace may hold 10^7 rows)
# what a plain chunk holds: printable ASCII but the quote (a quoted field is csv's) and the underscore (a digit
# separator, which params.text.number refuses), lines ended by \n or \r\n; every other chunk is read line by line
_PLAIN_BYTES = bytes(b for b in range(0x20, 0x7F) if b not in b'"_') + b"\r\n"
_NOT_SEPARATOR = bytes(b for b in range(256) if b not in b",\n")


def parse_trace(data: bytes, name: str) -> TraceFile:
    """Validate a trace's bytes; ``name`` is what the errors call the file. Memory: the bytes, a chunk's rows
    as Python objects, and 16 bytes per record (:class:`Records` holds arrays of doubles)."""
    reader = _Reader(name)
    pos, size = 0, FIRST_CHUNK_BYTES
    try:
        while pos < len(data):
            end = data.find(b"\n", pos + size)  # chunks end after a newline: no line, no UTF-8 character, is cut
            end = len(data) if end < 0 else end + 1
            chunk = data[pos:end]
            if reader.cols is None or not reader.plain(chunk):
                reader.by_line(chunk)
            pos, size = end, CHUNK_BYTES
        return reader.result()
    except ConfigError as exc:  # each refusal's line opens with the file's name: typed so (ConfigError.source)
        raise ConfigError(str(exc), source=name) from None


class _Reader:
    """A trace read chunk by chunk: a plain chunk of good rows at once (:meth:`plain`, numpy), any other line
    by line (:meth:`by_line`: every refusal and its line come from there); the same records either way."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.line = 0  # lines read, numbered as str.splitlines numbers them
        self.cols: tuple[str, ...] | None = None
        self.rows: dict[str, tuple[array[float], array[float]]] = {}
        self.last: dict[str, float] = {}  # each direction's last good t_s
        self.first_bad, self.bad = "", 0

    def by_line(self, chunk: bytes) -> None:
        for raw in io.BytesIO(chunk):  # shares the bytes; splits after each b"\n"
            try:
                text = utf8_text(raw) if self.line == 0 else raw.decode("utf-8")
            except UnicodeDecodeError:
                raise ConfigError(f"{self.name} line {self.line + 1}: not UTF-8 text (expected a CSV link trace)") \
                    from None
            for ln in text.splitlines():
                self.line += 1
                if ln.strip() and not ln.lstrip().startswith("#"):
                    self._take(ln)

    def _take(self, ln: str) -> None:
        fields, why = _fields(ln)
        if self.cols is None:  # the first line that is neither blank nor a comment
            if why:
                raise ConfigError(f"{self.name} line {self.line}: {why}")
            self.cols = _header(fields, self.name, self.line)
            return
        direction, t, d = "", math.nan, math.nan
        if not why:
            why, direction, t, d = _row(fields, self.cols, self.last)
        if direction and t == t:  # a good time on a bad row still orders the rows after it
            self.last[direction] = t
        if why:
            self.bad += 1
            self.first_bad = self.first_bad or f"{self.name} line {self.line}: {why}"
            return
        ts, ds = self.rows.setdefault(direction, (array("d"), array("d")))
        ts.append(t)
        ds.append(d)

    def plain(self, chunk: bytes) -> bool:
        """Take a chunk whose bytes are plain (:data:`_PLAIN_BYTES`) and whose every row is good, at once, as
        :meth:`by_line` would (the same float() of each field); False, nothing taken, if it is not one."""
        if chunk.translate(None, _PLAIN_BYTES) or chunk.count(b"\r") != chunk.count(b"\r\n"):
            return False
        text = chunk.decode("ascii").replace("\r\n", "\n")
        lines = text.count("\n") + (not text.endswith("\n"))
        if "#" in text or " " in text or "\n\n" in text or text.startswith("\n"):  # comments, blanks, spaces
            kept = [ln for ln in text.splitlines() if ln.strip() and ln.lstrip()[:1] != "#"]
            text = "\n".join(kept) + "\n" if kept else ""
        elif not text.endswith("\n"):
            text += "\n"
        cols = _plain_columns(text, self.cols or ())
        if cols is None:
            return False
        groups = _plain_records(cols)
        if groups is None or any(k in self.last and not t[0] > self.last[k] for k, (t, _) in groups.items()):
            return False
        for k, (t, d) in groups.items():
            ts, ds = self.rows.setdefault(k, (array("d"), array("d")))
            ts.frombytes(t.tobytes())
            ds.frombytes(d.tobytes())
            self.last[k] = float(t[-1])
        self.line += lines
        return True

    def result(self) -> TraceFile:
        name = self.name
        if self.cols is None:
            raise ConfigError(f"{name}: empty; expected a CSV header {','.join(REQUIRED)}[,direction] and records")
        if self.bad:
            more = f" (and {self.bad - 1} more bad row{'s' if self.bad > 2 else ''})" if self.bad > 1 else ""
            raise ConfigError(self.first_bad + more)
        if not self.rows:
            raise ConfigError(f"{name}: no records after the header (rows of {','.join(self.cols)})")
        recs = {k: make_records(*v) for k, v in self.rows.items()}
        if "direction" in self.cols:
            return TraceFile(name, up=recs.get("up"), down=recs.get("down"))
        return TraceFile(name, both=recs["both"])


def _plain_columns(text: str, cols: tuple[str, ...]) -> dict[str, list[str]] | None:
    """Each column's fields (stripped) of rows ``text`` (each ended by \\n), or None where a row has another
    number of fields or is too long (:meth:`_Reader.by_line` says which)."""
    n, k = text.count("\n"), len(cols)
    raw = text.encode("ascii")
    if not n or raw.translate(None, _NOT_SEPARATOR) != (b"," * (k - 1) + b"\n") * n:
        return None
    if int(np.diff(np.flatnonzero(np.frombuffer(raw, dtype=np.uint8) == 10), prepend=-1).max()) > MAX_ROW_CHARS + 1:
        return None
    flat = text.replace("\n", ",").split(",")  # the fields row by row, then the "" after the last
    spaced = " " in text
    return {c: list(map(str.strip, flat[i:n * k:k])) if spaced else flat[i:n * k:k] for i, c in enumerate(cols)}


def _plain_records(cols: dict[str, list[str]]) -> dict[str, tuple[np.ndarray, np.ndarray]] | None:
    """Each direction's (t_s, delay s) of these rows' fields, as _row reads them, or None if a row is bad or its
    t_s does not increase (the order past the chunk is the caller's)."""
    delays = cols["delay_ms"]
    try:  # float() as params.text.number calls it (no "_" here); an empty delay (lost) read as "nan"
        t = np.array(list(map(float, cols["t_s"])), dtype=float)
        d = np.array(list(map(float, [x or "nan" for x in delays])), dtype=float)
    except ValueError:
        return None
    (t_lo, t_hi), (d_lo, d_hi) = T_RANGE_S, DELAY_RANGE_MS
    given = np.array(list(map(bool, delays)), dtype=bool)
    if not (np.all((t >= t_lo) & (t <= t_hi)) and np.all((d >= d_lo) & (d <= d_hi) | ~given)):
        return None  # a NaN fails both: a "nan" given is refused, line by line
    d = np.where(given, d / 1000.0, math.nan)
    if "direction" not in cols:
        groups = {"both": (t, d)}
    else:
        dirs = cols["direction"]
        if not set(dirs) <= set(DIRECTIONS):
            return None
        up = np.array([x == "up" for x in dirs], dtype=bool)
        groups = {k: (t[m], d[m]) for k, m in (("up", up), ("down", ~up)) if m.any()}
    if any(len(t) > 1 and not np.all(np.diff(t) > 0.0) for t, _ in groups.values()):
        return None
    return groups


def _fields(line: str) -> tuple[list[str], str | None]:
    """The fields of one line, or why it is not one CSV record of a trace (a trace's fields are numbers
    and ``up``/``down``: a quote may wrap one, never a newline or a comma)."""
    if len(line) > MAX_ROW_CHARS:
        return [], f"{len(line)} characters long; a trace row is at most {MAX_ROW_CHARS} ({','.join(COLUMNS)})"
    if '"' not in line:
        return line.split(","), None
    try:
        return next(csv.reader([line], strict=True)), None
    except csv.Error as exc:
        why = "an unclosed quote (a field cannot hold a newline)" if "end of data" in str(exc) else str(exc)
        return [], f"not a CSV record: {why}"


def _header(names: list[str], name: str, line: int) -> tuple[str, ...]:
    cols = tuple(n.strip() for n in names)
    unknown = [c for c in cols if c not in COLUMNS]
    if unknown:
        raise ConfigError(f"{name} line {line}: unknown column {unknown[0]!r}; a trace has the columns "
                          f"{', '.join(COLUMNS)} (direction optional)")
    if len(set(cols)) != len(cols):
        raise ConfigError(f"{name} line {line}: a column is named twice ({', '.join(cols)})")
    missing = [c for c in REQUIRED if c not in cols]
    if missing:
        raise ConfigError(f"{name} line {line}: no {missing[0]} column; the header must name "
                          f"{', '.join(REQUIRED)} (and optionally direction)")
    return cols


def _row(fields: list[str], cols: tuple[str, ...], last: Mapping[str, float]) -> tuple[str | None, str, float, float]:
    """(why it is bad or None, direction ("" if unknown), t_s (nan if bad), delay s (nan: lost)) of one record."""
    nan = math.nan
    if len(fields) != len(cols):
        return f"{len(fields)} fields, the header has {len(cols)} ({','.join(cols)})", "", nan, nan
    v = dict(zip(cols, (f.strip() for f in fields), strict=True))
    direction = v.get("direction", "both")
    if direction not in ("both", *DIRECTIONS) or "direction" in v and direction == "both":
        return f"direction must be up or down, got {direction!r}", "", nan, nan
    t, why = _number(v["t_s"], "t_s", T_RANGE_S)
    if why:
        return why, direction, nan, nan
    if direction in last and not t > last[direction]:
        where = f" of the {direction} rows" if direction != "both" else ""
        return f"t_s must increase: {t!r} after {last[direction]!r}{where}", direction, nan, nan
    if v["delay_ms"] == "":
        return None, direction, t, nan
    d, why = _number(v["delay_ms"], "delay_ms", DELAY_RANGE_MS)
    return why, direction, t, d / 1000.0


def _number(text: str, key: str, bounds: tuple[float, float]) -> tuple[float, str | None]:
    try:
        x = number(text)
    except ValueError:
        return 0.0, f"{key} is not a number: {text[:40]!r}"
    if math.isnan(x):
        return 0.0, f"{key} is NaN (an empty delay_ms means lost)" if key == "delay_ms" else f"{key} is NaN"
    lo, hi = bounds
    if not lo <= x <= hi:
        return 0.0, f"{key} must be in [{lo:g}, {hi:g}], got {text[:40]}"
    return x, None


def records_problem(tf: TraceFile, direction: str) -> str | None:
    """Why ``direction`` cannot replay ``tf`` (no rows of its own), or None."""
    if tf.records(direction) is None:
        return f"has no {direction} rows (its direction column names only {'down' if direction == 'up' else 'up'})"
    return None


# -- a trace's own figures, and writing one ---------------------------------------------------------
def own_figures(trace: DirectionTrace) -> dict[str, Any]:
    """The trace's own records, loss (%) and delay percentiles (ms), for ``summary.json``."""
    r = trace.records
    d = np.asarray(r.delay_s, dtype=float)
    ok = d[~np.isnan(d)] * 1000.0
    pct = ({"p50": None, "p95": None, "p99": None, "max": None} if not len(ok) else
           dict(zip(("p50", "p95", "p99"), map(float, np.percentile(ok, (50.0, 95.0, 99.0))), strict=True))
           | {"max": float(ok.max())})
    return {"file": trace.path, "records": r.n, "length_s": r.length_s, "loop": trace.loop,
            "loss_pct": 100.0 * (r.n - len(ok)) / r.n if r.n else None, "delay_ms": pct}


def trace_text(rows: Iterable[tuple[float, float | None, str | None]], comments: Iterable[str] = ()) -> str:
    """A trace file's text: ``comments`` as ``#`` lines, then rows (t_s, delay_ms or None for lost,
    direction or None); a direction column when the first row has one. Floats as ``repr``."""
    out = [f"# {c}" for c in comments]
    rows = list(rows)
    with_dir = bool(rows) and rows[0][2] is not None
    out.append("t_s,delay_ms,direction" if with_dir else "t_s,delay_ms")
    for t, d, direction in rows:
        cell = "" if d is None or d != d else repr(d)
        out.append(f"{t!r},{cell},{direction}" if with_dir else f"{t!r},{cell}")
    return "\n".join(out) + "\n"


# -- the paths a [link] table names --------------------------------------------------------------------
def is_profile_path(name: str) -> bool:
    """Whether a ``profile`` value names a file (``*.toml`` or with a folder) rather than a shipped profile."""
    return name.endswith(".toml") or "/" in name or "\\" in name


def absolute_link_paths(table: Mapping[str, Any] | None, base: Path) -> dict[str, Any]:
    """A ``[link]`` table with its relative ``trace`` files (in it and in ``up`` / ``down``) and a
    ``profile`` file made absolute against ``base`` (a mission's folder, or the working directory for
    a flag), so that every process that reads the flown ``mission.toml`` finds the same files."""
    out: dict[str, Any] = {k: (dict(v) if isinstance(v, Mapping) else v) for k, v in (table or {}).items()}

    def fix(t: dict[str, Any], key: str) -> None:
        v = t.get(key)
        if isinstance(v, str) and v and (key == "trace" or is_profile_path(v)):
            p = Path(v).expanduser()
            t[key] = str(p if p.is_absolute() else (base / p).absolute())

    fix(out, "trace")
    fix(out, "profile")
    for d in DIRECTIONS:
        if isinstance(out.get(d), dict):
            fix(out[d], "trace")
    return out

"""``cells.csv``: one row per flown cell, its columns, how a finished run becomes a row, and
the file written a whole line at a time (so a killed sweep resumes with what it had).

In:  a :class:`~bridge.sweep.grid.Cell` and its :class:`~bridge.record.runlog.Run`; a ``cells.csv`` or
     ``sweep.json`` to read back
Out: rows of :data:`COLUMNS` (units: ``rms``/``max`` m, ``settling_s``/``flown_s`` s, ``tv_u2`` N/s,
     ``ripple_u2`` N, packet counts), appended to ``cells.csv`` one whole line each
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bridge.record.metrics import errors
from bridge.record.runlog import LineWriter, Run
from bridge.sweep.grid import AXES, Cell
from params import ConfigError

COLUMNS = (
    "controller", "rate_hz", "delay_ms", "jitter_ms", "loss_pct", "burst_len", "seed",
    "rms", "max", "settling_s", "tv_u2", "ripple_u2", "outcome", "class",
    "up_sent", "up_lost", "down_sent", "down_lost", "flown_s", "error",
)


INT_COLUMNS = ("seed", "up_sent", "up_lost", "down_sent", "down_lost")


STR_COLUMNS = ("controller", "outcome", "class", "error")


CELLS_CSV = "cells.csv"


SWEEP_JSON = "sweep.json"


RIPPLE_WINDOW_S = 0.2  # moving-average window of the u2 ripple: content above ~5 Hz counts


def ripple_rms(t: np.ndarray, u: np.ndarray, rate_hz: float, window_s: float = RIPPLE_WINDOW_S) -> float:
    """High-frequency RMS of a signal over the second half of its time span (same unit as u).

    The signal minus its centred moving average over ``window_s`` (so content above about
    1/window_s Hz), over t >= half the span, half a window away from both ends. This is the
    limit-cycle detector: a chattering or oscillating attitude input has a large ripple.
    """
    n = 2 * int(round(0.5 * window_s * rate_hz)) + 1  # odd: the average is centred exactly
    if len(u) < 3 * n:
        return 0.0
    mean = np.convolve(u, np.ones(n) / n, mode="same")
    sel = t >= t[0] + 0.5 * (t[-1] - t[0])
    sel[: n // 2 + 1] = False
    sel[len(sel) - n // 2 - 1:] = False
    if not sel.any():
        return 0.0
    return float(np.sqrt(np.mean((u - mean)[sel] ** 2)))


def row_from_run(cell: Cell, run: Run) -> dict[str, Any]:
    """A ``cells.csv`` row from a finished run (without ``class``)."""
    s = run.summary
    tr = run.trace
    t = tr["t"]
    late = t >= s["rms_from_s"]
    max3d = None
    if late.any():
        e = errors(tr)
        m = float(np.max(np.sqrt(e["x"][late] ** 2 + e["y"][late] ** 2 + e["z"][late] ** 2)))
        max3d = m if math.isfinite(m) else None
    settle = [s["axes"][a]["settling_s"] for a in ("x", "y", "z") if s["axes"][a]["settling_s"] is not None]
    link = s.get("link") or {}
    up, down = link.get("up") or {}, link.get("down") or {}
    ripple = ripple_rms(t, tr["u2"], s["rate_hz"]) if len(t) else None
    return {
        **{a: getattr(cell, a) for a in AXES},
        "seed": cell.seed,
        "rms": s.get("rms_3d"),
        "max": max3d,
        "settling_s": max(settle) if settle else None,
        "tv_u2": s["inputs"]["u2"]["tv_per_s"],
        "ripple_u2": ripple if ripple is None or math.isfinite(ripple) else None,
        "outcome": s["outcome"],
        "up_sent": int(up.get("sent", 0)),
        "up_lost": int(up.get("lost", 0)),
        "down_sent": int(down.get("sent", 0)),
        "down_lost": int(down.get("lost", 0)),
        "flown_s": s.get("duration_s"),
        "error": "",
    }


def error_row(cell: Cell, why: str) -> dict[str, Any]:
    """The row of a cell that could not be flown (outcome ``error``)."""
    row: dict[str, Any] = {c: None for c in COLUMNS}
    row.update({a: getattr(cell, a) for a in AXES})
    row.update(seed=cell.seed, outcome="error", error=" ".join(why.split())[:300])
    return row


def format_row(row: Mapping[str, Any]) -> str:
    """One ``cells.csv`` line (no newline): floats as ``repr`` (exact round trip), None empty."""
    out = io.StringIO()
    csv.writer(out, lineterminator="").writerow(_cell_text(row.get(c)) for c in COLUMNS)
    return out.getvalue()


def _cell_text(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return repr(v)
    return str(v)


def parse_row(values: Sequence[str]) -> dict[str, Any]:
    """A ``cells.csv`` record (strings, in :data:`COLUMNS` order) back to typed values."""
    row: dict[str, Any] = {}
    for c, v in zip(COLUMNS, values, strict=True):
        if c in STR_COLUMNS:
            row[c] = v
        elif v == "":
            row[c] = None
        elif c in INT_COLUMNS:
            row[c] = int(v)
        else:
            row[c] = float(v)
    return row


def read_cells(path: str | Path) -> list[dict[str, Any]]:
    """Read ``cells.csv``: whole, well-formed records only (a torn last line is ignored)."""
    p = Path(path)
    if not p.exists():
        raise ConfigError(f"{p}: no such file")
    text = p.read_text()
    lines = text.split("\n")
    if lines and lines[-1] != "":
        lines = lines[:-1]  # torn last line: no newline yet
    rows = []
    reader = csv.reader(lines)
    header = next(reader, None)
    if header is None:
        return rows
    if tuple(header[: len(COLUMNS)]) != COLUMNS:
        raise ConfigError(f"{p}: not a sweep's cells.csv (header {','.join(header[:4])}...)")
    for rec in reader:
        if len(rec) != len(COLUMNS):
            continue
        try:
            rows.append(parse_row(rec))
        except ValueError:
            continue
    return rows


def row_key(row: Mapping[str, Any]) -> tuple[Any, ...]:
    return tuple(row[a] for a in (*AXES, "seed"))


class CellsFile:
    """``cells.csv`` while a sweep runs: finished rows appended as whole lines, one write each."""

    def __init__(self, path: Path, rows: Iterable[Mapping[str, Any]] = ()) -> None:
        self.path = path
        tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
        self._w = LineWriter(tmp, ",".join(COLUMNS), batch=1)
        for r in rows:
            self._w.write(format_row(r))
        os.replace(tmp, path)  # the kept rows, or an empty table, replace the old file at once

    def append(self, row: Mapping[str, Any]) -> None:
        self._w.write(format_row(row))

    def close(self) -> None:
        self._w.close()


def write_cells(path: Path, rows: Iterable[Mapping[str, Any]]) -> None:
    """Write a complete ``cells.csv`` atomically (temporary name, then rename)."""
    CellsFile(path, rows).close()


def read_sweep_json(path: Path) -> dict[str, Any]:
    """A sweep's ``sweep.json`` (ConfigError naming the file if unreadable)."""
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise ConfigError(f"{path}: unreadable ({exc})") from None

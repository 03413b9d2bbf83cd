"""``cells.csv``: one row per flown cell, its columns, how a finished run becomes a row, and
the file written a whole line at a time (so a killed sweep resumes with what it had).

In:  a :class:`~bridge.sweep.grid.Cell` and its :class:`~bridge.record.runlog.Run`; a ``cells.csv`` or
     ``sweep.json`` to read back
Out: rows of :data:`COLUMNS` (units: ``rms``/``max`` m, ``settling_s``/``flown_s`` s, ``tv_u2`` N/s,
     ``ripple_u2`` N, packet counts; ``policies``: ``ok``, the broken policies' names, ``""`` not judged;
     ``jitter_capped``: each jitter the delay capped, the half-width flown ms, ``""`` none),
     appended to ``cells.csv`` one whole line each
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bridge.link.model import jitter_cell
from bridge.record.metrics import errors, ripple_rms  # ripple_rms lives with the other metrics
from bridge.record.runlog import LineWriter, Run
from bridge.swarm import SEVERITY, FleetRun
from bridge.sweep.classes import Classes, classify
from bridge.sweep.grid import AXES, NO_SCHEME, Cell
from controller.law import DISCRETIZED
from params import ConfigError, check_depth, read_regular_file
from params.text import one_line

COLUMNS = (
    "controller", "rate_hz", "delay_ms", "jitter_ms", "loss_pct", "burst_len", "estimator", "noise", "wind_mps",
    "turbulence", "discretization", "vehicles", "seed",
    "rms", "max", "settling_s", "tv_u2", "ripple_u2", "outcome", "class",
    "up_sent", "up_lost", "down_sent", "down_lost", "flown_s", "worst_vehicle", "closest_m", "error", "policies",
    "jitter_capped",
)
FLEET_COLUMNS = ("vehicles", "worst_vehicle", "closest_m")  # since issue 28: a cell of several vehicles (a fleet)
POLICIES_OK = "ok"  # the policies column: every policy held; else the broken ones' names; "" not judged


# cells.csv before the vehicle's axes (issue 12), before the air's (issue 27), before the discretization's (issue
# 24), before fleets (issue 28), before the policies column and before the jitter_capped one: read (bsst report)
# with the values its sweep.json's mission flew (one vehicle; policies not judged; jitter_capped "": not said), never
# resumed (bridge.sweep.campaign refuses it, naming the file)
_BEFORE_JITTER_CAP = tuple(c for c in COLUMNS if c != "jitter_capped")  # before the jitter_capped column
_BEFORE_POLICIES = tuple(c for c in _BEFORE_JITTER_CAP if c != "policies")
_SINGLE = tuple(c for c in _BEFORE_POLICIES if c not in FLEET_COLUMNS)
LEGACY_COLUMNS = tuple(c for c in _SINGLE
                       if c not in ("estimator", "noise", "wind_mps", "turbulence", "discretization"))
WEATHERLESS_COLUMNS = tuple(c for c in _SINGLE if c not in ("wind_mps", "turbulence", "discretization"))
LEGACY_LAYOUTS = (LEGACY_COLUMNS, WEATHERLESS_COLUMNS,
                  tuple(c for c in _SINGLE if c not in ("estimator", "noise", "discretization")),
                  tuple(c for c in _SINGLE if c != "discretization"), _SINGLE, _BEFORE_POLICIES, _BEFORE_JITTER_CAP)


INT_COLUMNS = ("vehicles", "seed", "up_sent", "up_lost", "down_sent", "down_lost", "worst_vehicle")


STR_COLUMNS = ("controller", "estimator", "turbulence", "discretization", "outcome", "class", "error", "policies",
               "jitter_capped")
# outcomes of a cell that measured nothing: it could not be flown, its law failed, or its vehicle denied the arm
FAILED = ("error", "law_failed", "denied")
OUTCOMES = (*SEVERITY, "error")  # a row's outcome: a run's (a fleet's worst vehicle's), or error (not flown)


KEY_COLUMNS = (*AXES, "seed")  # what names a row's cell: never empty but discretization, empty for a law without a
# super-twisting step (smc, pid, one's own), whose cell is one whatever the scheme (bridge.sweep.grid)


CELLS_CSV = "cells.csv"


SWEEP_JSON = "sweep.json"


MISSION_HASH = "mission_toml_sha256"  # sweep.json: the hash of the mission.toml the sweep wrote beside it
INPUT_HASHES = "input_files_sha256"  # sweep.json: {path: hash} of the law files, traces, profiles the cells read
ENGINES = "engines"  # sweep.json: the engines that flew its rows (two: a resume flew some on the other one)
UNRECORDED = "unrecorded"  # in ENGINES: rows kept from a sweep.json of before the field (which engine: not known)
RECORDS = (MISSION_HASH, INPUT_HASHES, ENGINES)  # sweep.json's records beside the sweep's identity


def row_from_run(cell: Cell, run: Run) -> dict[str, Any]:
    """A ``cells.csv`` row from a finished run (without ``class``, and without a fleet's ``worst_vehicle`` and
    ``closest_m``: empty for one vehicle, as in a batch row)."""
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
        **{f"{d}_{k}": _count(side, k) for d, side in (("up", up), ("down", down)) for k in ("sent", "lost")},
        "flown_s": s.get("duration_s"),
        # a law that failed in flight measured nothing: the row says why, as a cell that could not be flown does
        "error": one_line(str(s.get("ended_by", {}).get("how", ""))) if s["outcome"] in FAILED else "",
        "policies": policies_cell([s.get("policies")]),
        "jitter_capped": jitter_cell(link.get("jitter_capped") or ()),
    }


def _count(side: Mapping[str, Any], key: str) -> int | None:
    """A link direction's count (none: 0); null where a side killed left it unknown (its ``unknown``), as the
    cell's empty value, never 0."""
    v = side.get(key, 0)
    return None if v is None else int(v)


def broke_policy(row: Mapping[str, Any]) -> bool:
    """Whether a row's run broke a safety policy: its ``policies`` names one (``ok`` and not judged do not)."""
    return row.get("policies") not in (None, "", POLICIES_OK)


def seeds_alike(rows: Sequence[Mapping[str, Any]], point: Callable[[Mapping[str, Any]], Any]) -> bool | None:
    """Whether, at every ``point`` (a row's grid point or probed value), the rows' seeds flew the same flight (RMS
    and outcome alike: a mission that draws nothing at random), so that its seeds added nothing; None with fewer
    than two seeds."""
    if len({r["seed"] for r in rows}) < 2:
        return None
    flights: dict[Any, set[tuple[Any, Any]]] = {}
    for r in rows:
        flights.setdefault(point(r), set()).add((r["rms"], r["outcome"]))
    return all(len(f) == 1 for f in flights.values())


def policies_cell(verdicts: Sequence[Sequence[Mapping[str, Any]] | None]) -> str:
    """The ``policies`` column of one or more runs' ``summary["policies"]`` (bridge.record.policies): ``ok`` when
    every policy of every run held, else the broken ones' names (space-separated, in the order judged); ``""``
    (not judged) when a run has none."""
    if any(v is None for v in verdicts):
        return ""
    broken: list[str] = []
    for v in verdicts:
        broken += [d["name"] for d in v or () if not d.get("ok") and d["name"] not in broken]
    return " ".join(broken) if broken else POLICIES_OK


WORST_OF = ("rms", "max", "settling_s", "tv_u2", "ripple_u2")  # a fleet's row: the largest of its vehicles'


def row_from_fleet(cell: Cell, run: FleetRun) -> dict[str, Any]:
    """A ``cells.csv`` row from a fleet's flight (without ``class``): each figure of :data:`WORST_OF` the worst
    vehicle's (the largest any vehicle flew), the fleet's ``outcome`` (its worst vehicle's), the packets of every
    vehicle's link summed, ``worst_vehicle`` the id of the vehicle with the worst outcome and then the largest RMS,
    and ``closest_m`` the closest approach between any two rotor discs (m)."""
    rows = [row_from_run(cell, r) for r in run.runs]
    ids = [v["id"] for v in run.summary["vehicles"]]
    rank = {o: i for i, o in enumerate(SEVERITY)}
    outcomes = [v["outcome"] for v in run.summary["vehicles"]]  # a contact made it "collision" for both

    def badness(i: int) -> tuple[int, float]:
        rms = rows[i]["rms"]
        return rank.get(outcomes[i], len(SEVERITY)), math.inf if rms is None else rms

    worst = max(range(len(rows)), key=badness)
    out = dict(rows[worst])
    for c in WORST_OF:
        values = [r[c] for r in rows if r[c] is not None]
        out[c] = max(values) if values else None
    for c in ("up_sent", "up_lost", "down_sent", "down_lost"):  # unknown for one vehicle: unknown for the fleet
        out[c] = None if any(r[c] is None for r in rows) else sum(r[c] for r in rows)
    out["flown_s"] = max((r["flown_s"] for r in rows if r["flown_s"] is not None), default=None)
    errors = [f"vehicle {i}: {r['error']}" for i, r in zip(ids, rows) if r["error"]]
    out.update(outcome=run.summary["outcome"], worst_vehicle=ids[worst],
               closest_m=run.summary["separation"]["closest_m"], error=" ".join(errors)[:300],
               policies=policies_cell([r.summary.get("policies") for r in run.runs]),
               jitter_capped=" ".join(dict.fromkeys(r["jitter_capped"] for r in rows if r["jitter_capped"])))
    return out


def error_row(cell: Cell, why: str) -> dict[str, Any]:
    """The row of a cell that could not be flown (outcome ``error``)."""
    row: dict[str, Any] = {c: None for c in COLUMNS}
    row.update({a: getattr(cell, a) for a in AXES})
    row.update(seed=cell.seed, outcome="error", error=one_line(why), policies="", jitter_capped="")
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


def parse_row(values: Sequence[str], columns: Sequence[str] = COLUMNS) -> dict[str, Any]:
    """A ``cells.csv`` record (strings, in ``columns`` order) back to typed values; a
    ``ValueError`` names the column and what it holds when a value is not of its column's kind
    (numbers finite, the axes and the seed never empty but a law's without a scheme's ``discretization``, the outcome
    one of :data:`OUTCOMES`: what a sweep writes)."""
    if len(values) != len(columns):
        n = len(values)
        raise ValueError(f"{n} field{'s' if n != 1 else ''}, expected {len(columns)} ({','.join(columns[:3])},...)")
    row: dict[str, Any] = {}
    for c, v in zip(columns, values, strict=True):
        if c == "outcome" and v not in OUTCOMES:
            raise ValueError(f"outcome: expected one of {', '.join(OUTCOMES)}, got {v[:40]!r}")
        if c in STR_COLUMNS:
            row[c] = v
        elif v == "":
            if c in KEY_COLUMNS:
                raise ValueError(f"{c}: is empty (every row names its cell)")
            row[c] = None
        elif c in INT_COLUMNS:
            try:
                row[c] = int(v)
            except ValueError:
                raise ValueError(f"{c}: expected an integer, got {v[:40]!r}") from None
        else:
            try:
                x = float(v)
            except ValueError:
                raise ValueError(f"{c}: expected a number, got {v[:40]!r}") from None
            if not math.isfinite(x):
                raise ValueError(f"{c}: expected a finite number, got {v[:40]!r}")
            row[c] = x
    return row


def read_cells(path: str | Path, legacy: Mapping[str, Any] | None = None, classes: Classes | None = None,
               meta: Mapping[str, Any] | None = None) -> list[dict[str, Any]]:
    """Read ``cells.csv``: every whole line a well-formed row, or a :class:`ConfigError` naming the
    file, the line and what is wrong there. Only an unfinished last line (no newline yet: where a
    killed sweep stopped writing) is left out; a blank line is skipped. With ``classes`` (what a resume
    keeps) each row's ``class`` must be the one its outcome, RMS and ripple give by them. No two rows are
    one cell; with ``meta`` (the sweep's ``sweep.json``, ``bsst report``'s and a resume's) every row's values are
    among its grid's (:func:`grid_values`): both judged on the columns the file has.

    A file of an older sweep (:data:`LEGACY_LAYOUTS`: no ``estimator``, ``noise``, or no ``wind_mps``,
    ``turbulence``, or no ``discretization``, or no ``policies``) is read when ``legacy`` gives the values its
    cells flew (``{"estimator": ..., "noise": ..., "wind_mps": ..., "turbulence": ..., "discretization": ...,
    "policies": ""}``), refused otherwise."""
    p = Path(path)
    data = read_regular_file(p, f"a sweep's {CELLS_CSV}")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise ConfigError(f"{p}: line {line}: not UTF-8 text (byte {exc.start}); not a sweep's {CELLS_CSV}") from None
    lines = text.split("\n")[:-1]  # the part after the last newline is a torn row, or nothing
    rows: list[dict[str, Any]] = []
    if not lines:
        return rows
    header = _record(p, 1, lines[0])
    columns = COLUMNS
    if tuple(header) in LEGACY_LAYOUTS:
        columns = tuple(header)
        if legacy is None:
            lacks = ", ".join(c for c in COLUMNS if c not in columns)
            raise ConfigError(f"{p}: line 1: a {CELLS_CSV} of an older bsst (no {lacks} columns): "
                              "bsst report reads it, a sweep cannot add to it; fly the sweep into another --out")
    elif tuple(header) != COLUMNS:
        raise ConfigError(f"{p}: line 1: not a sweep's {CELLS_CSV} header (expected {','.join(COLUMNS[:4])},..., "
                          f"got {','.join(header[:4])[:60]!r}...)")
    grid = {a: v for a, v in (grid_values(meta) or {}).items() if a in columns} if meta is not None else {}
    seen: dict[tuple[Any, ...], int] = {}  # each cell's line
    for n, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        try:
            row = parse_row(_record(p, n, line), columns)
            want = row["class"] if classes is None else classify(row, classes)
            if (row["class"], want) == ("error", "crashed"):  # a sweep's of before the class (its crash an error
                row["class"] = want  # with no reason given): kept as a sweep classes it now
            if row["class"] != want:
                raise ValueError(f"class {row['class']!r} contradicts the row (outcome {row['outcome']}, rms "
                                 f"{row['rms']} m, ripple_u2 {row['ripple_u2']} N: {want!r} by the sweep's classes)")
            row = {c: row[c] if c in row else legacy[c] for c in COLUMNS} if legacy is not None else row
            outside = next((a for a in grid if not _in_grid(row, a, grid[a])), None)
            if outside is not None:  # hand-edited, or another sweep's: never counted as one of this grid's cells
                raise ValueError(f"{outside} {_shown(row[outside])} is not in the sweep's grid (its {SWEEP_JSON}: "
                                 f"{', '.join(_shown(v) for v in grid[outside][:10])}"
                                 f"{', ...' if len(grid[outside]) > 10 else ''})")
            key = tuple(row[c] for c in KEY_COLUMNS if c in columns)  # (an older file's: what it records)
            if key in seen:
                raise ValueError(f"the same cell as line {seen[key]} (a sweep writes one row per cell)")
            seen[key] = n
            rows.append(row)
        except ValueError as exc:
            raise ConfigError(f"{p}: line {n}: {exc} (a damaged row: mend or delete that line)") from None
    return rows


def _shown(v: Any) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)[:40] or "(empty)"


def _in_grid(row: Mapping[str, Any], axis: str, values: Sequence[Any]) -> bool:
    """Whether a row's value of ``axis`` is one of its grid's ``values``; a law without a super-twisting step's
    discretization also where empty (:data:`NO_SCHEME`: what its cells carry), and never so for ``bsst``'s."""
    if axis == "discretization" and row.get("controller") not in DISCRETIZED and row[axis] == NO_SCHEME:
        return True
    return row[axis] in values


def one_per_cell(rows: Iterable[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """``rows`` as the cells a sweep flies now: a row of a law without a super-twisting step that names a
    discretization (an older sweep's: it flew such a law once per scheme, the same flight under each label, until the
    third wave's thirty-ninth session) relabelled :data:`NO_SCHEME`, and only the first row of each cell kept."""
    out: dict[tuple[Any, ...], dict[str, Any]] = {}
    for r in rows:
        if r["controller"] not in DISCRETIZED and r["discretization"] != NO_SCHEME:
            r = {**r, "discretization": NO_SCHEME}
        out.setdefault(row_key(r), dict(r))
    return list(out.values())


def grid_values(meta: Mapping[str, Any]) -> dict[str, list[Any]] | None:
    """The values of each axis and the seeds (``seed``) of a sweep's grid, as its ``sweep.json`` (``meta``) says
    them, or None where it does not (no ``axes`` or ``seeds``: an older bsst's, or none): the rows that belong to
    the sweep (:func:`read_cells`) and how many there are (:func:`bridge.sweep.report.recorded_cell_count`)."""
    axes, seeds = meta.get("axes"), meta.get("seeds")
    if not isinstance(axes, Mapping) or not isinstance(seeds, list) or not seeds:
        return None
    return {**{a: axes[a] for a in AXES if axes.get(a)}, "seed": seeds}  # (an axis it does not list: not said)


def _record(p: Path, n: int, line: str) -> list[str]:
    """One line of ``cells.csv`` split into its fields (ConfigError naming the line if it cannot be)."""
    try:
        return next(csv.reader([line], strict=True), [])  # as csv.writer writes: a stray quote is damage
    except csv.Error as exc:
        raise ConfigError(f"{p}: line {n}: not a CSV row ({exc})") from None


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
    """A sweep's ``sweep.json``: a JSON object whose fields the readers use have their kinds
    (``mission``, ``grid``, ``classes`` objects; ``mode`` a string; ``swept`` and ``columns``
    lists of names; ``seeds`` a list of integers). Anything else is a :class:`ConfigError`
    naming the file and the field."""
    data = read_regular_file(path, f"a sweep's {SWEEP_JSON}", MAX_SWEEP_JSON_BYTES)
    try:
        meta = json.loads(data.decode("utf-8"))
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: not UTF-8 text; not a sweep's {SWEEP_JSON}") from None
    except ValueError as exc:
        raise ConfigError(f"{path}: not valid JSON ({exc})") from None
    except RecursionError:
        raise ConfigError(f"{path}: nested too deeply; not a sweep's {SWEEP_JSON}") from None
    if not isinstance(meta, dict):
        raise ConfigError(f"{path}: expected a JSON object, got {type(meta).__name__ if meta is not None else 'null'}")
    check_depth(meta, str(path))
    for key, kind in SWEEP_JSON_FIELDS.items():
        if key in meta and not _is_kind(meta[key], kind):
            raise ConfigError(f"{path}: {key}: expected {kind}, got {str(meta[key])[:40]!r}")
    name = meta.get("mission", {}).get("name", "")
    if not isinstance(name, str):
        raise ConfigError(f"{path}: mission.name: expected a string, got {str(name)[:40]!r}")
    lists = [a for a, v in meta.get("axes", {}).items() if not isinstance(v, list)]
    if lists:
        raise ConfigError(f"{path}: axes: {lists[0][:40]!r}: expected a list of values")
    unknown = [a for a in meta.get("swept", ()) if a not in AXES]
    if unknown:
        raise ConfigError(f"{path}: swept: {unknown[0][:40]!r} is not an axis ({', '.join(AXES)})")
    return meta


MAX_SWEEP_JSON_BYTES = 16 << 20  # a sweep.json is a few kB (its mission and grid)


SWEEP_JSON_FIELDS = {"mission": "an object", "grid": "an object", "classes": "an object", "mode": "a string",
                     "swept": "a list of names", "columns": "a list of names", "seeds": "a list of integers",
                     "axes": "an object", MISSION_HASH: "a string", INPUT_HASHES: "an object",
                     ENGINES: "a list of names"}


def _is_kind(v: Any, kind: str) -> bool:
    if kind == "an object":
        return isinstance(v, dict)
    if kind == "a string":
        return isinstance(v, str)
    if kind == "a list of names":
        return isinstance(v, list) and all(isinstance(x, str) for x in v)
    return isinstance(v, list) and all(isinstance(x, int) and not isinstance(x, bool) for x in v)

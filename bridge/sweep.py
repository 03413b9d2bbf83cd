"""Latency and dropout campaigns (``bsst sweep``): a grid of link impairments, flown in parallel.

A sweep flies one mission over the product of a few lists (the *grid*): control law, control
rate, link delay, jitter, loss and mean loss-burst length, each grid point with several
seeds. One grid point flown with one seed is a *cell*: one run, one row of ``cells.csv``.

Delay, jitter, loss and burst length apply to **both** link directions (``[link.up]``,
controller -> vehicle, and ``[link.down]``, vehicle -> controller) with the same values; the
mission's other link keys (blackouts, duplication, a direction's own seed, ...) are kept. An
axis that is not swept keeps the mission's own value and is not overridden.

Cells run in a local process pool (``jobs`` workers), or on a Dask distributed cluster
(``client``). Each finished cell is appended to ``cells.csv`` at once as one whole line, so a
sweep killed at any point resumes with only its missing cells (``resume=True``); at the end
the file is rewritten in grid order, so a resumed sweep's file equals an uninterrupted one's.
A cell that raises (or whose worker process dies) is recorded with outcome ``error`` and
never stops the sweep.

Scripting::

    from bridge.sweep import Grid, sweep
    rows = sweep("missions/sine.toml", Grid(delay_ms=(0, 10), loss_pct=(0, 20), seeds=2), jobs=2)
"""

from __future__ import annotations

import csv
import io
import json
import math
import multiprocessing as mp
import os
import signal
import sys
import time
from collections import deque
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import asdict, dataclass, field, fields
from itertools import product
from pathlib import Path
from typing import Any

import numpy as np

from bridge.metrics import errors
from bridge.runlog import LineWriter, Run, run_dir, write_json_atomic
from missions import CONTROLLERS, Mission, load_mission
from params import ConfigError, Table, dump_toml, load_toml

# Grid axes, in the order of the product (the last varies fastest; seeds vary faster still).
AXES = ("controller", "rate_hz", "delay_ms", "jitter_ms", "loss_pct", "burst_len")
LINK_AXES = ("delay_ms", "jitter_ms", "loss_pct", "burst_len")
# Short names: command-line flags (--delay ...) and heat-map file names (map_delay_loss.png).
SHORT = {"controller": "controller", "rate_hz": "rate", "delay_ms": "delay", "jitter_ms": "jitter",
         "loss_pct": "loss", "burst_len": "burst"}
# Value of a link axis when neither the sweep nor the mission's [link.up] sets it.
LINK_DEFAULTS = {"delay_ms": 0.0, "jitter_ms": 0.0, "loss_pct": 0.0, "burst_len": 0.0}
# (lo, hi) of every numeric axis, units in the names: ms, %, packets, Hz.
RANGES = {"rate_hz": (50.0, 1000.0), "delay_ms": (0.0, 10000.0), "jitter_ms": (0.0, 10000.0),
          "loss_pct": (0.0, 100.0), "burst_len": (0.0, 1e6)}
MODES = ("offline", "lockstep")

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


# ----------------------------------------------------------------------------- the grid


@dataclass(frozen=True)
class Grid:
    """The axes of a sweep. An empty axis is not swept: the mission's own value is flown.

    ``controller``: law names; ``rate_hz``: control rates (Hz); ``delay_ms``: fixed one-way
    delay (ms); ``jitter_ms``: jitter amplitude (ms); ``loss_pct``: packet loss (%);
    ``burst_len``: mean loss-burst length (packets, Gilbert-Elliott; 0 = independent losses).
    ``seeds``: how many seeds per grid point (mission seed, +1, ...) or the seeds themselves.
    """

    controller: tuple[str, ...] = ()
    rate_hz: tuple[float, ...] = ()
    delay_ms: tuple[float, ...] = ()
    jitter_ms: tuple[float, ...] = ()
    loss_pct: tuple[float, ...] = ()
    burst_len: tuple[float, ...] = ()
    seeds: int | tuple[int, ...] = 1

    def __post_init__(self) -> None:
        for name in AXES:
            values = getattr(self, name)
            if isinstance(values, (str, int, float)):
                values = (values,)
            values = tuple(values) if name == "controller" else tuple(float(v) for v in values)
            object.__setattr__(self, name, values)
            if len(set(values)) != len(values):
                raise ConfigError(f"grid.{name}: repeated value in {list(values)}")
            for v in values:
                if name == "controller":
                    if v not in CONTROLLERS:
                        raise ConfigError(f"grid.controller: must be among {', '.join(CONTROLLERS)}; got {v!r}")
                else:
                    lo, hi = RANGES[name]
                    if not (lo <= v <= hi):  # also rejects nan
                        raise ConfigError(f"grid.{name}: must be in [{lo:g}, {hi:g}], got {v:g}")
        s = self.seeds
        if isinstance(s, bool) or not isinstance(s, (int, tuple, list)):
            raise ConfigError(f"grid.seeds: expected a count or a list of seeds, got {s!r}")
        if isinstance(s, int):
            if not 1 <= s <= 10000:
                raise ConfigError(f"grid.seeds: must be in [1, 10000], got {s}")
        else:
            s = tuple(int(v) for v in s)
            object.__setattr__(self, "seeds", s)
            if not s or len(set(s)) != len(s) or not all(0 <= v <= 2**31 - 1 for v in s):
                raise ConfigError(f"grid.seeds: expected distinct seeds in [0, 2^31-1], got {list(s)}")

    @classmethod
    def of(cls, grid: Grid | Mapping[str, Any]) -> Grid:
        """A :class:`Grid`, or one from a mapping of axis name -> list (and ``seeds``)."""
        if isinstance(grid, Grid):
            return grid
        unknown = sorted(set(grid) - {f.name for f in fields(cls)})
        if unknown:
            raise ConfigError(f"grid.{unknown[0]}: unknown axis (axes: {', '.join(AXES)}, seeds)")
        return cls(**dict(grid))

    def swept(self) -> tuple[str, ...]:
        """The axes given (even with one value)."""
        return tuple(a for a in AXES if getattr(self, a))

    def seed_list(self, mission: Mission) -> tuple[int, ...]:
        """The seeds each grid point is flown with: a count counts up from the mission's seed."""
        if isinstance(self.seeds, int):
            return tuple(mission.seed + i for i in range(self.seeds))
        return tuple(self.seeds)

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {a: list(getattr(self, a)) for a in AXES if getattr(self, a)}
        d["seeds"] = self.seeds if isinstance(self.seeds, int) else list(self.seeds)
        return d


@dataclass(frozen=True)
class Cell:
    """One grid point flown with one seed: the effective values of every axis.

    ``link`` names the link axes that override the mission's ``[link.up]``/``[link.down]``.
    """

    controller: str
    rate_hz: float
    delay_ms: float
    jitter_ms: float
    loss_pct: float
    burst_len: float
    seed: int
    link: tuple[str, ...] = ()

    def key(self) -> tuple[Any, ...]:
        """What identifies the cell's row in ``cells.csv``."""
        return (self.controller, self.rate_hz, self.delay_ms, self.jitter_ms, self.loss_pct, self.burst_len,
                self.seed)

    def label(self) -> str:
        return " ".join(f"{a}={getattr(self, a):g}" if a != "controller" else f"{a}={self.controller}"
                        for a in (*AXES, "seed"))


def mission_value(mission: Mission, axis: str) -> Any:
    """The mission's own value of an axis (link axes: ``[link.up]``, else ``[link]``, else none)."""
    if axis == "controller":
        return mission.controller
    if axis == "rate_hz":
        return float(mission.rate_hz)
    up = mission.link.get("up")
    for table in (up if isinstance(up, Mapping) else {}, mission.link):
        v = table.get(axis)
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            return float(v)
    return LINK_DEFAULTS[axis]


def cells(mission: Mission, grid: Grid) -> list[Cell]:
    """Every cell of the sweep, in grid order (axes in :data:`AXES` order, seed fastest)."""
    given = set(grid.swept())
    lists = [getattr(grid, a) or (mission_value(mission, a),) for a in AXES]
    link = tuple(a for a in LINK_AXES if a in given)
    seeds = grid.seed_list(mission)
    return [Cell(*values, seed=s, link=link) for values in product(*lists) for s in seeds]


def cell_mission(mission: Mission, cell: Cell) -> Mission:
    """The mission a cell flies: law, rate and seed replaced, link axes set in both directions."""
    from bridge.link import DIRECTIONS, merge_link_tables

    over = {d: {a: getattr(cell, a) for a in cell.link} for d in DIRECTIONS} if cell.link else {}
    link = merge_link_tables(mission.link, over)
    return mission.with_overrides(controller=cell.controller, rate_hz=cell.rate_hz, seed=cell.seed, link=link)


# ----------------------------------------------------------------------------- one cell


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


def run_cell(mission: Mission, cell: Cell, mode: str = "offline") -> dict[str, Any]:
    """Fly one cell (in a worker process or on a Dask worker) and return its row.

    Never raises for a failing flight: the exception becomes an ``error`` row.
    """
    try:
        m = cell_mission(mission, cell)
        if mode == "lockstep":
            run = _fly_lockstep(m)
        else:
            from bridge.loop import simulate

            run = simulate(m, plots=False)
        return row_from_run(cell, run)
    except Exception as exc:  # a failed cell is a result, never the end of the sweep
        return error_row(cell, f"{type(exc).__name__}: {exc}")


def _fly_lockstep(mission: Mission) -> Run:
    """Fly with the full SITL processes in lockstep (the link model applied in simulation
    time, as offline), on an ``--instance`` port set held exclusively while it flies."""
    from bridge.session import instance_slot, sitl

    with instance_slot() as instance:
        return sitl(mission, realtime=False, instance=instance, plots=False)


# ----------------------------------------------------------------------------- cells.csv


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


# ----------------------------------------------------------------------------- the sweep


@dataclass(frozen=True)
class Classes:
    """Thresholds that class a cell (the rules: :func:`bridge.report.classify`).

    ``clean_rms_m``: 3-D RMS error (m) up to which a cell is clean; ``diverged_rms_m``: RMS (m)
    above which it counts as diverged even if the plant's own check did not trip;
    ``ripple_u2``: high-frequency RMS of u2 (N, see :func:`ripple_rms`) above which the
    attitude loop is limit-cycling.
    """

    clean_rms_m: float = 1e-3
    diverged_rms_m: float = 1.0
    ripple_u2: float = 20.0

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (0.0 < v < math.inf):
                raise ConfigError(f"classes.{f.name}: must be a positive number, got {v!r}")
        if self.diverged_rms_m <= self.clean_rms_m:
            raise ConfigError("classes.diverged_rms_m: must be larger than classes.clean_rms_m")

    @classmethod
    def from_table(cls, t: Table) -> Classes:
        d = cls()
        c = cls(**{f.name: t.number(f.name, getattr(d, f.name), lo=0.0, lo_open=True, hi=1e9) for f in fields(cls)})
        t.done()
        return c


@dataclass(frozen=True)
class Sweep:
    """A whole campaign: the mission, its grid, how to fly the cells and how to class them."""

    mission: Mission
    grid: Grid
    mode: str = "offline"
    classes: Classes = field(default_factory=Classes)
    jobs: int | None = None  # default worker count (a sweep file may set it)

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ConfigError(f"mode: must be one of {', '.join(MODES)}; got {self.mode!r}")

    def cells(self) -> list[Cell]:
        return cells(self.mission, self.grid)

    def identity(self) -> dict[str, Any]:
        """What ``sweep.json`` records, and what ``--resume`` must find unchanged."""
        return json.loads(json.dumps({
            "mission": self.mission.to_dict(),
            "mode": self.mode,
            "grid": self.grid.to_dict(),
            "seeds": list(self.grid.seed_list(self.mission)),
            "axes": {a: _axis_values(self, a) for a in AXES},
            "swept": list(self.grid.swept()),
            "classes": asdict(self.classes),
            "columns": list(COLUMNS),
        }))

    def validate(self) -> None:
        """Build the flight of every law, every rate and every combination of link values once
        (not every cell), so that a bad value fails before any cell runs."""
        from bridge.flight import prepare

        base = self.cells()[0]
        probes = [_replace_cell(base, **{a: v}) for a in ("controller", "rate_hz") for v in getattr(self.grid, a)]
        lists = [getattr(self.grid, a) or (getattr(base, a),) for a in LINK_AXES]
        probes += [_replace_cell(base, **dict(zip(LINK_AXES, vs, strict=True))) for vs in product(*lists)]
        for c in probes:
            try:
                prepare(cell_mission(self.mission, c))
            except ConfigError as exc:
                raise ConfigError(f"sweep cell ({c.label()}): {exc}") from None


def _axis_values(s: Sweep, axis: str) -> list[Any]:
    return list(getattr(s.grid, axis) or (mission_value(s.mission, axis),))


def _replace_cell(c: Cell, **kw: Any) -> Cell:
    d = asdict(c)
    d.update(kw)
    d["link"] = tuple(d["link"])
    return Cell(**d)


def load_sweep(path: str | Path) -> Sweep:
    """Read a sweep file (TOML): ``mission`` (path relative to the file), ``mode``, ``seeds``,
    ``jobs``, ``[grid]`` (axis = [values]) and ``[classes]`` (thresholds). Errors name file and key."""
    p = Path(path)
    src = str(p)
    t = Table(load_toml(p), src)
    mpath = Path(t.string("mission"))
    if not mpath.is_absolute():
        mpath = p.parent / mpath
    if not mpath.exists():
        raise t.error("mission", f"no such file {mpath}")
    mission = load_mission(mpath)
    mode = t.string("mode", "offline", choices=MODES)
    jobs = t.integer("jobs", 0, lo=0, hi=1024) or None
    seeds_raw = t.raw("seeds", 1)
    if isinstance(seeds_raw, list):
        seeds: int | tuple[int, ...] = tuple(_int_list(t, "seeds", 0, 2**31 - 1))
    else:
        seeds = t.integer("seeds", 1, lo=1, hi=10000)
    g = t.table("grid")
    axes: dict[str, Any] = {}
    for a in AXES:
        if g.has(a):
            if a == "controller":
                v = g.raw(a)
                if isinstance(v, str):
                    v = [v]
                if not isinstance(v, list) or not v or not all(isinstance(x, str) for x in v):
                    raise g.error(a, "expected a list of law names")
                bad = [x for x in v if x not in CONTROLLERS]
                if bad:
                    raise g.error(a, f"must be among {', '.join(CONTROLLERS)}; got {bad[0]!r}")
                axes[a] = tuple(v)
            else:
                lo, hi = RANGES[a]
                axes[a] = tuple(_number_list(g, a, lo, hi))
    g.done()
    classes = Classes.from_table(t.table("classes"))
    t.done()
    try:
        grid = Grid(seeds=seeds, **axes)
    except ConfigError as exc:
        raise ConfigError(f"{src}: {exc}") from None
    return Sweep(mission, grid, mode, classes, jobs)


def _number_list(t: Table, key: str, lo: float, hi: float) -> list[float]:
    v = t.raw(key)
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        v = [v]
    if not isinstance(v, list) or not v:
        raise t.error(key, f"expected a non-empty list of numbers, got {v!r}")
    out = []
    for i, x in enumerate(v):
        if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
            raise t.error(key, f"element {i} must be a finite number, got {x!r}")
        if not lo <= x <= hi:
            raise t.error(key, f"element {i} must be in [{lo:g}, {hi:g}], got {x:g}")
        out.append(float(x))
    if len(set(out)) != len(out):
        raise t.error(key, "repeated value")
    return out


def _int_list(t: Table, key: str, lo: int, hi: int) -> list[int]:
    v = t.raw(key)
    if not isinstance(v, list) or not v or not all(isinstance(x, int) and not isinstance(x, bool) for x in v):
        raise t.error(key, f"expected a count or a non-empty list of integers, got {v!r}")
    if not all(lo <= x <= hi for x in v) or len(set(v)) != len(v):
        raise t.error(key, f"seeds must be distinct and in [{lo}, {hi}]")
    return list(v)


def is_sweep_file(path: str | Path) -> bool:
    """Whether a TOML file declares a sweep (it has a ``[grid]`` table or a ``mission`` key)."""
    data = load_toml(path)
    return "grid" in data or isinstance(data.get("mission"), str)


# ----------------------------------------------------------------------------- execution


Report = Callable[[dict[str, Any]], None]  # called in the main process with each finished row


def _worker_init() -> None:
    # Ctrl-C goes to the whole process group: the main process stops the sweep; a worker
    # finishes (or is ended with) its cell rather than recording it as aborted.
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _pool(jobs: int) -> ProcessPoolExecutor:
    ctx = mp.get_context("forkserver")
    ctx.set_forkserver_preload(["bridge.sweep", "bridge.loop"])
    return ProcessPoolExecutor(max_workers=jobs, mp_context=ctx, initializer=_worker_init)


def _run_local(mission: Mission, todo: Sequence[Cell], mode: str, jobs: int, report: Report) -> None:
    """Fly cells in a local process pool, at most 2 x jobs in flight.

    If a worker process dies (the pool breaks), the cells that were in flight are flown
    again one at a time in a fresh one-worker pool: the one that breaks that one too is
    recorded as an error, the others get their real result.
    """
    queue: deque[Cell] = deque(todo)
    suspects: deque[Cell] = deque()
    while queue or suspects:
        if suspects:
            cell = suspects.popleft()
            with _pool(1) as p:
                try:
                    row = p.submit(run_cell, mission, cell, mode).result()
                except BrokenProcessPool:
                    row = error_row(cell, "worker process died")
            report(row)
            continue
        pool = _pool(jobs)
        inflight: dict[Any, Cell] = {}
        try:
            while queue or inflight:
                while queue and len(inflight) < 2 * jobs:
                    c = queue.popleft()
                    inflight[pool.submit(run_cell, mission, c, mode)] = c
                done, _ = wait(inflight, return_when=FIRST_COMPLETED)
                broken = False
                for f in done:
                    c = inflight.pop(f)
                    try:
                        report(f.result())
                    except BrokenProcessPool:
                        suspects.append(c)
                        broken = True
                if broken:
                    wait(inflight)
                    suspects.extend(inflight.values())
                    break
        finally:
            pool.shutdown(wait=True, cancel_futures=True)


def _run_dask(client: Any, mission: Mission, todo: Sequence[Cell], mode: str, report: Report) -> None:
    """Fly cells on a Dask distributed cluster; a task that fails there becomes an error row."""
    from distributed import as_completed

    mission_f = client.scatter(mission, broadcast=True)
    futures = {client.submit(run_cell, mission_f, c, mode, pure=False): c for c in todo}
    try:
        for f in as_completed(futures):
            c = futures[f]
            try:
                report(f.result())
            except Exception as exc:  # e.g. KilledWorker: the worker died on this cell
                report(error_row(c, f"{type(exc).__name__}: {exc}"))
    finally:
        client.cancel(list(futures))


class Progress:
    """Cells done / total, ETA and failures: a tqdm bar on a terminal, plain lines otherwise.

    Plain lines (about 20 per sweep, and at most one a second besides) go to stderr as
    ``sweep: 12/48 cells, 0 failed, ETA 3 s``; a test waits on them.
    """

    def __init__(self, total: int, done: int, stream: Any = None, enabled: bool = True) -> None:
        self.total, self.done, self.failed, self.ran = total, done, 0, 0
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = enabled
        self._bar = None
        self._t0 = time.monotonic()
        self._last = 0.0
        self._every = max(1, (total - done) // 20)
        if enabled and getattr(self.stream, "isatty", lambda: False)():
            from tqdm import tqdm

            self._bar = tqdm(total=total, initial=done, unit="cell", desc="sweep", file=self.stream,
                             dynamic_ncols=True, postfix={"failed": 0})

    def update(self, row: Mapping[str, Any]) -> None:
        self.done += 1
        self.ran += 1
        if row["outcome"] == "error":
            self.failed += 1
        if self._bar is not None:
            self._bar.set_postfix(failed=self.failed, refresh=False)
            self._bar.update(1)
            return
        now = time.monotonic()
        if self.enabled and (self.ran % self._every == 0 or now - self._last >= 1.0 or self.done == self.total):
            self._last = now
            rate = (now - self._t0) / self.ran
            self.stream.write(f"sweep: {self.done}/{self.total} cells, {self.failed} failed, "
                              f"ETA {rate * (self.total - self.done):.0f} s\n")
            self.stream.flush()

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()


def sweep(
    mission: Mission | str | Path,
    grid: Grid | Mapping[str, Any],
    *,
    jobs: int | None = None,
    client: Any = None,
    mode: str = "offline",
    out: str | Path | None = None,
    resume: bool = False,
    overwrite: bool = False,
    classes: Classes | None = None,
    progress: bool = False,
    report: bool = True,
    plots: bool = True,
) -> list[dict[str, Any]]:
    """Fly every cell of ``grid`` on ``mission``; return the rows in grid order.

    ``jobs``: local worker processes (default: all cores); ``client``: a
    ``distributed.Client`` to run the cells on a Dask cluster instead. With ``out`` the sweep
    directory is written (``sweep.json``, ``mission.toml``, ``cells.csv`` cell by cell, then
    ``report.md`` and the heat maps unless ``report`` is false); ``resume`` flies only the
    cells missing from its ``cells.csv`` (and those recorded as ``error``).
    """
    m = mission if isinstance(mission, Mission) else load_mission(mission)
    spec = Sweep(m, Grid.of(grid), mode, classes or Classes())
    return run_sweep(spec, jobs=jobs, client=client, out=out, resume=resume, overwrite=overwrite,
                     progress=progress, report=report, plots=plots).rows


@dataclass
class Outcome:
    """What :func:`run_sweep` did: all rows (grid order), how many it flew, the directory."""

    rows: list[dict[str, Any]]
    ran: int
    reused: int
    failed: int
    path: Path | None
    wall_s: float
    interrupted: bool = False


def run_sweep(
    spec: Sweep,
    *,
    jobs: int | None = None,
    client: Any = None,
    out: str | Path | None = None,
    resume: bool = False,
    overwrite: bool = False,
    progress: bool = False,
    report: bool = True,
    plots: bool = True,
    root: str | Path = "sweeps",
    write: bool = False,
) -> Outcome:
    """Run a :class:`Sweep` (see :func:`sweep`); ``write`` makes ``sweeps/<UTC>-<mission>``."""
    t0 = time.monotonic()
    spec.validate()
    all_cells = spec.cells()
    order = {c.key(): i for i, c in enumerate(all_cells)}
    jobs = jobs or spec.jobs or os.cpu_count() or 1
    results: dict[tuple[Any, ...], dict[str, Any]] = {}
    path: Path | None = None
    if out is not None or write:
        path, kept = _open_dir(spec, out, resume, overwrite, root)
        results.update({row_key(r): r for r in kept if row_key(r) in order})
    todo = [c for c in all_cells if c.key() not in results]
    sink = CellsFile(path / CELLS_CSV, [results[k] for k in sorted(results, key=order.__getitem__)]) if path else None
    bar = Progress(len(all_cells), len(results), enabled=progress)
    reused = len(results)

    def record(row: dict[str, Any]) -> None:
        if row["outcome"] == "aborted":  # interrupted, not a result: resume flies it again
            return
        from bridge.report import classify

        row["class"] = classify(row, spec.classes)
        results[row_key(row)] = row
        if sink is not None:
            sink.append(row)
        bar.update(row)

    interrupted = False
    try:
        if todo:
            if client is not None:
                _run_dask(client, spec.mission, todo, spec.mode, record)
            else:
                _run_local(spec.mission, todo, spec.mode, jobs, record)
    except KeyboardInterrupt:
        interrupted = True
    finally:
        bar.close()
        if sink is not None:
            sink.close()
    rows = [results[c.key()] for c in all_cells if c.key() in results]
    if path is not None and not interrupted:
        write_cells(path / CELLS_CSV, rows)
        if report:
            from bridge.report import write_report

            write_report(path, rows, spec.identity(), plots=plots)
    failed = sum(1 for r in rows if r["outcome"] == "error")
    return Outcome(rows, len(rows) - reused, reused, failed, path, time.monotonic() - t0, interrupted)


def _open_dir(spec: Sweep, out: str | Path | None, resume: bool, overwrite: bool,
              root: str | Path) -> tuple[Path, list[dict[str, Any]]]:
    """The sweep directory, and the rows already in it that ``resume`` keeps."""
    ident = spec.identity()
    if resume:
        if out is None:
            raise ConfigError("--resume: needs --out DIR, the directory of the sweep to resume")
        path = Path(out)
        meta = path / SWEEP_JSON
        if meta.exists():
            old = read_sweep_json(meta)
            if old != ident:
                diff = sorted(k for k in ident if old.get(k) != ident[k])
                raise ConfigError(f"--resume: {path} holds a different sweep ({', '.join(diff)} differ); "
                                  f"use another --out")
            kept = [r for r in read_cells(path / CELLS_CSV) if r["outcome"] != "error"] \
                if (path / CELLS_CSV).exists() else []
            return path, kept
        if path.exists() and any(path.iterdir()):
            raise ConfigError(f"--resume: {path} holds no {SWEEP_JSON}; not a sweep directory")
    path = run_dir(out, spec.mission.name, overwrite, root=root)
    plots_dir = path / "plots"  # run_dir makes it for a run; a sweep keeps its maps at the top
    if plots_dir.is_dir() and not any(plots_dir.iterdir()):
        plots_dir.rmdir()
    for stale in path.glob("map_*.png"):
        stale.unlink()
    write_json_atomic(path / SWEEP_JSON, ident)
    (path / "mission.toml").write_text(dump_toml(spec.mission.to_dict()))
    return path, []


def read_sweep_json(path: Path) -> dict[str, Any]:
    """A sweep's ``sweep.json`` (ConfigError naming the file if unreadable)."""
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise ConfigError(f"{path}: unreadable ({exc})") from None

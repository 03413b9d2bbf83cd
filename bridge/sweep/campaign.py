"""A campaign from start to end: open (or resume) the sweep directory, fly the missing cells,
record each as it comes, rewrite ``cells.csv`` in grid order, write the report.

In:  a :class:`~bridge.sweep.spec.Sweep` (for :func:`sweep`: a mission and a grid), ``jobs`` workers
     or a Dask client, a sweep directory to write or to resume
Out: an :class:`Outcome` (every row in grid order, counts, wall time s, the directory); in the
     directory ``sweep.json``, ``mission.toml``, ``cells.csv``, ``report.md`` and the heat maps
"""

from __future__ import annotations

import hashlib
import os
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bridge.core.interrupt import sigint_held
from bridge.core.overrides import check_switches
from bridge.record.outlock import holding_out
from bridge.record.runlog import check_out_dir, run_dir, write_json_atomic
from bridge.sweep.cells import (
    CELLS_CSV,
    COLUMNS,
    ENGINES,
    FAILED,
    FLEET_COLUMNS,
    INPUT_HASHES,
    MISSION_HASH,
    SWEEP_JSON,
    UNRECORDED,
    CellsFile,
    one_per_cell,
    read_cells,
    read_sweep_json,
    row_key,
    write_cells,
)
from bridge.sweep.classes import Classes, classify
from bridge.sweep.executors import (
    BATCH_CHUNK,
    check_main_guard,
    engine_for,
    run_batch,
    run_batch_dask,
    run_dask,
    run_local,
)
from bridge.sweep.grid import Grid
from bridge.sweep.inputs import check_inputs, input_hashes
from bridge.sweep.progress import Progress
from bridge.sweep.report import check_report_files, write_report
from bridge.sweep.spec import Sweep, check_jobs
from missions import Mission, load_mission
from params import ConfigError, dump_toml, look_up, read_regular_file, reads_inputs

MISSION_TOML = "mission.toml"


@reads_inputs
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
    classes: Classes | Mapping[str, float] | None = None,
    progress: bool = False,
    report: bool = True,
    plots: bool = True,
    max_cells: int | None = None,
    engine: str = "auto",
) -> list[dict[str, Any]]:
    """Fly every cell of ``grid`` on ``mission``; return the rows in grid order.

    ``jobs``: local worker processes (default: all cores); ``client``: a
    ``distributed.Client`` to run the cells on a Dask cluster instead. With ``out`` the sweep
    directory is written (``sweep.json``, ``mission.toml``, ``cells.csv`` cell by cell, then
    ``report.md`` and the heat maps unless ``report`` is false); ``resume`` flies only the
    cells missing from its ``cells.csv`` (and those recorded as ``error``). ``engine``: ``batch``
    flies the cells together in one numpy loop (:mod:`bridge.batch`), ``process`` one by one;
    ``auto`` takes the batch where the grid allows it (:func:`bridge.sweep.executors.engine_for`).
    A grid of more than
    ``max_cells`` cells (default :data:`bridge.sweep.spec.MAX_CELLS`) is refused before anything flies.

    A cell that fails is an ``error`` row (its ``error`` column says why); a sweep whose every cell
    failed raises :class:`SweepFailed` (naming the first error; the rows in its ``outcome``), so that it
    never passes for a result. :func:`run_sweep` raises nothing for it: its :class:`Outcome`'s ``status``
    says ``"all failed"``.

    Worker processes import the calling script again: a script calls this under
    ``if __name__ == "__main__":`` (refused at once without it: :func:`~bridge.sweep.executors.check_main_guard`).
    """
    check_switches(resume=resume, overwrite=overwrite, progress=progress, report=report, plots=plots)
    if client is not None and not callable(getattr(client, "submit", None)):  # (5: AttributeError 'nthreads')
        raise TypeError(f"client: expected a distributed.Client, got {client!r}"[:200])
    m = mission if isinstance(mission, Mission) else load_mission(mission)
    spec = Sweep(m, Grid.of(grid), mode, Classes.of(classes), max_cells=max_cells)
    res = run_sweep(spec, jobs=jobs, client=client, out=out, resume=resume, overwrite=overwrite, engine=engine,
                    progress=progress, report=report, plots=plots)
    if res.status == "all failed":
        raise SweepFailed(res)
    return res.rows


STATUSES = ("ok", "cells failed", "all failed", "interrupted")  # Outcome.status


# when a Ctrl-C came that stopped nothing (Outcome.stop_held): the cells flew to their end and the record is whole
STOPS_HELD = {"flying": "after its last cell was handed out: the cells in flight flew to their end",
              "writing": "while it wrote its record, every cell flown: the stop was held until cells.csv, sweep.json "
                         "and the report were whole"}


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
    engine: str = "process"  # what flew the cells: batch or process (the grid decides for "auto")
    engine_why: str = ""
    total: int = 0  # the grid's cells (len(rows) below it: interrupted, or a sweep of no rows yet)
    engines: list[str] = field(default_factory=list)  # what flew every row, kept ones too (two: mixed by a resume)
    stop_held: str = ""  # a Ctrl-C that stopped nothing (the sweep whole): "" none, else when (STOPS_HELD)

    @property
    def status(self) -> str:
        """One of :data:`STATUSES`: ``ok`` (no cell failed), ``cells failed`` (some), ``all failed`` (every row an
        ``error`` or ``law_failed``: nothing was measured), ``interrupted`` (stopped before its end; resume it)."""
        if self.interrupted:
            return "interrupted"
        if self.rows and self.failed == len(self.rows):
            return "all failed"
        return "cells failed" if self.failed else "ok"

    def first_error(self) -> str:
        """The ``error`` column of the first failed row ('' if none failed)."""
        return next((r["error"] or r["outcome"] for r in self.rows if r["outcome"] in FAILED), "")


class SweepFailed(Exception):
    """Every cell of a sweep failed (:func:`sweep`); ``outcome`` is the :class:`Outcome`, its rows included."""

    def __init__(self, outcome: Outcome) -> None:
        super().__init__(f"every cell of the sweep failed ({outcome.failed} of {len(outcome.rows)}); the first: "
                         f"{outcome.first_error()}")
        self.outcome = outcome


@reads_inputs
@holding_out  # one sweep writes its --out at a time (a resume too)
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
    engine: str = "auto",
) -> Outcome:
    """Run a :class:`Sweep` (see :func:`sweep`); ``write`` makes ``sweeps/<UTC>-<mission>``."""
    t0 = time.monotonic()
    spec.validate()
    all_cells = spec.cells()
    order = {c.key(): i for i, c in enumerate(all_cells)}
    check_jobs(jobs)
    jobs = jobs or spec.jobs or os.cpu_count() or 1
    results: dict[tuple[Any, ...], dict[str, Any]] = {}
    path: Path | None = None
    # the engine is the whole grid's (an --engine it cannot honour: refused before any file), so that a resume flies
    # the missing cells as the uninterrupted sweep would have, and its cells.csv is that sweep's byte for byte
    used, used_why = engine_for(spec.mission, all_cells, spec.mode, engine)
    if used == "process" and client is None:
        check_main_guard()  # a pool started from an unguarded script: refused before any file or flight
    engines: list[str] = []  # what flew the rows kept from before (sweep.json)
    if out is not None or write:
        path, kept, engines = _open_dir(spec, out, resume, overwrite, root)
        if resume and report:  # a report.md or map a directory: refused before any cell flies, as --overwrite does
            check_report_files(path, plots)
        results.update({row_key(r): r for r in kept if row_key(r) in order})
    todo = [c for c in all_cells if c.key() not in results]
    sink = CellsFile(path / CELLS_CSV, [results[k] for k in sorted(results, key=order.__getitem__)]) if path else None
    bar = Progress(len(all_cells), len(results), enabled=progress, lanes=_lanes(used, client, jobs))
    reused = len(results)

    def record(row: dict[str, Any]) -> None:
        if row["outcome"] == "aborted":  # interrupted, not a result: resume flies it again
            return
        row["class"] = classify(row, spec.classes)
        for column in FLEET_COLUMNS:  # one vehicle's row (and a batch row): empty, as cells.csv reads back
            row.setdefault(column, None)
        results[row_key(row)] = row
        if sink is not None:
            sink.append(row)
        bar.update(row)

    interrupted = False
    # a Ctrl-C stops the flights only: once they are over (every cell flown, or the stop taken) it is held, so that
    # the record and the report are written whole (it landed there and ended a whole sweep 'interrupted', exit 1,
    # with no report.md), and a whole sweep's stops nothing (docs/campaigns.md)
    with sigint_held() as held:
        try:
            with held.released():
                _fly(spec, todo, used, client, jobs, record)
        except KeyboardInterrupt:
            interrupted = True
        finally:
            bar.close()
            if sink is not None:
                sink.close()
        rows = [results[c.key()] for c in all_cells if c.key() in results]
        stopped = interrupted
        interrupted = interrupted and len(rows) < len(all_cells)  # a stop after the last cell was handed out: whole
        if len(rows) > reused and used not in engines:
            engines = [*engines, used]
        if path is not None:
            _record_engines(path / SWEEP_JSON, engines)
        if path is not None and not interrupted:
            write_cells(path / CELLS_CSV, rows)
            if report:
                write_report(path, rows, spec.identity() | {ENGINES: engines}, plots=plots)
        failed = sum(1 for r in rows if r["outcome"] in FAILED)
    # (read once the block has handled a stop that came in its last lines: sigint_held)
    stop_held = "" if interrupted else "flying" if stopped else "writing" if held.pending else ""
    return Outcome(rows, len(rows) - reused, reused, failed, path, time.monotonic() - t0, interrupted, used,
                   used_why, len(all_cells), engines, stop_held)


def _lanes(used: str, client: Any, jobs: int) -> int:
    """The cells that fly at once, each round's first carrying the start-up (the progress bar's lanes): a batch
    chunk's rows come together, and a Dask cluster's threads each fly a task."""
    if client is not None:
        at_once = sum(client.nthreads().values()) or 1
    else:
        at_once = 1 if used == "batch" else jobs  # (the batch engine: one chunk at a time)
    return (BATCH_CHUNK if used == "batch" else 1) * at_once


def _fly(spec: Sweep, todo: list[Any], used: str, client: Any, jobs: int,
         record: Callable[[dict[str, Any]], None]) -> None:
    """Fly the cells ``todo`` on the engine ``used`` (batch or one process a cell), on ``client``'s Dask cluster if
    given, else here on ``jobs`` cores; each row to ``record`` as it comes."""
    if todo and used == "batch":
        if client is not None:
            run_batch_dask(client, spec.mission, todo, record)
        else:
            run_batch(spec.mission, todo, record, jobs=jobs)
    elif todo:
        if client is not None:
            run_dask(client, spec.mission, todo, spec.mode, record)
        else:
            run_local(spec.mission, todo, spec.mode, jobs, record)


def _open_dir(spec: Sweep, out: str | Path | None, resume: bool, overwrite: bool,
              root: str | Path) -> tuple[Path, list[dict[str, Any]], list[str]]:
    """The sweep directory, the rows already in it that ``resume`` keeps, and the engines that flew them."""
    ident = spec.identity()
    if resume:
        if out is None:
            raise ConfigError("--resume: needs --out DIR, the directory of the sweep to resume")
        path = Path(out)
        check_out_dir(path)  # a file, a FIFO, /dev/null: refused as without --resume
        if look_up(path)[0] is None:  # nothing to resume: a typo in the name far more often than a plan
            raise ConfigError(f"--resume: --out {path}: no such directory, so no sweep to resume (to start a new "
                              "sweep there, drop --resume)")
        meta = path / SWEEP_JSON
        if meta.exists():
            old = read_sweep_json(meta)
            lacks = [c for c in COLUMNS if c not in old.get("columns", COLUMNS)]
            if lacks:  # before the vehicle's or the air's axes: another cells.csv
                raise ConfigError(f"--resume: {meta}: a sweep of an older bsst (its {CELLS_CSV} has no "
                                  f"{', '.join(lacks)} columns); bsst report still reads it; fly the sweep into "
                                  "another --out")
            recorded = old.pop(MISSION_HASH, None)
            inputs, engines = old.pop(INPUT_HASHES, {}), old.pop(ENGINES, [UNRECORDED])  # (an older bsst's)
            if old != ident:
                diff = sorted(k for k in ident if old.get(k) != ident[k])
                raise ConfigError(f"--resume: {path} holds a different sweep ({', '.join(diff)} differ); "
                                  f"use another --out")
            _check_mission_toml(path, recorded, spec)
            check_inputs(inputs, meta)
            rows = read_cells(path / CELLS_CSV, classes=spec.classes, meta=old) if (path / CELLS_CSV).exists() else []
            kept = one_per_cell(r for r in rows if r["outcome"] != "error")  # (an older sweep's smc: once per scheme)
            return path, kept, engines if kept else []
        if path.exists() and any(path.iterdir()):
            raise ConfigError(f"--resume: {path} holds no {SWEEP_JSON}; not a sweep directory")
    path = run_dir(out, spec.mission.name, overwrite, root=root)
    plots_dir = path / "plots"  # run_dir makes it for a run; a sweep keeps its maps at the top
    if plots_dir.is_dir() and not any(plots_dir.iterdir()):
        plots_dir.rmdir()
    for stale in path.glob("map_*.png"):
        stale.unlink()
    text = dump_toml(spec.mission.to_dict())
    (path / MISSION_TOML).write_text(text, encoding="utf-8")
    records = {MISSION_HASH: _sha256(text.encode()), INPUT_HASHES: input_hashes(ident), ENGINES: []}
    write_json_atomic(path / SWEEP_JSON, ident | records)
    return path, [], []


def _record_engines(meta: Path, engines: list[str]) -> None:
    """Write into ``sweep.json`` the engines that flew its rows (after a run; its other fields as they were)."""
    old = read_sweep_json(meta)
    if old.get(ENGINES) != engines:
        write_json_atomic(meta, old | {ENGINES: engines})


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _check_mission_toml(path: Path, recorded: str | None, spec: Sweep) -> None:
    """Refuse to resume into a directory whose ``mission.toml`` is not the one the sweep wrote (its hash in
    ``sweep.json``; a sweep.json of before the hash: the text the sweep's mission gives): every row, kept and
    new, must be one flight of the ``mission.toml`` beside it (report.md says so)."""
    f = path / MISSION_TOML
    try:
        data = read_regular_file(f, "the sweep's mission.toml")
    except ConfigError as exc:
        raise ConfigError(f"--resume: {exc} (the mission every cell flies; restore it, or fly the sweep into another "
                          f"--out)") from None
    same = _sha256(data) == recorded if recorded is not None else data == dump_toml(spec.mission.to_dict()).encode()
    if not same:
        raise ConfigError(f"--resume: {f}: edited after the sweep ({SWEEP_JSON} records another mission.toml): its "
                          f"rows fly the mission the sweep recorded; restore the file, or fly the sweep into another "
                          f"--out")

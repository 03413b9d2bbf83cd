"""The batch engine's flight: many cells of one mission flown at once, over a cell axis (numpy and numba).

In:  a mission (a :class:`~missions.Mission` or a TOML path) and, per cell, its
     :class:`~bridge.core.overrides.Overrides` (``controller``, ``discretization``, ``rate_hz`` Hz, ``seed``, a
     ``link`` table: what :func:`bridge.sweep.grid.cell_overrides` gives; or those fields as a mapping), or prepared
     :class:`~bridge.core.flight.Flight` s
Out: per cell the measured columns of a ``cells.csv`` row (:data:`MEASURES`: ``rms``/``max`` m,
     ``settling_s``/``flown_s`` s, ``tv_u2`` N/s, ``ripple_u2`` N, ``outcome``, packet counts, ``error``),
     the same numbers :func:`bridge.sweep.cells.row_from_run` takes from the scalar loop's run

The scalar loop (:func:`bridge.loop.fly`) stays the reference; this engine flies the same parts cell by
cell: the link model, the guard and the vehicle's timeout first, as a plan of the whole flight
(:func:`bridge.link.plan.plan_links`: with no bandwidth queue and no re-arming nothing of it depends
on the flight), then each cell's whole flight along it in one compiled call (:mod:`bridge.batch.flight`:
the wire, the prediction, the law and actuation, the physics steps, the failsafe landing, the running
figures), blocks of cells on ``jobs`` threads. The metrics are accumulated as the flight goes (running
sums and maxima, the last step outside the settling band), with one column kept whole, u2, for the
ripple of each cell's own second half; no trace is held.

What may be flown here, and why not (:func:`bridge.batch.scope.batch_problem`), is
:mod:`bridge.batch.scope`'s, which imports no numba.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from bridge.batch.flight import Cells, Constants, batch_arrays, fly_cells
from bridge.batch.metrics import Metrics, measured_rows
from bridge.batch.scope import CELL_STEPS, _prepare_all, flights_problem
from bridge.batch.weather import turbulent
from bridge.core.flight import Flight
from bridge.core.interrupt import sigint_futures, wait_or_interrupt
from bridge.core.overrides import Overrides
from bridge.link.model import jitter_cell
from bridge.link.plan import Clocks, plan_links
from bridge.record.metrics import RMS_FROM_S
from missions import MISSION_DIR, Mission, Sine, load_mission
from params.text import one_line

# the columns of a cells.csv row this engine measures (the cell's own axes and seed come from the cell)
MEASURES = ("rms", "max", "settling_s", "tv_u2", "ripple_u2", "outcome", "up_sent", "up_lost", "down_sent",
            "down_lost", "flown_s", "error", "policies", "jitter_capped")
# cells x physics steps of a batch that meets turbulence (its samples, 3 floats a physics step, are held for the
# whole flight: bridge.batch.weather): 120 MiB of them (the 30 s sine at 1 kHz: 166 cells a batch)
TURBULENCE_STEPS = 5_000_000
BLOCK_CELLS = 8  # cells a thread flies in one compiled call (~0.1 s of the 30 s sine): small enough to share out evenly
Progress = Callable[[int, int], None]  # (cells done, cells in all), now and then


def fly_batch(mission: Mission | str | Path, cells: Sequence[Overrides | Mapping[str, Any]], *,
              progress: Progress | None = None, jobs: int | None = None) -> list[dict[str, Any]]:
    """Fly every cell (the overrides of :func:`bridge.core.flight.prepare`) and return, in order, the
    measured columns (:data:`MEASURES`) of each one's ``cells.csv`` row; a cell that cannot be built gets
    outcome ``error`` and its message. ValueError (:func:`~bridge.batch.scope.batch_problem`'s line) if the batch
    cannot fly them. ``jobs``: threads flying cells (default: every core); the rows do not depend on it."""
    m = mission if isinstance(mission, Mission) else load_mission(mission)
    built = _prepare_all(m, cells)
    flights = [f for f in built if isinstance(f, Flight)]
    results = iter(fly_flights(flights, progress=progress, total=len(built), jobs=jobs))
    return [{**next(results), "jitter_capped": jitter_cell(f.link.jitter_capped())} if isinstance(f, Flight)
            else error_measures(f) for f in built]


def compile_batch() -> None:
    """Compile, or load from numba's on-disk cache, this engine's kernels in this process, by flying a
    few steps of every kind of cell: each law, wrench (paper) and motors (x500), plant effects, a lossy
    delayed link with prediction. A first batch on a machine compiles them (~23 s of CPU here: the whole
    flight's kernel inlines its helpers); after it, ~1 s."""
    cells = [{"controller": law} for law in ("bsst", "smc", "pid")]
    cells.append({"link": {"delay_ms": 8.0, "loss_pct": 10.0, "compensation": "predict"}})
    x500 = load_mission(MISSION_DIR / "robust-x500.toml")
    for m in (Mission(Sine(), duration_s=0.1), replace(x500, duration_s=0.1)):
        fly_batch(m, cells)


def error_measures(why: str) -> dict[str, Any]:
    """The measured columns of a cell that could not be flown (outcome ``error``)."""
    out: dict[str, Any] = {c: None for c in MEASURES}
    out.update(outcome="error", error=one_line(why), policies="", jitter_capped="")
    return out


def fly_flights(flights: Sequence[Flight], *, progress: Progress | None = None,
                total: int | None = None, jobs: int | None = None) -> list[dict[str, Any]]:
    """Fly prepared flights (of one mission, see :func:`~bridge.batch.scope.flights_problem`) on ``jobs`` threads
    (default: every core); the measured columns of each."""
    why = flights_problem(flights)
    if why:
        raise ValueError(why)
    out: list[dict[str, Any] | None] = [None] * len(flights)
    by_rate: dict[float, list[int]] = {}
    for i, f in enumerate(flights):
        by_rate.setdefault(f.mission.rate_hz, []).append(i)
    total = len(flights) if total is None else total
    done = total - len(flights)
    for idx in by_rate.values():
        f0 = flights[idx[0]]
        most = 1024
        if turbulent([flights[i] for i in idx]):
            most = TURBULENCE_STEPS // max(1, f0.mission.steps * f0.substeps)
        size = max(1, min(len(idx), CELL_STEPS // max(1, f0.mission.steps), most))
        for a in range(0, len(idx), size):
            part = idx[a:a + size]

            def report(k: int, of: int, base: int = done, n: int = len(part)) -> None:
                if progress is not None:
                    progress(base + n * k // max(of, 1), total)

            rows = _Batch([flights[i] for i in part]).fly(report, jobs or os.cpu_count() or 1)
            for i, r in zip(part, rows, strict=True):
                out[i] = r
            done += len(part)
            if progress is not None:
                progress(done, total)
    return [r for r in out if r is not None]


class _Batch:
    """One batch: flights of one mission and one control rate."""

    def __init__(self, flights: Sequence[Flight]) -> None:
        self.flights = list(flights)
        f0 = self.flights[0]
        m = f0.mission
        self.mission = m
        self.n = len(self.flights)
        self.clocks = Clocks(m.rate_hz, m.physics_hz, f0.substeps, m.steps)

    def fly(self, report: Callable[[int, int], None], jobs: int) -> list[dict[str, Any]]:
        fl = self.flights
        m = self.mission
        clocks = self.clocks
        steps = clocks.steps
        plan = plan_links([f.link for f in fl], [f.guard for f in fl], fl[0].failsafe.timeout_s, clocks, jobs)
        t_all = clocks.step_t
        c, a = batch_arrays(fl, plan, clocks, _references(m, t_all), lambda lag: _references(m, t_all + lag))
        _fly_blocks(c, a, steps, jobs, report)
        flown = a.flown
        outcome = np.where(a.diverged, "diverged", np.where(a.crashed, "crashed", np.where(
            plan.failsafe_step < flown, "failsafe", "completed")))
        met = Metrics(a.sq_sum, a.sq_max, a.last_out, a.tv, a.u2.T)  # u2 as the ripple reads it, [steps, n]
        rms_from = min(RMS_FROM_S, 0.5 * m.duration_s)
        return measured_rows(met, flown, outcome, plan.counts(flown), list(m.trajectory.change_times()), rms_from,
                             t_all, clocks.rate_hz)


def _fly_blocks(c: Constants, a: Cells, steps: int, jobs: int, report: Callable[[int, int], None]) -> None:
    """Fly every cell's whole flight, :data:`BLOCK_CELLS` at a time, on ``jobs`` threads (the kernel runs
    without the GIL); report (cells done, cells) as blocks end. Blocks are handed out as threads come
    free, so a core slowed by other work takes fewer; each cell flies alone, so the rows are the same. A Ctrl-C
    raises KeyboardInterrupt, one after the last block's wait too (as :func:`bridge.sweep.executors.run_local`)."""
    n = a.X.shape[0]
    blocks = [(lo, min(n, lo + BLOCK_CELLS)) for lo in range(0, n, BLOCK_CELLS)]
    done = 0
    if jobs <= 1 or len(blocks) == 1:
        for lo, hi in blocks:
            fly_cells(lo, hi, 0, steps, c, a)
            done += hi - lo
            report(done, n)
        return
    # Ctrl-C raises between waits, never inside the pool's locks (bridge.core.interrupt)
    with sigint_futures() as sigint, ThreadPoolExecutor(min(jobs, len(blocks))) as pool:
        running = {pool.submit(fly_cells, lo, hi, 0, steps, c, a): hi - lo for lo, hi in blocks}
        try:
            while running:
                for f in wait_or_interrupt(running, sigint.first):
                    f.result()
                    done += running.pop(f)
                    report(done, n)
        finally:
            for f in running:
                f.cancel()
    if sigint.first.done():  # taken after the last wait (read once the block has read every SIGINT): not lost
        raise KeyboardInterrupt


def _references(m: Mission, times: np.ndarray) -> np.ndarray:
    """[len(times), 4, 5]: the reference sample (x, y, z, psi; value and 4 derivatives) at each time."""
    sample = m.trajectory.sample
    return np.array([sample(float(t)) for t in times])


__all__ = ["MEASURES", "compile_batch", "error_measures", "fly_batch", "fly_flights"]
